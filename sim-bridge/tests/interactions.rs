//! Traffic and the expert at close quarters, on the hand-made two-lane road of
//! `maps/lane_drop.xodr` (road 1: lanes -1 and -2 eastbound, 3.5 m wide, centres at y = -1.75
//! and y = -5.25): a follower keeps off an ego that pokes into its lane and creeps past one that
//! has stood a while when there is room, the expert does not speed up while its heading is off
//! its route, and it does not wait for a car that ran into its rear; it keeps its speed past a
//! walker on the sidewalk and waits for one crossing; an ego caught on a car
//! at an angle scrapes past it, one that hits it head-on cannot drive into it. And on `maps/lane_add.xodr`
//! (a lane that begins at x = 100): the expert waits for a gap to change lanes, then noses into
//! a slow queue; traffic holds back for an ego that waits to change into its lane. And on
//! `maps/signal_junction.xodr` (a light whose stop line is at x = 100): red and yellow hold the
//! ego while its tail could still cross on red, and a head posted before the line holds it where
//! a camera still sees the lamp. And on `maps/short_sections.xodr`: lane sections
//! a few centimetres long do not hide a standing ego from the traffic behind them. And on the
//! bundled town of small T-junctions: at a junction without lights the ego takes its turn, and
//! traffic gives it, and traffic does not enter a junction it cannot leave. And on
//! `maps/cut_connector.xodr`: connectors conflict by their whole path through the junction.

use std::f64::consts::FRAC_PI_2;

use glam::{DVec2, DVec3};
use sim_bridge::expert::hazards::{self, HazardMemory};
use sim_bridge::map::{LaneIdx, Map, MapOptions};
use sim_bridge::route::DenseRoute;
use sim_bridge::towngen::{self, TownStyle};
use sim_bridge::world::ego::{Ego, EgoParams};
use sim_bridge::world::scenarios::Crosser;
use sim_bridge::world::state::{ActorKind, LightState};
use sim_bridge::world::vehicle::Vehicle;
use sim_bridge::world::{TrafficMode, World, WorldConfig};
use ssrdrive_proto::control::Control;
use ssrdrive_proto::dataset::BrakeReason;

fn load(name: &str, xml: &str) -> Map {
    Map::from_str(name, xml, MapOptions::default()).unwrap()
}

fn road() -> Map {
    load("lane-drop", include_str!("maps/lane_drop.xodr"))
}

/// The route between two keypoints, given in the map frame (x east, y north).
fn route(map: &Map, from: (f64, f64), to: (f64, f64)) -> DenseRoute {
    route_through(map, &[from, to])
}

/// The route through these keypoints, given in the map frame (x east, y north).
fn route_through(map: &Map, keypoints: &[(f64, f64)]) -> DenseRoute {
    // Route files use CARLA's frame: y flipped.
    let waypoints: String = keypoints
        .iter()
        .map(|(x, y)| format!(r#"<waypoint x="{x}" y="{}" z="0.0"/>"#, -y))
        .collect();
    let xml = format!(r#"<routes><route id="0" town="x">{waypoints}</route></routes>"#);
    let spec = &sim_bridge::route::xml::parse("test", &xml).unwrap()[0];
    sim_bridge::route::planner::plan_route(map, spec).unwrap()
}

/// A route along road 1's outer lane (y = -5.25).
fn outer_lane_route(map: &Map) -> DenseRoute {
    route(map, (20.0, -5.25), (250.0, -5.25))
}

/// A world with `vehicles` background vehicles and no scenarios or parked cars.
fn quiet_world<'m>(map: &'m Map, route: &DenseRoute, vehicles: usize) -> World<'m> {
    quiet_world_in(map, route, vehicles, TrafficMode::Courteous)
}

/// [`quiet_world`] with traffic of `mode`.
fn quiet_world_in<'m>(
    map: &'m Map,
    route: &DenseRoute,
    vehicles: usize,
    traffic: TrafficMode,
) -> World<'m> {
    let config = WorldConfig {
        vehicles,
        scenarios: false,
        parked_cars: false,
        traffic,
        ..WorldConfig::default()
    };
    World::new(map, route, config)
}

/// A world holding exactly one background vehicle, on lane `lane_id` of road `road` at `s`,
/// in traffic of `mode`.
fn world_with_one_vehicle<'m>(
    map: &'m Map,
    route: &DenseRoute,
    (road, lane_id): (&str, i32),
    s: f64,
    speed: f64,
    mode: TrafficMode,
) -> World<'m> {
    let mut world = quiet_world_in(map, route, 1, mode);
    let lane = map
        .lanes
        .iter()
        .find(|l| l.road_id == road && l.lane_id == lane_id)
        .unwrap();
    let v: &mut Vehicle = &mut world.traffic.vehicles[0];
    v.lane = lane.idx;
    v.s = s;
    v.lateral = 0.0;
    v.speed = speed;
    v.desired_speed = speed;
    v.next = lane.successors.first().copied().into_iter().collect();
    world
}

/// The ego's index on `route`.
fn ego_index(world: &World<'_>, route: &DenseRoute) -> usize {
    route.advance_index(0, world.ego_state().position.truncate(), route.points.len())
}

const HOLD: Control = Control {
    steer: 0.0,
    throttle: 0.0,
    brake: 1.0,
};

/// A follower coming at 8 m/s on lane -1 from `start_s`, an ego standing at x = 120 with its
/// centre at `ego_y`, in traffic of `mode`: runs `seconds`, asserts they never touch, and calls
/// `each_tick` with the time and the follower after every step. Returns the follower's final x.
fn follower_beside_standing_ego(
    (start_s, ego_y): (f64, f64),
    mode: TrafficMode,
    seconds: f64,
    mut each_tick: impl FnMut(f64, &Vehicle),
) -> f64 {
    let map = road();
    let route = outer_lane_route(&map);
    let mut world = world_with_one_vehicle(&map, &route, ("1", -1), start_s, 8.0, mode);
    world.ego = Ego::new(EgoParams::default(), DVec3::new(120.0, ego_y, 0.0), 0.0);
    let id = world.traffic.vehicles[0].id;
    for _ in 0..(seconds / 0.05) as usize {
        let contacts = world.step(HOLD);
        assert!(
            contacts.iter().all(|c| c.other_id != id),
            "the follower ran into the ego at t = {:.2} s",
            world.time
        );
        each_tick(world.time, &world.traffic.vehicles[0]);
    }
    world.traffic.vehicles[0].pose(&map).0.x
}

#[test]
fn a_follower_stops_for_an_ego_that_pokes_into_its_lane() {
    // The ego stands on the outer lane's inner edge: matched to lane -2, its left side 0.96 m
    // into lane -1, where the follower comes: too little room to pass, ever.
    let mut last_speed = f64::NAN;
    let x = follower_beside_standing_ego((60.0, -3.6), TrafficMode::Courteous, 20.0, |_, v| {
        last_speed = v.speed
    });
    assert!(last_speed < 0.1 && x < 120.0, "it waits behind the ego");
}

#[test]
fn a_follower_held_by_a_standing_ego_creeps_past_when_there_is_room() {
    // The ego stands matched to lane -2, its left side 0.55 m into lane -1: 1.2 m from the
    // follower's centre line, inside the clearance a follower keeps from an ego that may move
    // (its half width + 0.4 m) but wide enough to pass a standing one.
    let x = follower_beside_standing_ego((85.0, -4.01), TrafficMode::Courteous, 40.0, |t, v| {
        let front = v.s + v.half.x;
        if t < 5.0 {
            assert!(front < 117.5, "it holds while the ego may still move");
        }
        if front > 116.0 && front < 121.0 {
            assert!(v.speed < 1.5, "it creeps past: {:.2} m/s", v.speed);
        }
    });
    assert!(
        x > 140.0,
        "once the ego has stood a while it creeps past and goes on (x = {x:.1})"
    );
}

#[test]
fn carla_traffic_waits_behind_a_standing_ego_for_good() {
    // As CARLA's traffic manager: the follower never squeezes past an ego in its corridor.
    let mut last_speed = f64::NAN;
    let x = follower_beside_standing_ego((85.0, -4.01), TrafficMode::Carla, 40.0, |_, v| {
        last_speed = v.speed
    });
    assert!(last_speed < 0.1 && x < 120.0, "it still waits (x = {x:.1})");
}

#[test]
fn the_expert_does_not_speed_up_while_its_heading_is_off_its_route() {
    use sim_bridge::driver::{Agent, Observation, RouteContext};
    use sim_bridge::expert::Expert;
    use sim_bridge::route::plan::{RouteFollower, global_plan};
    let map = road();
    let route = outer_lane_route(&map);
    let mut world = quiet_world(&map, &route, 0);
    // At 3 m/s on the outer lane, heading 0.7 rad off it: a turn its path has already left.
    world.ego = Ego::new(EgoParams::default(), DVec3::new(60.0, -5.25, 0.0), 0.7);
    world.ego.speed = 3.0;
    let plan = global_plan(&route);
    let mut follower = RouteFollower::new(plan.clone());
    let mut expert = Expert::new();
    expert
        .start_route(&RouteContext {
            map: &map,
            route: &route,
            plan: &plan,
            route_id: "0",
            repetition: 0,
            seed: 0,
            ego_half_extent: world.ego_state().half_extent,
        })
        .unwrap();
    let mut misaligned_ticks = 0;
    for frame in 0..(12.0 / 0.05) as u64 {
        let ego = world.ego_state();
        let index = ego_index(&world, &route);
        let error = sim_bridge::map::angle_diff(ego.yaw, route.points[index].yaw).abs();
        if error > 0.35 {
            misaligned_ticks += 1;
            assert!(
                ego.speed < 3.05,
                "{:.2} m/s at {error:.2} rad off the route",
                ego.speed
            );
        }
        let node = follower.step(ego.position.truncate(), ego.yaw);
        let obs = Observation::of_ego(world.time, frame, &ego, &node, Vec::new());
        let control = expert.run_step(&obs, &world).unwrap();
        world.step(control);
    }
    assert!(misaligned_ticks > 5, "it started misaligned");
    assert!(
        world.ego_state().speed > 5.0,
        "aligned again, it speeds up ({:.2} m/s)",
        world.ego_state().speed
    );
}

#[test]
fn the_expert_does_not_wait_for_a_car_that_ran_into_its_rear() {
    let map = road();
    let route = outer_lane_route(&map);
    // The ego at s = 100 on the outer lane; a stopped car that ran 1.5 m into its rear.
    let mut world =
        world_with_one_vehicle(&map, &route, ("1", -2), 0.0, 0.0, TrafficMode::Courteous);
    world.ego = Ego::new(EgoParams::default(), DVec3::new(100.0, -5.25, 0.0), 0.0);
    let ego_half = world.ego_state().half_extent.x;
    let car = &mut world.traffic.vehicles[0];
    car.s = 100.0 - ego_half - car.half.x + 1.5;
    let index = ego_index(&world, &route);
    let view = hazards::scan(&world, &route, index, &mut HazardMemory::default());
    assert_eq!(view.obstacle, None, "{view:?}");
    // The same car ahead of the ego is an obstacle.
    let car = &mut world.traffic.vehicles[0];
    car.s = 100.0 + ego_half + car.half.x + 3.0;
    let view = hazards::scan(&world, &route, index, &mut HazardMemory::default());
    let (gap, _) = view.obstacle.expect("the car ahead");
    assert!(gap > 0.0 && gap <= 3.0, "gap {gap}");
}

#[test]
fn the_expert_keeps_its_speed_past_a_walker_on_the_sidewalk_and_waits_for_one_crossing() {
    let map = road();
    let route = outer_lane_route(&map);
    let mut world = quiet_world(&map, &route, 0);
    world.ego = Ego::new(EgoParams::default(), DVec3::new(100.0, -5.25, 0.0), 0.0);
    let index = ego_index(&world, &route);
    // A walker at 1.5 m/s starting 12 m ahead, at `y`, heading `yaw` (rad from east).
    let mut scan_with_walker = |y: f64, yaw: f64| {
        world.crossers = vec![Crosser {
            id: 100_000,
            kind: ActorKind::Walker,
            position: DVec3::new(112.0, y, 0.0),
            yaw,
            speed: 1.5,
            remaining: 50.0,
            moving: true,
            half: DVec2::splat(0.3),
            patrol: true,
            gone: false,
        }];
        hazards::scan(&world, &route, index, &mut HazardMemory::default())
    };
    // Walking along the sidewalk beside the outer lane (its edge at y = -7): nothing to do.
    let along = scan_with_walker(-9.0, 0.0);
    assert!(!along.walker_near && along.obstacle.is_none(), "{along:?}");
    // Stepping onto the road: the expert waits where the walker will cross.
    let crossing = scan_with_walker(-9.0, FRAC_PI_2);
    assert!(crossing.walker_near, "{crossing:?}");
    assert_eq!(crossing.cause, Some(BrakeReason::Walker));
    let (gap, speed) = crossing.obstacle.unwrap();
    assert!(
        (5.0..12.0).contains(&gap) && speed == 0.0,
        "gap {gap}, speed {speed}"
    );
    // Heading for the road from further away: walking pace, no stop yet.
    let coming = scan_with_walker(-12.5, FRAC_PI_2);
    assert!(
        coming.walker_near && coming.obstacle.is_none(),
        "{coming:?}"
    );
}

/// A world with one car standing on lane -1 at s = 130 and the ego caught on it: heading `yaw`
/// (rad, towards the car's lane when positive) with the corner of its box that leads towards
/// the car (front-left for a positive yaw) `depth` m inside the car's right side, `along` m
/// ahead of the car's rear. Returns the world and the car's id.
fn ego_caught_on_a_standing_car<'m>(
    map: &'m Map,
    route: &DenseRoute,
    yaw: f64,
    depth: f64,
    along: f64,
) -> (World<'m>, u32) {
    let mut world =
        world_with_one_vehicle(map, route, ("1", -1), 130.0, 0.0, TrafficMode::Courteous);
    let (car, _) = world.traffic.vehicles[0].pose(map);
    let half = world.traffic.vehicles[0].half;
    let corner = glam::DVec2::new(car.x - half.x + along, car.y - half.y + depth);
    let ego_half = EgoParams::default().half_extent;
    let centre = corner - glam::DVec2::from_angle(yaw).rotate(ego_half);
    world.ego = Ego::new(EgoParams::default(), centre.extend(0.0), yaw);
    let id = world.traffic.vehicles[0].id;
    (world, id)
}

const PUSH: Control = Control {
    steer: 0.0,
    throttle: 0.5,
    brake: 0.0,
};

#[test]
fn an_ego_caught_at_an_angle_on_a_standing_car_scrapes_past_it() {
    let map = road();
    let route = outer_lane_route(&map);
    let (mut world, car) = ego_caught_on_a_standing_car(&map, &route, 0.25, 0.3, 1.0);
    let mut touched = false;
    for _ in 0..200 {
        touched |= world.step(PUSH).iter().any(|c| c.other_id == car);
    }
    let (car_centre, _) = world.traffic.vehicles[0].pose(&map);
    let ego = world.ego_state();
    assert!(touched, "the boxes touched");
    assert!(
        ego.position.x - ego.half_extent.x > car_centre.x,
        "the ego slid past the car: its rear at x = {:.2}, the car's centre at {:.2}",
        ego.position.x - ego.half_extent.x,
        car_centre.x
    );
    assert!(ego.speed > 1.0, "and drives on ({:.2} m/s)", ego.speed);
}

#[test]
fn an_ego_cannot_drive_into_a_car_it_hits_head_on() {
    let map = road();
    let route = outer_lane_route(&map);
    // Square behind the car, 0.3 m into its rear, pushing on (the car creeps off).
    let mut world =
        world_with_one_vehicle(&map, &route, ("1", -1), 130.0, 0.0, TrafficMode::Courteous);
    let (car, _) = world.traffic.vehicles[0].pose(&map);
    let half = world.traffic.vehicles[0].half;
    let ego_half = EgoParams::default().half_extent;
    world.ego = Ego::new(
        EgoParams::default(),
        DVec3::new(car.x - half.x - ego_half.x + 0.3, car.y, 0.0),
        0.0,
    );
    for _ in 0..200 {
        world.step(PUSH);
        let (car, _) = world.traffic.vehicles[0].pose(&map);
        let depth = world.ego_state().position.x + ego_half.x - (car.x - half.x);
        assert!(
            depth <= 0.3 + 1e-9,
            "the ego drove {depth:.3} m into the car at t = {:.2} s",
            world.time
        );
    }
}

#[test]
fn the_expert_waits_for_a_lane_change_gap_then_noses_into_a_slow_queue() {
    let map = load("lane-add", include_str!("maps/lane_add.xodr"));
    let route = route(&map, (20.0, -1.75), (180.0, -5.25));
    // The ego stands just short of where the route changes into the new lane; a car crawls
    // alongside in it.
    let mut world =
        world_with_one_vehicle(&map, &route, ("2", -2), 1.0, 0.5, TrafficMode::Courteous);
    world.ego = Ego::new(EgoParams::default(), DVec3::new(96.0, -1.75, 0.0), 0.0);
    let index = ego_index(&world, &route);
    let mut memory = HazardMemory::default();

    let view = hazards::scan(&world, &route, index, &mut memory);
    assert_eq!(
        view.cause,
        Some(BrakeReason::LaneChange),
        "it waits: {view:?}"
    );
    assert!(!view.nosing_in);
    // Past its patience, a queue this slow does not stop it: it noses in.
    world.time += 9.0;
    let view = hazards::scan(&world, &route, index, &mut memory);
    assert!(view.nosing_in, "{view:?}");
    assert_ne!(view.cause, Some(BrakeReason::LaneChange));
    // A car that comes fast still does.
    world.traffic.vehicles[0].speed = 6.0;
    let view = hazards::scan(&world, &route, index, &mut memory);
    assert_eq!(view.cause, Some(BrakeReason::LaneChange), "{view:?}");
}

/// An ego standing 6 m short of where its route changes into the outer lane, a car coming up
/// that lane 40 m behind it at 8 m/s, traffic of `mode`: after 15 s, the car's speed and the
/// room it leaves behind the ego's rear; then, the lane change behind the ego, its speed 5 s on.
fn car_behind_an_ego_waiting_to_change_lanes(mode: TrafficMode) -> (f64, f64, f64) {
    let map = road();
    let route = route_through(&map, &[(20.0, -1.75), (150.0, -1.75), (250.0, -5.25)]);
    let start = route
        .points
        .iter()
        .position(|p| p.option.is_lane_change())
        .expect("the route changes into the outer lane");
    let stand = route.points[start - 6];
    let target = route.points[route.points.len() - 1].lane;
    let ego_s = map.lane(target).project(stand.position.truncate()).s;
    let mut world = world_with_one_vehicle(&map, &route, ("1", -2), ego_s - 40.0, 8.0, mode);
    world.ego = Ego::new(EgoParams::default(), stand.position, stand.yaw);
    let ego_half = world.ego_state().half_extent.x;
    for _ in 0..(15.0 / 0.05) as usize {
        let index = ego_index(&world, &route);
        world.trigger_scenarios(index);
        world.step(HOLD);
    }
    let car = &world.traffic.vehicles[0];
    let (waiting, room) = (car.speed, ego_s - ego_half - (car.s + car.half.x));
    world.trigger_scenarios(route.points.len() - 1);
    for _ in 0..(5.0 / 0.05) as usize {
        world.step(HOLD);
    }
    (waiting, room, world.traffic.vehicles[0].speed)
}

#[test]
fn traffic_lets_an_ego_that_waits_to_change_lanes_in() {
    let (speed, room, after) = car_behind_an_ego_waiting_to_change_lanes(TrafficMode::Courteous);
    assert!(speed < 0.1, "it waits for the ego: {speed:.2} m/s");
    assert!(
        (2.0..6.0).contains(&room),
        "it leaves {room:.1} m behind the ego"
    );
    // Once the ego no longer waits (the lane change is behind it), the car goes on.
    assert!(after > 1.0, "it drives on");
}

#[test]
fn carla_traffic_drives_past_an_ego_that_waits_to_change_lanes() {
    let (speed, room, _) = car_behind_an_ego_waiting_to_change_lanes(TrafficMode::Carla);
    assert!(
        speed > 1.0 && room < 0.0,
        "it passes without a gap: {speed:.2} m/s, {room:.1} m"
    );
}

#[test]
fn lights_hold_the_ego_while_its_tail_could_still_cross_on_red() {
    let map = load("signal-junction", include_str!("maps/signal_junction.xodr"));
    let through = route(&map, (50.0, -1.75), (200.0, -1.75));
    let mut world = quiet_world(&map, &through, 0);
    let scan_at = |world: &mut World<'_>, x: f64, speed: f64, state: LightState| {
        world.lights.force(map.lights[0].id, state, f64::INFINITY);
        world.lights.update(world.time);
        world.ego = Ego::new(EgoParams::default(), DVec3::new(x, -1.75, 0.0), 0.0);
        world.ego.speed = speed;
        let index = ego_index(world, &through);
        hazards::scan(world, &through, index, &mut HazardMemory::default())
    };
    // The route starts with the ego's centre 1 m past the line (a route may start so): its tail
    // has not crossed, and the leaderboard would count it crossing now.
    let view = scan_at(&mut world, 101.0, 0.0, LightState::Red);
    assert_eq!(view.cause, Some(BrakeReason::TrafficLight), "{view:?}");
    assert_eq!(view.obstacle, Some((0.0, 0.0)));
    assert_eq!(
        scan_at(&mut world, 101.0, 0.0, LightState::Green).obstacle,
        None
    );
    // Too fast to stop before the tail crosses: braking would only strand it in the junction.
    assert_eq!(
        scan_at(&mut world, 101.0, 8.0, LightState::Red).obstacle,
        None
    );
    // Once the tail is past the line, the light no longer concerns it.
    assert_eq!(
        scan_at(&mut world, 104.0, 0.0, LightState::Red).obstacle,
        None
    );
    // Short of the line, the light binds as always.
    let view = scan_at(&mut world, 90.0, 5.0, LightState::Red);
    let (gap, _) = view.obstacle.expect("the stop line ahead");
    assert!((gap - (10.0 - 2.45 - 1.0)).abs() < 1.5, "gap {gap}");

    // Yellow: a crawl that could not get its tail over the line before red stops while it can
    // (the front 1.2 m short of the line at 2.5 m/s), a car that clears the line in time goes
    // on (3 m short at 8 m/s).
    let front_short = |short: f64| 100.0 - 2.45 - short;
    let view = scan_at(&mut world, front_short(1.2), 2.5, LightState::Yellow);
    assert_eq!(view.cause, Some(BrakeReason::TrafficLight), "{view:?}");
    let view = scan_at(&mut world, front_short(3.0), 8.0, LightState::Yellow);
    assert_eq!(view.obstacle, None, "{view:?}");

    // A route that starts inside the junction does not include the lane of the line under the
    // ego's tail: the light binds all the same.
    let in_junction = route(&map, (101.5, -1.75), (200.0, -1.75));
    assert!(map.lane(in_junction.points[0].lane).in_junction());
    world
        .lights
        .force(map.lights[0].id, LightState::Red, f64::INFINITY);
    world.lights.update(world.time);
    world.ego = Ego::new(EgoParams::default(), DVec3::new(101.5, -1.75, 0.0), 0.0);
    let view = hazards::scan(&world, &in_junction, 0, &mut HazardMemory::default());
    assert_eq!(view.cause, Some(BrakeReason::TrafficLight), "{view:?}");
}

#[test]
fn the_expert_stops_short_of_a_light_head_that_stands_before_the_line() {
    let mut map = load("signal-junction", include_str!("maps/signal_junction.xodr"));
    // The head on the kerb 8 m before the line (x = 100), as Town01 and Town02 post theirs.
    map.lights[0].head = DVec3::new(92.0, -5.0, 3.0);
    let through = route(&map, (50.0, -1.75), (200.0, -1.75));
    let mut world = quiet_world(&map, &through, 0);
    world
        .lights
        .force(map.lights[0].id, LightState::Red, f64::INFINITY);
    world.lights.update(world.time);
    let mut gap_at = |x: f64, speed: f64| {
        world.ego = Ego::new(EgoParams::default(), DVec3::new(x, -1.75, 0.0), 0.0);
        world.ego.speed = speed;
        let index = ego_index(&world, &through);
        let view = hazards::scan(&world, &through, index, &mut HazardMemory::default());
        assert_eq!(view.cause, Some(BrakeReason::TrafficLight), "{view:?}");
        view.obstacle.expect("the light holds it").0
    };
    let front = |x: f64| x + EgoParams::default().half_extent.x;
    // Far off, the stop point keeps the front 4 m short of the head: the obstacle stands
    // there, and the expert comes to rest its standstill gap (4 m) short of it.
    let gap = gap_at(60.0, 6.0);
    assert!((gap - (92.0 - front(60.0))).abs() < 0.3, "gap {gap}");
    // Stopped there, it holds.
    let gap = gap_at(92.0 - 4.0 - EgoParams::default().half_extent.x, 0.0);
    assert!(gap < 4.3, "gap {gap}");
    // Too fast to stop short of the head, it stops at the line as before.
    let gap = gap_at(85.0, 8.0);
    assert!((gap - (100.0 - front(85.0) - 1.0)).abs() < 0.3, "gap {gap}");
}

#[test]
fn lanes_a_few_centimetres_long_do_not_hide_the_ego_from_traffic() {
    let map = load("short-sections", include_str!("maps/short_sections.xodr"));
    // The ego stands 8 m past road 2's three 5 cm sections, on road 3; a car comes up road 1.
    let route = route(&map, (58.0, -1.75), (140.0, -1.75));
    let config = |seed| WorldConfig {
        vehicles: 1,
        scenarios: false,
        parked_cars: false,
        seed,
        ..WorldConfig::default()
    };
    let mut world = (0..64)
        .map(|seed| World::new(&map, &route, config(seed)))
        .find(|w| map.lane(w.traffic.vehicles[0].lane).road_id == "1")
        .expect("a seed that spawns the car on road 1");
    let car = &mut world.traffic.vehicles[0];
    car.s = 10.0;
    car.speed = 8.0;
    car.desired_speed = 8.0;
    let id = car.id;
    for _ in 0..(15.0 / 0.05) as usize {
        let contacts = world.step(HOLD);
        assert!(
            contacts.iter().all(|c| c.other_id != id),
            "the car ran into the ego at t = {:.2} s",
            world.time
        );
    }
    assert!(
        world.traffic.vehicles[0].speed < 0.1,
        "it waits behind the ego"
    );
}

#[test]
fn the_ego_takes_its_turn_at_a_junction_without_lights() {
    let map = load("small", towngen::bundled(TownStyle::SmallTJunctions));
    let conflicts = sim_bridge::world::junctions::conflicts(&map);
    // A connector `a` entered from a lane without a light, and one `b` from another approach
    // that conflicts with it.
    let entered_from = |lane: LaneIdx| map.lane(lane).predecessors.first().copied();
    let open_approach =
        |lane: LaneIdx| !map.lane(lane).in_junction() && map.light_ending(lane).is_none();
    let (a, b) =
        map.junctions
            .iter()
            .flat_map(|j| j.lanes.iter().copied())
            .find_map(|a| {
                let from = entered_from(a).filter(|&l| open_approach(l))?;
                let b =
                    conflicts.get(&a)?.iter().copied().find(|&b| {
                        entered_from(b).is_some_and(|l| l != from && open_approach(l))
                    })?;
                (map.lane(from).length() > 30.0).then_some((a, b))
            })
            .expect("a junction without lights with two conflicting connectors");
    let approach = map.lane(entered_from(a).unwrap());
    let exit = map.lane(map.lane(a).successors[0]);
    let start = approach.pose_at(approach.length() - 25.0).position;
    let end = exit.pose_at(exit.length().min(15.0)).position;
    let route = route_through(&map, &[(start.x, start.y), (end.x, end.y)]);
    let entry = route
        .points
        .iter()
        .position(|p| p.lane == a)
        .expect("the route takes connector a");
    // The ego stands 8 m before the junction; a car stands on `b`.
    let stand = route.points[entry - 8];
    for mode in [TrafficMode::Courteous, TrafficMode::Carla] {
        let mut world = quiet_world_in(&map, &route, 1, mode);
        let car = &mut world.traffic.vehicles[0];
        car.speed = 0.0;
        car.lane = b;
        car.s = map.lane(b).length() / 2.0;
        car.next = map
            .lane(b)
            .successors
            .first()
            .copied()
            .into_iter()
            .collect();
        world.ego = Ego::new(EgoParams::default(), stand.position, stand.yaw);
        let index = ego_index(&world, &route);
        world.trigger_scenarios(index);
        world.step(HOLD);
        assert_eq!(world.ego_junction_request().map(|(c, _)| c), Some(a));
        let view = hazards::scan(&world, &route, index, &mut HazardMemory::default());
        assert_eq!(
            view.cause,
            Some(BrakeReason::Vehicle),
            "it waits its turn: {view:?}"
        );
        // With `b` clear the way is free.
        let far = (map.lanes.iter())
            .find(|l| !l.in_junction() && (l.points[0] - stand.position).length() > 200.0)
            .expect("a lane far away");
        world.traffic.vehicles[0].lane = far.idx;
        world.traffic.vehicles[0].s = 0.0;
        let view = hazards::scan(&world, &route, index, &mut HazardMemory::default());
        assert_eq!(view.obstacle, None, "{view:?}");

        // A car that comes to `b` after the ego waits for it.
        let b_approach = map.lane(entered_from(b).unwrap());
        let car = &mut world.traffic.vehicles[0];
        car.lane = b_approach.idx;
        car.s = b_approach.length() - 5.0;
        car.next = vec![b];
        car.arrival = None;
        for _ in 0..(5.0 / 0.05) as usize {
            world.trigger_scenarios(index);
            world.step(HOLD);
        }
        let car = &world.traffic.vehicles[0];
        match mode {
            TrafficMode::Courteous => assert_eq!(
                car.lane, b_approach.idx,
                "it leaves the turn to the ego: {car:?}"
            ),
            // CARLA's traffic manager knows nothing of the ego's turn: the car goes.
            TrafficMode::Carla => assert_ne!(car.lane, b_approach.idx, "it goes: {car:?}"),
        }
    }
}

#[test]
fn a_light_held_green_by_a_scenario_shows_yellow_before_red() {
    let map = load("signal-junction", include_str!("maps/signal_junction.xodr"));
    let route = route(&map, (50.0, -1.75), (200.0, -1.75));
    let id = map.lights[0].id;
    let (mut held_through_red, mut hold_ended_in_red) = (0, 0);
    for seed in 0..20 {
        let config = WorldConfig {
            vehicles: 0,
            seed,
            ..WorldConfig::default()
        };
        // Where the light's own cycle is when the hold ends: the case that needs a yellow
        // between the held green and the cycle's red.
        let mut unforced = World::new(&map, &route, config.clone());
        unforced.lights.update(7.05);
        hold_ended_in_red += usize::from(unforced.light_states()[id] == LightState::Red);
        let mut world = World::new(&map, &route, config);
        // Scenario 7 holds the ego's light green for a while, whatever its cycle says.
        world.lights.hold_green(id, 7.0);
        let mut previous = LightState::Green;
        for tick in 0..400 {
            let t = tick as f64 * 0.05;
            world.lights.update(t);
            let state = world.light_states()[id];
            assert!(
                !(previous == LightState::Green && state == LightState::Red),
                "seed {seed}: green turned red at t = {t:.2} s without yellow"
            );
            held_through_red += usize::from(t < 7.0 && state == LightState::Red);
            previous = state;
        }
    }
    assert_eq!(held_through_red, 0);
    assert!(
        hold_ended_in_red > 0,
        "no seed's hold ended in its cycle's red"
    );
}

#[test]
fn connectors_conflict_by_their_whole_path_through_the_junction() {
    let map = load("cut-connector", include_str!("maps/cut_connector.xodr"));
    let piece = |road: &str, section: usize| {
        (map.lanes.iter())
            .find(|l| l.road_id == road && l.section == section && l.in_junction())
            .unwrap_or_else(|| panic!("road {road} section {section}"))
            .idx
    };
    let (east, north_first, north_second) = (piece("10", 0), piece("11", 0), piece("11", 1));
    let conflicts = sim_bridge::world::junctions::conflicts(&map);
    let of = |lane| conflicts.get(&lane).cloned().unwrap_or_default();
    // Only road 11's second piece crosses road 10, but a car asking for its first piece must
    // wait for whoever is on road 10, and the ego there for a car on either piece.
    assert!(of(north_second).contains(&east));
    assert!(of(north_first).contains(&east), "{:?}", of(north_first));
    assert!(of(east).contains(&north_first) && of(east).contains(&north_second));
    // The two pieces of one path do not conflict with each other.
    assert!(!of(north_first).contains(&north_second));
}

/// Traffic does not enter a junction it cannot leave (CARLA's junction exit check): with a car
/// standing at the start of its way out, a car at the entry takes another way through the
/// junction that has room and never stops inside it. It used to drive in and stand there
/// behind the car, holding every connector that crosses its own; on Town02 queues spilling
/// back from junction to junction closed into a gridlock that held the ego for good.
#[test]
fn traffic_does_not_enter_a_junction_it_cannot_leave() {
    let map = load("small", towngen::bundled(TownStyle::SmallTJunctions));
    let out_of = |connector: LaneIdx| map.lane(connector).successors.first().copied();
    let long_exit = |connector: LaneIdx| {
        out_of(connector)
            .is_some_and(|exit| !map.lane(exit).in_junction() && map.lane(exit).length() > 30.0)
    };
    // An approach without a light with two ways through the junction onto long lanes.
    let (from, ways) = map
        .lanes
        .iter()
        .filter(|l| !l.in_junction() && l.length() > 40.0 && map.light_ending(l.idx).is_none())
        .find_map(|l| {
            let ways: Vec<LaneIdx> = (l.successors.iter().copied())
                .filter(|&c| map.lane(c).in_junction() && long_exit(c))
                .collect();
            (ways.len() >= 2).then_some((l.idx, ways))
        })
        .expect("an approach with two ways through a junction");
    let (blocked, exit) = (ways[0], out_of(ways[0]).unwrap());
    // The ego holds on a lane far away.
    let entry = map.lane(from).points.last().copied().unwrap();
    let far = (map.lanes.iter())
        .find(|l| !l.in_junction() && l.length() > 30.0 && (l.points[0] - entry).length() > 200.0)
        .expect("a lane far away");
    let (a, b) = (far.pose_at(5.0).position, far.pose_at(25.0).position);
    let route = route_through(&map, &[(a.x, a.y), (b.x, b.y)]);
    let mut world = quiet_world(&map, &route, 2);
    let stand_at = world.traffic.vehicles[0].half.x + 0.5;
    let pin_blocker = |world: &mut World<'_>| {
        let blocker = &mut world.traffic.vehicles[0];
        (blocker.lane, blocker.s, blocker.speed) = (exit, stand_at, 0.0);
        blocker.next = out_of(exit).into_iter().collect();
    };
    pin_blocker(&mut world);
    let car = &mut world.traffic.vehicles[1];
    (car.lane, car.s, car.speed, car.arrival) = (from, map.lane(from).length() - 8.0, 0.0, None);
    car.next = vec![blocked, exit];
    for _ in 0..(20.0 / 0.05) as usize {
        world.step(HOLD);
        pin_blocker(&mut world);
        let car = &world.traffic.vehicles[1];
        assert_ne!(
            car.lane, blocked,
            "it drove into the junction it cannot leave"
        );
        assert!(
            !(map.lane(car.lane).in_junction() && car.speed < 0.1),
            "it stands inside the junction at t = {:.2} s: {car:?}",
            world.time
        );
    }
    let car = &world.traffic.vehicles[1];
    assert_ne!(car.lane, from, "it went another way: {car:?}");
}

#[test]
fn the_expert_drives_on_past_a_walker_it_clears_well_before_the_walker_arrives() {
    let map = road();
    let route = outer_lane_route(&map);
    let mut world = quiet_world(&map, &route, 0);
    // A walker at 1.8 m/s heading across the road from 7.6 m right of the ego's lane centre
    // (6 m outside its corridor: it gets there in 3.3 s), its line 6 m ahead of the ego's front.
    world.crossers = vec![Crosser {
        id: 100_000,
        kind: ActorKind::Walker,
        position: DVec3::new(100.0 + 2.45 + 6.0, -5.25 - 1.66 - 6.0, 0.0),
        yaw: FRAC_PI_2,
        speed: 1.8,
        remaining: 50.0,
        moving: true,
        half: DVec2::splat(0.3),
        patrol: false,
        gone: false,
    }];
    let mut scan_at_speed = |speed: f64| {
        world.ego = Ego::new(EgoParams::default(), DVec3::new(100.0, -5.25, 0.0), 0.0);
        world.ego.speed = speed;
        let index = ego_index(&world, &route);
        hazards::scan(&world, &route, index, &mut HazardMemory::default())
    };
    // At 8 m/s its rear is past the line in 1.4 s: no walking pace, no stop (braking would
    // only leave it in the walker's way).
    let driving = scan_at_speed(8.0);
    assert!(
        !driving.walker_near && driving.obstacle.is_none(),
        "{driving:?}"
    );
    // Standing, it lets the walker cross first.
    assert!(scan_at_speed(0.0).walker_near);
}
