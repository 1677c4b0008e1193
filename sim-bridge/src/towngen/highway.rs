//! `ssr_train_highway`, a training town like CARLA Town04/06: a 600 x 350 m
//! loop of three-lane highway with large rounded corners around a local
//! grid of two-lane streets.
//!
//! The grid's middle row crosses to the loop's east and west sides in
//! signalized T-junctions. On the loop's north and south sides, traffic
//! running clockwise (the inner carriageway) leaves by a one-lane off-ramp
//! that diverges from its rightmost lane and comes back by an on-ramp that
//! merges into it. The south half is the north half turned half a turn.

use glam::DVec2;

use super::builder::{JunctionId, ManualLink, RoadId, TownBuilder};
use super::geometry::{Frame, Path, Pose};
use super::profile::{Profile, setback};
use super::town::Town;

/// The loop's centre line: x = ±LOOP_X, y = ±LOOP_Y.
const LOOP_X: f64 = 290.0;
const LOOP_Y: f64 = 165.0;
/// The radius of the loop's corners.
const CORNER: f64 = 110.0;
/// Highway lanes each way.
const LANES: usize = 3;
/// Half the length of a diverge or merge junction along the highway.
const RAMP_JUNCTION_HALF: f64 = 30.0;
/// Where the north side's diverge and merge junctions are centred (x).
const DIVERGE_X: f64 = -140.0;
const MERGE_X: f64 = 140.0;
/// How far inside the highway's centre line a ramp starts or ends.
const RAMP_INSET: f64 = 21.0;
/// The angle a ramp leaves or joins the highway at, in degrees.
const RAMP_ANGLE: f64 = 20.0;
/// The grid: column x and the y of the rows above and below the middle one.
const GRID_X: [f64; 4] = [-150.0, -50.0, 50.0, 150.0];
const GRID_Y: f64 = 60.0;
/// The radius of the grid's rounded outer corners.
const GRID_CORNER: f64 = 30.0;

struct Profiles {
    highway: Profile,
    local: Profile,
    ramp: Profile,
}

/// The junctions on the middle row, west to east, and on the loop.
struct Spine {
    west_gate: JunctionId,
    row: [JunctionId; 4],
    east_gate: JunctionId,
    north_diverge: JunctionId,
    north_merge: JunctionId,
    south_diverge: JunctionId,
    south_merge: JunctionId,
}

/// What one half (north, or the south turned) adds that the town needs
/// later: the grid junction an off-ramp ends in and the roads of its
/// traffic control.
struct Half {
    off_ramp: RoadId,
    on_ramp: RoadId,
    ramp_end: JunctionId,
    /// The curved streets at the row's ends, west then east.
    curves: [RoadId; 2],
}

/// Build the town.
pub fn build() -> Town {
    let p = Profiles {
        highway: Profile::highway(LANES, 90),
        local: Profile::street(2, false, 40),
        ramp: Profile::ramp(60),
    };
    let mut b = TownBuilder::new("ssr_train_highway", Frame::IDENTITY);
    let s = spine(&mut b, &p);
    let north = half(&mut b, &p, &s, Hemisphere::North);
    let south = half(&mut b, &p, &s, Hemisphere::South);
    let ring = ring(&mut b, &p, &s);
    ramp_junctions(&mut b, &s, &ring, &north, &south);
    control(&mut b, &s, &north, &south);
    b.build()
}

fn spine(b: &mut TownBuilder, p: &Profiles) -> Spine {
    let gate = setback(&[&p.highway, &p.local]);
    let local = setback(&[&p.local, &p.ramp]);
    let west_gate = b.junction("WestGate", DVec2::new(-LOOP_X, 0.0), gate);
    let row = GRID_X.map(|x| b.junction(format!("M{x}"), DVec2::new(x, 0.0), local));
    let east_gate = b.junction("EastGate", DVec2::new(LOOP_X, 0.0), gate);
    let mut on_loop =
        |name: &str, x: f64, y: f64| b.junction(name, DVec2::new(x, y), RAMP_JUNCTION_HALF);
    let north_diverge = on_loop("NorthDiverge", DIVERGE_X, LOOP_Y);
    let north_merge = on_loop("NorthMerge", MERGE_X, LOOP_Y);
    let south_diverge = on_loop("SouthDiverge", -DIVERGE_X, -LOOP_Y);
    let south_merge = on_loop("SouthMerge", -MERGE_X, -LOOP_Y);
    let mut stops = vec![west_gate];
    stops.extend(row);
    stops.push(east_gate);
    for w in stops.windows(2) {
        b.street(w[0], w[1], &p.local);
    }
    Spine {
        west_gate,
        row,
        east_gate,
        north_diverge,
        north_merge,
        south_diverge,
        south_merge,
    }
}

/// One half of the grid and its ramps.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Hemisphere {
    North,
    South,
}

impl Hemisphere {
    /// How the north half's coordinates are placed for this half.
    fn frame(self) -> Frame {
        match self {
            Self::North => Frame::IDENTITY,
            Self::South => Frame::HALF_TURN,
        }
    }

    fn name(self) -> &'static str {
        match self {
            Self::North => "North",
            Self::South => "South",
        }
    }
}

/// The grid's north half, or the south half by a half turn: a row of two
/// junctions above the middle row, joined to it by two columns and two
/// rounded corners, and the ramps from and to the loop.
fn half(b: &mut TownBuilder, p: &Profiles, s: &Spine, hemisphere: Hemisphere) -> Half {
    let f = hemisphere.frame();
    let prefix = hemisphere.name();
    let (row, diverge, merge) = match hemisphere {
        Hemisphere::North => (s.row, s.north_diverge, s.north_merge),
        Hemisphere::South => {
            let mut row = s.row;
            row.reverse();
            (row, s.south_diverge, s.south_merge)
        }
    };
    let sb = setback(&[&p.local, &p.ramp]);
    let at = |x: f64, y: f64| f.point(DVec2::new(x, y));
    let west = b.junction(format!("{prefix}West"), at(GRID_X[1], GRID_Y), sb);
    let east = b.junction(format!("{prefix}East"), at(GRID_X[2], GRID_Y), sb);
    let west_curve = b.street_via(
        row[0],
        &[at(GRID_X[0], GRID_Y)],
        GRID_CORNER,
        west,
        &p.local,
    );
    b.street(west, east, &p.local);
    let east_curve = b.street_via(
        east,
        &[at(GRID_X[3], GRID_Y)],
        GRID_CORNER,
        row[3],
        &p.local,
    );
    b.street(row[1], west, &p.local);
    b.street(row[2], east, &p.local);

    let angle = RAMP_ANGLE.to_radians();
    let quarter = std::f64::consts::FRAC_PI_2;
    let ramp_top = LOOP_Y - RAMP_INSET;
    let leave = Pose::new(DIVERGE_X + RAMP_JUNCTION_HALF, ramp_top, -angle);
    let arrive = Pose::new(GRID_X[1], GRID_Y + sb, -quarter);
    let off = Path::connect(f.pose(leave), f.pose(arrive));
    let off_ramp = b.road(
        format!("{prefix} off-ramp"),
        off,
        &p.ramp,
        Some(diverge),
        Some(west),
    );
    let depart = Pose::new(GRID_X[2], GRID_Y + sb, quarter);
    let join = Pose::new(MERGE_X - RAMP_JUNCTION_HALF, ramp_top, angle);
    let on = Path::connect(f.pose(depart), f.pose(join));
    let on_ramp = b.road(
        format!("{prefix} on-ramp"),
        on,
        &p.ramp,
        Some(east),
        Some(merge),
    );
    Half {
        off_ramp,
        on_ramp,
        ramp_end: west,
        curves: [west_curve, east_curve],
    }
}

/// The loop's roads, counter-clockwise from the east gate.
struct Ring {
    north_east: RoadId,
    north: RoadId,
    north_west: RoadId,
    south_west: RoadId,
    south: RoadId,
    south_east: RoadId,
}

fn ring(b: &mut TownBuilder, p: &Profiles, s: &Spine) -> Ring {
    let corner = |x: f64, y: f64| [DVec2::new(x * LOOP_X, y * LOOP_Y)];
    let hw = &p.highway;
    Ring {
        north_east: b.street_via(s.east_gate, &corner(1.0, 1.0), CORNER, s.north_merge, hw),
        north: b.street(s.north_merge, s.north_diverge, hw),
        north_west: b.street_via(s.north_diverge, &corner(-1.0, 1.0), CORNER, s.west_gate, hw),
        south_west: b.street_via(s.west_gate, &corner(-1.0, -1.0), CORNER, s.south_merge, hw),
        south: b.street(s.south_merge, s.south_diverge, hw),
        south_east: b.street_via(s.south_diverge, &corner(1.0, -1.0), CORNER, s.east_gate, hw),
    }
}

/// The links of a diverge or merge junction between highway roads `up`
/// and `down` (in the clockwise traffic's direction): every lane straight
/// on both ways, plus the ramp from or to the clockwise rightmost lane.
fn ramp_links(up: RoadId, down: RoadId, ramp: RoadId, diverge: bool) -> Vec<ManualLink> {
    let link = |from, from_lane, to, to_lane| ManualLink {
        from,
        from_lane,
        to,
        to_lane,
    };
    let mut links: Vec<ManualLink> = (1..=LANES)
        .flat_map(|j| [link(up, j, down, j), link(down, j, up, j)])
        .collect();
    links.push(if diverge {
        link(up, LANES, ramp, 1)
    } else {
        link(ramp, 1, down, LANES)
    });
    links
}

fn ramp_junctions(b: &mut TownBuilder, s: &Spine, r: &Ring, north: &Half, south: &Half) {
    let (nd, nm) = (s.north_diverge, s.north_merge);
    b.connect_manually(nd, ramp_links(r.north_west, r.north, north.off_ramp, true));
    b.connect_manually(nm, ramp_links(r.north, r.north_east, north.on_ramp, false));
    let (sd, sm) = (s.south_diverge, s.south_merge);
    b.connect_manually(sd, ramp_links(r.south_east, r.south, south.off_ramp, true));
    b.connect_manually(sm, ramp_links(r.south, r.south_west, south.on_ramp, false));
}

fn control(b: &mut TownBuilder, s: &Spine, north: &Half, south: &Half) {
    for j in [s.west_gate, s.east_gate, s.row[1], s.row[2]] {
        b.lights(j);
    }
    for half in [north, south] {
        b.stop_signs(half.ramp_end, &[half.off_ramp]);
    }
    // The outer row junctions: the curved streets stop there.
    b.stop_signs(s.row[0], &[north.curves[0], south.curves[1]]);
    b.stop_signs(s.row[3], &[north.curves[1], south.curves[0]]);
}
