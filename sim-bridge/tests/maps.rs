//! Map loading errors and the bundled towns' traffic control, through the public API.

mod common;

use common::lights_unseen_from;
use sim_bridge::map::{Map, MapError, MapOptions};
use sim_bridge::route::DenseRoute;
use sim_bridge::towngen::{self, TownStyle};

/// The route from `from` to `to`, keypoints in a route file's (CARLA's) frame: y flipped.
fn plan(map: &Map, from: (f64, f64), to: (f64, f64)) -> DenseRoute {
    let xml = format!(
        r#"<routes><route id="0" town="x">
            <waypoint x="{}" y="{}" z="0.0"/><waypoint x="{}" y="{}" z="0.0"/>
        </route></routes>"#,
        from.0, from.1, to.0, to.1
    );
    let spec = &sim_bridge::route::xml::parse("test", &xml).unwrap()[0];
    sim_bridge::route::planner::plan_route(map, spec).unwrap()
}

#[test]
fn malformed_opendrive_is_a_clear_error() {
    let not_xml = Map::from_str("broken", "<OpenDRIVE><road", MapOptions::default()).unwrap_err();
    assert!(matches!(not_xml, MapError::Invalid { .. }), "{not_xml}");
    assert!(not_xml.to_string().contains("broken"));
    let empty = Map::from_str(
        "empty",
        "<OpenDRIVE><header revMajor='1' revMinor='4'/></OpenDRIVE>",
        MapOptions::default(),
    )
    .unwrap_err();
    assert!(
        matches!(
            empty,
            MapError::NoDrivingLanes { .. } | MapError::Invalid { .. }
        ),
        "{empty}"
    );
    let missing = Map::load_file(
        std::path::Path::new("/nonexistent/town.xodr"),
        MapOptions::default(),
    )
    .unwrap_err();
    assert!(
        matches!(missing, MapError::Io { .. })
            && missing.to_string().contains("/nonexistent/town.xodr")
    );
}

#[test]
fn bundled_towns_have_lights_stop_signs_and_a_test_town_of_town05_size() {
    for style in TownStyle::ALL {
        let map =
            Map::from_str(style.name(), towngen::bundled(style), MapOptions::default()).unwrap();
        assert!(!map.lights.is_empty(), "{}: no lights", style.name());
        for light in &map.lights {
            assert!(!light.stop_lines.is_empty());
            assert!(map.junctions[light.junction.0 as usize].signalized);
        }
        if style.is_test_town() {
            let size = map.bounds.1 - map.bounds.0;
            assert!(
                (430.0..530.0).contains(&size.x) && (360.0..440.0).contains(&size.y),
                "{size:?}"
            );
            assert!(!map.stop_signs.is_empty());
            let unsignalized = map.junctions.iter().filter(|j| !j.signalized).count();
            assert!(unsignalized >= 8, "{unsignalized} unsignalized junctions");
        }
    }
}

#[test]
fn placing_lights_is_only_for_maps_without_any() {
    let style = TownStyle::Town05Style;
    let with = Map::from_str(
        "a",
        towngen::bundled(style),
        MapOptions {
            place_missing_lights: true,
        },
    )
    .unwrap();
    let without = Map::from_str(
        "b",
        towngen::bundled(style),
        MapOptions {
            place_missing_lights: false,
        },
    )
    .unwrap();
    assert_eq!(
        with.lights.len(),
        without.lights.len(),
        "a map with signals keeps its own"
    );
    assert!(with.lights.iter().all(|l| l.from_map));

    // The same town without its traffic-light signals (as CARLA's old Town03): lights are
    // placed at its multi-lane four-way junctions, and only when asked.
    let bare = without_traffic_lights(towngen::bundled(style));
    let load = |place_missing_lights| {
        let options = MapOptions {
            place_missing_lights,
        };
        Map::from_str("bare", &bare, options).unwrap()
    };
    let (placed, left_bare) = (load(true), load(false));
    assert!(left_bare.lights.is_empty());
    assert!(!placed.lights.is_empty());
    assert!(placed.lights.iter().all(|l| !l.from_map));
    for junction in placed.junctions.iter().filter(|j| j.signalized) {
        assert!(junction.approaches.len() >= 4);
        assert!(junction.approaches.iter().any(|a| a.lanes.len() >= 2));
    }
    // Placed heads stand across the junction: a car waiting at the stop line sees them.
    let rig = ssrdrive_proto::camera::Rig::tcp();
    let unseen = lights_unseen_from(&placed, &rig, placed.lights.iter(), 3.0);
    assert!(
        unseen.is_empty(),
        "placed lights {unseen:?} unseen from the stop line"
    );
}

/// `xml` without its traffic-light signals (type 1000001); stop signs stay.
fn without_traffic_lights(xml: &str) -> String {
    let (mut out, mut rest) = (String::new(), xml);
    while let Some(at) = rest.find("<signal ") {
        out.push_str(&rest[..at]);
        let end = at + rest[at..].find("</signal>").expect("a closed signal") + "</signal>".len();
        let signal = &rest[at..end];
        let tag = &signal[..signal.find('>').unwrap()];
        if !tag.contains(r#"type="1000001""#) {
            out.push_str(signal);
        }
        rest = &rest[end..];
    }
    out + rest
}

/// CARLA's junction roads step their laneOffset at a lane-section boundary while the lanes
/// beside it compensate, so the centre lines are continuous. A lane must not end with a
/// sideways jump to where the next section's offset would put it (a 3.5 m spike here; up to
/// 7 m in Town04), which the dense route would draw out and back and the route-deviation
/// check could not get past.
#[test]
fn a_lane_offset_step_at_a_section_boundary_leaves_the_lanes_continuous() {
    let xml = include_str!("maps/offset_step.xodr");
    let map = Map::from_str("offset-step", xml, MapOptions::default()).unwrap();
    let driving: Vec<_> = map
        .lanes
        .iter()
        .filter(|l| l.kind == sim_bridge::map::LaneKind::Driving)
        .collect();
    assert_eq!(driving.len(), 2, "one driving lane per section");
    for lane in &driving {
        for w in lane.points.windows(3) {
            let (u, v) = ((w[1] - w[0]).truncate(), (w[2] - w[1]).truncate());
            assert!(
                u.angle_to(v).abs() < 0.2,
                "lane {} turns {:.2} rad between {:?} and {:?}",
                lane.lane_id,
                u.angle_to(v),
                w[1],
                w[2]
            );
        }
    }
    let (first, second) = (driving[0], driving[1]);
    let gap = (first.points.last().unwrap().truncate() - second.points[0].truncate()).length();
    assert!(gap < 0.5, "the lanes meet: {gap:.2} m apart");
    assert_eq!(first.successors, vec![second.idx]);
}

/// A lane whose width record ends short of the next one's value (Town06's connector 400 widens
/// from 3.0 m to 3.5 m at one record) steps its centre line sideways; the baked lane ramps
/// across the step so its heading never swings (it turned 0.8 rad and back in 0.35 m).
#[test]
fn a_width_step_inside_a_lane_section_leaves_the_heading_continuous() {
    let xml = r#"<?xml version="1.0" standalone="yes"?>
<OpenDRIVE>
  <header revMajor="1" revMinor="4" name="width-step"/>
  <road name="r" length="40.0" id="1" junction="-1">
    <link/>
    <planView>
      <geometry s="0.0" x="0.0" y="0.0" hdg="0.0" length="40.0"><arc curvature="0.02"/></geometry>
    </planView>
    <elevationProfile><elevation s="0" a="0" b="0" c="0" d="0"/></elevationProfile>
    <lateralProfile>
      <superelevation s="0" a="0" b="0" c="0" d="0"/>
      <superelevation s="20" a="0" b="0" c="0" d="0"/>
    </lateralProfile>
    <lanes>
      <laneSection s="0.0">
        <center><lane id="0" type="none" level="false"><link/></lane></center>
        <right>
          <lane id="-1" type="driving" level="false"><link/>
            <width sOffset="0" a="3.0" b="0" c="0" d="0"/>
            <width sOffset="20" a="3.5" b="0" c="0" d="0"/></lane>
        </right>
      </laneSection>
    </lanes>
  </road>
</OpenDRIVE>"#;
    let map = Map::from_str("width-step", xml, MapOptions::default()).unwrap();
    let lane = &map.lanes[0];
    let mut s = 0.0;
    while s + 0.5 <= lane.length() {
        let turn = sim_bridge::map::angle_diff(lane.pose_at(s + 0.5).yaw, lane.pose_at(s).yaw);
        assert!(turn.abs() < 0.2, "turns {turn:.2} rad after s {s:.2}");
        s += 0.05;
    }
    let end = lane.points.last().unwrap().truncate();
    let expected = glam::DVec2::new(0.0, 50.0)
        + glam::DVec2::from_angle(0.8 - std::f64::consts::FRAC_PI_2) * 51.75;
    assert!(
        (end - expected).length() < 0.05,
        "the lane still ends at {expected}: {end}"
    );
}

/// A road too short to carry geometry (CARLA's Town03 has roads of 1 mm between its
/// roundabout and the streets) still links the roads on either side: the lane before it leads
/// into the lane after it.
#[test]
fn a_road_too_short_for_geometry_still_links_its_neighbours() {
    let xml = include_str!("maps/degenerate_road.xodr");
    let map = Map::from_str("degenerate-road", xml, MapOptions::default()).unwrap();
    let lane_of = |road: &str| {
        map.lanes
            .iter()
            .find(|l| l.road_id == road && l.kind == sim_bridge::map::LaneKind::Driving)
            .unwrap_or_else(|| panic!("road {road} has a driving lane"))
    };
    let (before, after) = (lane_of("1"), lane_of("3"));
    assert_eq!(before.successors, vec![after.idx]);
    assert_eq!(after.predecessors, vec![before.idx]);
}

/// A keypoint far from every lane still matches the nearest driving lane, as CARLA's
/// `get_waypoint` projects to the road from anywhere (TransFuser's Town01 and Town06 short
/// routes hold keypoints up to 100 m off the map).
#[test]
fn a_keypoint_far_off_the_map_matches_the_nearest_lane() {
    let xml = include_str!("maps/degenerate_road.xodr");
    let map = Map::from_str("degenerate-road", xml, MapOptions::default()).unwrap();
    let route = plan(&map, (2.0, 1.75), (55.0, -90.0));
    let end = route.points.last().unwrap().position;
    assert!(
        (end.x - 55.0).abs() < 1.0 && (end.y + 1.75).abs() < 0.5,
        "{end:?}"
    );
}

/// A keypoint a few metres into a lane that begins beside another (no predecessor: only a lane
/// change reaches it) plans with a lane change shorter than the usual 12 m, which would land
/// past it (CARLA's Town03 and Town06 routes have such keypoints).
#[test]
fn a_keypoint_just_into_a_lane_that_begins_plans_with_a_short_change() {
    let xml = include_str!("maps/lane_add.xodr");
    let map = Map::from_str("lane-add", xml, MapOptions::default()).unwrap();
    let route = plan(&map, (20.0, 1.75), (105.0, 5.25));
    let end = route.points.last().unwrap().position;
    assert!(
        (end.x - 105.0).abs() < 1.0 && (end.y + 5.25).abs() < 0.3,
        "{end:?}"
    );
    assert!(
        route.points.iter().any(|p| p.option.is_lane_change()),
        "it changes lanes"
    );
}

/// A road whose first lane section is too short to bake (5 um, with a lane that shifts its id
/// across it, as on CARLA's Town03 roundabout connectors) still continues the lanes that lead
/// into it: every driving lane after it has a predecessor.
#[test]
fn a_lane_section_too_short_to_bake_keeps_the_links_through_it() {
    let xml = include_str!("maps/tiny_section.xodr");
    let map = Map::from_str("tiny-section", xml, MapOptions::default()).unwrap();
    let after: Vec<_> = map
        .lanes
        .iter()
        .filter(|l| l.road_id == "2" && l.kind == sim_bridge::map::LaneKind::Driving)
        .collect();
    assert_eq!(after.len(), 2, "road 2's baked driving lanes");
    for lane in after {
        assert!(
            !lane.predecessors.is_empty(),
            "lane {} of road 2 begins from nowhere",
            lane.lane_id
        );
    }
}

/// A lane whose width polynomial runs wild (3.5 m + 5 s^3: 135,000 km wide at 300 m; found by
/// the map fuzzer, where it took 8 s to load) is left out, not indexed over millions of grid
/// cells.
#[test]
fn a_lane_of_absurd_width_is_left_out() {
    let xml =
        include_str!("../../tests/fuzz/regressions/map_xodr/slow-cubic-lane-width-135000-km.xodr");
    let map = Map::from_str("wild-width", xml, MapOptions::default()).unwrap();
    assert!(
        map.lanes.iter().all(|l| l.road_id != "2"),
        "road 2's lane is left out"
    );
    assert!(
        map.lanes.iter().any(|l| l.road_id == "1"),
        "the rest of the map loads"
    );
}

/// Two connectors that end in the same lane conflict (traffic takes turns entering them) even
/// when one reaches that lane through a further piece of the junction: CARLA cuts some
/// connectors at section seams, and the pieces hid merges, so traffic piled into each other
/// inside Town03's junctions.
#[test]
fn connectors_that_merge_through_a_split_piece_conflict() {
    let xml = include_str!("maps/split_connector.xodr");
    let map = Map::from_str("split-connector", xml, MapOptions::default()).unwrap();
    let lane_of = |road: &str| {
        map.lanes
            .iter()
            .find(|l| l.road_id == road && l.kind == sim_bridge::map::LaneKind::Driving)
            .unwrap_or_else(|| panic!("road {road}"))
            .idx
    };
    let (first_piece, second_piece, turn) = (lane_of("10"), lane_of("11"), lane_of("12"));
    let conflicts = sim_bridge::world::junctions::conflicts(&map);
    let of = |lane| conflicts.get(&lane).cloned().unwrap_or_default();
    assert!(of(first_piece).contains(&turn), "{:?}", of(first_piece));
    assert!(of(second_piece).contains(&turn), "{:?}", of(second_piece));
    assert!(
        !of(first_piece).contains(&second_piece),
        "the two pieces of one connector do not conflict"
    );
}

/// Parked cars go on parking lanes wide enough to hold them clear of the driving lanes, never
/// where the car would reach into a driving lane (CARLA's Town03 has parking strips beside
/// junction connectors, where a parked car blocked every route through).
#[test]
fn parked_cars_stay_clear_of_driving_lanes() {
    use rand::SeedableRng;
    let xml = include_str!("maps/parking.xodr");
    let map = Map::from_str("parking", xml, MapOptions::default()).unwrap();
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(1);
    let cars = sim_bridge::world::scenarios::parked_cars(&map, &mut rng);
    assert!(
        cars.len() > 3,
        "the wide parking lane holds cars: {}",
        cars.len()
    );
    for car in &cars {
        assert!(
            car.obb.centre.y < 25.0,
            "a car on the narrow strip beside road 2: {:?}",
            car.obb.centre
        );
    }
}

/// Background vehicles merge out of a lane that ends (a lane drop, as on CARLA's Town06
/// highways) instead of queueing at its end, where they jammed the ego's lane for good.
#[test]
fn traffic_merges_out_of_a_lane_that_ends() {
    use sim_bridge::world::{World, WorldConfig};
    use ssrdrive_proto::control::Control;
    let xml = include_str!("maps/lane_drop.xodr");
    let map = Map::from_str("lane-drop", xml, MapOptions::default()).unwrap();
    let dropped = map
        .lanes
        .iter()
        .find(|l| l.road_id == "1" && l.lane_id == -2)
        .expect("the dropped lane");
    assert!(dropped.successors.is_empty(), "it ends");
    // The ego waits on a road of its own, far away.
    let route = plan(&map, (5.0, -401.75), (90.0, -401.75));
    let hold = Control {
        steer: 0.0,
        throttle: 0.0,
        brake: 1.0,
    };
    // Traffic never spawns on a lane without successors: one vehicle per world is put on the
    // dropped lane, 200 m before its end, and followed.
    for seed in 0..4 {
        let config = WorldConfig {
            vehicles: 12,
            scenarios: false,
            parked_cars: false,
            seed,
            ..WorldConfig::default()
        };
        let mut world = World::new(&map, &route, config);
        let placed = &mut world.traffic.vehicles[0];
        placed.lane = dropped.idx;
        placed.s = dropped.length() - 200.0;
        placed.lateral = 0.0;
        placed.speed = 8.0;
        placed.next.clear();
        let id = placed.id;
        let mut last = placed.pose(&map).0;
        let mut waited_at_end = 0.0;
        for _ in 0..(60.0 / 0.05) as usize {
            world.step(hold);
            let v = world.traffic.vehicles.iter().find(|v| v.id == id);
            let v = v.expect("the placed vehicle stays in the world");
            if v.lane == dropped.idx && dropped.length() - v.s < 12.0 && v.speed < 0.1 {
                waited_at_end += 0.05;
            }
            // A respawn (the rule for a car stuck 40 s) would also take it off the lane.
            let now = v.pose(&map).0;
            assert!(
                now.distance(last) < 2.0,
                "seed {seed}: respawned, not merged"
            );
            last = now;
        }
        let v = world.traffic.vehicles.iter().find(|v| v.id == id).unwrap();
        assert_ne!(
            v.lane, dropped.idx,
            "seed {seed}: still on the dropped lane"
        );
        assert!(
            waited_at_end < 3.0,
            "seed {seed}: waited {waited_at_end:.1} s at the lane's end"
        );
    }
}
