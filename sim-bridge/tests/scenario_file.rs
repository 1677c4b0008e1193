//! Leaderboard scenario files (`--scenarios`): parsing and its refusals, matching triggers to a
//! dense route as the leaderboard 1.0 does (distance, angle, the next turn, one scenario per
//! position), the world placing what the matches call for, and the public file on CARLA towns.

mod common;

use common::carla_dir;
use sim_bridge::eval::run_route;
use sim_bridge::expert::Expert;
use sim_bridge::map::{Map, MapOptions};
use sim_bridge::route::scenario_file::{ScenarioFile, Trigger, Turn, match_to_route};
use sim_bridge::route::sets::RouteSet;
use sim_bridge::route::{DenseRoute, planner, xml};
use sim_bridge::scoring::ScoringConfig;
use sim_bridge::towngen;
use sim_bridge::world::state::ActorKind;
use sim_bridge::world::{World, WorldConfig};
use ssrdrive_proto::command::RoadOption;

/// Route `k` of the bundled `set`, planned on its town.
fn bundled_route(set: &str, k: usize) -> (Map, xml::RouteSpec, DenseRoute) {
    let set = RouteSet::find(set).unwrap();
    let map = Map::from_str(
        set.town.name(),
        towngen::bundled(set.town),
        MapOptions::default(),
    )
    .unwrap();
    let spec = xml::parse(set.name, set.bundled_xml()).unwrap()[k].clone();
    let dense = planner::plan_route(&map, &spec).unwrap();
    (map, spec, dense)
}

/// A trigger of scenario `n` on route point `k`, moved `side` m to its left and turned `turn`
/// degrees.
fn trigger_at(route: &DenseRoute, k: usize, n: u8, side: f64, turn: f64) -> Trigger {
    let p = route.points[k];
    Trigger {
        scenario: n,
        position: p.position + p.forward().perp().extend(0.0) * side,
        yaw: p.yaw + turn.to_radians(),
    }
}

/// A scenario file of one town in CARLA's frame (y and yaw flipped) from OpenDRIVE-frame
/// triggers.
fn file_text(town: &str, triggers: &[Trigger]) -> String {
    let scenarios: Vec<String> = triggers
        .iter()
        .map(|t| {
            format!(
                r#"{{"scenario_type": "Scenario{}", "available_event_configurations": [{{"transform": {{"x": "{}", "y": "{}", "z": "{}", "yaw": "{}", "pitch": "0"}}}}]}}"#,
                t.scenario,
                t.position.x,
                -t.position.y,
                t.position.z,
                -t.yaw.to_degrees()
            )
        })
        .collect();
    format!(
        r#"{{"available_scenarios": [{{"{town}": [{}]}}]}}"#,
        scenarios.join(",")
    )
}

fn refusal(text: &str) -> String {
    ScenarioFile::parse(text, "test.json")
        .unwrap_err()
        .to_string()
}

#[test]
fn a_broken_scenario_file_is_refused_naming_the_problem() {
    assert!(refusal("{").contains("not JSON"));
    assert!(refusal("{}").contains("no \"available_scenarios\""));
    let unknown = r#"{"available_scenarios": [{"Town01": [{"scenario_type": "Scenario11",
        "available_event_configurations": []}]}]}"#;
    assert!(refusal(unknown).contains("unknown scenario type \"Scenario11\""));
    let nan = r#"{"available_scenarios": [{"Town01": [{"scenario_type": "Scenario1",
        "available_event_configurations": [{"transform": {"x": "NaN", "y": "1", "yaw": "0"}}]}]}]}"#;
    assert!(refusal(nan).contains("transform x = \"NaN\" is not a finite number"));
    let no_y = r#"{"available_scenarios": [{"Town01": [{"scenario_type": "Scenario1",
        "available_event_configurations": [{"transform": {"x": "1", "yaw": "0"}}]}]}]}"#;
    assert!(refusal(no_y).contains("Town01 Scenario1 event 0: its transform has no \"y\""));
    let file = ScenarioFile::parse(&file_text("Town01", &[]), "t.json").unwrap();
    assert!(file.town("town01").is_ok(), "towns match in any case");
    let missing = file.town("Town02").unwrap_err().to_string();
    assert!(
        missing.contains("no scenarios for town Town02 (it has town01)"),
        "{missing}"
    );
    let err = ScenarioFile::read(std::path::Path::new("/nonexistent/s.json")).unwrap_err();
    assert!(err.to_string().contains("/nonexistent/s.json"), "{err}");
}

#[test]
fn triggers_match_the_route_within_two_metres_and_ten_degrees() {
    let (_, _, route) = bundled_route("train-small", 0);
    let k = route.points.len() / 2;
    let on = |side: f64, turn: f64| {
        match_to_route(&[trigger_at(&route, k, 1, side, turn)], &route, 0)
            .first()
            .map(|m| m.index)
    };
    let index = on(0.0, 0.0).expect("a trigger on the route matches");
    assert!(
        (k - 2..=k).contains(&index),
        "the first point within 2 m: {index} for {k}"
    );
    assert!(
        on(1.5, 8.0).is_some(),
        "1.5 m aside and 8 degrees off still match"
    );
    assert_eq!(on(2.5, 0.0), None, "2.5 m aside is another lane");
    assert_eq!(on(0.0, 15.0), None, "15 degrees off is another direction");
    assert_eq!(on(0.0, 180.0), None, "the opposite lane's trigger");
    // The file's frame is CARLA's: a trigger read from a file lands where it was written.
    let file = ScenarioFile::parse(
        &file_text("ssr_train_small", &[trigger_at(&route, k, 3, 0.0, 0.0)]),
        "t.json",
    )
    .unwrap();
    let read = file.town("ssr_train_small").unwrap();
    let m = match_to_route(&read.triggers, &route, 0);
    assert_eq!(m.len(), 1);
    assert_eq!(m[0].index, index);
}

#[test]
fn turn_scenarios_need_the_routes_next_turn_and_one_scenario_stands_per_position() {
    let (_, _, route) = bundled_route("train-small", 0);
    let next_turn = |k: usize| {
        route.points[k..]
            .iter()
            .map(|p| p.option)
            .find(|o| *o != RoadOption::LaneFollow && !o.is_lane_change())
    };
    // A point before a turn of each kind the route has, with lane-follow points behind it (a
    // trigger matches the first point within 2 m, which may lie a metre or two back).
    let before = |want: RoadOption| {
        (3..route.points.len()).find(|&k| {
            route.points[k - 3..=k]
                .iter()
                .all(|p| p.option == RoadOption::LaneFollow)
                && next_turn(k - 3) == Some(want)
        })
    };
    let mut seen = 0;
    for (option, turn) in [
        (RoadOption::Left, Turn::Left),
        (RoadOption::Right, Turn::Right),
        (RoadOption::Straight, Turn::Straight),
    ] {
        let Some(k) = before(option) else { continue };
        seen += 1;
        for n in [4, 7, 8, 9] {
            let matched = match_to_route(&[trigger_at(&route, k, n, 0.0, 0.0)], &route, 0);
            let runs = matches!(
                (n, option),
                (4, RoadOption::Left | RoadOption::Right)
                    | (7, _)
                    | (8, RoadOption::Left)
                    | (9, RoadOption::Right)
            );
            assert_eq!(
                matched.len(),
                usize::from(runs),
                "Scenario{n} before {option:?}"
            );
            if runs {
                assert_eq!(matched[0].turn, Some(turn));
            }
        }
    }
    assert!(seen >= 2, "the route has turns of two kinds");

    // Scenario1 and Scenario3 at one position: the higher number stands.
    let k = route.points.len() / 3;
    let both = [
        trigger_at(&route, k, 1, 0.0, 0.0),
        trigger_at(&route, k, 3, 0.5, 0.0),
    ];
    let kept = match_to_route(&both, &route, 0);
    assert_eq!(kept.len(), 1);
    assert_eq!(kept[0].trigger.scenario, 3);
    // A position whose every scenario stands within 2 m of one kept before keeps none.
    let crowded = [
        trigger_at(&route, k, 3, 0.0, 0.0),
        trigger_at(&route, k, 1, 1.9, 0.0),
        trigger_at(&route, k, 2, -1.9, 0.0),
    ];
    let kept = match_to_route(&crowded, &route, 7);
    assert_eq!(kept.len(), 1, "{kept:?}");
}

#[test]
fn scenario1_lays_debris_that_is_seen_and_driven_over() {
    let (map, spec, route) = bundled_route("train-small", 0);
    // A trigger where the next 80 m stay out of junctions.
    let k = (0..route.points.len())
        .find(|&k| {
            let end = route.cum[k] + 80.0;
            route.cum.last().is_some_and(|l| *l > end)
                && route.points[k..]
                    .iter()
                    .zip(&route.cum[k..])
                    .take_while(|(_, c)| **c < end)
                    .all(|(p, _)| !map.lane(p.lane).in_junction())
        })
        .expect("80 m without a junction");
    let text = file_text("ssr_train_small", &[trigger_at(&route, k, 1, 0.0, 0.0)]);
    let file = ScenarioFile::parse(&text, "t.json").unwrap();
    let config = WorldConfig {
        vehicles: 0,
        scenario_file: Some(file.town("ssr_train_small").unwrap()),
        ..WorldConfig::default()
    };
    let world = World::new(&map, &route, config.clone());
    let debris: Vec<_> = world
        .visible_actors()
        .into_iter()
        .filter(|a| a.kind == ActorKind::Debris)
        .collect();
    assert_eq!(debris.len(), 3, "three patches");
    assert!(world.actors().iter().all(|a| a.kind != ActorKind::Debris));
    let run = run_route(
        &map,
        &spec,
        &route,
        &mut Expert::new(),
        config,
        ScoringConfig::default(),
        0,
        0,
        |_| {},
    );
    assert!(run.infractions.is_empty(), "{:?}", run.infractions);
    assert_eq!(run.record.scores.score_route, 100.0);
}

#[test]
fn the_public_scenario_file_gives_carla_long_routes_their_scenarios() {
    let Some(dir) = carla_dir() else { return };
    let file = ScenarioFile::read(&dir.join("all_towns_traffic_scenarios_public.json")).unwrap();
    let map = Map::load_file(&dir.join("Town01.xodr"), MapOptions::default()).unwrap();
    let triggers = file.town("Town01").unwrap();
    let routes =
        xml::read_file(&dir.join("training_routes/transfuser/routes_town01_long.xml")).unwrap();
    let mut counts = [0usize; 11];
    for spec in &routes {
        let dense = planner::plan_route(&map, spec).unwrap();
        for m in match_to_route(&triggers.triggers, &dense, 0) {
            counts[m.trigger.scenario as usize] += 1;
        }
    }
    eprintln!("Town01 long routes: scenarios by number {counts:?}");
    // The public file holds Scenario1, 3 and 4 only; every kind lands on the long routes.
    assert!(
        counts[1] > 0 && counts[3] > 0 && counts[4] > 0,
        "{counts:?}"
    );
    assert_eq!(
        counts.iter().sum::<usize>(),
        counts[1] + counts[3] + counts[4]
    );
}
