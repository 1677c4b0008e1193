//! The bundled route sets: route files the project generates itself, deterministically, on its
//! own towns, and commits under `sim-bridge/routes/`; and random route sets on any map
//! ([`random_routes`], `sim-bridge routes random`) for towns that come without a route file.
//!
//! - `town05-long-style`: 10 routes on the evaluation town with the lengths of CARLA's Town05
//!   Long routes (0.53 to 2.1 km, 12.3 km in all), turning at signalized junctions, using the
//!   three-lane ring road and changing lanes.
//! - `town05-short-style`: 20 routes of 100 to 400 m on the same town, for quick checks.
//! - `train-small`, `train-highway`, `train-dense`: 200 short routes (60 to 300 m, as TCP's
//!   training routes) on each training town.
//! - `heldout-radial`: 20 routes of 400 to 1,200 m on the held-out radial town, which no
//!   training set drives (part of the held-out suite, `eval --suite unseen`).
//!
//! Beside them, `town05-style-scenarios.json`: a leaderboard scenario file for the Town05-style
//! town ([`TOWN05_STYLE_SCENARIOS`]), which no public file covers.
//!
//! A route is a random walk over the lane graph (seeded by the set) that prefers turns at
//! junctions and sometimes changes lanes; its keypoints are placed every [`KEYPOINT_SPACING`]
//! metres, in every junction it crosses and on both sides of every lane change, so the planner
//! turns the keypoints back into the same path.

use rand::{Rng, RngExt as _, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::planner::plan_route;
use super::xml::{Keypoint, RouteSpec, write};
use super::{scenario_file, scenario_triggers};
use crate::map::{LaneIdx, LaneKind, Map};
use crate::towngen::TownStyle;

/// Metres between keypoints outside junctions.
pub const KEYPOINT_SPACING: f64 = 40.0;

/// Lengths of CARLA's Town05 Long routes 16-25, metres (keypoint lengths from the notes).
const TOWN05_LONG_LENGTHS: [f64; 10] = [
    1071.0, 862.4, 1018.2, 1651.1, 1247.5, 531.1, 991.8, 1271.9, 2101.2, 1554.6,
];

/// A bundled route set.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RouteSet {
    /// Its name on the command line.
    pub name: &'static str,
    /// The town it runs on.
    pub town: TownStyle,
    /// One line for listings.
    pub description: &'static str,
    seed: u64,
}

/// Every bundled set.
pub const SETS: [RouteSet; 6] = [
    RouteSet {
        name: "town05-long-style",
        town: TownStyle::Town05Style,
        description: "10 long routes (0.5-2.1 km, 12.3 km) on the evaluation town",
        seed: 16,
    },
    RouteSet {
        name: "town05-short-style",
        town: TownStyle::Town05Style,
        description: "20 short routes (100-400 m) on the evaluation town",
        seed: 5,
    },
    RouteSet {
        name: "train-small",
        town: TownStyle::SmallTJunctions,
        description: "200 short training routes on the small T-junction town",
        seed: 101,
    },
    RouteSet {
        name: "train-highway",
        town: TownStyle::Highway,
        description: "200 short training routes on the highway town",
        seed: 102,
    },
    RouteSet {
        name: "train-dense",
        town: TownStyle::DenseMultiLane,
        description: "200 short training routes on the dense multi-lane town",
        seed: 103,
    },
    RouteSet {
        name: "heldout-radial",
        town: TownStyle::HeldOutRadial,
        description: "20 routes (400-1200 m) on the held-out radial town, in no training set",
        seed: 57,
    },
];

impl RouteSet {
    /// The set called `name`.
    pub fn find(name: &str) -> Option<RouteSet> {
        SETS.into_iter().find(|s| s.name == name)
    }

    /// The committed route file.
    pub fn bundled_xml(self) -> &'static str {
        match self.name {
            "town05-long-style" => include_str!("../../routes/town05-long-style.xml"),
            "town05-short-style" => include_str!("../../routes/town05-short-style.xml"),
            "train-small" => include_str!("../../routes/train-small.xml"),
            "train-highway" => include_str!("../../routes/train-highway.xml"),
            "heldout-radial" => include_str!("../../routes/heldout-radial.xml"),
            _ => include_str!("../../routes/train-dense.xml"),
        }
    }

    /// The target length of each route.
    fn lengths(self, rng: &mut impl Rng) -> Vec<f64> {
        match self.name {
            "town05-long-style" => TOWN05_LONG_LENGTHS.to_vec(),
            "town05-short-style" => (0..20).map(|_| rng.random_range(100.0..400.0)).collect(),
            "heldout-radial" => (0..20).map(|_| rng.random_range(400.0..1200.0)).collect(),
            _ => (0..200).map(|_| rng.random_range(60.0..300.0)).collect(),
        }
    }

    /// Generate the set on `map` (which must be the set's town).
    pub fn generate(self, map: &Map) -> Vec<RouteSpec> {
        let mut rng = ChaCha8Rng::seed_from_u64(self.seed);
        let long = self.name == "town05-long-style";
        let lengths = self.lengths(&mut rng);
        let walk_style = if long || self.town.is_held_out() {
            WalkStyle {
                turn_bias: 0.45,
                change_rate: 0.5,
            }
        } else {
            WalkStyle {
                turn_bias: 0.35,
                change_rate: 0.15,
            }
        };
        let mut routes = Vec::new();
        for (i, &length) in lengths.iter().enumerate() {
            let id = if long {
                (16 + i).to_string()
            } else {
                i.to_string()
            };
            // Long routes must show the ring road (every other one) and lane changes.
            let wants_ring = long && i % 2 == 1;
            let accept = |walk: &Walk| {
                (!wants_ring || walk.lanes.iter().any(|l| is_three_lane(map, *l)))
                    && (!long || walk.changed_lanes)
            };
            let town = self.town.name();
            if let Some(spec) = draw_route(map, &mut rng, &id, town, length, walk_style, accept) {
                routes.push(spec);
            }
        }
        routes
    }
}

/// A route file the project drew itself (`routes random`) on a CARLA town it does not ship,
/// committed under `sim-bridge/routes/` so that its routes stay fixed: the map comes from a
/// folder of CARLA maps (`--maps ../shared/carla`).
#[derive(Debug, Clone, PartialEq)]
pub struct CarlaRouteFile {
    /// Its name on the command line (`--routes NAME`).
    pub name: &'static str,
    /// The CARLA town its routes name (the map file is `<town>.xodr`).
    pub town: &'static str,
    /// One line for listings.
    pub description: &'static str,
    /// The draw that wrote it: `routes random --map <town>.xodr` with these options.
    pub draw: RandomRoutes,
    /// The committed file.
    pub xml: &'static str,
}

/// Every committed route file on a CARLA town.
pub static CARLA_ROUTE_FILES: [CarlaRouteFile; 1] = [CarlaRouteFile {
    name: "heldout-town02",
    town: "Town02",
    description: "40 random routes (400-1200 m) on CARLA's Town02, in no training set",
    draw: RandomRoutes {
        count: 40,
        length: [400.0, 1200.0],
        seed: 57,
        style: WalkStyle {
            turn_bias: 0.45,
            change_rate: 0.3,
        },
    },
    xml: include_str!("../../routes/heldout-town02.xml"),
}];

impl CarlaRouteFile {
    /// The file called `name`.
    pub fn find(name: &str) -> Option<&'static CarlaRouteFile> {
        CARLA_ROUTE_FILES.iter().find(|f| f.name == name)
    }
}

/// How a random walk chooses at junctions and on multi-lane roads.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WalkStyle {
    /// The chance of taking a turning connector where a junction offers one (never at two
    /// junctions in a row).
    pub turn_bias: f64,
    /// The chance of a lane change where a lane is long enough for one.
    pub change_rate: f64,
}

/// Random routes on any map (`sim-bridge routes random`): what to draw.
#[derive(Debug, Clone, PartialEq)]
pub struct RandomRoutes {
    /// How many routes.
    pub count: usize,
    /// Each route's length is drawn uniformly from this range, metres.
    pub length: [f64; 2],
    /// The seed of every draw: the same map and options give the same routes.
    pub seed: u64,
    /// Junction and lane-change choices.
    pub style: WalkStyle,
}

/// Up to `options.count` routes on `map`, named `town` in the route file, each with its draw's
/// index as id:
/// random walks over the driving lanes that plan back into a route of about the walked length.
/// A route the map cannot give in [`ATTEMPTS`] walks (a length longer than any path without a
/// dead end, say) is left out, so fewer may come back.
pub fn random_routes(map: &Map, town: &str, options: &RandomRoutes) -> Vec<RouteSpec> {
    let mut rng = ChaCha8Rng::seed_from_u64(options.seed);
    let [low, high] = options.length;
    let lengths: Vec<f64> = (0..options.count)
        .map(|_| {
            if high > low {
                rng.random_range(low..high)
            } else {
                low
            }
        })
        .collect();
    lengths
        .iter()
        .enumerate()
        .filter_map(|(i, &length)| {
            let id = i.to_string();
            draw_route(map, &mut rng, &id, town, length, options.style, |_| true)
        })
        .collect()
}

/// Walks tried for one route before it is left out.
pub const ATTEMPTS: usize = 500;

/// The first of up to [`ATTEMPTS`] random walks of `length` that `accept` takes and whose
/// keypoints plan back into a route of about the walked length.
fn draw_route(
    map: &Map,
    rng: &mut impl Rng,
    id: &str,
    town: &str,
    length: f64,
    style: WalkStyle,
    accept: impl Fn(&Walk) -> bool,
) -> Option<RouteSpec> {
    for _attempt in 0..ATTEMPTS {
        let Some(walk) = random_walk(map, rng, length, style) else {
            continue;
        };
        if !accept(&walk) {
            continue;
        }
        let spec = RouteSpec {
            id: id.to_string(),
            town: town.to_string(),
            keypoints: keypoints(map, &walk),
        };
        let planned = plan_route(map, &spec)
            .is_ok_and(|d| (d.length() - walk.length).abs() < 0.1 * walk.length + 20.0);
        if planned {
            return Some(spec);
        }
    }
    None
}

/// Regenerate every bundled set's file into `dir`, loading each town from the bundled maps.
pub fn write_bundled(dir: &std::path::Path) -> anyhow::Result<()> {
    std::fs::create_dir_all(dir)?;
    for set in SETS {
        let map = Map::from_str(
            set.town.name(),
            crate::towngen::bundled(set.town),
            Default::default(),
        )?;
        std::fs::write(
            dir.join(format!("{}.xml", set.name)),
            write(&set.generate(&map)),
        )?;
    }
    let town = TownStyle::Town05Style;
    let map = Map::from_str(
        town.name(),
        crate::towngen::bundled(town),
        Default::default(),
    )?;
    let triggers = scenario_triggers::place(&map, scenario_triggers::DEFAULT_SPACING_M, 0);
    std::fs::write(
        dir.join(TOWN05_STYLE_SCENARIOS),
        scenario_file::write(town.name(), &triggers),
    )?;
    Ok(())
}

/// The scenario file of the Town05-style town beside its route files: the triggers
/// [`scenario_triggers::place`] puts there (default spacing, seed 0), for
/// `eval --scenarios sim-bridge/routes/town05-style-scenarios.json`.
pub const TOWN05_STYLE_SCENARIOS: &str = "town05-style-scenarios.json";

/// A walked path: the lanes in order with the arc length entered at, and the total.
struct Walk {
    lanes: Vec<LaneIdx>,
    /// (lane, s from, s to) pieces.
    pieces: Vec<(LaneIdx, f64, f64)>,
    length: f64,
    changed_lanes: bool,
}

fn is_three_lane(map: &Map, lane: LaneIdx) -> bool {
    let l = map.lane(lane);
    let count = |mut at: Option<LaneIdx>, left: bool| {
        let mut n = 0;
        while let Some(x) = at {
            n += 1;
            at = if left {
                map.lane(x).left
            } else {
                map.lane(x).right
            };
        }
        n
    };
    1 + count(l.left, true) + count(l.right, false) >= 3
}

fn random_walk(map: &Map, rng: &mut impl Rng, length: f64, style: WalkStyle) -> Option<Walk> {
    let WalkStyle {
        turn_bias,
        change_rate,
    } = style;
    let starts: Vec<&crate::map::Lane> = map
        .lanes
        .iter()
        .filter(|l| l.kind == LaneKind::Driving && !l.in_junction() && l.length() > 30.0)
        .collect();
    let start = starts.get(rng.random_range(0..starts.len().max(1)))?;
    let mut lane = start.idx;
    let mut s = rng.random_range(2.0..start.length() / 2.0);
    let mut walk = Walk {
        lanes: vec![lane],
        pieces: Vec::new(),
        length: 0.0,
        changed_lanes: false,
    };
    let mut last_junction_turned = false;
    while walk.length < length {
        let l = map.lane(lane);
        let remaining = length - walk.length;
        // A lane change in the first half of a long enough lane.
        let neighbour = if rng.random_range(0.0..1.0) < 0.5 {
            l.left
        } else {
            l.right
        };
        if !l.in_junction()
            && l.length() - s > 70.0
            && remaining > 80.0
            && rng.random_range(0.0..1.0) < change_rate
            && let Some(n) = neighbour.filter(|n| map.lane(*n).kind == LaneKind::Driving)
        {
            let at = s + 20.0;
            walk.pieces.push((lane, s, at));
            walk.length += at - s;
            let proj = map.lane(n).project(
                l.pose_at(at + super::planner::LANE_CHANGE_LENGTH)
                    .position
                    .truncate(),
            );
            lane = n;
            s = proj.s;
            walk.lanes.push(lane);
            walk.changed_lanes = true;
            continue;
        }
        let end = (s + remaining).min(l.length());
        walk.pieces.push((lane, s, end));
        walk.length += end - s;
        if end < l.length() {
            break;
        }
        let options: Vec<LaneIdx> = l
            .successors
            .iter()
            .copied()
            .filter(|x| map.lane(*x).kind == LaneKind::Driving)
            .collect();
        if options.is_empty() {
            return None;
        }
        let turns: Vec<LaneIdx> = options
            .iter()
            .copied()
            .filter(|x| is_turn(map, *x))
            .collect();
        let pick =
            if !turns.is_empty() && !last_junction_turned && rng.random_range(0.0..1.0) < turn_bias
            {
                turns[rng.random_range(0..turns.len())]
            } else {
                options[rng.random_range(0..options.len())]
            };
        if map.lane(pick).in_junction() {
            last_junction_turned = is_turn(map, pick);
        }
        lane = pick;
        s = 0.0;
        walk.lanes.push(lane);
    }
    Some(walk)
}

fn is_turn(map: &Map, lane: LaneIdx) -> bool {
    let l = map.lane(lane);
    l.in_junction()
        && crate::map::angle_diff(l.pose_at(l.length()).yaw, l.pose_at(0.0).yaw).abs() > 0.6
}

/// Keypoints for a walk: its start, every [`KEYPOINT_SPACING`] m, the middle of each junction
/// connector, both ends of each lane change, and its end.
fn keypoints(map: &Map, walk: &Walk) -> Vec<Keypoint> {
    let mut out: Vec<Keypoint> = Vec::new();
    let mut since = 0.0;
    let at = |lane: LaneIdx, s: f64| {
        let p = map.lane(lane).pose_at(s);
        Keypoint {
            position: p.position,
            yaw: p.yaw,
        }
    };
    for (k, &(lane, from, to)) in walk.pieces.iter().enumerate() {
        let l = map.lane(lane);
        let changed_into = k > 0
            && walk.pieces[k - 1].0 != lane
            && !map.lane(walk.pieces[k - 1].0).successors.contains(&lane);
        if k == 0 || changed_into {
            out.push(at(lane, from));
            since = 0.0;
        }
        if l.in_junction() {
            out.push(at(lane, (from + to) / 2.0));
            since = 0.0;
            continue;
        }
        let mut s = from;
        while s + (KEYPOINT_SPACING - since) < to {
            s += KEYPOINT_SPACING - since;
            since = 0.0;
            out.push(at(lane, s));
        }
        since += to - s;
        let next_is_change = walk
            .pieces
            .get(k + 1)
            .is_some_and(|n| !l.successors.contains(&n.0) && n.0 != lane);
        if next_is_change || k + 1 == walk.pieces.len() {
            out.push(at(lane, to));
            since = 0.0;
        }
    }
    out.dedup_by(|a, b| (a.position - b.position).length() < 1.0);
    out
}
