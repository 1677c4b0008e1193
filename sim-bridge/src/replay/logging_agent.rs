//! [`LoggingAgent`]: wraps any agent and writes one step log per route run into a folder:
//! each tick's request (as an agent server would get it, images PNG-encoded), the wrapped
//! agent's control and planned trajectory, the time it took, and privileged ground truth (ego
//! pose, actors and light heads within 60 m) for open-loop metrics and failure analysis. An
//! agent without cameras (the expert) is shown the recording rig, so its logs can be replayed
//! to a server as "the recorded expert".

use std::path::PathBuf;
use std::time::Instant;

use ssrdrive_proto::camera::Rig;
use ssrdrive_proto::control::Control;
use ssrdrive_proto::{v1, wire};

use super::log::{LOG_FORMAT, LOG_VERSION, LogWriter};
use crate::driver::{Agent, AgentError, Observation, RouteContext};
use crate::world::World;
use crate::world::state::ActorKind;

/// Actors farther than this from the ego are left out of the ground truth, metres.
const TRUTH_RADIUS: f64 = 60.0;

/// See the module doc.
pub struct LoggingAgent {
    inner: Box<dyn Agent>,
    rig: Rig,
    dir: PathBuf,
    log: Option<LogWriter>,
}

impl LoggingAgent {
    /// Logs `inner` into `dir`; `rig` is used when `inner` has no cameras of its own.
    pub fn new(inner: Box<dyn Agent>, rig: Rig, dir: PathBuf) -> Self {
        let rig = inner.sensors().unwrap_or(rig);
        Self {
            inner,
            rig,
            dir,
            log: None,
        }
    }
}

fn fail(error: impl ToString) -> AgentError {
    AgentError(format!("step log: {}", error.to_string()))
}

fn kind_name(kind: ActorKind) -> &'static str {
    match kind {
        ActorKind::Vehicle => "vehicle",
        ActorKind::Cyclist => "cyclist",
        ActorKind::Walker => "walker",
        ActorKind::Static => "static",
        ActorKind::Debris => "debris",
    }
}

fn png_images(obs: &Observation) -> Result<Vec<v1::Image>, ssrdrive_proto::image::ImageError> {
    obs.frames
        .iter()
        .map(|frame| {
            Ok(v1::Image {
                camera_id: frame.camera.clone(),
                width: frame.width,
                height: frame.height,
                encoding: v1::ImageEncoding::Png as i32,
                data: ssrdrive_proto::image::encode_png(frame.width, frame.height, &frame.rgb)?,
            })
        })
        .collect()
}

impl Agent for LoggingAgent {
    fn name(&self) -> String {
        self.inner.name()
    }

    fn identity(&self) -> String {
        self.inner.identity()
    }

    fn start_route(&mut self, ctx: &RouteContext<'_>) -> Result<(), AgentError> {
        self.inner.start_route(ctx)?;
        let name = format!(
            "{}__route_{}__rep{}.ssrlog",
            ssrdrive_proto::dataset::safe_name(&ctx.map.name),
            ssrdrive_proto::dataset::safe_name(ctx.route_id),
            ctx.repetition
        );
        let header = v1::LogHeader {
            format: LOG_FORMAT.into(),
            version: LOG_VERSION,
            agent: self.inner.name(),
            town: ctx.map.name.clone(),
            route_id: ctx.route_id.to_string(),
            repetition: ctx.repetition as u32,
            seed: ctx.seed,
            rig: Some(wire::rig_to_proto(&self.rig)),
            tick_s: crate::world::DT,
            ego_half_length: ctx.ego_half_extent.x,
            ego_half_width: ctx.ego_half_extent.y,
        };
        match LogWriter::create(&self.dir.join(name), header) {
            Ok(log) => {
                self.log = Some(log);
                Ok(())
            }
            Err(e) => Err(fail(e)),
        }
    }

    fn end_route(&mut self) {
        self.inner.end_route();
        if let Some(log) = self.log.take()
            && let Err(e) = log.finish()
        {
            tracing::error!("step log: {e}");
        }
    }

    fn sensors(&self) -> Option<Rig> {
        Some(self.rig.clone())
    }

    fn wants_frames(&self, _frame: u64) -> bool {
        true
    }

    fn run_step(&mut self, obs: &Observation, world: &World<'_>) -> Result<Control, AgentError> {
        let started = Instant::now();
        let control = self.inner.run_step(obs, world)?;
        let agent_ms = started.elapsed().as_secs_f64() * 1e3;
        let mut request = obs.step_request("");
        request.images = png_images(obs).map_err(fail)?;
        let ego = world.ego_state();
        let actors = world
            .actors()
            .into_iter()
            .filter(|a| a.obb.centre.distance(ego.position.truncate()) <= TRUTH_RADIUS)
            .map(|a| v1::ActorBox {
                id: a.id,
                kind: kind_name(a.kind).into(),
                x: a.obb.centre.x,
                y: a.obb.centre.y,
                yaw: a.obb.yaw,
                half_length: a.obb.half.x,
                half_width: a.obb.half.y,
            })
            .collect();
        let lights = world
            .map
            .lights
            .iter()
            .zip(world.light_states())
            .filter(|(light, _)| {
                light.head.truncate().distance(ego.position.truncate()) <= TRUTH_RADIUS
            })
            .map(|(light, state)| v1::LightTruth {
                id: light.id as u32,
                head_x: light.head.x,
                head_y: light.head.y,
                head_yaw: light.head_yaw,
                state: state.name().into(),
            })
            .collect();
        let tick = v1::LogTick {
            request: Some(request),
            control: Some(wire::control_to_proto(control)),
            trajectory: self
                .inner
                .planned_trajectory()
                .iter()
                .map(|p| v1::EgoPoint { x: p.x, y: p.y })
                .collect(),
            ego: Some(v1::Pose {
                x: ego.position.x,
                y: ego.position.y,
                z: ego.position.z,
                yaw: ego.yaw,
            }),
            actors,
            agent_ms,
            lights,
        };
        if let Some(log) = self.log.as_mut()
            && let Err(e) = log.tick(tick)
        {
            return Err(fail(e));
        }
        Ok(control)
    }
}
