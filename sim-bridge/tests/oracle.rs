//! The expert's plan and the oracle-plan agent: the plan is where the expert really goes, and
//! the served agent's controller, fed that plan, drives a Town05-style route as well as the
//! expert does (the controller's own tests check the geometry on a simulated car).

use glam::DVec2;
use sim_bridge::driver::{Agent, AgentError, Observation, RouteContext};
use sim_bridge::eval::run_route;
use sim_bridge::expert::Expert;
use sim_bridge::expert::oracle::{OraclePlan, sim_control_config};
use sim_bridge::map::{Map, MapOptions};
use sim_bridge::route::planner::plan_route;
use sim_bridge::route::sets::RouteSet;
use sim_bridge::route::xml::{self, RouteSpec};
use sim_bridge::scoring::ScoringConfig;
use sim_bridge::towngen::bundled;
use sim_bridge::world::{World, WorldConfig};
use ssrdrive_proto::command::RoadOption;
use ssrdrive_proto::control::Control;

fn town05_short() -> (Map, Vec<RouteSpec>) {
    let set = RouteSet::find("town05-short-style").expect("bundled set");
    let map = Map::from_str(set.town.name(), bundled(set.town), MapOptions::default()).unwrap();
    (map, xml::parse(set.name, set.bundled_xml()).unwrap())
}

fn drive(map: &Map, spec: &RouteSpec, agent: &mut dyn Agent) -> (f64, String) {
    let dense = plan_route(map, spec).unwrap();
    let world = WorldConfig {
        vehicles: 30,
        seed: 3,
        ..WorldConfig::default()
    };
    let run = run_route(
        map,
        spec,
        &dense,
        agent,
        world,
        ScoringConfig::default(),
        0,
        0,
        |_| {},
    );
    (run.record.scores.score_composed, run.record.status)
}

/// The expert, remembering the ego's world pose and its plan (in world coordinates) each tick.
struct PlanWatcher {
    expert: Expert,
    poses: Vec<(DVec2, f64)>,
    plans: Vec<Vec<DVec2>>,
}

impl Agent for PlanWatcher {
    fn name(&self) -> String {
        "plan watcher".into()
    }
    fn start_route(&mut self, ctx: &RouteContext<'_>) -> Result<(), AgentError> {
        self.expert.start_route(ctx)
    }
    fn run_step(&mut self, obs: &Observation, world: &World<'_>) -> Result<Control, AgentError> {
        let control = self.expert.run_step(obs, world)?;
        let (p, yaw) = (obs.position.truncate(), obs.yaw);
        let (forward, left) = (DVec2::from_angle(yaw), DVec2::from_angle(yaw).perp());
        let plan = self.expert.planned_trajectory();
        self.plans.push(
            plan.iter()
                .map(|w| p + forward * w.x + left * w.y)
                .collect(),
        );
        self.poses.push((p, yaw));
        Ok(control)
    }
}

#[test]
fn the_expert_plans_where_it_goes() {
    let (map, specs) = town05_short();
    let mut watcher = PlanWatcher {
        expert: Expert::new(),
        poses: Vec::new(),
        plans: Vec::new(),
    };
    let (ds, _) = drive(&map, &specs[0], &mut watcher);
    assert!(ds > 90.0, "the expert drives the route: DS {ds}");
    let ticks = watcher.poses.len();
    assert!(ticks > 400, "{ticks} ticks");
    let mut errors = Vec::new();
    for (t, plan) in watcher.plans.iter().enumerate() {
        assert_eq!(plan.len(), 6, "six waypoints, 0.5 s apart");
        // The first second of the plan against where the expert was 0.5 s and 1 s later.
        for (k, waypoint) in plan.iter().take(2).enumerate() {
            if let Some((actual, _)) = watcher.poses.get(t + 10 * (k + 1)) {
                errors.push((*waypoint - *actual).length());
            }
        }
    }
    errors.sort_by(f64::total_cmp);
    let median = errors[errors.len() / 2];
    let p90 = errors[errors.len() * 9 / 10];
    assert!(
        median < 0.3 && p90 < 1.0,
        "plan vs path: median {median:.2} m, p90 {p90:.2} m"
    );
}

#[test]
fn the_oracle_plan_agent_drives_the_route_with_the_most_turns() {
    let (map, specs) = town05_short();
    // The route with the most turning: the controller matters most there.
    let spec = specs
        .iter()
        .max_by_key(|s| {
            let dense = plan_route(&map, s).unwrap();
            dense
                .points
                .iter()
                .filter(|p| matches!(p.option, RoadOption::Left | RoadOption::Right))
                .count()
        })
        .unwrap();
    let (ds, end) = drive(&map, spec, &mut OraclePlan::new(sim_control_config()));
    assert!(ds > 90.0, "as served, route {}: DS {ds}, {end}", spec.id);
    let (ds, end) = drive(&map, spec, &mut OraclePlan::plan_only(sim_control_config()));
    assert!(
        ds > 90.0,
        "on the plan alone, route {}: DS {ds}, {end}",
        spec.id
    );
}
