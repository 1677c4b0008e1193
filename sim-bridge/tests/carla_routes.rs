//! CARLA training routes from ../shared/carla plan into dense routes on the real maps.

mod common;

use common::carla_dir;
use sim_bridge::eval::run_route;
use sim_bridge::expert::Expert;
use sim_bridge::expert::hazards::{self, HazardMemory};
use sim_bridge::map::{LaneKind, Map, MapOptions};
use sim_bridge::route::scenario_file::ScenarioFile;
use sim_bridge::route::{planner, xml};
use sim_bridge::scoring::ScoringConfig;
use sim_bridge::world::ego::{Ego, EgoParams};
use sim_bridge::world::state::LightState;
use sim_bridge::world::{TrafficMode, World, WorldConfig, leaderboard_vehicles};
use ssrdrive_proto::control::Control;
use ssrdrive_proto::dataset::BrakeReason;

/// The expert's driving score on one route (run `index` of its evaluation).
fn expert_ds(map: &Map, spec: &xml::RouteSpec, world: WorldConfig, index: usize) -> f64 {
    let dense = planner::plan_route(map, spec).unwrap();
    let run = run_route(
        map,
        spec,
        &dense,
        &mut Expert::new(),
        world,
        ScoringConfig::default(),
        index,
        0,
        |_| {},
    );
    run.record.scores.score_composed
}

#[test]
fn tcp_training_routes_plan_on_carla_towns() {
    let Some(dir) = carla_dir() else { return };
    for town in ["town01", "town03", "town04", "town06"] {
        let map_name = format!("Town{}.xodr", &town[4..]);
        let map = Map::load_file(&dir.join(map_name), MapOptions::default()).unwrap();
        let routes =
            xml::read_file(&dir.join(format!("training_routes/tcp/routes_{town}.xml"))).unwrap();
        let (mut ok, mut failed) = (0, Vec::new());
        let t0 = std::time::Instant::now();
        for spec in routes.iter().take(60) {
            match planner::plan_route(&map, spec) {
                Ok(route) => {
                    let ratio = route.length() / spec.keypoint_length();
                    assert!(
                        ratio > 0.95,
                        "{town} route {}: dense {:.0} m vs keypoints {:.0} m",
                        spec.id,
                        route.length(),
                        spec.keypoint_length()
                    );
                    for w in route.points.windows(2) {
                        let d = (w[1].position - w[0].position).length();
                        assert!(
                            d < 1.6,
                            "{town} route {}: gap {d:.2} m between {:?} and {:?} ({:?} / {:?})",
                            spec.id,
                            w[0],
                            w[1],
                            map.lane(w[0].lane),
                            map.lane(w[1].lane).points.first()
                        );
                    }
                    ok += 1;
                }
                Err(e) => failed.push(e.to_string()),
            }
        }
        eprintln!(
            "{town}: {ok} planned, {} failed, {:.0?}: {:?}",
            failed.len(),
            t0.elapsed(),
            failed.iter().take(3).collect::<Vec<_>>()
        );
        // CARLA's 2019 Town03 export predates the routes; a few of its links differ.
        assert!(failed.len() * 8 <= ok, "{town}: too many failures");
    }
}

/// Every route of every route file in ../shared/carla (TCP's and TransFuser's, each naming its
/// town) plans on its map. Three of 1,977 find no path: TransFuser's Town03 short 4-6 start
/// 29 m from any driving lane, at a 0.1 m dead-end stub (the file was made on a later Town03
/// export than ../shared's 2019 one); the bound only goes down.
#[test]
fn every_carla_route_file_plans_on_its_town() {
    let Some(dir) = carla_dir() else { return };
    let (mut planned, mut failed) = (0, Vec::new());
    let mut maps = std::collections::HashMap::new();
    for set in ["tcp", "transfuser"] {
        let mut files: Vec<_> = std::fs::read_dir(dir.join("training_routes").join(set))
            .unwrap()
            .map(|e| e.unwrap().path())
            .filter(|p| p.extension().is_some_and(|e| e == "xml"))
            .collect();
        files.sort();
        for file in files {
            for spec in xml::read_file(&file).unwrap() {
                let town = spec.town.clone();
                let map = maps.entry(town.clone()).or_insert_with(|| {
                    Map::load_file(&dir.join(format!("{town}.xodr")), MapOptions::default())
                        .unwrap()
                });
                match planner::plan_route(map, &spec) {
                    Ok(_) => planned += 1,
                    Err(e) => failed.push(format!("{}: {e}", file.display())),
                }
            }
        }
    }
    eprintln!(
        "{planned} routes planned, {} failed: {failed:#?}",
        failed.len()
    );
    assert!(planned > 1900, "{planned} routes planned");
    assert!(
        failed.len() <= 3,
        "{} routes failed: {failed:#?}",
        failed.len()
    );
}

/// A dense route never turns back on itself: consecutive 1 m steps differ in heading by less
/// than 90 degrees. (xodr's laneOffset artefact and bad lane joins drew spikes, out and straight
/// back, that the leaderboard's route-deviation check cannot get past.)
#[test]
fn dense_routes_on_carla_towns_never_turn_back() {
    let Some(dir) = carla_dir() else { return };
    let mut reversals = Vec::new();
    for town in ["01", "03", "04", "06"] {
        let map =
            Map::load_file(&dir.join(format!("Town{town}.xodr")), MapOptions::default()).unwrap();
        for length in ["long", "short"] {
            let file = dir.join(format!(
                "training_routes/transfuser/routes_town{town}_{length}.xml"
            ));
            for spec in xml::read_file(&file).unwrap() {
                let Ok(route) = planner::plan_route(&map, &spec) else {
                    continue;
                };
                for (i, w) in route.points.windows(3).enumerate() {
                    let (u, v) = (
                        (w[1].position - w[0].position).truncate(),
                        (w[2].position - w[1].position).truncate(),
                    );
                    if u.length() > 0.05 && v.length() > 0.05 && u.dot(v) < 0.0 {
                        reversals.push(format!(
                            "Town{town} {length} route {} point {} at ({:.1}, {:.1}) lanes {} {}",
                            spec.id,
                            i + 1,
                            w[1].position.x,
                            w[1].position.y,
                            map.lane(w[0].lane).road_id,
                            map.lane(w[2].lane).road_id
                        ));
                    }
                }
            }
        }
    }
    assert!(
        reversals.is_empty(),
        "{} reversals: {reversals:#?}",
        reversals.len()
    );
}

/// The privileged expert drives a fixed sample of TransFuser's long routes on each CARLA town
/// (the first four of each file, the leaderboard's traffic, seed 0) with a mean DS above a floor
/// per town: a regression guard for the map, planner, traffic and expert on real maps. The
/// floors sit below today's means (Town01 and Town04 100; Town03 82.5, two routes with a
/// collision; Town06 83). Four routes with one seed are a small sample: over all 20 of Town03's
/// long routes and 3 repetitions the expert scores 91.
#[test]
fn the_expert_drives_a_sample_of_long_routes_on_each_carla_town() {
    let Some(dir) = carla_dir() else { return };
    for (town, floor) in [("01", 90.0), ("03", 75.0), ("04", 90.0), ("06", 75.0)] {
        let map =
            Map::load_file(&dir.join(format!("Town{town}.xodr")), MapOptions::default()).unwrap();
        let file = dir.join(format!(
            "training_routes/transfuser/routes_town{town}_long.xml"
        ));
        let specs: Vec<_> = xml::read_file(&file).unwrap().into_iter().take(4).collect();
        let world = WorldConfig {
            vehicles: leaderboard_vehicles(&map),
            seed: 0,
            ..WorldConfig::default()
        };
        let scores: Vec<f64> = specs
            .iter()
            .enumerate()
            .map(|(index, spec)| expert_ds(&map, spec, world.clone(), index))
            .collect();
        let mean = scores.iter().sum::<f64>() / scores.len() as f64;
        eprintln!("Town{town}: DS {scores:?}, mean {mean:.1}");
        assert!(
            mean >= floor,
            "Town{town}: mean DS {mean:.1} under {floor}: {scores:?}"
        );
    }
}

/// The long routes where the expert once stood for good at a green light, held by another
/// approach's red: a light whose line ends the lane the route leaves by a lane change, or a
/// kerb-side head of a light further on projected onto a turning ego's heading. It drives them
/// through, in CARLA-like traffic.
#[test]
fn the_expert_is_held_only_by_the_light_of_its_own_next_stop_line() {
    let Some(dir) = carla_dir() else { return };
    for (town, ids) in [("03", ["10", "21"]), ("04", ["14", "38"])] {
        let map =
            Map::load_file(&dir.join(format!("Town{town}.xodr")), MapOptions::default()).unwrap();
        let file = dir.join(format!(
            "training_routes/transfuser/routes_town{town}_long.xml"
        ));
        let specs = xml::read_file(&file).unwrap();
        let world = WorldConfig {
            vehicles: leaderboard_vehicles(&map),
            traffic: TrafficMode::Carla,
            ..WorldConfig::default()
        };
        for (index, spec) in specs
            .iter()
            .enumerate()
            .filter(|(_, s)| ids.contains(&s.id.as_str()))
        {
            let ds = expert_ds(&map, spec, world.clone(), index);
            assert!(ds > 99.0, "Town{town} route {}: DS {ds:.1}", spec.id);
        }
    }
}

/// Town03 cuts junction connectors into pieces, the first 3 cm long: a dense route's first
/// point in the junction lies past that piece, on a lane the approach does not lead to
/// directly. The approach's light still governs it: the expert stops for it red, and labels it
/// as the light ahead (it ran a red on the long route 24 when it did not).
#[test]
fn the_expert_stops_for_a_light_whose_first_connector_piece_the_route_skips() {
    let Some(dir) = carla_dir() else { return };
    let map = Map::load_file(&dir.join("Town03.xodr"), MapOptions::default()).unwrap();
    let specs =
        xml::read_file(&dir.join("training_routes/transfuser/routes_town03_long.xml")).unwrap();
    let spec = specs.iter().find(|s| s.id == "24").unwrap();
    let route = planner::plan_route(&map, spec).unwrap();
    // The last point on the approach, where the next one is past the connector's first piece.
    let line = (0..route.points.len() - 1)
        .find(|&j| {
            let (lane, next) = (map.lane(route.points[j].lane), route.points[j + 1].lane);
            map.light_ending(lane.idx).is_some()
                && map.lane(next).in_junction()
                && !lane.successors.contains(&next)
        })
        .expect("a skipped first piece at a light");
    let light = map.light_ending(route.points[line].lane).unwrap().id;
    let start = (0..line)
        .rev()
        .find(|&j| route.cum[line] - route.cum[j] > 25.0)
        .unwrap();
    let config = WorldConfig {
        vehicles: 0,
        scenarios: false,
        parked_cars: false,
        ..WorldConfig::default()
    };
    let mut world = World::new(&map, &route, config);
    let p = route.points[start];
    world.ego = Ego::new(EgoParams::default(), p.position, p.yaw);
    world.lights.force(light, LightState::Red, 1000.0);
    world.step(Control::default());
    let view = hazards::scan(&world, &route, start, &mut HazardMemory::default());
    let ahead = view
        .light_ahead
        .expect("the approach's light is the light ahead");
    assert_eq!((ahead.state, ahead.id), (LightState::Red, light));
    assert!(
        (15.0..25.0).contains(&ahead.gap),
        "{:.1} m to its line",
        ahead.gap
    );
    assert_eq!(view.cause, Some(BrakeReason::TrafficLight));
}

/// Town06's long route 48 (with the leaderboard's public scenario file) changes lanes into a
/// queue that moves in waves with car-length gaps; in CARLA-like traffic nobody leaves a gap,
/// and the expert once stood at the change until blocked. It zip-merges ahead of a car that
/// can stop short of its nose.
#[test]
fn the_expert_merges_into_a_moving_queue() {
    let Some(dir) = carla_dir() else { return };
    let map = Map::load_file(&dir.join("Town06.xodr"), MapOptions::default()).unwrap();
    let specs =
        xml::read_file(&dir.join("training_routes/transfuser/routes_town06_long.xml")).unwrap();
    let (index, spec) = specs
        .iter()
        .enumerate()
        .find(|(_, s)| s.id == "48")
        .unwrap();
    let scenarios = ScenarioFile::read(&dir.join("all_towns_traffic_scenarios_public.json"))
        .unwrap()
        .town("Town06")
        .unwrap();
    let world = WorldConfig {
        vehicles: leaderboard_vehicles(&map),
        traffic: TrafficMode::Carla,
        scenario_file: Some(scenarios),
        ..WorldConfig::default()
    };
    let ds = expert_ds(&map, spec, world, index);
    assert!(ds > 99.0, "Town06 route 48: DS {ds:.1}");
}

/// Generalisation: on Town02, a town with no route file in ../shared (nothing was tuned on it),
/// routes between points 10 m into long non-junction driving lanes, picked evenly over the map,
/// plan, and the expert drives them with the leaderboard's traffic at a mean DS of 85 or more
/// (91.9 when this test was written: 8 of 10 at 100).
#[test]
fn the_expert_drives_routes_on_a_town_it_was_never_tuned_on() {
    let Some(dir) = carla_dir() else { return };
    let map = Map::load_file(&dir.join("Town02.xodr"), MapOptions::default()).unwrap();
    let starts: Vec<(f64, f64, f64)> = map
        .lanes
        .iter()
        .filter(|l| l.kind == LaneKind::Driving && !l.in_junction() && l.length() > 30.0)
        .map(|l| {
            let pose = l.pose_at(10.0);
            (pose.position.x, pose.position.y, pose.yaw)
        })
        .collect();
    assert!(starts.len() > 20, "{} lanes", starts.len());
    let step = starts.len() / 10;
    let world = WorldConfig {
        vehicles: leaderboard_vehicles(&map),
        seed: 0,
        ..WorldConfig::default()
    };
    let mut scores = Vec::new();
    for k in 0..10 {
        let (a, b) = (
            starts[k * step],
            starts[(k * step + starts.len() / 2) % starts.len()],
        );
        // Route files use CARLA's frame: y and yaw flipped.
        let waypoint = |(x, y, yaw): (f64, f64, f64)| {
            format!(
                r#"<waypoint x="{x}" y="{}" z="0.0" yaw="{}"/>"#,
                -y,
                -yaw.to_degrees()
            )
        };
        let xml = format!(
            r#"<routes><route id="{k}" town="Town02">{}{}</route></routes>"#,
            waypoint(a),
            waypoint(b)
        );
        let spec = &xml::parse("town02", &xml).unwrap()[0];
        scores.push(expert_ds(&map, spec, world.clone(), k));
    }
    let mean = scores.iter().sum::<f64>() / scores.len() as f64;
    eprintln!("Town02: DS {scores:?}, mean {mean:.1}");
    assert!(mean >= 85.0, "Town02: mean DS {mean:.1}: {scores:?}");
}

/// Scenario crossers wait off every driving lane: where CARLA's roads bend or meet, a spot
/// beside one road can lie on another, the route's own among them, and a cyclist waiting there
/// for the ego to reach its trigger held the ego for good (Town03, TCP route 132).
#[test]
fn scenario_crossers_wait_off_the_driving_lanes() {
    let Some(dir) = carla_dir() else { return };
    let map = Map::load_file(&dir.join("Town03.xodr"), MapOptions::default()).unwrap();
    let routes = xml::read_file(&dir.join("training_routes/tcp/routes_town03.xml")).unwrap();
    let mut crossers = 0;
    for spec in &routes {
        let Ok(dense) = planner::plan_route(&map, spec) else {
            continue;
        };
        let world = sim_bridge::world::World::new(&map, &dense, WorldConfig::default());
        for crosser in &world.crossers {
            crossers += 1;
            let obb = crosser.obb();
            let on_lane = map
                .lanes_near(obb.centre, obb.half.length() + 2.0, |l| {
                    l.kind == LaneKind::Driving
                })
                .into_iter()
                .any(|(lane, p)| p.distance + 0.3 < map.lane(lane).width / 2.0);
            assert!(
                !on_lane,
                "route {}: crosser {} waits on a driving lane at {:?}",
                spec.id, crosser.id, obb.centre
            );
        }
    }
    assert!(crossers > 50, "{crossers} crossers placed");
}
