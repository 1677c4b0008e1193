//! Scenarios from a leaderboard scenario file (`--scenarios`): the triggers the leaderboard 1.0
//! gives a route ([`crate::route::scenario_file::match_to_route`]), each placed as its
//! scenario_runner class places it, where this simulator can:
//! - Scenario1 ControlLoss: three patches of debris 12, 46 and 72 m past the trigger along the
//!   ego's lane (stopping at a junction), driven over. scenario_runner also declares a noise on
//!   the ego's steering and throttle there, but nothing applies it (`change_control` is never
//!   called in leaderboard 1.0), so none is added here either.
//! - Scenario3 DynamicObjectCrossing: a walker waits behind a parked van on the right edge of
//!   the rightmost driving lane, 12 m past the trigger plus 1.5 m per lane it is to the right
//!   of the ego's, and crosses the whole road when the ego reaches the trigger (scenario_runner:
//!   a vending machine for the van, the walker at 3 m/s starting 12 m before it along the
//!   route; here 1.8 m/s).
//! - Scenario4 VehicleTurningRoute: a cyclist crosses the exit road 8 m past the junction of
//!   the route's next left or right turn, starting when the ego is [`S4_START`] m short of it
//!   along the route (scenario_runner: 13 m plus about one lane width; 10 m/s, here 4 m/s).
//! - Scenario7, 8 and 9 SignalJunctionCrossingRoute: at the junction of the route's next turn,
//!   the ego's light held green while a vehicle on a conflicting approach runs its red, as
//!   the seed's placement does (scenario_runner changes the junction's lights so background
//!   traffic crosses against the ego, and spawns nobody; with CARLA-like traffic the runner
//!   goes straight on, as its standalone `OppositeVehicleRunningRedLight` drives one). Skipped
//!   where the ego's approach has no light.
//! - Scenario2 FollowLeadingVehicle: at the trigger a vehicle appears 25 m ahead on the ego's
//!   lane (nearer where a junction comes first), drives at 10 m/s and stops 20 m short of the
//!   next junction; it leaves once the ego has stood 1 s within 20 m of it (as
//!   scenario_runner's).
//! - Scenario5 OtherLeadingVehicle: a vehicle stands 35 m ahead on the ego's lane and another
//!   36 m ahead on the lane to its left from the start of the route; at the trigger they drive
//!   off at 17.2 and 45 m/s, and leave once the ego has driven 140 m past it (as
//!   scenario_runner's; its left vehicle takes the left lane whatever its direction, here only
//!   a same-direction one).
//! - Scenario6 ManeuverOppositeDirection: two street barriers across the ego's lane 50 and 52 m
//!   past the trigger, and from the trigger vehicles on the oncoming lane from 110 m ahead at
//!   5.56 m/s, the next whenever none is within 40 m of the source, at most 7, until the ego
//!   has driven 220 m past it (as scenario_runner's). The ego has to pass the barriers on the
//!   oncoming lane; the bundled expert does not overtake, so it waits there until blocked.
//! - Scenario10 NoSignalJunctionCrossingRoute: at the first junction after the trigger whose
//!   approach has no light, a vehicle on another approach whose way crosses the ego's drives
//!   across without giving way, placed 30 m before the ego's entry so that it arrives about
//!   when the ego does. scenario_runner's route version spawns nobody (it waits for the ego to
//!   cross; any crossing vehicle is background traffic); this one brings the crossing vehicle
//!   its standalone version has.
//!
//! A file's `other_actors` are read by no route scenario of the leaderboard 1.0 (only its
//! sampling looks at them); they are ignored here.

use super::builders::{
    index_ahead, index_back, junction_runs, red_light_runner, s2_leading_vehicle, s3_walker,
    s4_cyclist, s5_other_leading_vehicles, s6_maneuver_opposite_direction, s10_junction_crosser,
};
use super::{IdSource, Placement, StaticProp};
use crate::map::{LaneKind, Map};
use crate::route::DenseRoute;
use crate::route::scenario_file::{Trigger, match_to_route};
use crate::world::state::Obb;

/// Metres past the trigger where scenario_runner's ControlLoss lays its debris (its 14, 48 and
/// 74 m less the 2 m it subtracts).
pub const S1_DEBRIS: [f64; 3] = [12.0, 46.0, 72.0];
/// How far short of the cyclist's crossing, along the route, the ego starts Scenario4, m.
pub const S4_START: f64 = 17.0;
/// Metres past the junction's end where the Scenario4 cyclist crosses.
const S4_PAST_JUNCTION: f64 = 8.0;

/// The leaderboard's names, by scenario number.
const NAMES: [&str; 11] = [
    "",
    "Scenario1",
    "Scenario2",
    "Scenario3",
    "Scenario4",
    "Scenario5",
    "Scenario6",
    "Scenario7",
    "Scenario8",
    "Scenario9",
    "Scenario10",
];

/// Place the scenarios the leaderboard gives `route` from a town's `triggers`; `seed` draws
/// between two at one position.
pub fn place_from_file(
    map: &Map,
    route: &DenseRoute,
    triggers: &[Trigger],
    seed: u64,
    ids: &mut IdSource,
) -> Placement {
    let mut out = Placement::default();
    let runs = junction_runs(map, route);
    let n = route.points.len();
    for matched in match_to_route(triggers, route, seed) {
        let i = matched.index;
        let name = NAMES[matched.trigger.scenario as usize];
        // The junction of the route's next turn (the first junction at or after the trigger).
        let next_junction = runs.iter().find(|(start, _, _)| *start >= i);
        let mut one = Placement::default();
        match matched.trigger.scenario {
            1 => debris(map, route, i, &mut one),
            3 => {
                let lanes = lanes_to_the_right(map, route.points[i].lane);
                if let Some(at) = index_ahead(route, i, 12.0 + 1.5 * lanes as f64) {
                    s3_walker(map, route, (i, at), ids, &mut one);
                }
            }
            4 => {
                if let Some(&(_, end, _)) = next_junction
                    && let Some(at) = index_ahead(route, end.min(n - 1), S4_PAST_JUNCTION)
                {
                    let start = index_back(route, at, S4_START).max(i);
                    s4_cyclist(map, route, (start, at), ids, &mut one);
                }
            }
            7..=9 => {
                if let Some(&(start, _, _)) = next_junction {
                    red_light_runner(map, route, start, name, &mut one);
                }
            }
            2 => s2_leading_vehicle(map, route, i, &mut one),
            5 => s5_other_leading_vehicles(map, route, i, ids, &mut one),
            6 => s6_maneuver_opposite_direction(map, route, i, &mut one),
            10 => s10_junction_crosser(map, route, i, &mut one),
            _ => {}
        }
        out.add_unless_in_the_way(map, route, i, one);
    }
    out.scenarios.sort_by_key(|s| s.trigger);
    out
}

/// Driving lanes to the right of `lane` in its direction.
fn lanes_to_the_right(map: &Map, lane: crate::map::LaneIdx) -> usize {
    let mut count = 0;
    let mut l = map.lane(lane);
    while let Some(r) = l.right.filter(|r| map.lane(*r).kind == LaneKind::Driving) {
        count += 1;
        l = map.lane(r);
    }
    count
}

/// Scenario1's debris: [`S1_DEBRIS`] metres past route index `at` along the route, none past
/// the next junction's entry (scenario_runner's lane walk stops there).
fn debris(map: &Map, route: &DenseRoute, at: usize, out: &mut Placement) {
    for metres in S1_DEBRIS {
        let Some(k) = index_ahead(route, at, metres) else {
            return;
        };
        if route.points[at..=k]
            .iter()
            .any(|p| map.lane(p.lane).in_junction())
        {
            return;
        }
        let p = route.points[k];
        out.debris.push(StaticProp {
            obb: Obb {
                centre: p.position.truncate(),
                yaw: p.yaw,
                half: glam::DVec2::new(1.2, 0.9),
            },
            z: p.position.z,
        });
    }
}
