//! The camera renderer: RGB8 frames of the world through a rig, on the CPU, single-threaded and
//! deterministic (the same map, appearance, state and frame index give the same bytes).
//!
//! Each frame starts from a precomputed sky-and-terrain background (it depends only on the
//! camera's pitch and roll, since the ego stays level), then draws the static scene within
//! [`DRAW_DISTANCE`] and the field of view, then the actors within [`ACTOR_DISTANCE`] and the
//! traffic-light lamps (the lit one blooming to [`LAMP_BLOOM_PIXELS`]), all with a depth test;
//! sensor noise, if the appearance asks for it, comes last. The projection is exactly
//! [`CameraSpec::project`]'s.

use glam::{DVec3, Vec3};
use ssrdrive_proto::camera::{CameraSpec, Rig};

use super::actors::{push_actor, push_lamps};
use super::raster::{Target, View};
use super::scene::StaticScene;
use super::shapes::Tri;
use super::style::{Appearance, pack};
use crate::driver::CameraFrame;
use crate::map::Map;
use crate::world::ActorView;
use crate::world::state::{EgoState, LightState};

/// How far the road, paint, signs and lights are drawn, metres.
pub const DRAW_DISTANCE: f32 = 150.0;
/// How far actors are drawn, metres.
pub const ACTOR_DISTANCE: f32 = 100.0;
/// Radius, in pixels, that a lit traffic-light lamp seen head-on covers at any distance (its
/// bloom; less toward the side, with the cosine of the angle off its axis): a 0.13 m lamp is
/// under a pixel across beyond about 35 m at 320 pixels and 100 degrees, where a point-sampled
/// lamp would flicker in and out between pixel centres.
pub const LAMP_BLOOM_PIXELS: f32 = 1.2;

/// What a camera sees of the world at one instant.
#[derive(Debug, Clone, Copy)]
pub struct SceneState<'a> {
    /// The ego, which carries the rig (it is not drawn itself).
    pub ego: EgoState,
    /// Every other actor.
    pub actors: &'a [ActorView],
    /// Light states, indexed like `Map::lights`.
    pub lights: &'a [LightState],
}

/// Renders camera frames of one map in one appearance.
pub struct CameraRenderer {
    scene: StaticScene,
    appearance: Appearance,
    /// Sky-and-terrain backgrounds, one per camera spec seen so far.
    backgrounds: Vec<(CameraSpec, Vec<u32>)>,
    target: Target,
    dynamic: Vec<Tri>,
}

impl CameraRenderer {
    /// Bake `map` for rendering in `appearance`.
    pub fn new(map: &Map, appearance: Appearance) -> Self {
        Self {
            scene: StaticScene::bake(map, &appearance),
            appearance,
            backgrounds: Vec::new(),
            target: Target::new(0, 0),
            dynamic: Vec::new(),
        }
    }

    /// The appearance frames are drawn in.
    pub fn appearance(&self) -> &Appearance {
        &self.appearance
    }

    /// Triangles in the baked static scene.
    pub fn static_triangles(&self) -> usize {
        self.scene.len()
    }

    /// One frame per camera of `rig`, in rig order; `frame` seeds the sensor noise.
    pub fn render(&mut self, rig: &Rig, state: &SceneState<'_>, frame: u64) -> Vec<CameraFrame> {
        rig.cameras
            .iter()
            .enumerate()
            .map(|(k, camera)| self.render_camera(camera, state, frame, k as u64))
            .collect()
    }

    fn render_camera(
        &mut self,
        camera: &CameraSpec,
        state: &SceneState<'_>,
        frame: u64,
        index: u64,
    ) -> CameraFrame {
        let (width, height) = (camera.width as usize, camera.height as usize);
        if self.target.width != width || self.target.height != height {
            self.target = Target::new(width, height);
        }
        let k = self.background_index(camera);
        self.target.clear(&self.backgrounds[k].1);
        let view = world_view(camera, &state.ego);
        let eye = view.origin.truncate();
        let forward = view.forward.truncate().normalize_or_zero();
        let wedge = plan_half_angle(camera, &view);
        let target = &mut self.target;
        self.scene
            .visible(eye, forward, wedge, DRAW_DISTANCE, |tris| {
                for t in tris {
                    target.triangle(&view, t.corners, t.colour);
                }
            });
        self.dynamic.clear();
        for actor in state.actors {
            let d = actor.obb.centre.as_vec2() - eye;
            let behind = wedge.is_some() && d.dot(forward) < -actor.obb.half.length() as f32;
            if d.length() <= ACTOR_DISTANCE && !behind {
                push_actor(&mut self.dynamic, actor, &self.appearance, view.origin);
            }
        }
        for head in &self.scene.heads {
            let toward_eye = eye - head.lamps[1].truncate();
            let distance = toward_eye.length();
            // The cosine of the eye's angle off the lamps' axis: their glow fades toward the side.
            let on_axis = toward_eye.dot(head.facing) / distance;
            let state = state.lights.get(head.light).copied();
            if let Some(light) = state
                && distance <= DRAW_DISTANCE
                && on_axis > 0.0
            {
                let bloom = LAMP_BLOOM_PIXELS * on_axis * distance / camera.focal();
                push_lamps(&mut self.dynamic, head, light, &self.appearance, eye, bloom);
            }
        }
        for t in &self.dynamic {
            self.target.triangle(&view, t.corners, t.colour);
        }
        let noise_seed = self.appearance.noise_seed
            ^ frame.wrapping_mul(0x9e37_79b9_7f4a_7c15)
            ^ index.wrapping_mul(0xc2b2_ae3d_27d4_eb4f);
        CameraFrame {
            camera: camera.id.clone(),
            width: camera.width,
            height: camera.height,
            rgb: to_rgb8(&self.target.colour, self.appearance.noise, noise_seed),
        }
    }

    /// Where `camera`'s background is in the cache, computing it on first use.
    fn background_index(&mut self, camera: &CameraSpec) -> usize {
        if let Some(k) = self.backgrounds.iter().position(|(c, _)| c == camera) {
            return k;
        }
        let image = sky_and_terrain(camera, &self.appearance);
        self.backgrounds.push((camera.clone(), image));
        self.backgrounds.len() - 1
    }
}

/// The camera in the world: the ego pose applied to the camera's pose in the ego frame.
pub fn world_view(camera: &CameraSpec, ego: &EgoState) -> View {
    let pose = camera.pose_in_ego();
    let (s, c) = (ego.yaw as f32).sin_cos();
    let rotate = |v: [f32; 3]| Vec3::new(c * v[0] - s * v[1], s * v[0] + c * v[1], v[2]);
    let origin: DVec3 = ego.position;
    View {
        origin: origin.as_vec3() + rotate(pose.position),
        right: rotate(pose.right),
        up: rotate(pose.up),
        forward: rotate(pose.forward),
        focal: camera.focal(),
        centre: [camera.width as f32 / 2.0, camera.height as f32 / 2.0],
    }
}

/// Half the plan angle the image covers around the optical axis, for culling; `None` when
/// the camera looks too steeply up or down for a plan wedge to bound what it sees.
fn plan_half_angle(camera: &CameraSpec, view: &View) -> Option<f32> {
    if camera.pitch.abs() > 30.0 || camera.roll.abs() > 30.0 {
        return None;
    }
    let axis = view.forward.truncate();
    let (w, h) = (camera.width as f32, camera.height as f32);
    let corners = [(0.0, 0.0), (w, 0.0), (0.0, h), (w, h)];
    let widest = corners
        .iter()
        .map(|&(u, v)| axis.angle_to(view.ray(u, v).truncate()).abs())
        .fold(0.0f32, f32::max);
    (widest < 1.5).then_some(widest)
}

/// The sky above the horizon and hazy terrain below it, for a level ego.
fn sky_and_terrain(camera: &CameraSpec, app: &Appearance) -> Vec<u32> {
    let level = EgoState {
        position: DVec3::ZERO,
        yaw: 0.0,
        speed: 0.0,
        half_extent: glam::DVec2::ONE,
    };
    let view = world_view(camera, &level);
    let height = view.origin.z.max(0.1);
    let (w, h) = (camera.width as usize, camera.height as usize);
    let mut out = Vec::with_capacity(w * h);
    for j in 0..h {
        for i in 0..w {
            let ray = view.ray(i as f32 + 0.5, j as f32 + 0.5).normalize();
            let colour = if ray.z >= 0.0 {
                app.sky_horizon.lerp(app.sky_top, ray.z.sqrt())
            } else {
                let distance = height / -ray.z;
                let haze = 1.0 - (-distance / 250.0).exp();
                app.terrain_near.lerp(app.terrain_far, haze) * app.exposure
            };
            out.push(pack(colour));
        }
    }
    out
}

/// Packed colours to RGB8, with per-channel noise of standard deviation about `sigma`.
fn to_rgb8(colour: &[u32], sigma: f32, seed: u64) -> Vec<u8> {
    let mut out = Vec::with_capacity(colour.len() * 3);
    if sigma <= 0.0 {
        for &c in colour {
            out.extend_from_slice(&[(c >> 16) as u8, (c >> 8) as u8, c as u8]);
        }
        return out;
    }
    let mut state = seed | 1;
    // Sum of two uniforms on [-1, 1): triangular, standard deviation sqrt(2/3).
    let scale = sigma / (2.0f32 / 3.0).sqrt();
    let mut next = || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        let a = (state & 0xffff) as f32 / 32768.0 - 1.0;
        let b = ((state >> 16) & 0xffff) as f32 / 32768.0 - 1.0;
        (a + b) * scale
    };
    for &c in colour {
        for shift in [16, 8, 0] {
            let v = ((c >> shift) & 0xff) as f32 + next();
            out.push(v.clamp(0.0, 255.0) as u8);
        }
    }
    out
}
