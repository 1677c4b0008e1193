//! Leaderboard scenario files (`--scenarios`): parsing and its refusals, matching triggers to a
//! dense route as the leaderboard 1.0 does (distance, angle, the next turn, one scenario per
//! position), the world placing what the matches call for, and the public file on CARLA towns.

mod common;

use common::carla_dir;
use sim_bridge::eval::run_route;
use sim_bridge::expert::Expert;
use sim_bridge::map::{Map, MapOptions};
use sim_bridge::route::scenario_file::{ScenarioFile, Trigger, Turn, match_to_route, write};
use sim_bridge::route::scenario_triggers;
use sim_bridge::route::sets::RouteSet;
use sim_bridge::route::{DenseRoute, planner, xml};
use sim_bridge::scoring::ScoringConfig;
use sim_bridge::towngen;
use sim_bridge::world::ego::{Ego, EgoParams};
use sim_bridge::world::state::ActorKind;
use sim_bridge::world::vehicle::Script;
use sim_bridge::world::{TrafficMode, World, WorldConfig};
use ssrdrive_proto::command::RoadOption;
use ssrdrive_proto::control::Control;

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
    let file = ScenarioFile::parse(&write("Town01", &[]), "t.json").unwrap();
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
        &write("ssr_train_small", &[trigger_at(&route, k, 3, 0.0, 0.0)]),
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
    let text = write("ssr_train_small", &[trigger_at(&route, k, 1, 0.0, 0.0)]);
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

/// A world on `route` without background traffic, whose scenarios come from one trigger of
/// scenario `n` at route index `k`.
fn world_with<'m>(map: &'m Map, town: &str, route: &DenseRoute, n: u8, k: usize) -> World<'m> {
    World::new(map, route, scenario_world(town, route, n, k))
}

/// A world without traffic or parked cars whose only scenario is `n`, triggered at route index `k`.
fn scenario_world(town: &str, route: &DenseRoute, n: u8, k: usize) -> WorldConfig {
    let file =
        ScenarioFile::parse(&write(town, &[trigger_at(route, k, n, 0.0, 0.0)]), "t").unwrap();
    WorldConfig {
        vehicles: 0,
        parked_cars: false,
        scenario_file: Some(file.town(town).unwrap()),
        ..WorldConfig::default()
    }
}

/// Put the ego on route point `k`, fire what it has reached and tick `seconds` with it held
/// there (standing).
fn stand_at(world: &mut World<'_>, route: &DenseRoute, k: usize, seconds: f64) {
    let p = route.points[k];
    world.ego = Ego::new(EgoParams::default(), p.position, p.yaw);
    for _ in 0..(seconds / 0.05).round() as usize {
        world.trigger_scenarios(k);
        world.step(HOLD);
    }
}

const HOLD: Control = Control {
    steer: 0.0,
    throttle: 0.0,
    brake: 1.0,
};

/// The first route index from which `metres` of road stay out of junctions and a junction
/// follows within `then` more metres.
fn before_a_junction(map: &Map, route: &DenseRoute, metres: f64, then: f64) -> usize {
    let in_junction = |k: usize| map.lane(route.points[k].lane).in_junction();
    (0..route.points.len())
        .find(|&k| {
            let clear_to = route.cum[k] + metres;
            let junction = (k..route.points.len()).find(|&j| in_junction(j));
            junction.is_some_and(|j| route.cum[j] > clear_to && route.cum[j] < clear_to + then)
                && !in_junction(k)
        })
        .expect("a stretch before a junction")
}

#[test]
fn scenario2_a_leader_drives_off_stops_short_of_the_junction_and_leaves_once_the_ego_waits() {
    let (map, _, route) = bundled_route("train-small", 0);
    let k = before_a_junction(&map, &route, 40.0, 80.0);
    let mut world = world_with(&map, "ssr_train_small", &route, 2, k);
    assert!(
        world.traffic.vehicles.is_empty(),
        "nothing before the trigger"
    );
    stand_at(&mut world, &route, k, 20.0);
    let leader = world
        .traffic
        .vehicles
        .first()
        .expect("the leader appeared")
        .clone();
    assert_eq!(leader.script, Script::StopsShortOfJunction(20.0));
    assert!(leader.speed < 0.1, "it stopped: {leader:?}");
    let at = leader.pose(&map).0;
    let junction = route.points[k..]
        .iter()
        .find(|p| map.lane(p.lane).in_junction())
        .unwrap()
        .position;
    let short = (junction - at).truncate().length();
    assert!(
        (18.0..26.0).contains(&short),
        "{short:.1} m short of the junction"
    );
    // The ego comes up behind it and waits: the leader leaves.
    let behind = (k..route.points.len())
        .find(|&j| (route.points[j].position - at).truncate().length() < 9.0)
        .unwrap();
    stand_at(&mut world, &route, behind, 2.0);
    assert!(world.traffic.vehicles.is_empty(), "the leader left");
}

#[test]
fn scenario5_two_vehicles_wait_for_the_trigger_then_drive_off_and_leave() {
    // A multi-lane street: the dense training town's first route that has a left lane.
    let set = RouteSet::find("train-dense").unwrap();
    let map = Map::from_str(
        set.town.name(),
        towngen::bundled(set.town),
        MapOptions::default(),
    )
    .unwrap();
    let specs = xml::parse(set.name, set.bundled_xml()).unwrap();
    let (route, k) = specs
        .iter()
        .filter_map(|s| planner::plan_route(&map, s).ok())
        .find_map(|r| {
            let k = (40..r.points.len()).find(|&k| {
                let ahead = (k..r.points.len()).find(|&j| r.cum[j] > r.cum[k] + 40.0);
                ahead.is_some_and(|j| {
                    r.points[k - 10..=j]
                        .iter()
                        .all(|p| !map.lane(p.lane).in_junction() && map.lane(p.lane).left.is_some())
                })
            })?;
            Some((r, k))
        })
        .expect("a route with 40 m of two lanes one way");
    let mut world = world_with(&map, set.town.name(), &route, 5, k);
    let waiting: Vec<_> = world.traffic.vehicles.iter().map(|v| (v.id, v.s)).collect();
    assert_eq!(waiting.len(), 2, "two vehicles stand from the start");
    // Far behind for longer than a stuck background car is left alone: they stay.
    stand_at(&mut world, &route, 0, 45.0);
    stand_at(&mut world, &route, k.saturating_sub(30), 10.0);
    for (v, (_, s)) in world.traffic.vehicles.iter().zip(&waiting) {
        assert_eq!(v.script, Script::Waits);
        assert!((v.s - s).abs() < 0.01, "they wait for the trigger");
    }
    stand_at(&mut world, &route, k, 5.0);
    assert!(
        world.traffic.vehicles.iter().all(|v| v.speed > 3.0),
        "they drive off: {:?}",
        world.traffic.vehicles
    );
    let far = (k..route.points.len()).find(|&j| route.cum[j] > route.cum[k] + 141.0);
    if let Some(far) = far {
        stand_at(&mut world, &route, far, 0.1);
        assert!(world.traffic.vehicles.is_empty(), "they left after 140 m");
    }
}

#[test]
fn scenario6_barriers_block_the_lane_and_a_flow_comes_the_other_way() {
    let (map, route, k) = s6_route();
    let plain = world_with(&map, "ssr_train_small", &route, 1, k);
    let mut world = world_with(&map, "ssr_train_small", &route, 6, k);
    assert_eq!(world.statics.len(), plain.statics.len() + 2, "two barriers");
    let barrier = world.statics.last().unwrap().obb;
    let ego_lane = map.lane(route.points[k].lane);
    let on_lane = ego_lane.project(barrier.centre);
    assert!(
        on_lane.distance < ego_lane.width / 2.0,
        "across the ego's lane"
    );
    stand_at(&mut world, &route, k, 1.0);
    let first = world.traffic.vehicles.first().expect("an oncoming vehicle");
    let (_, yaw) = first.pose(&map);
    let source = (k..route.points.len())
        .find(|&j| route.cum[j] >= route.cum[k] + 110.0)
        .unwrap();
    let heading = sim_bridge::map::angle_diff(yaw, route.points[source].yaw).abs();
    assert!(heading > 2.5, "it comes the other way");
    // The source sends the next once the last is 40 m away, up to 7.
    stand_at(&mut world, &route, k, 60.0);
    let sent = world.traffic.vehicles.len();
    assert!((2..=7).contains(&sent), "{sent} sent");
}

/// A train-small route with 115 m of road out of junctions from route index `k` (Scenario6's
/// barriers stand at 50 m, its source at 110 m).
fn s6_route() -> (Map, DenseRoute, usize) {
    (0..40)
        .find_map(|r| {
            let (map, _, route) = bundled_route("train-small", r);
            let clear = |k: usize| {
                (k..route.points.len())
                    .take_while(|&j| route.cum[j] < route.cum[k] + 115.0)
                    .all(|j| !map.lane(route.points[j].lane).in_junction())
            };
            let k = (0..route.points.len())
                .find(|&k| route.cum[k] + 120.0 < route.length() && clear(k))?;
            Some((map, route, k))
        })
        .expect("115 m without a junction")
}

/// Leaderboard 2.0's scenario timeout: a car that has not got past Scenario6's barriers 240 s
/// after the trigger sees the scenario end, barriers and oncoming flow gone, and it is
/// reported once; under 1.0's rules (no timeout) the barriers stand for good; a car past the
/// barriers in time reports nothing.
#[test]
fn scenario6_times_out_under_leaderboard_2_rules_and_its_barriers_go() {
    let (map, route, k) = s6_route();
    let timeout = sim_bridge::scoring::Rules::Lb2.scenario_timeout();
    let with_timeout = |scenario_timeout| {
        let config = WorldConfig {
            scenario_timeout,
            ..scenario_world("ssr_train_small", &route, 6, k)
        };
        World::new(&map, &route, config)
    };
    let plain = world_with(&map, "ssr_train_small", &route, 1, k)
        .statics
        .len();

    let mut world = with_timeout(timeout);
    stand_at(&mut world, &route, k, 239.0);
    assert_eq!(
        world.statics.len(),
        plain + 2,
        "barriers stand before the timeout"
    );
    assert!(world.take_scenario_timeouts().is_empty());
    stand_at(&mut world, &route, k, 2.0);
    let ended = world.take_scenario_timeouts();
    assert_eq!(ended.len(), 1, "{ended:?}");
    assert_eq!(ended[0].name, "Scenario6");
    assert!((239.9..240.2).contains(&ended[0].time), "{}", ended[0].time);
    assert_eq!(world.statics.len(), plain, "its barriers are gone");
    assert!(world.traffic.vehicles.is_empty(), "its flow left");
    stand_at(&mut world, &route, k, 5.0);
    assert!(world.take_scenario_timeouts().is_empty(), "reported once");

    let mut lb1 = with_timeout(None);
    stand_at(&mut lb1, &route, k, 241.0);
    assert_eq!(lb1.statics.len(), plain + 2, "1.0: they stand for good");
    assert!(lb1.take_scenario_timeouts().is_empty());

    let mut passed = with_timeout(timeout);
    stand_at(&mut passed, &route, k, 1.0);
    let beyond = (k..route.points.len())
        .find(|&j| route.cum[j] > route.cum[k] + 60.0)
        .unwrap();
    stand_at(&mut passed, &route, beyond, 241.0);
    assert!(
        passed.take_scenario_timeouts().is_empty(),
        "got past in time"
    );
    assert_eq!(passed.statics.len(), plain + 2);
}

#[test]
fn scenario10_a_vehicle_crosses_the_junction_without_lights_in_the_egos_way() {
    let (map, _, route) = bundled_route("train-small", 0);
    let conflicts = sim_bridge::world::junctions::conflicts(&map);
    // A junction without a light on the ego's approach, 60 m or more after the trigger.
    let k = (1..route.points.len())
        .find(|&j| {
            let lane = map.lane(route.points[j].lane);
            lane.in_junction()
                && !map.lane(route.points[j - 1].lane).in_junction()
                && map.light_ending(route.points[j - 1].lane).is_none()
                && route.cum[j] > 70.0
        })
        .map(|j| {
            (0..j)
                .rev()
                .find(|&t| route.cum[j] - route.cum[t] > 60.0)
                .unwrap()
        })
        .expect("a junction without lights");
    let mut world = world_with(&map, "ssr_train_small", &route, 10, k);
    let junction_start = (k..route.points.len())
        .find(|&j| map.lane(route.points[j].lane).in_junction())
        .unwrap();
    let fire = (0..junction_start)
        .rev()
        .find(|&j| route.cum[junction_start] - route.cum[j] >= 30.0)
        .unwrap();
    stand_at(&mut world, &route, fire - 1, 0.1);
    assert!(
        world.traffic.vehicles.is_empty(),
        "not before 30 m short of it"
    );
    stand_at(&mut world, &route, fire, 0.05);
    let crosser = world.traffic.vehicles.first().expect("a crossing vehicle");
    assert!(crosser.ignores_lights(), "it does not give way");
    let its_way = crosser
        .next
        .first()
        .copied()
        .expect("a path into the junction");
    let ego_connector = route.points[junction_start].lane;
    assert!(
        conflicts[&ego_connector].contains(&its_way),
        "its way crosses the ego's"
    );
}

#[test]
fn scenario7s_runner_in_carla_traffic_goes_straight_on_across_the_egos_way() {
    let mut runners = 0;
    for k in 0..20 {
        let (map, _, route) = bundled_route("town05-short-style", k);
        let in_junction = |j: usize| map.lane(route.points[j].lane).in_junction();
        // Each junction with lights where the route turns, 40 points clear of the one before.
        let turns = (41..route.points.len()).filter(|&j| {
            in_junction(j)
                && !(j - 40..j).any(in_junction)
                && map.light_ending(route.points[j - 1].lane).is_some()
                && matches!(route.points[j].option, RoadOption::Left | RoadOption::Right)
        });
        for junction in turns {
            let config = WorldConfig {
                traffic: TrafficMode::Carla,
                ..scenario_world("ssr_town05", &route, 7, junction - 40)
            };
            let mut world = World::new(&map, &route, config);
            stand_at(&mut world, &route, junction - 1, 0.05);
            let Some(runner) = world.traffic.vehicles.first() else {
                continue; // no approach of this junction crosses the ego's way
            };
            runners += 1;
            let approach = map.lane(runner.lane);
            let end = approach.pose_at(approach.length());
            let (straight, _) = map
                .straight_on(runner.lane, end.yaw)
                .expect("a way straight on");
            assert_eq!(
                runner.next[0], straight,
                "route {k}: the runner goes straight on"
            );
            let conflicts = sim_bridge::world::junctions::conflicts(&map);
            let ego_connector = route.points[junction].lane;
            assert!(
                conflicts[&ego_connector].contains(&straight),
                "across the ego's way"
            );
        }
    }
    assert!(runners >= 3, "{runners} runners");
}

#[test]
fn triggers_placed_by_rule_stand_on_their_lanes_read_back_and_give_the_long_routes_their_kinds() {
    let (map, _, _) = bundled_route("town05-long-style", 0);
    let spacing = scenario_triggers::DEFAULT_SPACING_M;
    let triggers = scenario_triggers::place(&map, spacing, 0);
    assert_eq!(triggers, scenario_triggers::place(&map, spacing, 0));
    assert_ne!(triggers, scenario_triggers::place(&map, spacing, 1));
    for t in &triggers {
        let (lane, at) = map.lane_for_pose(t.position, t.yaw).unwrap();
        assert!(
            at.distance < 0.01,
            "{t:?} is {} m off its lane",
            at.distance
        );
        assert!(!map.lane(lane).in_junction(), "{t:?}");
    }
    // The file reads back to the centimetre, grouped by type in placement order.
    let text = write("ssr_town05", &triggers);
    let file = ScenarioFile::parse(&text, "t").unwrap();
    let back = file.town("ssr_town05").unwrap().triggers;
    let mut by_type = triggers.clone();
    by_type.sort_by_key(|t| t.scenario);
    assert_eq!(back.len(), by_type.len());
    for (a, b) in by_type.iter().zip(back.iter()) {
        assert_eq!(a.scenario, b.scenario);
        assert!((a.position - b.position).length() < 0.01, "{a:?} {b:?}");
        assert!(
            sim_bridge::map::angle_diff(a.yaw, b.yaw).abs() < 1e-3,
            "{a:?} {b:?}"
        );
    }
    // The committed file is what the rule writes (`sim-bridge routes generate`).
    assert!(
        text == include_str!("../routes/town05-style-scenarios.json"),
        "sim-bridge/routes/town05-style-scenarios.json is stale: run `sim-bridge routes generate`"
    );
    // The long routes meet every kind the town has room for.
    let set = RouteSet::find("town05-long-style").unwrap();
    let mut counts = [0usize; 11];
    for spec in xml::parse(set.name, set.bundled_xml()).unwrap() {
        let dense = planner::plan_route(&map, &spec).unwrap();
        for m in match_to_route(&triggers, &dense, 0) {
            counts[m.trigger.scenario as usize] += 1;
        }
    }
    eprintln!("Town05-style long routes: scenarios by number {counts:?}");
    for n in [1, 3, 4, 7, 10] {
        assert!(counts[n] > 0, "no Scenario{n}: {counts:?}");
    }
}

#[test]
fn triggers_placed_by_rule_are_about_as_dense_on_carla_long_routes_as_the_public_file() {
    let Some(dir) = carla_dir() else { return };
    let file = ScenarioFile::read(&dir.join("all_towns_traffic_scenarios_public.json")).unwrap();
    for town in ["Town01", "Town03", "Town06"] {
        let map = Map::load_file(&dir.join(format!("{town}.xodr")), MapOptions::default()).unwrap();
        let public = file.town(town).unwrap().triggers;
        let placed = scenario_triggers::place(&map, scenario_triggers::DEFAULT_SPACING_M, 0);
        let routes = dir.join(format!(
            "training_routes/transfuser/routes_{}_long.xml",
            town.to_lowercase()
        ));
        let (mut km, mut from_public, mut from_rule) = (0.0, 0, 0);
        for spec in &xml::read_file(&routes).unwrap() {
            let dense = planner::plan_route(&map, spec).unwrap();
            km += dense.length() / 1000.0;
            from_public += match_to_route(&public, &dense, 0).len();
            from_rule += match_to_route(&placed, &dense, 0).len();
        }
        let (public, rule) = (from_public as f64 / km, from_rule as f64 / km);
        eprintln!(
            "{town} long routes: {public:.1} scenarios/km from the public file, {rule:.1} by rule"
        );
        assert!(
            (0.5..=2.0).contains(&(rule / public)),
            "{town}: {rule:.1} vs {public:.1} per km"
        );
    }
}

#[test]
fn a_scenario_whose_vehicles_stand_where_the_route_passes_before_its_trigger_is_left_out() {
    // Town05-style long route 24 starts on the ring and comes back along it at its end.
    let (map, spec, route) = bundled_route("town05-long-style", 8);
    assert_eq!(spec.id, "24");
    let town = map.name.clone();
    let driven_before = |k: usize, j: usize| {
        let p = route.points[j];
        route.points[..k].iter().any(|q| {
            (q.position - p.position).length() < 1.0
                && sim_bridge::map::angle_diff(q.yaw, p.yaw).abs() < 0.2
        })
    };
    // Scenario5 stands a vehicle 35 m past its trigger from the start of the run.
    let metres_ahead =
        |k: usize, m: f64| (k..route.points.len()).find(|&j| route.cum[j] >= route.cum[k] + m);
    let place = |passed: bool| {
        (100..route.points.len())
            .find(|&k| {
                let Some(j) = metres_ahead(k, 35.0) else {
                    return false;
                };
                route.points[k - 10..=j]
                    .iter()
                    .all(|p| !map.lane(p.lane).in_junction())
                    && driven_before(k, j) == passed
            })
            .unwrap()
    };
    let (fresh, passed) = (place(false), place(true));
    assert!(
        !world_with(&map, &town, &route, 5, fresh)
            .traffic
            .vehicles
            .is_empty()
    );
    assert!(
        world_with(&map, &town, &route, 5, passed)
            .traffic
            .vehicles
            .is_empty(),
        "the vehicles of a trigger at {passed} would stand on the route's start"
    );
}
