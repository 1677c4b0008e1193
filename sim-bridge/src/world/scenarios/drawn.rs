//! Scenarios drawn along a route from the world seed, for routes without a scenario file: S3
//! about every [`S3_SPACING`] m of straight road, and at each junction the route crosses an S7
//! red-light runner (where the ego's approach has a light, half the time) or else, after a left
//! or right turn, an S4 cyclist (half the time).

use rand::{Rng, RngExt as _};
use ssrdrive_proto::command::RoadOption;

use super::builders::{junction_runs, red_light_runner, s3_walker, s4_cyclist};
use super::{CROSSING_AHEAD, IdSource, Placement, S3_SPACING};
use crate::map::Map;
use crate::route::DenseRoute;

/// Place scenarios along `route` from `rng`.
pub fn place_route_scenarios(
    map: &Map,
    route: &DenseRoute,
    ids: &mut IdSource,
    rng: &mut impl Rng,
) -> Placement {
    let mut out = Placement::default();
    let n = route.points.len();
    let ahead = CROSSING_AHEAD as usize;
    // S3: straight stretches, away from junctions and lane changes.
    let mut next_s3 = rng.random_range(80.0..S3_SPACING);
    let mut i = 0;
    while i + ahead + 15 < n {
        let p = route.points[i];
        let window = &route.points[i..i + ahead + 15];
        let straight = window
            .iter()
            .all(|q| crate::map::angle_diff(q.yaw, p.yaw).abs() < 0.1);
        let clear = straight
            && window
                .iter()
                .all(|q| q.option == RoadOption::LaneFollow && !map.lane(q.lane).in_junction());
        if route.cum[i] >= next_s3 && clear {
            let mut one = Placement::default();
            s3_walker(map, route, (i, i + ahead), ids, &mut one);
            out.add_unless_in_the_way(map, route, i, one);
            next_s3 = route.cum[i] + rng.random_range(0.6..1.4) * S3_SPACING;
            i += ahead + 15;
            continue;
        }
        i += 1;
    }
    // Junction runs: S7 at signalized junctions, else S4 after turns.
    for (start, end, option) in junction_runs(map, route) {
        let has_light = {
            let incoming = route.points[start.saturating_sub(1)].lane;
            map.lights
                .iter()
                .any(|l| l.stop_lines.iter().any(|s| s.lane == incoming))
        };
        // Drawn whether or not there is a light, so the stream stays as it always was.
        let runner = rng.random_range(0.0..1.0) < 0.5;
        let mut one = Placement::default();
        if has_light
            && runner
            && red_light_runner(map, route, start, "Scenario7", &mut one)
            && out.add_unless_in_the_way(map, route, start, one)
        {
            continue;
        }
        if matches!(option, RoadOption::Left | RoadOption::Right)
            && end + ahead < n
            && rng.random_range(0.0..1.0) < 0.5
        {
            let mut one = Placement::default();
            s4_cyclist(map, route, (start, (end + 10).min(n - 1)), ids, &mut one);
            out.add_unless_in_the_way(map, route, start, one);
        }
    }
    out.scenarios.sort_by_key(|s| s.trigger);
    out
}
