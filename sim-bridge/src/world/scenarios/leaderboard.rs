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
//!   traffic crosses against the ego, and spawns nobody). Skipped where the ego's approach has
//!   no light.
//!
//! Scenario2, 5, 6 and 10 are matched and sampled like the others (they take their position
//! from a lower-numbered one) but place nothing yet.

use super::builders::{junction_runs, red_light_runner, s3_walker, s4_cyclist};
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
        match matched.trigger.scenario {
            1 => debris(map, route, i, &mut out),
            3 => {
                let lanes = lanes_to_the_right(map, route.points[i].lane);
                if let Some(at) = index_ahead(route, i, 12.0 + 1.5 * lanes as f64) {
                    s3_walker(map, route, (i, at), ids, &mut out);
                }
            }
            4 => {
                if let Some(&(_, end, _)) = next_junction
                    && let Some(at) = index_ahead(route, end.min(n - 1), S4_PAST_JUNCTION)
                {
                    let start = index_back(route, at, S4_START).max(i);
                    s4_cyclist(map, route, (start, at), ids, &mut out);
                }
            }
            7..=9 => {
                if let Some(&(start, _, _)) = next_junction {
                    red_light_runner(map, route, start, name, &mut out);
                }
            }
            _ => {}
        }
    }
    out.scenarios.sort_by_key(|s| s.trigger);
    out
}

/// The route index `metres` past index `from`, if the route goes that far.
fn index_ahead(route: &DenseRoute, from: usize, metres: f64) -> Option<usize> {
    let goal = route.cum[from] + metres;
    (from..route.points.len()).find(|&k| route.cum[k] >= goal)
}

/// The route index `metres` before index `from` (0 at the start).
fn index_back(route: &DenseRoute, from: usize, metres: f64) -> usize {
    let goal = route.cum[from] - metres;
    (0..=from)
        .rev()
        .find(|&k| route.cum[k] <= goal)
        .unwrap_or(0)
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
