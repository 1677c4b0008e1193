//! One builder per scenario type, placing its actors for a route at given route indices; both
//! placements ([`super::drawn`] from the seed, [`super::leaderboard`] from a scenario file) call
//! them.

use glam::{DVec2, DVec3};
use ssrdrive_proto::command::RoadOption;

use super::{
    ActorKind, CYCLIST_SPEED, Crosser, IdSource, Placement, ScenarioAction, StaticProp,
    WALKER_SPEED, WaitingVehicle,
};
use crate::map::{LaneIdx, LaneKind, Map};
use crate::route::DenseRoute;
use crate::world::state::Obb;

/// The carriageway across a route point: the point on its right edge, the outward (rightward)
/// unit vector, and the distance from that edge to the far (left) edge of the whole road,
/// opposite lanes included.
fn carriageway(map: &Map, lane: LaneIdx, at: DVec3, yaw: f64) -> (DVec3, DVec2, f64) {
    let mut l = map.lane(lane);
    while let Some(r) = l.right.filter(|r| map.lane(*r).kind == LaneKind::Driving) {
        l = map.lane(r);
    }
    let proj = l.project(at.truncate());
    let centre = l.pose_at(proj.s).position;
    let right = -DVec2::from_angle(yaw).perp();
    let edge = centre + (right * (l.width / 2.0)).extend(0.0);
    let across = map
        .lanes_near(edge.truncate(), 25.0, |x| {
            x.kind == LaneKind::Driving && !x.in_junction()
        })
        .into_iter()
        .map(|(x, p)| {
            let point = map.lane(x).pose_at(p.s).position.truncate();
            (point - edge.truncate()).dot(-right) + map.lane(x).width / 2.0
        })
        .filter(|w| *w < 25.0)
        .fold(l.width, f64::max);
    (edge, right, across)
}

/// A crosser (`mover`: kind, speed, half size) waiting `offset` m outside the right edge of the
/// road at route index `at`, facing across it; with that edge point and the rightward unit vector.
fn crosser_at(
    map: &Map,
    route: &DenseRoute,
    at: usize,
    mover: (ActorKind, f64, DVec2),
    offset: f64,
    ids: &mut IdSource,
) -> (Crosser, DVec3, DVec2) {
    let c = route.points[at];
    let (edge, right, across) = carriageway(map, c.lane, c.position, c.yaw);
    let crosser = Crosser::waiting_to_cross(ids.next(), mover, edge, right, offset, across);
    (crosser, edge, right)
}

/// S3 DynamicObjectCrossing: a walker waits behind a parked van on the right edge at route
/// index `at` and crosses the whole road when the ego reaches index `trigger`.
pub(super) fn s3_walker(
    map: &Map,
    route: &DenseRoute,
    (trigger, at): (usize, usize),
    ids: &mut IdSource,
    out: &mut Placement,
) {
    let walker = (ActorKind::Walker, WALKER_SPEED, DVec2::splat(0.3));
    let (crosser, edge, right) = crosser_at(map, route, at, walker, 2.5, ids);
    let yaw = route.points[at].yaw;
    out.statics.push(StaticProp {
        obb: Obb {
            centre: edge.truncate() + right * 1.4 - DVec2::from_angle(yaw) * 3.5,
            yaw,
            half: DVec2::new(2.5, 1.1),
        },
        z: edge.z,
    });
    out.add_crossing(map, "Scenario3", trigger, crosser);
}

/// S4 VehicleTurningRoute: a cyclist crosses the exit road at route index `at` (past a turn)
/// when the ego reaches index `trigger`.
pub(super) fn s4_cyclist(
    map: &Map,
    route: &DenseRoute,
    (trigger, at): (usize, usize),
    ids: &mut IdSource,
    out: &mut Placement,
) {
    let cyclist = (ActorKind::Cyclist, CYCLIST_SPEED, DVec2::new(0.9, 0.35));
    let (crosser, _, _) = crosser_at(map, route, at, cyclist, 3.0, ids);
    out.add_crossing(map, "Scenario4", trigger, crosser);
}

/// S7-S9 SignalJunctionCrossingRoute at the junction the route enters at index `start`: the
/// ego's light is held green while a vehicle on a conflicting approach runs its red. False,
/// with nothing placed, where the ego's approach has no light or no approach conflicts.
pub(super) fn red_light_runner(
    map: &Map,
    route: &DenseRoute,
    start: usize,
    name: &'static str,
    out: &mut Placement,
) -> bool {
    let incoming = route.points[start.saturating_sub(1)].lane;
    let Some(ego_light) = map
        .lights
        .iter()
        .find(|l| l.stop_lines.iter().any(|s| s.lane == incoming))
        .map(|l| l.id)
    else {
        return false;
    };
    let ego_connector = route.points[start].lane;
    let Some((lane, s, _)) = runner_start(map, ego_connector, ego_light, false) else {
        return false;
    };
    let straight = runner_start(map, ego_connector, ego_light, true)
        .and_then(|(lane, s, through)| Some((lane, s, through?)));
    let action = ScenarioAction::RedLightRunner {
        ego_light,
        lane,
        s,
        straight,
    };
    out.add(name, start.saturating_sub(30), action);
    true
}

/// A place 35 m before the stop line of an approach (of the same junction, not the ego's) whose
/// connectors conflict with `ego_connector`; with `straight_on`, one whose straight-on
/// connector does, and that connector.
fn runner_start(
    map: &Map,
    ego_connector: LaneIdx,
    ego_light: usize,
    straight_on: bool,
) -> Option<(LaneIdx, f64, Option<LaneIdx>)> {
    let junction = map.lane(ego_connector).junction?;
    let conflicts = crate::world::junctions::conflicts(map);
    let theirs = conflicts.get(&ego_connector)?;
    for light in map
        .lights
        .iter()
        .filter(|l| l.junction == junction && l.id != ego_light)
    {
        for line in &light.stop_lines {
            let lane = map.lane(line.lane);
            let through = map
                .straight_on(line.lane, line.yaw)
                .map(|(connector, _)| connector)
                .filter(|connector| theirs.contains(connector));
            let crosses = if straight_on {
                through.is_some()
            } else {
                lane.successors.iter().any(|s| theirs.contains(s))
            };
            if crosses && lane.length() > 40.0 {
                return Some((line.lane, lane.length() - 35.0, through));
            }
        }
    }
    None
}

/// The stretches of `route` on junction lanes, as index ranges, with the option the route
/// takes through each.
pub(super) fn junction_runs(map: &Map, route: &DenseRoute) -> Vec<(usize, usize, RoadOption)> {
    let n = route.points.len();
    let mut runs = Vec::new();
    let mut i = 0;
    while i < n {
        if !map.lane(route.points[i].lane).in_junction() {
            i += 1;
            continue;
        }
        let start = i;
        while i < n && map.lane(route.points[i].lane).in_junction() {
            i += 1;
        }
        runs.push((start, i, route.points[start].option));
    }
    runs
}

/// The route index `metres` past index `from`, if the route goes that far.
pub(super) fn index_ahead(route: &DenseRoute, from: usize, metres: f64) -> Option<usize> {
    let goal = route.cum[from] + metres;
    (from..route.points.len()).find(|&k| route.cum[k] >= goal)
}

/// The route index `metres` before index `from` (0 at the start).
pub(super) fn index_back(route: &DenseRoute, from: usize, metres: f64) -> usize {
    let goal = route.cum[from] - metres;
    (0..=from)
        .rev()
        .find(|&k| route.cum[k] <= goal)
        .unwrap_or(0)
}

/// The route index `metres` past `from` along the ego's road, or the last one before the next
/// junction if that comes first (scenario_runner's lane walks stop at a junction); `None` when
/// the route ends first.
pub(super) fn ahead_on_road(
    map: &Map,
    route: &DenseRoute,
    from: usize,
    metres: f64,
) -> Option<usize> {
    let goal = route.cum[from] + metres;
    let mut last = from;
    for k in from..route.points.len() {
        if map.lane(route.points[k].lane).in_junction() {
            return Some(last);
        }
        last = k;
        if route.cum[k] >= goal {
            return Some(k);
        }
    }
    None
}

/// Where route index `k` lies on its lane: (lane, arc length).
fn lane_place(map: &Map, route: &DenseRoute, k: usize) -> (LaneIdx, f64) {
    let p = route.points[k];
    (p.lane, map.lane(p.lane).project(p.position.truncate()).s)
}

/// Scenario2 FollowLeadingVehicle, fired at route index `trigger`: a vehicle appears 25 m ahead
/// on the ego's lane (nearer where a junction comes first) and drives at 10 m/s until it stops
/// short of the next junction ([`ScenarioAction::LeadingVehicle`]).
pub(super) fn s2_leading_vehicle(
    map: &Map,
    route: &DenseRoute,
    trigger: usize,
    out: &mut Placement,
) {
    let Some(k) = ahead_on_road(map, route, trigger, 25.0).filter(|&k| k > trigger + 8) else {
        return;
    };
    let (lane, s) = lane_place(map, route, k);
    let action = ScenarioAction::LeadingVehicle {
        lane,
        s,
        speed: 10.0,
    };
    out.add("Scenario2", trigger, action);
}

/// Scenario5 OtherLeadingVehicle at route index `trigger`: a vehicle stands 35 m ahead on the
/// ego's lane and another 36 m ahead on the lane to its left (same direction; none where there
/// is no such lane) from the start; at the trigger they drive off at 17.2 and 45 m/s, and they
/// leave once the ego has driven 140 m past it (scenario_runner's constants).
pub(super) fn s5_other_leading_vehicles(
    map: &Map,
    route: &DenseRoute,
    trigger: usize,
    ids: &mut IdSource,
    out: &mut Placement,
) {
    let mut vehicles = Vec::new();
    if let Some(k) = ahead_on_road(map, route, trigger, 35.0).filter(|&k| k > trigger + 8) {
        let (lane, s) = lane_place(map, route, k);
        vehicles.push((
            WaitingVehicle {
                id: ids.next(),
                lane,
                s,
            },
            55.0 / 3.2,
        ));
    }
    if let Some(k) = ahead_on_road(map, route, trigger, 36.0).filter(|&k| k > trigger + 8)
        && let Some(left) = map.lane(route.points[k].lane).left
    {
        let s = map
            .lane(left)
            .project(route.points[k].position.truncate())
            .s;
        vehicles.push((
            WaitingVehicle {
                id: ids.next(),
                lane: left,
                s,
            },
            45.0,
        ));
    }
    if vehicles.is_empty() {
        return;
    }
    out.vehicles.extend(vehicles.iter().map(|(v, _)| *v));
    let action = ScenarioAction::Release {
        vehicles: vehicles.iter().map(|(v, speed)| (v.id, *speed)).collect(),
        metres: 140.0,
    };
    out.add("Scenario5", trigger, action);
}

/// The ego is past Scenario6's barriers once its route progress is this far beyond the last
/// one (its length and a margin), m.
const PAST_BARRIERS: f64 = 6.0;

/// Scenario6 ManeuverOppositeDirection at route index `trigger`: two street barriers across
/// the ego's lane 50 and 52 m ahead (the second half a lane to the right), and from the
/// trigger a flow of vehicles on the oncoming lane from 110 m ahead at 5.56 m/s, at most 7,
/// until the ego has driven 220 m past the trigger (scenario_runner's constants). Nothing is
/// placed where the road has no oncoming lane.
pub(super) fn s6_maneuver_opposite_direction(
    map: &Map,
    route: &DenseRoute,
    trigger: usize,
    out: &mut Placement,
) {
    let (Some(first), Some(source)) = (
        ahead_on_road(map, route, trigger, 50.0),
        index_ahead(route, trigger, 110.0),
    ) else {
        return;
    };
    let p = route.points[source];
    let lane_width = map.lane(p.lane).width;
    let oncoming = map.oncoming_lane(p.position.truncate(), p.yaw, lane_width);
    let Some((lane, projection)) = oncoming else {
        return;
    };
    let second = ahead_on_road(map, route, first, 2.0).unwrap_or(first);
    let mut barriers = Vec::new();
    for (k, aside) in [(first, 0.0), (second, -0.5 * lane_width)] {
        let q = route.points[k];
        let centre = q.position.truncate() + q.forward().perp() * aside;
        barriers.push(centre);
        out.statics.push(StaticProp {
            obb: Obb {
                centre,
                yaw: q.yaw + std::f64::consts::FRAC_PI_2,
                half: DVec2::new(1.0, 0.3),
            },
            z: q.position.z,
        });
    }
    let action = ScenarioAction::OncomingFlow {
        lane,
        s: projection.s,
        speed: 5.56,
        count: 7,
        metres: 220.0,
        barriers,
        past: route.cum[second] + PAST_BARRIERS,
    };
    out.add("Scenario6", trigger, action);
}

/// Scenario10 NoSignalJunctionCrossingRoute at the first junction without a light on the ego's
/// approach from route index `trigger` on: a vehicle on another approach whose way crosses
/// the ego's drives across without giving way, timed to meet the ego there; it starts 30 m
/// before the ego's junction entry (not before the trigger).
pub(super) fn s10_junction_crosser(
    map: &Map,
    route: &DenseRoute,
    trigger: usize,
    out: &mut Placement,
) {
    let conflicts = crate::world::junctions::conflicts(map);
    for (start, _, _) in junction_runs(map, route)
        .into_iter()
        .filter(|r| r.0 > trigger)
    {
        let incoming = route.points[start - 1].lane;
        if map.light_ending(incoming).is_some() {
            continue;
        }
        let ego_connector = route.points[start].lane;
        let approach = conflicts.get(&ego_connector).and_then(|theirs| {
            theirs
                .iter()
                .filter_map(|c| map.lane(*c).predecessors.first().copied())
                .find(|&a| {
                    a != incoming && !map.lane(a).in_junction() && map.lane(a).length() > 15.0
                })
        });
        if let Some(lane) = approach {
            let fire = index_back(route, start, 30.0).max(trigger);
            let action = ScenarioAction::JunctionCrosser {
                lane,
                ego_to_junction: route.cum[start] - route.cum[fire],
            };
            out.add("Scenario10", fire, action);
        }
        return;
    }
}
