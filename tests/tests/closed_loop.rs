//! Closed loop through the public API: agents drive bundled routes in the simulator and the
//! scorer judges them, the way `sim-bridge eval` does.

use sim_bridge::driver::{Agent, AgentError, Observation, RouteContext};
use sim_bridge::eval::run_route;
use sim_bridge::expert::Expert;
use sim_bridge::map::{Map, MapOptions};
use sim_bridge::route::planner::plan_route;
use sim_bridge::route::sets::RouteSet;
use sim_bridge::route::xml;
use sim_bridge::scoring::{InfractionKind, ScoringConfig};
use sim_bridge::world::{World, WorldConfig};
use ssrdrive_proto::control::Control;

fn short_routes() -> (Map, Vec<xml::RouteSpec>) {
    let set = RouteSet::find("town05-short-style").unwrap();
    let map = Map::from_str(
        set.town.name(),
        sim_bridge::towngen::bundled(set.town),
        MapOptions::default(),
    )
    .unwrap();
    (map, xml::parse(set.name, set.bundled_xml()).unwrap())
}

/// A scripted agent that sends the same control every tick, whatever the road does.
struct Fixed(Control);

/// Straight on at half throttle.
const STRAIGHT_ON: Control = Control {
    steer: 0.0,
    throttle: 0.5,
    brake: 0.0,
};
/// Never moves.
const PARKED: Control = Control {
    steer: 0.0,
    throttle: 0.0,
    brake: 1.0,
};

impl Agent for Fixed {
    fn name(&self) -> String {
        format!("fixed control {:?}", self.0)
    }
    fn start_route(&mut self, _ctx: &RouteContext<'_>) -> Result<(), AgentError> {
        Ok(())
    }
    fn run_step(&mut self, _obs: &Observation, _world: &World<'_>) -> Result<Control, AgentError> {
        Ok(self.0)
    }
}

#[test]
fn the_expert_completes_short_routes_with_traffic() {
    let (map, specs) = short_routes();
    let mut expert = Expert::new();
    let (mut rc, mut ds, mut collisions) = (0.0, 0.0, 0);
    for (i, spec) in specs.iter().take(4).enumerate() {
        let dense = plan_route(&map, spec).unwrap();
        let config = WorldConfig {
            seed: 3,
            ..WorldConfig::default()
        };
        let run = run_route(
            &map,
            spec,
            &dense,
            &mut expert,
            config,
            ScoringConfig::default(),
            i,
            0,
            |_| {},
        );
        rc += run.record.scores.score_route;
        ds += run.record.scores.score_composed;
        collisions += [
            InfractionKind::CollisionVehicle,
            InfractionKind::CollisionPedestrian,
            InfractionKind::CollisionLayout,
        ]
        .iter()
        .map(|&k| run.record.infractions.count(k))
        .sum::<usize>();
    }
    assert!(rc / 4.0 > 99.0, "mean RC {}", rc / 4.0);
    assert!(ds / 4.0 > 95.0, "mean DS {}", ds / 4.0);
    assert_eq!(collisions, 0, "the expert collided");
}

#[test]
fn runs_replay_identically_from_a_seed() {
    let (map, specs) = short_routes();
    let dense = plan_route(&map, &specs[1]).unwrap();
    let run = |seed| {
        let config = WorldConfig {
            seed,
            walkers: 20,
            ..WorldConfig::default()
        };
        let mut r = run_route(
            &map,
            &specs[1],
            &dense,
            &mut Expert::new(),
            config,
            ScoringConfig::default(),
            0,
            0,
            |_| {},
        );
        r.record.meta.duration_system = 0.0;
        (r.record, r.trace)
    };
    assert_eq!(run(11), run(11));
}

#[test]
fn an_agent_that_never_moves_is_blocked_after_180_s() {
    let (map, specs) = short_routes();
    // A route long enough that its timeout, int(0.8 s/m * length + 5 s), is past 180 s.
    let (spec, dense) = specs
        .iter()
        .map(|s| (s, plan_route(&map, s).unwrap()))
        .find(|(_, d)| d.length() > 250.0)
        .expect("a short route over 250 m");
    let config = WorldConfig {
        vehicles: 0,
        scenarios: false,
        ..WorldConfig::default()
    };
    let run = run_route(
        &map,
        spec,
        &dense,
        &mut Fixed(PARKED),
        config,
        ScoringConfig::default(),
        0,
        0,
        |_| {},
    );
    assert_eq!(run.record.status, "Failed - Agent got blocked");
    assert!(
        (180.0..181.0).contains(&run.record.meta.duration_game),
        "{}",
        run.record.meta.duration_game
    );
    assert_eq!(run.record.scores.score_route, 0.0);
}

#[test]
fn a_runs_infraction_list_holds_every_infraction_of_its_record() {
    // Driving straight on leaves the route's lanes, an event the scorer adds only when the run
    // ends; the pictures `eval --pictures` draws from the list must still show it.
    let (map, specs) = short_routes();
    let config = WorldConfig {
        vehicles: 0,
        walkers: 0,
        scenarios: false,
        ..WorldConfig::default()
    };
    let mut off_lane = 0;
    for spec in specs.iter().take(3) {
        let dense = plan_route(&map, spec).unwrap();
        let run = run_route(
            &map,
            spec,
            &dense,
            &mut Fixed(STRAIGHT_ON),
            config.clone(),
            ScoringConfig::default(),
            0,
            0,
            |_| {},
        );
        for kind in InfractionKind::ALL {
            let listed = run.infractions.iter().filter(|i| i.kind == kind).count();
            assert_eq!(listed, run.record.infractions.count(kind), "{kind:?}");
        }
        off_lane += run
            .record
            .infractions
            .count(InfractionKind::OutsideRouteLanes);
    }
    assert!(off_lane > 0, "no run left its lanes");
}
