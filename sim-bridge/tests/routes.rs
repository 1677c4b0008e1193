//! Route files, dense routes, RoadOption labels, the global plan and the route follower,
//! through the public API on the bundled evaluation town.

use glam::{DVec2, DVec3};
use sim_bridge::map::{LaneKind, Map, MapOptions, angle_diff};
use sim_bridge::route::plan::{PlanNode, RouteFollower, downsample, global_plan, to_ego_frame};
use sim_bridge::route::planner::plan_route;
use sim_bridge::route::sets::{RandomRoutes, RouteSet, SETS, WalkStyle, random_routes};
use sim_bridge::route::xml::{self, Keypoint, RouteFileError, RouteSpec};
use sim_bridge::towngen::{self, TownStyle};
use ssrdrive_proto::command::RoadOption;

fn town05() -> Map {
    Map::from_str(
        "ssr_town05",
        towngen::bundled(TownStyle::Town05Style),
        MapOptions::default(),
    )
    .unwrap()
}

#[test]
fn route_xml_round_trips_and_flips_carla_y() {
    let text = r#"<routes><route id="7" town="Town05">
        <waypoint x="10.5" y="-20.25" z="0.5" pitch="0" roll="0" yaw="90.0"/>
        <weather id="x"><waypoint x="30" y="-20.25" z="0" yaw="-45"/></weather>
    </route></routes>"#;
    let routes = xml::parse("inline", text).unwrap();
    assert_eq!(routes.len(), 1);
    let k = routes[0].keypoints[0];
    // CARLA (x, y, yaw) = OpenDRIVE (x, -y, -yaw).
    assert_eq!(k.position, DVec3::new(10.5, 20.25, 0.5));
    assert!((k.yaw + std::f64::consts::FRAC_PI_2).abs() < 1e-12);
    assert_eq!(
        routes[0].keypoints.len(),
        2,
        "waypoints nested in <weather> are read"
    );
    let again = xml::parse("written", &xml::write(&routes)).unwrap();
    assert_eq!(again[0].id, "7");
    assert_eq!(again[0].town, "Town05");
    for (a, b) in routes[0].keypoints.iter().zip(&again[0].keypoints) {
        assert!((a.position - b.position).length() < 1e-5);
        assert!(angle_diff(a.yaw, b.yaw).abs() < 1e-6);
    }
}

#[test]
fn malformed_route_files_name_the_problem() {
    let cases = [
        ("<routes><route id='1'>", "not well-formed"),
        ("<trips/>", "expected <routes>"),
        ("<routes/>", "no <route>"),
        (
            "<routes><route><waypoint x='1' y='2'/><waypoint x='1' y='2'/></route></routes>",
            "has no id",
        ),
        (
            "<routes><route id='3'><waypoint y='2'/><waypoint x='1' y='2'/></route></routes>",
            "has no 'x'",
        ),
        (
            "<routes><route id='4'><waypoint x='NaN' y='2'/><waypoint x='1' y='2'/></route></routes>",
            "not a finite number",
        ),
        (
            "<routes><route id='5'><waypoint x='1' y='2'/></route></routes>",
            "at least 2",
        ),
        (
            "<routes><route id='6'><waypoint x='1' y='2'/>\n<waypont x='5' y='2'/><waypoint x='9' y='2'/></route></routes>",
            "route 6: unknown element <waypont> on line 2",
        ),
    ];
    for (text, needle) in cases {
        let err = xml::parse("bad.xml", text).expect_err(text).to_string();
        assert!(
            err.contains(needle) && err.contains("bad.xml"),
            "{text}: {err}"
        );
    }
    let missing = xml::read_file(std::path::Path::new("/nonexistent/routes.xml")).unwrap_err();
    assert!(matches!(missing, RouteFileError::Io { .. }));
}

#[test]
fn junction_connectors_get_left_right_straight_labels() {
    let map = town05();
    let (mut seen_left, mut seen_right, mut seen_straight) = (false, false, false);
    for connector in map
        .lanes
        .iter()
        .filter(|l| l.in_junction() && l.kind == LaneKind::Driving)
    {
        let (Some(&from), Some(&to)) =
            (connector.predecessors.first(), connector.successors.first())
        else {
            continue;
        };
        let (a, b) = (map.lane(from), map.lane(to));
        if a.in_junction() || b.in_junction() || a.length() < 20.0 || b.length() < 20.0 {
            continue;
        }
        let at = |l: &sim_bridge::map::Lane, s: f64| {
            let p = l.pose_at(s);
            Keypoint {
                position: p.position,
                yaw: p.yaw,
            }
        };
        // Keypoints before, inside and after the junction pin the route to this connector.
        let spec = RouteSpec {
            id: "j".into(),
            town: map.name.clone(),
            keypoints: vec![
                at(a, a.length() - 15.0),
                at(connector, connector.length() / 2.0),
                at(b, 15.0),
            ],
        };
        let route = plan_route(&map, &spec).unwrap();
        let turn = angle_diff(b.pose_at(0.0).yaw, a.pose_at(a.length()).yaw);
        let expected = if turn.abs() < 33f64.to_radians() {
            RoadOption::Straight
        } else if turn > 0.0 {
            RoadOption::Left
        } else {
            RoadOption::Right
        };
        for p in &route.points {
            if p.lane == connector.idx {
                assert_eq!(
                    p.option,
                    expected,
                    "connector {:?} turning {:.0} deg",
                    connector.idx,
                    turn.to_degrees()
                );
            } else if !map.lane(p.lane).in_junction() {
                assert_eq!(p.option, RoadOption::LaneFollow);
            }
        }
        seen_left |= expected == RoadOption::Left;
        seen_right |= expected == RoadOption::Right;
        seen_straight |= expected == RoadOption::Straight;
    }
    assert!(
        seen_left && seen_right && seen_straight,
        "the town has every kind of junction move"
    );
}

#[test]
fn dense_routes_are_continuous_and_plans_follow_the_50_m_rule() {
    let map = town05();
    let set = RouteSet::find("town05-long-style").unwrap();
    let specs = xml::parse(set.name, set.bundled_xml()).unwrap();
    let mut changes = 0;
    for spec in &specs {
        let route = plan_route(&map, spec).unwrap();
        for w in route.points.windows(2) {
            assert!(
                (w[1].position - w[0].position).length() < 1.5,
                "route {} has a gap",
                spec.id
            );
        }
        let kept = downsample(&route, 50.0);
        assert_eq!(kept[0], 0);
        assert_eq!(*kept.last().unwrap(), route.points.len() - 1);
        for w in kept.windows(2) {
            assert!(
                route.cum[w[1]] - route.cum[w[0]] <= 52.0,
                "route {}: plan nodes too far apart",
                spec.id
            );
        }
        for (i, p) in route.points.iter().enumerate() {
            if p.option.is_lane_change() {
                changes += 1;
                assert!(kept.contains(&i), "every lane-change point is a plan node");
            }
        }
    }
    assert!(changes > 0, "the long routes change lanes");
}

#[test]
fn route_follower_passes_nodes_within_4_m_and_keeps_two() {
    let node = |x: f64, option| PlanNode {
        position: DVec3::new(x, 0.0, 0.0),
        option,
    };
    let plan = vec![
        node(0.0, RoadOption::LaneFollow),
        node(3.0, RoadOption::LaneFollow),
        node(20.0, RoadOption::Left),
        node(70.0, RoadOption::LaneFollow),
    ];
    let mut f = RouteFollower::new(plan);
    // At x = 0 the node at 3 m is within 4 m: it is passed, the target is the node at 20 m.
    let target = f.step(DVec2::new(0.0, 0.0), 0.0);
    assert_eq!(target.position.x, 20.0);
    assert_eq!(target.option, RoadOption::Left);
    // Far from everything: no change.
    assert_eq!(f.step(DVec2::new(-50.0, 0.0), 0.0).position.x, 20.0);
    // Past the end: two nodes are always kept, so the target is the last node.
    assert_eq!(f.step(DVec2::new(69.0, 0.0), 0.0).position.x, 70.0);
    assert_eq!(f.remaining(), 2);
    // Ego frame: x forward, y left.
    let p = to_ego_frame(
        DVec3::new(0.0, 10.0, 0.0),
        DVec3::ZERO,
        std::f64::consts::FRAC_PI_2,
    );
    assert!((p.x - 10.0).abs() < 1e-9 && p.y.abs() < 1e-9);
    let left = to_ego_frame(
        DVec3::new(-3.0, 0.0, 0.0),
        DVec3::ZERO,
        std::f64::consts::FRAC_PI_2,
    );
    assert!(
        (left.y - 3.0).abs() < 1e-9,
        "a point to the west is on the left of a north-facing ego"
    );
}

#[test]
fn route_follower_does_not_skip_a_u_turn_loop_at_its_neck() {
    // West along y = 0 into a teardrop loop, back east along y = -3.5 (a lane's width beside
    // the way in): the loop's far node lies 30 m west; the first node of the way back lies
    // within 4 m of the ego at the neck, and within the 50 m look-ahead, which adds up
    // straight lines between nodes.
    let node = |x: f64, y: f64| PlanNode {
        position: DVec3::new(x, y, 0.0),
        option: RoadOption::LaneFollow,
    };
    let plan = vec![
        node(10.0, 0.0),
        node(-30.0, -1.0),
        node(-1.0, -3.5),
        node(50.0, -3.5),
    ];
    let heading_west = std::f64::consts::PI;
    let mut f = RouteFollower::new(plan.clone());
    // At the neck, heading west: the loop is still ahead, the target stays on it.
    assert_eq!(f.step(DVec2::new(0.0, 0.0), heading_west).position.x, -30.0);
    assert_eq!(f.remaining(), 4);
    // Round the loop, heading east on the way back: the node there is passed.
    assert_eq!(f.step(DVec2::new(-2.0, -3.5), 0.0).position.x, 50.0);
    // At the neck heading east (TCP's follower reads no heading, so it passes the node from
    // any pose): the loop is skipped and the target jumps 50 m behind a car heading west.
    let mut f = RouteFollower::new(plan);
    assert_eq!(f.step(DVec2::new(0.0, 0.0), 0.0).position.x, 50.0);
}

#[test]
fn bundled_route_sets_are_current_and_fit_their_specs() {
    for set in SETS {
        let map = Map::from_str(
            set.town.name(),
            towngen::bundled(set.town),
            MapOptions::default(),
        )
        .unwrap();
        let generated = xml::write(&set.generate(&map));
        assert_eq!(
            generated,
            set.bundled_xml(),
            "{}: run `sim-bridge routes generate`",
            set.name
        );
    }
    let map = town05();
    let long = xml::parse(
        "long",
        RouteSet::find("town05-long-style").unwrap().bundled_xml(),
    )
    .unwrap();
    assert_eq!(long.len(), 10);
    let lengths: Vec<f64> = long
        .iter()
        .map(|s| plan_route(&map, s).unwrap().length())
        .collect();
    let total: f64 = lengths.iter().sum();
    assert!(
        lengths.iter().all(|l| (480.0..2300.0).contains(l)),
        "{lengths:?}"
    );
    assert!((11_000.0..13_500.0).contains(&total), "total {total}");
    let plans: Vec<_> = long
        .iter()
        .map(|s| global_plan(&plan_route(&map, s).unwrap()))
        .collect();
    assert!(plans.iter().all(|p| p.len() >= 2));
}

/// `random_routes` draws routes of the asked lengths on any map that plan back into the walked
/// path, the same for the same seed, others for another.
#[test]
fn random_routes_have_the_asked_lengths_and_follow_their_seed() {
    let map = Map::from_str(
        "ssr_train_dense",
        towngen::bundled(TownStyle::DenseMultiLane),
        MapOptions::default(),
    )
    .unwrap();
    let options = RandomRoutes {
        count: 6,
        length: [300.0, 600.0],
        seed: 9,
        style: WalkStyle {
            turn_bias: 0.5,
            change_rate: 0.3,
        },
    };
    let routes = random_routes(&map, "my_town", &options);
    assert_eq!(routes.len(), 6);
    let mut turns = 0;
    for (i, spec) in routes.iter().enumerate() {
        assert_eq!(spec.id, i.to_string());
        assert_eq!(spec.town, "my_town");
        let dense = plan_route(&map, spec).unwrap();
        // The draw keeps a walk whose plan is within 10 % + 20 m of its length.
        assert!(
            (300.0 * 0.9 - 20.0..600.0 * 1.1 + 20.0).contains(&dense.length()),
            "route {i}: {:.0} m",
            dense.length()
        );
        turns += dense
            .points
            .windows(2)
            .filter(|w| {
                w[1].option != w[0].option
                    && matches!(w[1].option, RoadOption::Left | RoadOption::Right)
            })
            .count();
    }
    assert!(turns > 0, "a turn bias of 0.5 gave no turn in 6 routes");
    let again = random_routes(&map, "my_town", &options);
    assert_eq!(xml::write(&routes), xml::write(&again));
    let other = random_routes(
        &map,
        "my_town",
        &RandomRoutes {
            seed: 10,
            ..options
        },
    );
    assert_ne!(xml::write(&routes), xml::write(&other));
}

#[test]
fn a_keypoint_too_close_to_the_junction_for_a_full_lane_change_still_plans() {
    // The first keypoint on the inner lane 5 m before the junction, the second 7 m into the
    // road after the right turn, which leaves from the outer lane only: CARLA's planner joins
    // them with a lane change over the 5 m left, and so does ours.
    let map = Map::from_str(
        "outer-lane-turn",
        include_str!("maps/outer_lane_turn.xodr"),
        MapOptions::default(),
    )
    .unwrap();
    let spec = RouteSpec {
        id: "0".into(),
        town: "outer-lane-turn".into(),
        keypoints: vec![
            Keypoint {
                position: DVec3::new(45.0, -1.75, 0.0),
                yaw: 0.0,
            },
            Keypoint {
                position: DVec3::new(58.25, -20.5, 0.0),
                yaw: -std::f64::consts::FRAC_PI_2,
            },
        ],
    };
    let route = plan_route(&map, &spec).expect("the pair plans");
    let first = route.points.first().unwrap().position;
    let last = route.points.last().unwrap().position;
    assert!(
        (first - DVec3::new(45.0, -1.75, 0.0)).length() < 0.5,
        "{first}"
    );
    assert!(
        (last - DVec3::new(58.25, -20.5, 0.0)).length() < 0.5,
        "{last}"
    );
    assert!(
        route
            .points
            .iter()
            .any(|p| p.option == RoadOption::ChangeLaneRight),
        "the change is labelled"
    );
    assert!(
        route.points.iter().any(|p| p.option == RoadOption::Right),
        "the turn is labelled"
    );
    // The change happens before the junction, within the 5 m left.
    let change = route
        .points
        .iter()
        .find(|p| p.option == RoadOption::ChangeLaneRight)
        .unwrap();
    assert!(
        (45.0..=50.5).contains(&change.position.x),
        "{}",
        change.position
    );
    // Consecutive points stay close: the jump is drawn, not skipped.
    assert!(
        route
            .points
            .windows(2)
            .all(|w| (w[1].position - w[0].position).length() < 1.6),
        "a continuous route"
    );
}
