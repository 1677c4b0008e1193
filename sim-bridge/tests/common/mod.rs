//! Helpers shared by the integration tests (each test crate uses some of them).
#![allow(dead_code)]

use std::path::PathBuf;

use glam::DVec2;
use sim_bridge::map::{LaneIdx, LanePose, Map, TrafficLight};
use sim_bridge::render::{Appearance, CameraRenderer, SceneState};
use sim_bridge::world::state::{EgoState, LightState};
use ssrdrive_proto::camera::Rig;

/// ../shared/carla beside the checkout, if present; prints a skip notice otherwise, or fails
/// with `SSRDRIVE_REQUIRE_CARLA` set (the CARLA maps and routes are never copied into the
/// repository).
pub fn carla_dir() -> Option<PathBuf> {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../shared/carla");
    if dir.is_dir() {
        Some(dir)
    } else {
        // Where the maps are meant to be there (a CI that provides them), missing is a failure,
        // not a pass.
        assert!(
            std::env::var_os("SSRDRIVE_REQUIRE_CARLA").is_none(),
            "SSRDRIVE_REQUIRE_CARLA is set and {} is not there",
            dir.display()
        );
        eprintln!(
            "SKIP: {} not found; CARLA map and route tests skipped",
            dir.display()
        );
        None
    }
}

/// The lights of `map` (among `lights`) whose red lamp the front camera of `rig` does not see
/// from `back` m before the light's first stop line, on its lane (followed back through first
/// predecessors) and looking along it: more pure-red pixels with the light red than green,
/// every other light green.
pub fn lights_unseen_from<'a>(
    map: &Map,
    rig: &Rig,
    lights: impl Iterator<Item = &'a TrafficLight>,
    back: f64,
) -> Vec<usize> {
    let mut renderer = CameraRenderer::new(map, Appearance::default());
    let mut unseen = Vec::new();
    for light in lights {
        let pose = upstream(map, light.stop_lines[0].lane, back);
        let ego = EgoState {
            position: pose.position,
            yaw: pose.yaw,
            speed: 0.0,
            half_extent: DVec2::new(2.4, 1.0),
        };
        let mut red_pixels = |state: LightState| {
            let mut states = vec![LightState::Green; map.lights.len()];
            states[light.id] = state;
            let scene = SceneState {
                ego,
                actors: &[],
                lights: &states,
            };
            let rgb = renderer.render(rig, &scene, 0).remove(0).rgb;
            rgb.chunks_exact(3)
                .filter(|p| p[0] > 200 && p[1] < 60 && p[2] < 60)
                .count()
        };
        if red_pixels(LightState::Red) <= red_pixels(LightState::Green) {
            unseen.push(light.id);
        }
    }
    unseen
}

/// The pose `back` m before the end of `lane`, following first predecessors (or the start of
/// the first lane that has none).
fn upstream(map: &Map, mut lane: LaneIdx, mut back: f64) -> LanePose {
    loop {
        let l = map.lane(lane);
        match l.predecessors.first() {
            Some(&previous) if back > l.length() => {
                back -= l.length();
                lane = previous;
            }
            _ => return l.pose_at((l.length() - back).max(0.0)),
        }
    }
}
