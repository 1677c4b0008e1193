//! One builder per scenario type, placing its actors for a route at given route indices; both
//! placements ([`super::drawn`] from the seed, [`super::leaderboard`] from a scenario file) call
//! them.

use glam::{DVec2, DVec3};
use ssrdrive_proto::command::RoadOption;

use super::{
    ActorKind, CYCLIST_SPEED, Crosser, IdSource, Placement, Scenario, ScenarioAction, StaticProp,
    WALKER_SPEED,
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

/// S3 DynamicObjectCrossing: a walker waits behind a parked van on the right edge at route
/// index `at` and crosses the whole road when the ego reaches index `trigger`.
pub(super) fn s3_walker(
    map: &Map,
    route: &DenseRoute,
    (trigger, at): (usize, usize),
    ids: &mut IdSource,
    out: &mut Placement,
) {
    let c = route.points[at];
    let (edge, right, across) = carriageway(map, c.lane, c.position, c.yaw);
    let forward = DVec2::from_angle(c.yaw);
    let van_centre = edge.truncate() + right * 1.4 - forward * 3.5;
    out.statics.push(StaticProp {
        obb: Obb {
            centre: van_centre,
            yaw: c.yaw,
            half: DVec2::new(2.5, 1.1),
        },
        z: edge.z,
    });
    let walker = (ActorKind::Walker, WALKER_SPEED, DVec2::splat(0.3));
    let crosser = Crosser::waiting_to_cross(ids.next(), walker, edge, right, 2.5, across);
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
    let c = route.points[at];
    let (edge, right, across) = carriageway(map, c.lane, c.position, c.yaw);
    let cyclist = (ActorKind::Cyclist, CYCLIST_SPEED, DVec2::new(0.9, 0.35));
    let crosser = Crosser::waiting_to_cross(ids.next(), cyclist, edge, right, 3.0, across);
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
    let Some((lane, s)) = runner_start(map, route.points[start].lane, ego_light) else {
        return false;
    };
    out.scenarios.push(Scenario {
        name,
        trigger: start.saturating_sub(30),
        action: ScenarioAction::RedLightRunner { ego_light, lane, s },
        fired: false,
    });
    true
}

/// A place 35 m before the stop line of an approach (of the same junction, not the ego's) whose
/// connectors conflict with `ego_connector`.
fn runner_start(map: &Map, ego_connector: LaneIdx, ego_light: usize) -> Option<(LaneIdx, f64)> {
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
            let crosses = lane.successors.iter().any(|s| theirs.contains(s));
            if crosses && lane.length() > 40.0 {
                return Some((line.lane, lane.length() - 35.0));
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
