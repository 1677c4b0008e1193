//! The camera renderer: projection through a rolled, pitched and yawed camera, occlusion
//! order, traffic-light colours in the pixels, lights seen from their stop lines, and
//! determinism; and the top-down local view's plan and target overlay.

mod common;

use common::lights_unseen_from;
use glam::{DVec2, DVec3};
use sim_bridge::map::{Map, MapOptions};
use sim_bridge::render::{Appearance, CameraRenderer, SceneState};
use sim_bridge::towngen::{TownStyle, bundled};
use sim_bridge::world::ActorView;
use sim_bridge::world::state::{ActorKind, EgoState, LightState, Obb};
use ssrdrive_proto::camera::{CameraSpec, Rig};

fn town() -> Map {
    let style = TownStyle::SmallTJunctions;
    Map::from_str(style.name(), bundled(style), MapOptions::default()).expect("bundled town")
}

fn ego_at(position: DVec3, yaw: f64) -> EgoState {
    EgoState {
        position,
        yaw,
        speed: 0.0,
        half_extent: DVec2::new(2.4, 1.0),
    }
}

/// An ego pose out in the terrain, away from every road.
fn off_road(map: &Map) -> EgoState {
    ego_at(
        DVec3::new(map.bounds.1.x + 300.0, map.bounds.1.y + 300.0, 0.0),
        0.3,
    )
}

fn actor(id: u32, kind: ActorKind, centre: DVec2, yaw: f64, half: DVec2) -> ActorView {
    ActorView {
        id,
        kind,
        obb: Obb { centre, yaw, half },
        z: 0.0,
        velocity: DVec2::ZERO,
    }
}

fn render(
    renderer: &mut CameraRenderer,
    rig: &Rig,
    ego: EgoState,
    actors: &[ActorView],
    lights: &[LightState],
) -> Vec<u8> {
    let scene = SceneState {
        ego,
        actors,
        lights,
    };
    renderer.render(rig, &scene, 0).remove(0).rgb
}

fn pixel(rgb: &[u8], width: u32, u: f32, v: f32) -> [u8; 3] {
    let i = ((v as usize) * width as usize + u as usize) * 3;
    [rgb[i], rgb[i + 1], rgb[i + 2]]
}

/// An ego-frame point as a world point, for an ego at `ego`.
fn to_world(ego: &EgoState, p: [f32; 3]) -> DVec3 {
    let (s, c) = ego.yaw.sin_cos();
    let (x, y) = (p[0] as f64, p[1] as f64);
    ego.position + DVec3::new(c * x - s * y, s * x + c * y, p[2] as f64)
}

#[test]
fn a_world_point_lands_on_the_pixel_the_rig_projects_it_to() {
    let map = town();
    let camera = CameraSpec {
        id: "tilted".into(),
        x: 0.8,
        y: -0.4,
        z: 1.6,
        roll: 12.0,
        pitch: -8.0,
        yaw: 35.0,
        width: 400,
        height: 300,
        fov: 90.0,
    };
    let rig = Rig::new(vec![camera.clone()]).unwrap();
    let ego = off_road(&map);
    let mut renderer = CameraRenderer::new(&map, Appearance::default());
    let empty = render(&mut renderer, &rig, ego, &[], &[]);
    // A small post whose centre is at a chosen ego-frame point 12 m ahead and to the right
    // (CARLA yaw 35 turns the camera right; the ego frame's y is left).
    for target in [[10.0f32, -6.0, 1.2], [14.0, -9.0, 0.4], [8.0, -3.0, 2.0]] {
        let (uv, _) = camera.project(target).expect("in front");
        assert!(
            uv[0] > 20.0 && uv[0] < 380.0 && uv[1] > 20.0 && uv[1] < 280.0,
            "{uv:?}"
        );
        let centre = to_world(&ego, [target[0], target[1], 0.0]);
        let mut post = actor(
            0,
            ActorKind::Walker,
            centre.truncate(),
            0.0,
            DVec2::splat(0.15),
        );
        // A walker is 1.72 m tall: lower it so its body straddles the target height.
        post.z = target[2] as f64 - 0.7;
        let seen = render(&mut renderer, &rig, ego, &[post], &[]);
        assert_ne!(
            pixel(&seen, 400, uv[0], uv[1]),
            pixel(&empty, 400, uv[0], uv[1]),
            "the post is not at its projection {uv:?}"
        );
        let changed: Vec<(usize, usize)> = (0..300)
            .flat_map(|v| (0..400).map(move |u| (u, v)))
            .filter(|&(u, v)| {
                pixel(&seen, 400, u as f32, v as f32) != pixel(&empty, 400, u as f32, v as f32)
            })
            .collect();
        let far = changed
            .iter()
            .filter(|&&(u, v)| {
                (u as f32 + 0.5 - uv[0]).abs() > 40.0 || (v as f32 + 0.5 - uv[1]).abs() > 120.0
            })
            .count();
        assert_eq!(far, 0, "pixels changed far from {uv:?}");
    }
}

#[test]
fn the_nearer_of_two_cars_hides_the_farther_whatever_the_draw_order() {
    let map = town();
    let rig = Rig::tcp();
    let ego = off_road(&map);
    let ahead = |d: f64| ego.position.truncate() + DVec2::from_angle(ego.yaw) * d;
    let half = DVec2::new(2.2, 0.9);
    let near = actor(1, ActorKind::Vehicle, ahead(12.0), ego.yaw, half);
    let far = actor(2, ActorKind::Vehicle, ahead(24.0), ego.yaw, half);
    let mut renderer = CameraRenderer::new(&map, Appearance::default());
    let only_near = render(&mut renderer, &rig, ego, &[near], &[]);
    let only_far = render(&mut renderer, &rig, ego, &[far], &[]);
    // Row 150 of the centre column: the near car's cabin (13.5 m from the camera) covers it,
    // and so does the far car's body (25.5 m).
    let (u, v) = (450.0, 150.0);
    assert_ne!(
        pixel(&only_near, 900, u, v),
        pixel(&only_far, 900, u, v),
        "the two cars must look different there for the test to mean anything"
    );
    for actors in [[near, far], [far, near]] {
        let both = render(&mut renderer, &rig, ego, &actors, &[]);
        assert_eq!(pixel(&both, 900, u, v), pixel(&only_near, 900, u, v));
    }
}

#[test]
fn a_traffic_light_shows_its_state_in_the_pixels() {
    let map = town();
    let light = map.lights.first().expect("the town has traffic lights");
    let facing = DVec2::from_angle(light.head_yaw);
    // Stand 14 m in front of the head, looking at it.
    let position = light.head.truncate() + facing * 14.0;
    let ground = light.stop_lines[0].position.z;
    let ego = ego_at(
        position.extend(ground),
        light.head_yaw + std::f64::consts::PI,
    );
    let rig = Rig::tcp();
    let mut renderer = CameraRenderer::new(&map, Appearance::default());
    let mut count = |state: LightState, test: fn([u8; 3]) -> bool| {
        let mut lights = vec![LightState::Yellow; map.lights.len()];
        lights[light.id] = state;
        let rgb = render(&mut renderer, &rig, ego, &[], &lights);
        rgb.chunks_exact(3)
            .filter(|p| test([p[0], p[1], p[2]]))
            .count()
    };
    let red_lamp = |p: [u8; 3]| p[0] > 200 && p[1] < 60 && p[2] < 60;
    let green_lamp = |p: [u8; 3]| p[1] > 200 && p[0] < 60 && p[2] < 140;
    assert!(
        count(LightState::Red, red_lamp) >= 4,
        "red lamp not visible"
    );
    assert_eq!(count(LightState::Red, green_lamp), 0);
    assert!(
        count(LightState::Green, green_lamp) >= 4,
        "green lamp not visible"
    );
    assert_eq!(count(LightState::Green, red_lamp), 0);
}

#[test]
fn the_same_seed_renders_the_same_bytes() {
    let map = town();
    let lane = &map.lanes[0];
    let pose = lane.pose_at(lane.length() / 2.0);
    let ego = ego_at(pose.position, pose.yaw);
    let car = actor(
        9,
        ActorKind::Vehicle,
        pose.position.truncate() + DVec2::from_angle(pose.yaw) * 15.0,
        pose.yaw,
        DVec2::new(2.2, 0.9),
    );
    let lights = vec![LightState::Red; map.lights.len()];
    let rig = Rig::tcp_small();
    let frame = |seed: u64| {
        let mut renderer = CameraRenderer::new(&map, Appearance::randomised(seed));
        render(&mut renderer, &rig, ego, &[car], &lights)
    };
    assert_eq!(frame(7), frame(7));
    assert_ne!(frame(7), frame(8));
    let mut renderer = CameraRenderer::new(&map, Appearance::default());
    let canonical = render(&mut renderer, &rig, ego, &[car], &lights);
    assert_eq!(canonical, render(&mut renderer, &rig, ego, &[car], &lights));
    assert_eq!(canonical.len(), 320 * 96 * 3);
}

/// The bundled towns stand their lights US-style, across the junction: a car waiting at the
/// stop line sees its light (a head beside the line, as these towns first had, is out of the
/// camera's view there, so the green could not be seen). T-junction stems keep theirs beside
/// the line.
#[test]
fn a_car_at_the_stop_line_sees_its_light_across_the_junction() {
    for style in TownStyle::ALL {
        let map = Map::from_str(style.name(), bundled(style), MapOptions::default()).unwrap();
        let across: Vec<_> = map
            .lights
            .iter()
            .filter(|l| {
                let line = l.stop_lines[0];
                (l.head - line.position)
                    .truncate()
                    .dot(DVec2::from_angle(line.yaw))
                    > 5.0
            })
            .collect();
        assert!(
            across.len() * 4 > map.lights.len() * 3,
            "{}: {} of {} across",
            style.name(),
            across.len(),
            map.lights.len()
        );
        // The ego's centre 3 m before the line: its front at the line.
        let unseen = lights_unseen_from(&map, &Rig::tcp(), across.into_iter(), 3.0);
        assert!(
            unseen.is_empty(),
            "{}: lights {unseen:?} unseen from their stop line",
            style.name()
        );
    }
}

/// A lit lamp blooms to a few pixels at any distance, so the model's 320x96 camera sees a red
/// light from where a car has to start braking for it: 30 m before the stop line, with the head
/// up to 65 m away across the junction (a 0.13 m lamp is a third of a pixel there, and a
/// point-sampled one falls between pixel centres).
#[test]
fn the_small_camera_sees_every_red_light_from_its_braking_distance() {
    for style in TownStyle::ALL {
        let map = Map::from_str(style.name(), bundled(style), MapOptions::default()).unwrap();
        let unseen = lights_unseen_from(&map, &Rig::tcp_small(), map.lights.iter(), 30.0);
        assert!(
            unseen.is_empty(),
            "{}: lights {unseen:?} of {} unseen from 30 m before their stop line",
            style.name(),
            map.lights.len()
        );
    }
}

#[test]
fn the_local_view_draws_the_plan_and_the_target_point_where_the_ego_frame_puts_them() {
    use sim_bridge::render::topdown::{Intent, local_view};
    let map = town();
    let route = sim_bridge::route::DenseRoute::new(Vec::new(), 0.0);
    let ego = off_road(&map);
    let (radius, side) = (30.0, 300);
    let colour_at = |view: &sim_bridge::render::canvas::Canvas, ego_frame: DVec2| {
        let world = to_world(&ego, [ego_frame.x as f32, ego_frame.y as f32, 0.0]);
        let corner = ego.position.truncate() - DVec2::splat(radius);
        let u = (world.x - corner.x) * view.scale();
        let v = f64::from(side) - (world.y - corner.y) * view.scale();
        pixel(view.pixels(), side, u as f32, v as f32)
    };
    let plan = [
        DVec2::new(4.0, 0.5),
        DVec2::new(8.0, 1.5),
        DVec2::new(12.0, 3.0),
    ];
    let intent = Intent {
        target_point: Some(DVec2::new(20.0, -6.0)),
        plan: &plan,
    };
    let view = local_view(&map, &route, &ego, &[], intent, radius, side);
    assert_eq!(
        colour_at(&view, plan[2]),
        [40, 230, 230],
        "the plan's last waypoint"
    );
    assert_eq!(
        colour_at(&view, DVec2::new(20.0, -6.0)),
        [235, 60, 235],
        "the target"
    );
    // Mirrored across the heading, where nothing was planned, the terrain shows.
    let plain = local_view(&map, &route, &ego, &[], Intent::default(), radius, side);
    assert_eq!(
        colour_at(&view, DVec2::new(12.0, -3.0)),
        colour_at(&plain, plan[2])
    );
}
