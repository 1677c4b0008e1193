//! Top-down pictures: the whole of one route run (lanes coloured by type, the route in blue, the
//! ego's trace in green, red where it ended, other actors at the end of the run, each
//! infraction as a marker coloured by kind; a title, a legend and a scale bar), and the local
//! view around the ego at one instant
//! that `sim-bridge render` puts beside the camera frames, with the agent's planned trajectory
//! and target point drawn over it.

use std::path::Path;

use glam::{DVec2, DVec3};

use super::canvas::Canvas;
use crate::map::{LaneKind, Map};
use crate::route::DenseRoute;
use crate::scoring::{Infraction, InfractionKind};
use crate::world::ActorView;
use crate::world::state::{ActorKind, EgoState, Obb};

/// Longest side of the picture, px.
const MAX_SIDE: u32 = 1400;
/// Terrain colour.
const BACKGROUND: [u8; 3] = [34, 92, 46];

/// What the driver intends at one instant, drawn over the local view in the ego frame (x
/// forward, y left, metres, origin at the box centre): the route follower's target point and
/// the trajectory the agent planned (empty for agents that plan none).
#[derive(Debug, Clone, Copy, Default)]
pub struct Intent<'a> {
    /// The target point the agent was given.
    pub target_point: Option<DVec2>,
    /// The agent's planned waypoints.
    pub plan: &'a [DVec2],
}

/// Colour of the planned trajectory.
const PLAN_COLOUR: [u8; 3] = [40, 230, 230];
/// Colour of the target point.
const TARGET_COLOUR: [u8; 3] = [235, 60, 235];

/// The `radius` metres around the ego at one instant, north up, `side` pixels square: lanes,
/// stop lines, the route, the actors, the ego (white, with its heading) and what it intends
/// (the planned trajectory in cyan, the target point in magenta).
pub fn local_view(
    map: &Map,
    route: &DenseRoute,
    ego: &EgoState,
    actors: &[ActorView],
    intent: Intent<'_>,
    radius: f64,
    side: u32,
) -> Canvas {
    let centre = ego.position.truncate();
    let mut c = Canvas::around(centre, radius, side, BACKGROUND);
    draw_map(&mut c, map, route, Some((centre, radius * 1.5)));
    for a in actors {
        if (a.obb.centre - centre).length() < radius * 1.5 {
            draw_box(&mut c, &a.obb, actor_colour(a.kind));
        }
    }
    draw_box(&mut c, &ego.obb(), [255, 255, 255]);
    let nose = centre + ego.forward() * ego.half_extent.x;
    c.line(centre, nose, 0.4, [240, 40, 40]);
    let to_world = |p: DVec2| centre + ego.forward() * p.x + ego.forward().perp() * p.y;
    let plan: Vec<DVec2> = std::iter::once(centre)
        .chain(intent.plan.iter().map(|&p| to_world(p)))
        .collect();
    for w in plan.windows(2) {
        c.line(w[0], w[1], 0.3, PLAN_COLOUR);
    }
    for &p in &plan[1..] {
        c.disc(p, 0.45, PLAN_COLOUR);
    }
    if let Some(target) = intent.target_point {
        c.disc(to_world(target), 0.9, TARGET_COLOUR);
    }
    c
}

/// Lanes by type, stop lines and the route; with `near`, only what lies within the given
/// distance of the given point.
fn draw_map(c: &mut Canvas, map: &Map, route: &DenseRoute, near: Option<(DVec2, f64)>) {
    let keep = |p: DVec2| near.is_none_or(|(centre, r)| (p - centre).length() < r);
    for lane in &map.lanes {
        let colour = match lane.kind {
            LaneKind::Driving => [70, 70, 74],
            LaneKind::Parking => [95, 95, 100],
            LaneKind::Sidewalk => [160, 155, 145],
            LaneKind::Shoulder => [110, 105, 95],
            LaneKind::Other => [80, 110, 80],
        };
        for w in lane.points.windows(2) {
            let (a, b) = (w[0].truncate(), w[1].truncate());
            if keep(a) || keep(b) {
                c.line(a, b, lane.width, colour);
            }
        }
    }
    for line in map.lights.iter().flat_map(|l| &l.stop_lines) {
        let (a, b) = line.ends(1.0);
        if keep(a) {
            c.line(a, b, 0.6, [230, 230, 230]);
        }
    }
    for w in route.points.windows(2) {
        let (a, b) = (w[0].position.truncate(), w[1].position.truncate());
        if keep(a) || keep(b) {
            c.line(a, b, 1.2, ROUTE_COLOUR);
        }
    }
}

fn actor_colour(kind: ActorKind) -> [u8; 3] {
    match kind {
        ActorKind::Vehicle => [240, 200, 60],
        ActorKind::Cyclist => [250, 140, 40],
        ActorKind::Walker => [250, 90, 200],
        ActorKind::Static => [150, 120, 90],
        ActorKind::Debris => [90, 80, 70],
    }
}

fn draw_box(c: &mut Canvas, obb: &Obb, colour: [u8; 3]) {
    let (f, l) = obb.axes();
    let (hx, hy) = (f * obb.half.x, l * obb.half.y);
    let o = obb.centre;
    c.polygon(
        &[o + hx + hy, o - hx + hy, o - hx - hy, o + hx - hy],
        colour,
    );
}

/// Colours of a run picture's marks, in legend order.
const TRACE_COLOUR: [u8; 3] = [80, 230, 90];
const ROUTE_COLOUR: [u8; 3] = [60, 120, 235];
const START_COLOUR: [u8; 3] = [255, 255, 255];
const END_COLOUR: [u8; 3] = [240, 40, 40];
const COLLISION_COLOUR: [u8; 3] = [255, 0, 0];
const SIGNAL_COLOUR: [u8; 3] = [255, 0, 255];
const OTHER_INFRACTION_COLOUR: [u8; 3] = [255, 255, 0];
/// The title band's colour and its text's.
const HEADER: [u8; 3] = [24, 24, 28];
const HEADER_TEXT: [u8; 3] = [235, 235, 235];
/// Glyph scale of the title and legend (8 px glyphs times this).
const TEXT_SIZE: i64 = 2;

/// The colour of an infraction's marker.
fn infraction_colour(kind: InfractionKind) -> [u8; 3] {
    match kind {
        InfractionKind::CollisionPedestrian
        | InfractionKind::CollisionVehicle
        | InfractionKind::CollisionLayout => COLLISION_COLOUR,
        InfractionKind::RedLight | InfractionKind::StopSign => SIGNAL_COLOUR,
        _ => OTHER_INFRACTION_COLOUR,
    }
}

/// Draw a run and write it as PNG to `path`, with `title` (route, repetition, status, scores)
/// above a legend of what the colours mean, and a scale bar.
pub fn write_run_png(
    map: &Map,
    route: &DenseRoute,
    trace: &[DVec3],
    actors: &[ActorView],
    infractions: &[Infraction],
    title: &str,
    path: &Path,
) -> std::io::Result<()> {
    let line = 10 * TEXT_SIZE;
    let mut c = Canvas::fit(map.bounds.0, map.bounds.1, 10.0, MAX_SIDE, BACKGROUND)
        .with_header((3 * line + 8) as u32, HEADER);
    draw_map(&mut c, map, route, None);
    for w in trace.windows(2) {
        c.line(w[0].truncate(), w[1].truncate(), 0.9, TRACE_COLOUR);
    }
    for a in actors {
        draw_box(&mut c, &a.obb, actor_colour(a.kind));
    }
    if let Some(last) = trace.last() {
        c.disc(last.truncate(), 2.5, END_COLOUR);
    }
    if let Some(first) = route.points.first() {
        c.disc(first.position.truncate(), 2.5, START_COLOUR);
    }
    for inf in infractions {
        c.disc(inf.location.truncate(), 4.0, [0, 0, 0]);
        c.disc(inf.location.truncate(), 3.0, infraction_colour(inf.kind));
    }
    c.text_px(8, 6, title, TEXT_SIZE, HEADER_TEXT);
    legend(&mut c, 8, 6 + line + 4, line);
    scale_bar(&mut c);
    let file = std::fs::File::create(path)?;
    c.write_png(std::io::BufWriter::new(file))
        .map_err(std::io::Error::other)
}

/// Two rows of swatches and names, from pixel (`x`, `y`), `line` pixels apart.
fn legend(c: &mut Canvas, x: i64, y: i64, line: i64) {
    let rows: [&[(&str, [u8; 3])]; 2] = [
        &[
            ("route", ROUTE_COLOUR),
            ("trace", TRACE_COLOUR),
            ("start", START_COLOUR),
            ("end", END_COLOUR),
            ("collision", COLLISION_COLOUR),
            ("red light/stop", SIGNAL_COLOUR),
            ("other infraction", OTHER_INFRACTION_COLOUR),
        ],
        &[
            ("vehicle", actor_colour(ActorKind::Vehicle)),
            ("cyclist", actor_colour(ActorKind::Cyclist)),
            ("walker", actor_colour(ActorKind::Walker)),
            ("prop", actor_colour(ActorKind::Static)),
        ],
    ];
    for (r, items) in rows.iter().enumerate() {
        let mut at = x;
        let top = y + r as i64 * line;
        for (name, colour) in *items {
            c.rect_px(at, top + 2, 12, 12, *colour);
            at = c.text_px(at + 16, top, name, TEXT_SIZE, HEADER_TEXT) + 20;
        }
    }
}

/// A white bar of a round length (10 m to 1 km, about a fifth of the width at most) at the
/// bottom left, its length written above it.
fn scale_bar(c: &mut Canvas) {
    let width_m = c.width as f64 / c.scale();
    let metres = [10.0, 20.0, 50.0, 100.0, 200.0, 500.0, 1000.0]
        .into_iter()
        .rev()
        .find(|&m| m <= 0.2 * width_m)
        .unwrap_or(10.0);
    let length = (metres * c.scale()).round() as i64;
    let (x, y) = (12, c.height as i64 - 14);
    c.rect_px(x - 1, y - 1, length + 2, 8, [0, 0, 0]);
    c.rect_px(x, y, length, 6, [255, 255, 255]);
    c.text_px(
        x,
        y - 20,
        &format!("{metres:.0} m"),
        TEXT_SIZE,
        [255, 255, 255],
    );
}
