//! Records one episode while the expert drives: an [`Agent`] that asks for the rig's frames
//! every `ticks_per_frame` ticks, writes them as PNG, injects noise into the executed control
//! while labelling each frame with the expert's own control and plan, and fills in each frame's
//! future (waypoints and controls every 0.5 s for 3 s) once that future has been driven.
//!
//! With a driver (DAgger: the learner being trained, through its server), the driver's control
//! is executed instead of the expert's, so the episode visits the states the learner drives
//! into, and each frame is still labelled by the expert, who watches every tick from the same
//! state: its control and its plan from there.
//! One recorder records one route run: a second `start_route` is refused (an error at
//! [`EpisodeRecorder::finish`]), since the episode folder holds one run.

use std::collections::VecDeque;
use std::io::Write;
use std::path::{Path, PathBuf};

use glam::{DVec2, DVec3};
use rand::{RngExt as _, SeedableRng};
use rand_chacha::ChaCha8Rng;
use ssrdrive_proto::camera::Rig;
use ssrdrive_proto::control::Control;
use ssrdrive_proto::dataset::{
    ACTOR_RANGE, ActorClass, ActorRecord, BrakeReason, FUTURE_COUNT, FUTURE_STEP, FrameRecord,
    NoiseConfig,
};
use ssrdrive_proto::image::encode_png;

use crate::driver::{Agent, AgentError, Observation, RouteContext};
use crate::expert::Expert;
use crate::map::angle_diff;
use crate::route::plan::to_ego_frame;
use crate::world::state::ActorKind;
use crate::world::{DT, World};

/// The ego on one tick, kept to compute earlier frames' futures.
#[derive(Debug, Clone, Copy)]
struct TickState {
    position: DVec2,
    yaw: f64,
    label: Control,
}

/// What a perturbation does to the executed control.
#[derive(Debug, Clone, Copy)]
enum Perturbation {
    /// Adds this to the steer.
    Steer(f64),
    /// Holds the pedals: this throttle and brake.
    Pedals { throttle: f64, brake: f64 },
}

/// The expert, recording into an episode folder (and, with a driver, labelling the states the
/// driver visits).
pub struct EpisodeRecorder<'d> {
    expert: Expert,
    driver: Option<&'d mut (dyn Agent + 'static)>,
    rig: Rig,
    dir: PathBuf,
    ticks_per_frame: u64,
    noise: NoiseConfig,
    rng: ChaCha8Rng,
    /// Remaining ticks of the current perturbation and what it does.
    perturbation: Option<(u64, Perturbation)>,
    history: Vec<TickState>,
    pending: VecDeque<FrameRecord>,
    measurements: std::io::BufWriter<std::fs::File>,
    frames: usize,
    truncated: usize,
    bytes: u64,
    error: Option<std::io::Error>,
}

/// What a finished recording holds.
#[derive(Debug, Clone, Copy)]
pub struct RecordingTotals {
    /// Frames written.
    pub frames: usize,
    /// Frames written whose future was cut by the end of the route.
    pub truncated_frames: usize,
    /// Bytes of images and measurements written.
    pub bytes: u64,
}

impl<'d> EpisodeRecorder<'d> {
    /// Record into `dir` (created, with one subfolder per camera); `driver`, if any, drives
    /// (its rig must be `rig`: it sees the frames the dataset stores).
    pub fn create(
        dir: &Path,
        rig: Rig,
        ticks_per_frame: u64,
        noise: NoiseConfig,
        seed: u64,
        driver: Option<&'d mut (dyn Agent + 'static)>,
    ) -> std::io::Result<Self> {
        for camera in &rig.cameras {
            std::fs::create_dir_all(dir.join(&camera.id))?;
        }
        let file = std::fs::File::create(dir.join("measurements.jsonl"))?;
        Ok(Self {
            expert: Expert::new(),
            driver,
            rig,
            dir: dir.to_path_buf(),
            ticks_per_frame: ticks_per_frame.max(1),
            noise,
            rng: ChaCha8Rng::seed_from_u64(seed ^ 0x0150_15e0),
            perturbation: None,
            history: Vec::new(),
            pending: VecDeque::new(),
            measurements: std::io::BufWriter::new(file),
            frames: 0,
            truncated: 0,
            bytes: 0,
            error: None,
        })
    }

    /// Write out the frames still waiting for their future (marked incomplete) and flush.
    pub fn finish(mut self) -> std::io::Result<RecordingTotals> {
        if let Some(e) = self.error.take() {
            return Err(e);
        }
        while let Some(record) = self.pending.pop_front() {
            self.write_record(record)?;
        }
        self.measurements.flush()?;
        Ok(RecordingTotals {
            frames: self.frames,
            truncated_frames: self.truncated,
            bytes: self.bytes,
        })
    }

    /// Ticks between two future instants.
    fn future_ticks(&self) -> u64 {
        (FUTURE_STEP / DT).round() as u64
    }

    /// The executed control: the label, pushed off now and then by noise. A perturbation that
    /// presses on ends while the expert holds for a light (`holds_for_light`): a foot does not
    /// slip off the brake at a red light, and a car pushed past a head at the kerb before its
    /// stop line stands there blind, its camera no longer showing the lamp; such waits taught
    /// a learner that standing by a head means red (24 of 27 blind waits at red in 720
    /// episodes of kerb-light towns followed a push).
    fn perturb(&mut self, label: Control, holds_for_light: bool) -> (Control, bool) {
        if self.perturbation.is_none()
            && self.noise.rate > 0.0
            && self.rng.random_bool((self.noise.rate * DT).clamp(0.0, 1.0))
        {
            let [d0, d1] = self.noise.duration;
            let [s0, s1] = self.noise.steer;
            let ticks = (self.rng.random_range(d0..=d1.max(d0)) / DT).round() as u64;
            let sign = if self.rng.random_bool(0.5) { 1.0 } else { -1.0 };
            let kind = if self
                .rng
                .random_bool(self.noise.longitudinal.clamp(0.0, 1.0))
            {
                // Half coast with a light brake (the car falls behind its plan), half press on
                // (it runs ahead of it).
                if sign > 0.0 {
                    Perturbation::Pedals {
                        throttle: 0.0,
                        brake: self.rng.random_range(0.1..=0.3),
                    }
                } else {
                    Perturbation::Pedals {
                        throttle: self.rng.random_range(0.4..=0.7),
                        brake: 0.0,
                    }
                }
            } else {
                Perturbation::Steer(sign * self.rng.random_range(s0..=s1.max(s0)))
            };
            self.perturbation = Some((ticks.max(1), kind));
        }
        if holds_for_light
            && let Some((_, Perturbation::Pedals { throttle, .. })) = self.perturbation
            && throttle > 0.0
        {
            self.perturbation = None;
        }
        match self.perturbation {
            Some((left, kind)) => {
                self.perturbation = (left > 1).then_some((left - 1, kind));
                let executed = match kind {
                    Perturbation::Steer(offset) => Control {
                        steer: (f64::from(label.steer) + offset).clamp(-1.0, 1.0) as f32,
                        ..label
                    },
                    Perturbation::Pedals { throttle, brake } => Control {
                        throttle: throttle as f32,
                        brake: brake as f32,
                        ..label
                    },
                };
                (executed, true)
            }
            None => (label, false),
        }
    }

    fn store_frames(&mut self, obs: &Observation) -> std::io::Result<Vec<String>> {
        let mut images = Vec::with_capacity(obs.frames.len());
        for frame in &obs.frames {
            let rel = format!("{}/{:06}.png", frame.camera, self.frames);
            let png =
                encode_png(frame.width, frame.height, &frame.rgb).map_err(std::io::Error::other)?;
            std::fs::write(self.dir.join(&rel), &png)?;
            self.bytes += png.len() as u64;
            images.push(rel);
        }
        Ok(images)
    }

    fn write_record(&mut self, mut record: FrameRecord) -> std::io::Result<()> {
        let step = self.future_ticks();
        let start = record.tick as usize;
        let origin = self.history[start];
        record.waypoints.clear();
        record.future_controls.clear();
        for k in 1..=FUTURE_COUNT as u64 {
            let Some(future) = self.history.get(start + (k * step) as usize) else {
                break;
            };
            let local = to_ego_frame(
                future.position.extend(0.0),
                origin.position.extend(0.0),
                origin.yaw,
            );
            record.waypoints.push([local.x, local.y]);
            record.future_controls.push(future.label);
        }
        record.future_complete = record.waypoints.len() == FUTURE_COUNT;
        if !record.future_complete {
            self.truncated += 1;
        }
        let line = serde_json::to_string(&record).map_err(std::io::Error::other)?;
        self.measurements.write_all(line.as_bytes())?;
        self.measurements.write_all(b"\n")?;
        self.bytes += line.len() as u64 + 1;
        Ok(())
    }

    fn record_tick(
        &mut self,
        obs: &Observation,
        world: &World<'_>,
        label: Control,
        executed: Control,
        noise: bool,
    ) -> std::io::Result<()> {
        if !obs.frames.is_empty() && obs.frame.is_multiple_of(self.ticks_per_frame) {
            let images = self.store_frames(obs)?;
            self.pending.push_back(FrameRecord {
                index: self.frames,
                tick: obs.frame,
                time: obs.time,
                speed: obs.speed,
                position: obs.position.to_array(),
                yaw: obs.yaw,
                command: obs.command.value(),
                target_point: obs.target_point.to_array(),
                control: label,
                executed,
                noise,
                brake_reason: self.expert.brake_reason(),
                waypoints: Vec::new(),
                plan: self
                    .expert
                    .planned_trajectory()
                    .iter()
                    .map(|w| w.to_array())
                    .collect(),
                future_controls: Vec::new(),
                future_complete: false,
                images,
                actors: Some(actors_near(obs, world)),
                light: Some(self.expert.light_ahead()),
                light_in_view: self
                    .expert
                    .light_ahead_id()
                    .map(|id| head_in_view(&self.rig, world.map.lights[id].head, obs)),
            });
            self.frames += 1;
        }
        let horizon = self.future_ticks() * FUTURE_COUNT as u64;
        while self
            .pending
            .front()
            .is_some_and(|r| r.tick + horizon < self.history.len() as u64)
        {
            let record = self.pending.pop_front().expect("checked");
            self.write_record(record)?;
        }
        Ok(())
    }
}

/// Whether a light's head (world frame) projects into a frame of `rig` from the ego's pose.
fn head_in_view(rig: &Rig, head: DVec3, obs: &Observation) -> bool {
    let head = to_ego_frame(head, obs.position, obs.yaw).as_vec3();
    rig.sees(head.to_array())
}

/// The actors whose centre is within [`ACTOR_RANGE`] of the ego, in its frame.
fn actors_near(obs: &Observation, world: &World<'_>) -> Vec<ActorRecord> {
    world
        .actors()
        .iter()
        .filter(|a| a.obb.centre.distance(obs.position.truncate()) <= ACTOR_RANGE)
        .map(|a| {
            let centre = to_ego_frame(a.obb.centre.extend(0.0), obs.position, obs.yaw);
            ActorRecord {
                class: match a.kind {
                    ActorKind::Vehicle => ActorClass::Vehicle,
                    ActorKind::Cyclist => ActorClass::Cyclist,
                    ActorKind::Walker => ActorClass::Walker,
                    ActorKind::Static | ActorKind::Debris => ActorClass::Static,
                },
                centre: [centre.x, centre.y],
                yaw: angle_diff(a.obb.yaw, obs.yaw),
                half: a.obb.half.to_array(),
            }
        })
        .collect()
}

impl Agent for EpisodeRecorder<'_> {
    fn name(&self) -> String {
        match &self.driver {
            Some(driver) => format!("{} (labelled by the expert, recording)", driver.name()),
            None => "expert (recording)".into(),
        }
    }

    fn start_route(&mut self, ctx: &RouteContext<'_>) -> Result<(), AgentError> {
        if !self.history.is_empty() && self.error.is_none() {
            self.error = Some(std::io::Error::other(
                "an episode recorder records one route run; this one was started twice",
            ));
        }
        if let Some(driver) = self.driver.as_deref_mut() {
            driver.start_route(ctx)?;
        }
        self.expert.start_route(ctx)
    }

    fn end_route(&mut self) {
        if let Some(driver) = self.driver.as_deref_mut() {
            driver.end_route();
        }
    }

    fn sensors(&self) -> Option<Rig> {
        Some(self.rig.clone())
    }

    fn wants_frames(&self, frame: u64) -> bool {
        // A driver sees every tick; only every ticks_per_frame-th is stored.
        self.driver.is_some() || frame.is_multiple_of(self.ticks_per_frame)
    }

    fn run_step(&mut self, obs: &Observation, world: &World<'_>) -> Result<Control, AgentError> {
        let label = self.expert.run_step(obs, world)?;
        if self.history.len() as u64 != obs.frame && self.error.is_none() {
            self.error = Some(std::io::Error::other(format!(
                "tick {} arrived after {} ticks: recording needs every tick from 0",
                obs.frame,
                self.history.len()
            )));
        }
        self.history.push(TickState {
            position: obs.position.truncate(),
            yaw: obs.yaw,
            label,
        });
        let (executed, noise) = match self.driver.as_deref_mut() {
            Some(driver) => (driver.run_step(obs, world)?, false),
            None => {
                let holds_for_light = self.expert.brake_reason() == Some(BrakeReason::TrafficLight);
                self.perturb(label, holds_for_light)
            }
        };
        if self.error.is_none()
            && let Err(e) = self.record_tick(obs, world, label, executed, noise)
        {
            self.error = Some(e);
        }
        Ok(executed)
    }
}
