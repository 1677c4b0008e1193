//! The top-down picture of one route run: lanes coloured by type, the route in blue, the ego's
//! trace in green (red where it ended), other actors at the end of the run, and each infraction
//! as a marker coloured by kind.

use std::path::Path;

use glam::{DVec2, DVec3};

use super::canvas::Canvas;
use crate::map::{LaneKind, Map};
use crate::route::DenseRoute;
use crate::scoring::{Infraction, InfractionKind};
use crate::world::ActorView;
use crate::world::state::ActorKind;

/// Longest side of the picture, px.
const MAX_SIDE: u32 = 1400;

/// Draw a run and write it as PNG to `path`.
pub fn write_run_png(
    map: &Map,
    route: &DenseRoute,
    trace: &[DVec3],
    actors: &[ActorView],
    infractions: &[Infraction],
    path: &Path,
) -> std::io::Result<()> {
    let mut c = Canvas::fit(map.bounds.0, map.bounds.1, 10.0, MAX_SIDE, [34, 92, 46]);
    for lane in &map.lanes {
        let colour = match lane.kind {
            LaneKind::Driving => [70, 70, 74],
            LaneKind::Parking => [95, 95, 100],
            LaneKind::Sidewalk => [160, 155, 145],
            LaneKind::Shoulder => [110, 105, 95],
            LaneKind::Other => [80, 110, 80],
        };
        for w in lane.points.windows(2) {
            c.line(w[0].truncate(), w[1].truncate(), lane.width, colour);
        }
    }
    for light in &map.lights {
        for line in &light.stop_lines {
            let (a, b) = line.ends(1.0);
            c.line(a, b, 0.6, [230, 230, 230]);
        }
    }
    let route_pts: Vec<DVec2> = route.points.iter().map(|p| p.position.truncate()).collect();
    for w in route_pts.windows(2) {
        c.line(w[0], w[1], 1.2, [60, 120, 235]);
    }
    for w in trace.windows(2) {
        c.line(w[0].truncate(), w[1].truncate(), 0.9, [80, 230, 90]);
    }
    for a in actors {
        let colour = match a.kind {
            ActorKind::Vehicle => [240, 200, 60],
            ActorKind::Cyclist => [250, 140, 40],
            ActorKind::Walker => [250, 90, 200],
            ActorKind::Static => [150, 120, 90],
        };
        let (f, l) = a.obb.axes();
        let (hx, hy) = (f * a.obb.half.x, l * a.obb.half.y);
        let o = a.obb.centre;
        c.polygon(
            &[o + hx + hy, o - hx + hy, o - hx - hy, o + hx - hy],
            colour,
        );
    }
    if let Some(last) = trace.last() {
        c.disc(last.truncate(), 2.5, [240, 40, 40]);
    }
    if let Some(first) = route_pts.first() {
        c.disc(*first, 2.5, [255, 255, 255]);
    }
    for inf in infractions {
        let colour = match inf.kind {
            InfractionKind::CollisionPedestrian
            | InfractionKind::CollisionVehicle
            | InfractionKind::CollisionLayout => [255, 0, 0],
            InfractionKind::RedLight | InfractionKind::StopSign => [255, 0, 255],
            _ => [255, 255, 0],
        };
        c.disc(inf.location.truncate(), 4.0, [0, 0, 0]);
        c.disc(inf.location.truncate(), 3.0, colour);
    }
    let file = std::fs::File::create(path)?;
    c.write_png(std::io::BufWriter::new(file))
        .map_err(std::io::Error::other)
}
