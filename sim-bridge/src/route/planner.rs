//! The global route planner: keypoints -> a dense route at about 1 m over the lane graph, with a
//! RoadOption per point, as the leaderboard's `interpolate_trajectory` builds it with CARLA's
//! GlobalRoutePlanner.
//!
//! Between consecutive keypoints an A* search runs over (lane, entry arc length) states with two
//! kinds of edge: driving on into a successor lane, and a lane change into a same-direction
//! neighbour outside junctions (costed [`LANE_CHANGE_LENGTH`] + [`LANE_CHANGE_PENALTY`] so that
//! routes change lanes only when they must; shorter, and costlier, to land on a goal a full
//! change would overshoot; and where nothing else joins a keypoint pair, a second search allows
//! changes squeezed into the room left before a lane ends, down to [`SQUEEZED_CHANGE_MIN`]:
//! CARLA's lane-change edges have no minimum length). A keypoint's goal is every lane it matches equally well: CARLA's
//! junctions hold connectors that overlap for tens of metres, and a route that reached the
//! keypoint on the neighbouring connector must not be sent around the block to reach the other.
//! The next search starts where the previous one arrived. Labels: points on junction connectors get LEFT,
//! RIGHT or STRAIGHT from the heading change over the whole junction (|change| < 33 degrees is
//! STRAIGHT, as CARLA's `_turn_decision`); points of a lane change get CHANGELANELEFT/RIGHT;
//! everything else is LANEFOLLOW. A lane change is drawn as a smooth lateral transition over
//! [`LANE_CHANGE_LENGTH`] metres (or the room there is) rather than CARLA's jump, so a follower
//! sees a drivable path where there is one.

use std::cmp::Ordering;
use std::collections::{BinaryHeap, HashMap};

use glam::{DVec2, DVec3};
use ssrdrive_proto::command::RoadOption;

use super::xml::{Keypoint, RouteSpec};
use super::{DenseRoute, RoutePoint};
use crate::map::{LaneIdx, LaneKind, Map, angle_diff};

/// Spacing of dense route points, metres (the GlobalRoutePlanner's hop resolution).
pub const RESOLUTION: f64 = 1.0;
/// Distance over which a lane change moves across, metres.
pub const LANE_CHANGE_LENGTH: f64 = 12.0;
/// Extra cost of a lane change, metres of driving.
pub const LANE_CHANGE_PENALTY: f64 = 20.0;
/// Shortest lane change the planner draws to land on a goal, metres.
const SHORT_CHANGE_MIN: f64 = 3.0;
/// Least forward travel of a change squeezed in before a lane ends, metres.
const SQUEEZED_CHANGE_MIN: f64 = 1.0;
/// Search effort cap per keypoint pair (states expanded).
const MAX_EXPANSIONS: usize = 200_000;
/// Lanes whose centre lines pass this close to a keypoint (and agree with its heading and
/// height like the matched lane) are goals as good as it, metres.
const GOAL_SPREAD: f64 = 1.0;
/// Junction heading changes below this are STRAIGHT (CARLA uses 33 degrees... in its own way).
const STRAIGHT_LIMIT: f64 = 33.0 * std::f64::consts::PI / 180.0;

/// Why a route could not be planned.
#[derive(Debug, thiserror::Error)]
pub enum PlanError {
    /// A keypoint has no driving lane to match (the map has none).
    #[error("route {route}: keypoint {index} at ({x:.1}, {y:.1}): the map has no driving lane")]
    OffMap {
        /// The route's id.
        route: String,
        /// Index of the keypoint in the route, from 0.
        index: usize,
        /// The keypoint's x, world frame (OpenDRIVE, east), m.
        x: f64,
        /// The keypoint's y, world frame (OpenDRIVE, north), m.
        y: f64,
    },
    /// No path over the lane graph.
    #[error("route {route}: no path over the lane graph from keypoint {from} to keypoint {to}")]
    NoPath {
        /// The route's id.
        route: String,
        /// Index of the keypoint the leg starts at, from 0.
        from: usize,
        /// Index of the keypoint the leg should reach (`from + 1`).
        to: usize,
    },
}

/// A place on a lane.
#[derive(Debug, Clone, Copy, PartialEq)]
struct LaneSpot {
    lane: LaneIdx,
    s: f64,
}

/// One piece of a planned path.
#[derive(Debug, Clone, Copy)]
enum Leg {
    /// Drive along `lane` from `from` to `to`.
    Drive { lane: LaneIdx, from: f64, to: f64 },
    /// Move from `from` at `s0` to `to` at `s1` over `length` metres ([`LANE_CHANGE_LENGTH`],
    /// or less to land on a goal or where the lane ends first).
    Change {
        from: LaneIdx,
        s0: f64,
        to: LaneIdx,
        s1: f64,
        length: f64,
        left: bool,
    },
}

/// Plan the dense route of a route file entry.
pub fn plan_route(map: &Map, spec: &RouteSpec) -> Result<DenseRoute, PlanError> {
    let spots = spec
        .keypoints
        .iter()
        .enumerate()
        .map(|(index, k)| {
            snap(map, k).ok_or(PlanError::OffMap {
                route: spec.id.clone(),
                index,
                x: k.position.x,
                y: k.position.y,
            })
        })
        .collect::<Result<Vec<_>, _>>()?;
    let mut legs: Vec<Leg> = Vec::new();
    let mut from = spots[0][0];
    for (i, goals) in spots.iter().enumerate().skip(1) {
        // Squeezed lane changes only where nothing else joins the pair: they reach export
        // artefacts (links to a lane that starts beside the neighbour's end) on CARLA's towns.
        let found = search(map, from, goals, false).or_else(|| search(map, from, goals, true));
        let (found, reached) = found.ok_or(PlanError::NoPath {
            route: spec.id.clone(),
            from: i - 1,
            to: i,
        })?;
        legs.extend(found);
        from = reached;
    }
    Ok(DenseRoute::new(densify(map, &legs), spec.keypoint_length()))
}

/// The lane spots of a keypoint: the driving lane that matches its position and heading first,
/// then the other driving lanes that pass as close to it with the same heading and height.
fn snap(map: &Map, k: &Keypoint) -> Option<Vec<LaneSpot>> {
    let (lane, proj) = map.lane_for_pose(k.position, k.yaw)?;
    let matched = map.lane(lane).pose_at(proj.s);
    let mut spots = vec![LaneSpot { lane, s: proj.s }];
    for (other, p) in map.lanes_near(k.position.truncate(), proj.distance + GOAL_SPREAD, |l| {
        l.kind == LaneKind::Driving
    }) {
        let pose = map.lane(other).pose_at(p.s);
        if other != lane
            && angle_diff(pose.yaw, matched.yaw).abs() < 0.3
            && (pose.position.z - matched.position.z).abs() < 1.5
            && (pose.position - matched.position).truncate().length() < GOAL_SPREAD
        {
            spots.push(LaneSpot {
                lane: other,
                s: p.s,
            });
        }
    }
    Some(spots)
}

#[derive(Debug, Clone, Copy)]
struct Open {
    f: f64,
    g: f64,
    spot: LaneSpot,
    id: usize,
}

impl PartialEq for Open {
    fn eq(&self, other: &Self) -> bool {
        self.f == other.f && self.id == other.id
    }
}
impl Eq for Open {}
impl PartialOrd for Open {
    fn partial_cmp(&self, other: &Self) -> Option<Ordering> {
        Some(self.cmp(other))
    }
}
impl Ord for Open {
    fn cmp(&self, other: &Self) -> Ordering {
        other.f.total_cmp(&self.f).then(other.id.cmp(&self.id))
    }
}

/// A* from `start` to the first of `goals` reached; returns the legs and the goal reached.
fn search(
    map: &Map,
    start: LaneSpot,
    goals: &[LaneSpot],
    squeeze: bool,
) -> Option<(Vec<Leg>, LaneSpot)> {
    let goal_pos = map.lane(goals[0].lane).pose_at(goals[0].s).position;
    let h = |spot: LaneSpot| (map.lane(spot.lane).pose_at(spot.s).position - goal_pos).length();
    // Arena of visited states: (spot, parent, leg that reached it).
    let mut arena: Vec<(LaneSpot, Option<usize>, Option<Leg>)> = vec![(start, None, None)];
    let mut best: HashMap<(LaneIdx, i64), f64> = HashMap::new();
    let mut heap = BinaryHeap::new();
    heap.push(Open {
        f: h(start),
        g: 0.0,
        spot: start,
        id: 0,
    });
    let mut expansions = 0;
    while let Some(Open { g, spot, id, .. }) = heap.pop() {
        expansions += 1;
        if expansions > MAX_EXPANSIONS {
            return None;
        }
        if let Some(&goal) = goals
            .iter()
            .find(|goal| spot.lane == goal.lane && spot.s <= goal.s + 1e-6)
        {
            let mut legs = vec![Leg::Drive {
                lane: spot.lane,
                from: spot.s,
                to: goal.s,
            }];
            let mut at = id;
            while let (_, Some(parent), Some(leg)) = arena[at] {
                legs.push(leg);
                at = parent;
            }
            legs.reverse();
            return Some((legs, goal));
        }
        for (next, cost, leg) in moves(map, spot, goals, squeeze) {
            let key = (next.lane, (next.s * 2.0).round() as i64);
            let g2 = g + cost;
            if best.get(&key).is_some_and(|&b| b <= g2) {
                continue;
            }
            best.insert(key, g2);
            arena.push((next, Some(id), Some(leg)));
            heap.push(Open {
                f: g2 + h(next),
                g: g2,
                spot: next,
                id: arena.len() - 1,
            });
        }
    }
    None
}

/// The moves out of `spot`, each with its cost: on to every driving successor, and, outside
/// junctions, changes to each driving neighbour (a short one onto a goal a full change would
/// overshoot; a full one as soon as there is room and the target lane goes on after it; with
/// `squeeze`, one over the room left before the lane ends).
fn moves(
    map: &Map,
    spot: LaneSpot,
    goals: &[LaneSpot],
    squeeze: bool,
) -> Vec<(LaneSpot, f64, Leg)> {
    let lane = map.lane(spot.lane);
    let mut out = Vec::new();
    let rest = lane.length() - spot.s;
    for &succ in &lane.successors {
        if map.lane(succ).kind != LaneKind::Driving {
            continue;
        }
        let leg = Leg::Drive {
            lane: spot.lane,
            from: spot.s,
            to: lane.length(),
        };
        out.push((LaneSpot { lane: succ, s: 0.0 }, rest.max(0.0), leg));
    }
    if lane.in_junction() {
        return out;
    }
    for (neighbour, left) in [(lane.left, true), (lane.right, false)] {
        let Some(n) = neighbour else { continue };
        if map.lane(n).kind != LaneKind::Driving {
            continue;
        }
        // A goal on the neighbour that a full-length change would overshoot (a keypoint a
        // few metres into a lane that only a lane change reaches): a shorter change that
        // lands on it, costed as the full one plus the penalty again.
        // (Projected only when a goal is on the neighbour: this is the search's inner loop.)
        let beside = || {
            map.lane(n)
                .project(lane.pose_at(spot.s).position.truncate())
                .s
        };
        for goal in goals.iter().filter(|g| g.lane == n) {
            let length = goal.s - beside();
            if (SHORT_CHANGE_MIN..LANE_CHANGE_LENGTH).contains(&length)
                && spot.s + length <= lane.length()
            {
                let leg = Leg::Change {
                    from: spot.lane,
                    s0: spot.s,
                    to: n,
                    s1: goal.s,
                    length,
                    left,
                };
                let cost = LANE_CHANGE_LENGTH + 2.0 * LANE_CHANGE_PENALTY;
                out.push((*goal, cost, leg));
            }
        }
        // Change as soon as there is room, and only where the target lane goes on after it.
        let target = map.lane(n);
        let s_end = spot.s + LANE_CHANGE_LENGTH;
        let (s1, length, penalties) = if s_end <= lane.length() {
            let proj = target.project(lane.pose_at(s_end).position.truncate());
            if proj.s >= target.length() - 1.0 {
                continue;
            }
            (proj.s, LANE_CHANGE_LENGTH, 1.0)
        } else if squeeze {
            // Only when the pair has no path without it ([`plan_route`]'s second search):
            // no room left for a full change before the lane ends (a keypoint a few metres
            // before a junction whose turn leaves from the neighbour only), so as CARLA's
            // planner, whose lane-change edges have no minimum length, change over what is
            // left, onto a neighbour that goes on (its successors count), as long as the
            // route still moves forward across it (a step back is a route no car can
            // follow).
            let end = lane.pose_at(lane.length());
            let proj = target.project(end.position.truncate());
            let land = target.pose_at(proj.s).position - end.position;
            let forward = rest + land.truncate().dot(DVec2::from_angle(end.yaw));
            let goes_on = !target.successors.is_empty() || proj.s < target.length() - 1.0;
            if forward < SQUEEZED_CHANGE_MIN || !goes_on {
                continue;
            }
            (proj.s, rest.max(0.0), 3.0)
        } else {
            continue;
        };
        let leg = Leg::Change {
            from: spot.lane,
            s0: spot.s,
            to: n,
            s1,
            length,
            left,
        };
        let cost = LANE_CHANGE_LENGTH + penalties * LANE_CHANGE_PENALTY;
        out.push((LaneSpot { lane: n, s: s1 }, cost, leg));
    }
    out
}

/// Sample the legs at [`RESOLUTION`] and label every point.
fn densify(map: &Map, legs: &[Leg]) -> Vec<RoutePoint> {
    let mut points: Vec<RoutePoint> = Vec::new();
    // Some exported maps link lanes whose ends do not meet (CARLA's 2019 Town03 has gaps of a
    // few metres inside junctions): bridge such gaps with straight points.
    let push = |p: RoutePoint, points: &mut Vec<RoutePoint>| {
        let Some(&q) = points.last() else {
            points.push(p);
            return;
        };
        let gap = (p.position - q.position).length();
        if gap <= 0.05 {
            // A lane change starts where the previous leg ended: keep its label.
            if p.option.is_lane_change() {
                points.last_mut().expect("checked above").option = p.option;
            }
            return;
        }
        let steps = (gap / RESOLUTION).ceil() as usize;
        for k in 1..steps {
            let position = q.position.lerp(p.position, k as f64 / steps as f64);
            points.push(RoutePoint { position, ..p });
        }
        points.push(p);
    };
    for leg in legs {
        match *leg {
            Leg::Drive { lane, from, to } => {
                let l = map.lane(lane);
                let n = ((to - from) / RESOLUTION).ceil().max(1.0) as usize;
                for i in 0..=n {
                    let pose = l.pose_at(from + (to - from) * i as f64 / n as f64);
                    let option = RoadOption::LaneFollow;
                    push(
                        RoutePoint {
                            position: pose.position,
                            yaw: pose.yaw,
                            option,
                            lane,
                        },
                        &mut points,
                    );
                }
            }
            Leg::Change {
                from,
                s0,
                to,
                s1,
                length,
                left,
            } => {
                let (a, b) = (map.lane(from), map.lane(to));
                let change = if left {
                    RoadOption::ChangeLaneLeft
                } else {
                    RoadOption::ChangeLaneRight
                };
                let n = (length / RESOLUTION).round().max(2.0) as usize;
                for i in 0..=n {
                    let t = i as f64 / n as f64;
                    let w = t * t * (3.0 - 2.0 * t);
                    let pa = a.pose_at(s0 + length * t);
                    let pb = b.pose_at(s1 - length * (1.0 - t));
                    let position: DVec3 = pa.position.lerp(pb.position, w);
                    let lane = if w < 0.5 { from } else { to };
                    let yaw = pa.yaw + angle_diff(pb.yaw, pa.yaw) * w;
                    // Like CARLA: the point where the change starts and one a few metres in.
                    let option = if i == 0 || i == n / 2 {
                        change
                    } else {
                        RoadOption::LaneFollow
                    };
                    push(
                        RoutePoint {
                            position,
                            yaw,
                            option,
                            lane,
                        },
                        &mut points,
                    );
                }
            }
        }
    }
    fix_headings(&mut points);
    label_junctions(map, &mut points);
    points
}

/// Point headings follow the drawn path (matters inside lane changes).
fn fix_headings(points: &mut [RoutePoint]) {
    for i in 0..points.len() {
        let (a, b) = match (i.checked_sub(1), points.get(i + 1)) {
            (_, Some(next)) => (points[i].position, next.position),
            (Some(prev), None) => (points[prev].position, points[i].position),
            (None, None) => continue,
        };
        let d = (b - a).truncate();
        if d.length() > 1e-6 {
            points[i].yaw = d.y.atan2(d.x);
        }
    }
}

/// LEFT / RIGHT / STRAIGHT over each run of junction-connector points.
fn label_junctions(map: &Map, points: &mut [RoutePoint]) {
    let mut i = 0;
    while i < points.len() {
        if !map.lane(points[i].lane).in_junction() || points[i].option.is_lane_change() {
            i += 1;
            continue;
        }
        let start = i;
        while i < points.len() && map.lane(points[i].lane).in_junction() {
            i += 1;
        }
        let entry = points[start.saturating_sub(1)].yaw;
        let exit = points[i.min(points.len() - 1)].yaw;
        let turn = angle_diff(exit, entry);
        let option = if turn.abs() < STRAIGHT_LIMIT {
            RoadOption::Straight
        } else if turn > 0.0 {
            RoadOption::Left
        } else {
            RoadOption::Right
        };
        for p in &mut points[start..i] {
            p.option = option;
        }
    }
}
