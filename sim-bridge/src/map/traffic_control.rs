//! Traffic control derived from a map: junctions with their approaches, traffic lights and stop
//! signs, each with the stop lines the world and the scorer test against.
//!
//! Rules (documented in sim-bridge/README.md):
//! - A junction's *approaches* are its incoming driving lanes (lanes outside the junction whose
//!   successors are inside it), grouped by incoming road and side.
//! - A junction is signalized when the file has a traffic-light `<signal>` (dynamic, type
//!   1000001 as CARLA writes them) that applies to one of its incoming or connector lanes, or,
//!   with [`MapOptions::place_missing_lights`] and a map that has no traffic-light signal at
//!   all, when it has four or more approaches and one of them has two or more lanes. Every approach of a signalized junction gets one light.
//! - A stop sign is a `<signal>` of type 206 (stop); its stop lines are the ends of the lanes it
//!   applies to.
//! - A stop line lies across the end of an incoming lane, where the lane enters the junction.
//! - A light's head (what cameras see) stands where the file's signal does, its centre
//!   [`HEAD_HEIGHT`] above the road unless the file mounts it at least [`MIN_MOUNTED_HEIGHT`]
//!   up ([`mounted_head`]). A placed light's head stands US-style, across the junction on the
//!   far right corner where the approach's straight-on lanes leave it ([`placed_head`]), as
//!   CARLA's US-style towns stand theirs (the exports of Town04 and Town06 put every head
//!   8-54 m past its stop line; a car waiting at the line sees it ahead); an approach with no
//!   straight-on connector (a T-junction's stem) gets it beside its rightmost stop line. Every
//!   head faces the traffic of its approach: CARLA's exports give the post's yaw, which for
//!   about half their lights points away from the lanes the light controls.

use std::collections::BTreeMap;

use glam::{DVec2, DVec3};

use super::{JunctionIdx, LaneIdx, LaneKind, Map, MapOptions};

/// OpenDRIVE signal type CARLA uses for traffic lights.
const TRAFFIC_LIGHT_TYPE: &str = "1000001";
/// OpenDRIVE (German catalogue) signal type for a stop sign.
const STOP_SIGN_TYPE: &str = "206";
/// Height of a light head's centre above the road, m: the heads the simulator places, those
/// of its own towns, and those of files that give only the post's foot.
const HEAD_HEIGHT: f64 = 3.0;
/// A traffic-light signal lower than this above the road (m) marks its post's foot, not its head.
const MIN_MOUNTED_HEIGHT: f64 = 2.0;
/// How far right of a lane's edge a placed head's post stands, m.
const POST_OFFSET: f64 = 1.5;
/// A connector turning less than this (radians, about 20 degrees) carries its lane straight on.
pub(crate) const STRAIGHT_ON: f64 = 0.35;

/// A stop line across the end of one lane.
#[derive(Debug, Clone, Copy)]
pub struct StopLine {
    /// The lane it closes.
    pub lane: LaneIdx,
    /// Centre of the line, on the lane centre.
    pub position: DVec3,
    /// Heading of travel on the lane, radians.
    pub yaw: f64,
    /// Half the lane width, metres.
    pub half_width: f64,
}

impl StopLine {
    fn at_end_of(map: &Map, lane: LaneIdx) -> StopLine {
        let l = map.lane(lane);
        let pose = l.pose_at(l.length());
        StopLine {
            lane,
            position: pose.position,
            yaw: pose.yaw,
            half_width: l.width / 2.0,
        }
    }

    /// The line's two end points at `fraction` of the half width (the leaderboard uses 0.4 of
    /// the lane width each side, i.e. `fraction = 0.8`).
    pub fn ends(&self, fraction: f64) -> (DVec2, DVec2) {
        let across = DVec2::from_angle(self.yaw).perp() * self.half_width * fraction;
        let c = self.position.truncate();
        (c - across, c + across)
    }
}

/// The incoming lanes of one road into a junction.
#[derive(Debug, Clone)]
pub struct Approach {
    /// The incoming road's OpenDRIVE id.
    pub road_id: String,
    /// Incoming lanes, ordered by index.
    pub lanes: Vec<LaneIdx>,
    /// Heading of travel where the lanes enter the junction, radians.
    pub yaw: f64,
    /// The light controlling it, for a signalized junction.
    pub light: Option<usize>,
}

/// One junction.
#[derive(Debug, Clone)]
pub struct Junction {
    /// This junction's index.
    pub idx: JunctionIdx,
    /// The OpenDRIVE `<junction id>`.
    pub od_id: String,
    /// Connector lanes inside the junction.
    pub lanes: Vec<LaneIdx>,
    /// Its approaches.
    pub approaches: Vec<Approach>,
    /// Whether lights control it.
    pub signalized: bool,
    /// Plan centre (mean of connector lane points).
    pub centre: DVec2,
}

/// A traffic light controlling one approach of a junction.
#[derive(Debug, Clone)]
pub struct TrafficLight {
    /// Position in [`Map::lights`].
    pub id: usize,
    /// The junction.
    pub junction: JunctionIdx,
    /// Index of the approach within the junction (also its slot in the junction's cycle).
    pub approach: usize,
    /// One stop line per incoming lane.
    pub stop_lines: Vec<StopLine>,
    /// Where the head's centre stands ([`mounted_head`] for a file's signal, else
    /// [`placed_head`]), [`HEAD_HEIGHT`] above the road unless the file mounts it higher.
    pub head: DVec3,
    /// The direction the head faces: towards the traffic of its approach.
    pub head_yaw: f64,
    /// Whether the map file placed it (false: placed by the simulator).
    pub from_map: bool,
}

impl TrafficLight {
    /// Centre of the stop lines (the light's "trigger" location for distance tests).
    pub fn trigger_centre(&self) -> DVec2 {
        let sum: DVec2 = self.stop_lines.iter().map(|s| s.position.truncate()).sum();
        sum / self.stop_lines.len().max(1) as f64
    }
}

/// A stop sign.
#[derive(Debug, Clone)]
pub struct StopSign {
    /// Position in [`Map::stop_signs`].
    pub id: usize,
    /// One stop line per lane it applies to.
    pub stop_lines: Vec<StopLine>,
    /// Where the sign stands.
    pub position: DVec3,
    /// The direction it faces.
    pub yaw: f64,
}

/// Fill `map.junctions`, `map.lights` and `map.stop_signs`.
pub(super) fn derive(
    map: &mut Map,
    net: &xodr::RoadNetwork,
    junction_ids: Vec<String>,
    options: MapOptions,
) {
    map.junctions = build_junctions(map, junction_ids);
    let file_lights = file_signals(net, TRAFFIC_LIGHT_TYPE, true);
    let mut heads: BTreeMap<(usize, usize), DVec3> = BTreeMap::new();
    let lane_of = lane_lookup(&map.lanes, net);
    for signal in &file_lights {
        let lanes: Vec<LaneIdx> = signal.lanes.iter().filter_map(|l| lane_of(*l)).collect();
        for lane in lanes {
            if let Some((j, a)) = approach_of(map, lane) {
                let head = mounted_head(signal);
                heads.entry((j, a)).or_insert(head);
                map.junctions[j].signalized = true;
            }
        }
    }
    // Only a map without any traffic-light signal (CARLA's old Town03) gets placed lights: in a
    // map that has some, a junction without them is unsignalized on purpose.
    if options.place_missing_lights && file_lights.is_empty() {
        for j in &mut map.junctions {
            let multi_lane = j.approaches.iter().any(|a| a.lanes.len() >= 2);
            if !j.signalized && j.approaches.len() >= 4 && multi_lane {
                j.signalized = true;
            }
        }
    }
    for j in 0..map.junctions.len() {
        if !map.junctions[j].signalized {
            continue;
        }
        for a in 0..map.junctions[j].approaches.len() {
            let stop_lines: Vec<StopLine> = map.junctions[j].approaches[a]
                .lanes
                .iter()
                .map(|&l| StopLine::at_end_of(map, l))
                .collect();
            let (placed, head_yaw) = placed_head(map, &stop_lines);
            let (head, from_map) = match heads.get(&(j, a)) {
                Some(&file) => (file, true),
                None => (placed, false),
            };
            let id = map.lights.len();
            map.lights.push(TrafficLight {
                id,
                junction: JunctionIdx(j as u32),
                approach: a,
                stop_lines,
                head,
                head_yaw,
                from_map,
            });
            map.junctions[j].approaches[a].light = Some(id);
        }
    }
    for signal in file_signals(net, STOP_SIGN_TYPE, false) {
        let stop_lines: Vec<StopLine> = signal
            .lanes
            .iter()
            .filter_map(|l| lane_of(*l))
            .filter(|l| map.lane(*l).kind == LaneKind::Driving)
            .map(|l| StopLine::at_end_of(map, l))
            .collect();
        if stop_lines.is_empty() {
            continue;
        }
        let id = map.stop_signs.len();
        map.stop_signs.push(StopSign {
            id,
            stop_lines,
            position: to_dvec3(signal.position),
            yaw: signal.heading as f64,
        });
    }
}

/// Where a file's traffic light shows its lamps. OpenDRIVE puts a signal's bottom edge
/// `zOffset` above the road, and this simulator's towns write the head 3 m up; CARLA's exports
/// instead give the foot of the light's post (`zOffset` about -0.55 m, with the 1.16 m housing
/// as `height`), which drawn as is buries the head under the road, out of every camera's view.
/// A signal lower than [`MIN_MOUNTED_HEIGHT`] above the road is therefore read as a post's foot
/// and its head raised to [`HEAD_HEIGHT`] above the road there.
fn mounted_head(signal: &xodr::Signal) -> DVec3 {
    let position = to_dvec3(signal.position);
    let road = signal.applies_at.first().map_or(position.z, |p| p.z as f64);
    if position.z - road >= MIN_MOUNTED_HEIGHT {
        position
    } else {
        DVec3::new(position.x, position.y, road + HEAD_HEIGHT)
    }
}

fn to_dvec3(p: xodr::Point) -> DVec3 {
    DVec3::new(p.x as f64, p.y as f64, p.z as f64)
}

/// Signals of one type; `dynamic` must match for lights (CARLA's are dynamic).
fn file_signals<'a>(
    net: &'a xodr::RoadNetwork,
    kind: &str,
    dynamic: bool,
) -> Vec<&'a xodr::Signal> {
    net.signals()
        .iter()
        .filter(|s| s.kind == kind && (s.dynamic || !dynamic))
        .collect()
}

/// Map an xodr lane id to ours through (road, section, lane id).
fn lane_lookup<'a>(
    lanes: &[super::Lane],
    net: &'a xodr::RoadNetwork,
) -> impl Fn(xodr::LaneId) -> Option<LaneIdx> + use<'a> {
    let mut by_key: BTreeMap<(String, usize, i32), LaneIdx> = BTreeMap::new();
    for l in lanes {
        by_key.insert((l.road_id.clone(), l.section, l.lane_id), l.idx);
    }
    move |id| {
        let rl = net.road_lane(id)?;
        let road = net.road(rl.road)?;
        by_key
            .get(&(road.od_id().to_string(), rl.section, rl.od_id))
            .copied()
    }
}

/// The (junction, approach) a lane controls entry to: an incoming lane directly, a connector
/// through its predecessors, or a lane one step before an incoming lane.
fn approach_of(map: &Map, lane: LaneIdx) -> Option<(usize, usize)> {
    let find = |l: LaneIdx| {
        map.junctions.iter().enumerate().find_map(|(j, junction)| {
            junction
                .approaches
                .iter()
                .position(|a| a.lanes.contains(&l))
                .map(|a| (j, a))
        })
    };
    let l = map.lane(lane);
    if l.in_junction() {
        return l.predecessors.iter().find_map(|&p| find(p));
    }
    find(lane).or_else(|| l.successors.iter().find_map(|&s| find(s)))
}

fn build_junctions(map: &Map, junction_ids: Vec<String>) -> Vec<Junction> {
    let mut junctions: Vec<Junction> = junction_ids
        .into_iter()
        .enumerate()
        .map(|(i, od_id)| Junction {
            idx: JunctionIdx(i as u32),
            od_id,
            lanes: Vec::new(),
            approaches: Vec::new(),
            signalized: false,
            centre: DVec2::ZERO,
        })
        .collect();
    let mut incoming: BTreeMap<(u32, String, bool), Vec<LaneIdx>> = BTreeMap::new();
    for lane in &map.lanes {
        if lane.kind != LaneKind::Driving {
            continue;
        }
        if let Some(j) = lane.junction {
            junctions[j.0 as usize].lanes.push(lane.idx);
            continue;
        }
        for s in &lane.successors {
            if let Some(j) = map.lane(*s).junction {
                let key = (j.0, lane.road_id.clone(), lane.lane_id < 0);
                let lanes = incoming.entry(key).or_default();
                if !lanes.contains(&lane.idx) {
                    lanes.push(lane.idx);
                }
            }
        }
    }
    for ((j, road_id, _), lanes) in incoming {
        let first = map.lane(lanes[0]);
        let yaw = first.pose_at(first.length()).yaw;
        junctions[j as usize].approaches.push(Approach {
            road_id,
            lanes,
            yaw,
            light: None,
        });
    }
    for j in &mut junctions {
        let pts: Vec<DVec2> = j
            .lanes
            .iter()
            .flat_map(|l| map.lane(*l).points.iter().map(|p| p.truncate()))
            .collect();
        if !pts.is_empty() {
            j.centre = pts.iter().sum::<DVec2>() / pts.len() as f64;
        }
    }
    junctions
}

/// Where the simulator stands a light it places, [`HEAD_HEIGHT`] up and facing the traffic of
/// the approach whose stop lines are `lines`: across the junction, [`POST_OFFSET`] right of
/// the approach's right edge where its rightmost straight-on lane leaves the junction; beside
/// the rightmost stop line when no lane goes straight on.
fn placed_head(map: &Map, lines: &[StopLine]) -> (DVec3, f64) {
    let mut right_to_left = lines.to_vec();
    right_to_left.sort_by(|a, b| rightness(a).total_cmp(&rightness(b)));
    let Some(&rightmost) = right_to_left.first() else {
        return (DVec3::ZERO, 0.0);
    };
    let facing = rightmost.yaw + std::f64::consts::PI;
    let across = right_to_left.iter().find_map(|line| {
        let (_, exit) = map.straight_on(line.lane, line.yaw)?;
        // The approach's right edge, measured from this lane's centre.
        let to_edge = (rightness(line) - rightness(&rightmost)) + rightmost.half_width;
        Some(beside(exit.position, rightmost.yaw, to_edge))
    });
    let head =
        across.unwrap_or_else(|| beside(rightmost.position, rightmost.yaw, rightmost.half_width));
    (head, facing)
}

/// How far left a stop line's centre lies, across its own heading (smaller is further right).
fn rightness(line: &StopLine) -> f64 {
    DVec2::from_angle(line.yaw).perp_dot(line.position.truncate())
}

/// A head `to_edge` + [`POST_OFFSET`] m right of `at` (for travel heading `yaw`), [`HEAD_HEIGHT`]
/// above it.
fn beside(at: DVec3, yaw: f64, to_edge: f64) -> DVec3 {
    let right = -DVec2::from_angle(yaw).perp() * (to_edge + POST_OFFSET);
    at + DVec3::new(right.x, right.y, HEAD_HEIGHT)
}
