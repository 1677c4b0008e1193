//! Training samples from a collected expert dataset (`sim-bridge collect`).
//!
//! A sample is one stored frame t with everything SSR trains on: the frame itself, the frame
//! [`HISTORY_S`] before it (its BEV, encoded with the frame before that as its own history, is
//! the temporal history: the contract serving keeps, see [`HISTORY_S`]), the frame
//! [`FUTURE_BEV_S`] later (its BEV is the FFP's target) and the expert's labels (waypoints,
//! control now and at each future step, speed). Waypoint labels are the expert's plan from the
//! frame's state ([`Labels::Plan`]) or the positions it went on to drive ([`Labels::Driven`]).
//! Measurements of every episode are read once into an index, with each sample's sampling
//! weight; images are read from disk batch by batch. Frames whose label follows a lamp no camera
//! shows are left out ([`blind_to_its_light`]).
//!
//! Episodes are split into training and validation by a hash of their route (town, route set,
//! route id), so every repetition of a route lands on the same side and validation routes are
//! never trained on.
//!
//! Guarantees: a missing or malformed manifest, measurement file or image is a
//! [`DatasetError`] naming the file; a dataset whose rate, rig or futures cannot feed the
//! network is refused with the reason before training starts.

use std::path::Path;

use burn::tensor::{Device, Tensor};
use ssrdrive_proto::camera::Rig;
use ssrdrive_proto::command::{COMMANDS, RoadOption};
use ssrdrive_proto::control::Control;
use ssrdrive_proto::dataset::{
    ActorRecord, BrakeReason, Dataset, DatasetError, FUTURE_STEP, FrameRecord, LightAhead, fnv1a,
};

use super::augment::Photometric;
use super::loss::{BetaTargets, ImitationTargets};
use super::occupancy::{actors_in_frame_of, point_in_frame_of};
use crate::history::History;
use crate::model::backbone::frame_to_input;
use crate::model::bev::{GeometryTensors, HISTORY_S, SampleGeometry};
use crate::model::config::SsrConfig;
use crate::model::hazard::Hazard;
use crate::model::{ModelInput, Navigation, float_tensor};
use crate::pose::{EgoMotion, Pose2};

/// Seconds from a frame to the future frame whose BEV the FFP predicts (SSR's code: 1.5 s) and
/// whose actors label the motion head.
pub const FUTURE_BEV_S: f64 = crate::model::occupancy::MOTION_HORIZON_S;

/// The farthest a sample's later target point is taken from ([`SampleDraw::later_target`]),
/// seconds: the route follower's target of a frame up to this much later.
pub const LATER_TARGET_S: f64 = 3.0;

/// How one sample of a batch is varied: its photometric jitter, whether it trains the
/// first-frame path (history and ego motion dropped, as on an episode's first tick), and
/// whether it is shown a later frame's target point.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct SampleDraw {
    /// The jitter applied to every frame of the sample; `None` leaves the frames as recorded.
    pub photometric: Option<Photometric>,
    /// Train the first-frame path: no history BEV and no ego motion.
    pub drop_history: bool,
    /// Show the sample the target point the route follower gave this share (0 to 1] of
    /// [`LATER_TARGET_S`] later (at least a frame), in the sample's own ego frame; the labels
    /// stay. Often the same plan node; past one, the next: beyond the next bend, across ground
    /// the labels do not cross. Against the shortcut of driving the straight line to the
    /// target: at a U-turn loop's mouth (Town03) the bundled network drove across the grass to
    /// the node at the loop's far end. A sample too near its episode's end keeps its own.
    pub later_target: Option<f64>,
}

/// Where the waypoint labels come from.
#[derive(
    Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize, clap::ValueEnum,
)]
#[serde(rename_all = "kebab-case")]
pub enum Labels {
    /// The expert's plan from the frame's state (on the route's centre line at the expert's
    /// speed profile): clean inside perturbations, where driven positions follow the drift.
    Plan,
    /// The positions the car went on to drive (the first bundled checkpoint's labels).
    Driven,
}

impl Labels {
    /// The labels of a training config that names none: it was written before plans were
    /// labels (`TrainConfig::new` and the command line choose [`Labels::Plan`]).
    pub fn of_configs_before_plans() -> Self {
        Labels::Driven
    }
}

/// One sample: a frame of an episode (indices into [`TrainingData`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SampleRef {
    /// Index of the episode in the training data.
    pub episode: u32,
    /// Index of the frame in the episode.
    pub frame: u32,
}

struct Episode {
    name: String,
    frames: Vec<FrameRecord>,
}

/// The dataset's index, split into training and validation samples.
pub struct TrainingData {
    dataset: Dataset,
    episodes: Vec<Episode>,
    history_offset: usize,
    future_offset: usize,
    /// Frames in [`LATER_TARGET_S`].
    later_target_frames: usize,
    pred_len: usize,
    labels: Labels,
    /// Samples of the training routes.
    pub train: Vec<SampleRef>,
    /// Each training sample's sampling weight ([`sampling_weight`]), in `train`'s order.
    pub train_weights: Vec<f32>,
    /// Samples of the held-out routes.
    pub validation: Vec<SampleRef>,
    /// Routes (town/set/id) on the training side.
    pub train_routes: usize,
    /// Routes (town/set/id) on the validation side.
    pub validation_routes: usize,
}

/// Whether a route belongs to the validation side for the given fraction.
fn is_validation(town: &str, route_set: &str, route_id: &str, fraction: f64) -> bool {
    let key = format!("{town}/{route_set}/{route_id}");
    (fnv1a(key.as_bytes()) % 10_000) as f64 / 10_000.0 < fraction
}

/// The manifest's timing, horizon and rig fit the network: (frames back to the history, frames
/// ahead to the FFP target).
fn check_manifest(
    dataset: &Dataset,
    root: &Path,
    config: &SsrConfig,
) -> Result<(usize, usize), DatasetError> {
    let m = &dataset.manifest;
    let refuse = |problem: String| Err(DatasetError::invalid(&root.join("manifest.json"), problem));
    if (m.future_step_s - FUTURE_STEP).abs() > 1e-9 {
        return refuse(format!(
            "future_step_s = {} but the head plans every {FUTURE_STEP} s",
            m.future_step_s
        ));
    }
    let pred_len = config.head.pred_len;
    if m.future_count < pred_len {
        return refuse(format!(
            "{} future waypoints per frame, the model plans {pred_len}",
            m.future_count
        ));
    }
    let frames_in = |seconds: f64| (seconds * m.rate_hz).round() as usize;
    let (history_offset, future_offset) = (frames_in(HISTORY_S), frames_in(FUTURE_BEV_S));
    if !(m.rate_hz.is_finite() && history_offset >= 1 && future_offset >= 1) {
        return refuse(format!(
            "rate_hz = {} gives no frame {HISTORY_S} s back (the history) or \
             {FUTURE_BEV_S} s ahead (the FFP target)",
            m.rate_hz
        ));
    }
    if let Err(e) = m.rig.validate() {
        return refuse(format!("its camera rig is unusable: {e}"));
    }
    let (width, height) = (config.image_width, config.image_height);
    if let Some(small) = m
        .rig
        .cameras
        .iter()
        .find(|c| (c.width as usize) < width || (c.height as usize) < height)
    {
        return refuse(format!(
            "camera {} records {}x{} frames, smaller than the network's {width}x{height} input: \
             it would train on enlarged frames; record the data at the input size \
             (`sim-bridge collect --rig`)",
            small.id, small.width, small.height
        ));
    }
    Ok((history_offset, future_offset))
}

/// An episode's frames hold an image per camera and, to train on plans, the expert's plan.
fn check_frames(
    dataset: &Dataset,
    episode: &str,
    frames: &[FrameRecord],
    labels: Labels,
    pred_len: usize,
) -> Result<(), DatasetError> {
    let refuse = |problem: String| {
        Err(DatasetError::invalid(
            &dataset.episode_dir(episode).join("measurements.jsonl"),
            problem,
        ))
    };
    let cameras = dataset.manifest.rig.cameras.len();
    if let Some(bad) = frames.iter().find(|f| f.images.len() != cameras) {
        return refuse(format!(
            "frame {} lists {} images, the rig has {cameras} cameras",
            bad.index,
            bad.images.len()
        ));
    }
    if labels == Labels::Plan && frames.iter().any(|f| f.plan.len() < pred_len) {
        return refuse(format!(
            "frames without the expert's {pred_len}-step plan (recorded before plans were \
             stored?): collect the data again, or train with --labels driven"
        ));
    }
    Ok(())
}

impl TrainingData {
    /// Opens the dataset at `root` and indexes the samples `config` can train on.
    /// `progress` is called after each episode's measurements are read.
    pub fn open(
        root: &Path,
        config: &SsrConfig,
        labels: Labels,
        validation_fraction: f64,
        mut progress: impl FnMut(usize, usize),
    ) -> Result<Self, DatasetError> {
        let dataset = Dataset::open(root)?;
        let (history_offset, future_offset) = check_manifest(&dataset, root, config)?;
        let m = &dataset.manifest;
        let later_target_frames = ((LATER_TARGET_S * m.rate_hz).round() as usize).max(1);
        let pred_len = config.head.pred_len;
        let total = m.episode_list.len();
        let mut episodes = Vec::with_capacity(total);
        let (mut train, mut validation) = (Vec::new(), Vec::new());
        let mut train_weights = Vec::new();
        let mut routes = (
            std::collections::BTreeSet::new(),
            std::collections::BTreeSet::new(),
        );
        for (index, entry) in m.episode_list.iter().enumerate() {
            let frames = dataset.frames(&entry.name)?;
            check_frames(&dataset, &entry.name, &frames, labels, pred_len)?;
            let held_out = is_validation(
                &entry.town,
                &entry.route_set,
                &entry.route_id,
                validation_fraction,
            );
            let (side, side_routes) = if held_out {
                (&mut validation, &mut routes.1)
            } else {
                (&mut train, &mut routes.0)
            };
            side_routes.insert((&entry.town, &entry.route_set, &entry.route_id));
            let learner_drove = dataset.episode(&entry.name)?.driver.is_some();
            let usable = frames.iter().filter(|f| {
                f.future_complete
                    && f.waypoints.len() >= pred_len
                    && f.future_controls.len() >= pred_len
                    && f.index + future_offset < frames.len()
                    && !blind_to_its_light(f)
            });
            for f in usable {
                if !held_out {
                    train_weights.push(sampling_weight(f, learner_drove));
                }
                side.push(SampleRef {
                    episode: index as u32,
                    frame: f.index as u32,
                });
            }
            episodes.push(Episode {
                name: entry.name.clone(),
                frames,
            });
            progress(index + 1, total);
        }
        if train.is_empty() {
            return Err(DatasetError::invalid(
                &root.join("manifest.json"),
                format!(
                    "no training samples: {total} episodes, {} validation samples, none with a \
                 complete {pred_len}-step future outside the validation routes",
                    validation.len()
                ),
            ));
        }
        let (train_routes, validation_routes) = (routes.0.len(), routes.1.len());
        Ok(Self {
            dataset,
            episodes,
            history_offset,
            future_offset,
            later_target_frames,
            pred_len,
            labels,
            train,
            train_weights,
            validation,
            train_routes,
            validation_routes,
        })
    }

    /// The camera rig every frame was taken with.
    pub fn rig(&self) -> &Rig {
        &self.dataset.manifest.rig
    }

    /// The manifest: towns, routes and counts, for the model card.
    pub fn manifest(&self) -> &ssrdrive_proto::dataset::Manifest {
        &self.dataset.manifest
    }

    fn record(&self, sample: SampleRef, offset: isize) -> Option<&FrameRecord> {
        let frames = &self.episodes[sample.episode as usize].frames;
        let index = sample.frame as isize + offset;
        usize::try_from(index).ok().and_then(|i| frames.get(i))
    }

    /// The network inputs of one frame: images at the config's size, augmented if asked.
    fn images(
        &self,
        sample: SampleRef,
        record: &FrameRecord,
        config: &SsrConfig,
        augment: Option<&Photometric>,
        out: &mut Vec<f32>,
    ) -> Result<(), DatasetError> {
        let name = &self.episodes[sample.episode as usize].name;
        for mut image in self.dataset.images(name, record)? {
            if let Some(augment) = augment {
                augment.apply(&mut image.rgb);
            }
            out.extend(frame_to_input(
                &image.rgb,
                image.width as usize,
                image.height as usize,
                config.image_width,
                config.image_height,
            ));
        }
        Ok(())
    }

    /// Reads and prepares a batch. `draw` gives each sample's variation: its photometric jitter
    /// (the same for its history, current and future frames, so they still show one scene) and
    /// whether its history is dropped. The frame 1 s back (the deep frame) is read only for
    /// [`History::Chain`].
    pub fn batch(
        &self,
        samples: &[SampleRef],
        config: &SsrConfig,
        history_mode: History,
        mut draw: impl FnMut(usize) -> SampleDraw,
    ) -> Result<Batch, DatasetError> {
        let rig = self.rig();
        let grid = &config.bev.grid;
        let heights = &config.bev.pillar_heights;
        let p = self.pred_len;
        let mut batch = Batch {
            size: samples.len(),
            cameras: rig.cameras.len(),
            ..Batch::default()
        };
        // Context order is [history of every sample..., future of every sample...].
        let mut future_images = Vec::new();
        let mut future_geometry = Vec::with_capacity(samples.len());
        for (i, &sample) in samples.iter().enumerate() {
            let now = self.record(sample, 0).expect("sample refs index frames");
            let future = self
                .record(sample, self.future_offset as isize)
                .expect("samples have their future frame");
            let SampleDraw {
                photometric,
                drop_history,
                later_target,
            } = draw(i);
            let back = self.history_offset as isize;
            let history = (!drop_history)
                .then(|| self.record(sample, -back))
                .flatten();
            let deep = history
                .filter(|_| history_mode == History::Chain)
                .and_then(|_| self.record(sample, -2 * back));
            let jitter = photometric.as_ref();
            let blank = batch.cameras * 3 * config.image_height * config.image_width;
            self.images(sample, now, config, jitter, &mut batch.current_images)?;
            self.images(sample, future, config, jitter, &mut future_images)?;
            for (frame, out) in [
                (history, &mut batch.context_images),
                (deep, &mut batch.deep_images),
            ] {
                match frame {
                    Some(r) => self.images(sample, r, config, jitter, out)?,
                    None => out.extend(std::iter::repeat_n(0.0, blank)),
                }
            }
            let pose = |r: &FrameRecord| {
                Pose2::new(r.position[0] as f32, r.position[1] as f32, r.yaw as f32)
            };
            let geometry = |r: &FrameRecord, before: Option<&FrameRecord>| {
                let motion = before.map(|b| EgoMotion::between(pose(b), pose(r)));
                let speed = config.shown_speed(r.speed as f32);
                SampleGeometry::new(grid, heights, rig, motion, speed)
            };
            batch.current_geometry.push(geometry(now, history));
            batch
                .context_geometry
                .push(geometry(history.unwrap_or(now), deep));
            batch
                .deep_geometry
                .push(geometry(deep.unwrap_or(now), None));
            future_geometry.push(geometry(future, None));
            batch.speed.push(now.speed as f32);
            batch
                .shown_speed
                .push(config.shown_speed(now.speed as f32).unwrap_or(0.0));
            let later = later_target.and_then(|share| {
                let frames = (share * self.later_target_frames as f64).ceil().max(1.0);
                self.record(sample, frames as isize)
            });
            let target = match later {
                Some(later) => point_in_frame_of(
                    later.target_point,
                    later.position,
                    later.yaw,
                    now.position,
                    now.yaw,
                ),
                None => now.target_point,
            };
            batch.target_point.extend(target.map(|v| v as f32));
            let command = RoadOption::from_value(now.command).unwrap_or(RoadOption::LaneFollow);
            batch.command.extend(command.one_hot());
            let labels = match self.labels {
                Labels::Plan => &now.plan,
                Labels::Driven => &now.waypoints,
            };
            for waypoint in &labels[..p] {
                batch.waypoints.extend(waypoint.map(|v| v as f32));
            }
            for control in std::iter::once(&now.control).chain(&now.future_controls[..p]) {
                batch.actions.extend(action_of(control));
            }
            batch.expert.push(now.control);
            batch.brake_reasons.push(now.brake_reason);
            batch.actors.push(now.actors.clone());
            batch.lights.push(now.light);
            batch
                .future_actors
                .push(future.actors.as_ref().map(|actors| {
                    actors_in_frame_of(actors, future.position, future.yaw, now.position, now.yaw)
                }));
        }
        batch.context_images.append(&mut future_images);
        batch.context_geometry.append(&mut future_geometry);
        Ok(batch)
    }
}

/// How much more often a frame from an episode the learner drove (DAgger: the states the
/// learner reaches, labelled by the expert) is drawn than the same frame from an expert episode.
/// A round adds a few thousand frames to half a million; drawn at par they would hardly count.
pub const LEARNER_DROVE_WEIGHT: f32 = 3.0;

/// How much more often a frame where the expert brakes for a stop sign it has not yet stopped
/// at is drawn: about 0.7 % of the expert's frames, and an agent trained without it ran 7 stop
/// signs in 60 Town05-style short runs.
pub const STOP_SIGN_WEIGHT: f32 = 3.0;

/// How much more often a frame where the expert brakes for a walker on its path is drawn: 0.26 %
/// of the expert's frames, and a learner trained without it crept on at the expert's walking
/// pace into walkers crossing its lane in 5 of 30 home long runs.
pub const WALKER_BRAKE_WEIGHT: f32 = 4.0;

/// Whether a frame is left out of training and validation because its label follows a lamp no
/// camera shows: the expert brakes or holds for the light ahead while its head is out of the
/// cameras' view ([`FrameRecord::light_in_view`] false), whoever drove.
///
/// Such frames taught "standing by a kerb-side head means red": in 720 episodes of kerb-light
/// towns the expert stood blind at red for 762 frames against 3 going at green (most of those
/// waits followed collection's noise pushing it past its stopping point, which `sim-bridge
/// collect` no longer does). Leaving them out does not stop a learner braking as a green
/// kerb-side lamp leaves its frame on Town02: networks trained without them, one with its
/// planner drawn fresh, still do (models/candidates/README.md, v24 and v25), since the scene
/// the front camera shows there reads as a yield. The other frames with the lamp out of view
/// stay, a learner's included: going on past a head at green, and waiting for a car the camera
/// shows, are labels the camera supports.
pub fn blind_to_its_light(frame: &FrameRecord) -> bool {
    frame.light_in_view == Some(false) && frame.brake_reason == Some(BrakeReason::TrafficLight)
}

/// How often a training frame is drawn relative to an ordinary one: standing still (and staying
/// still) is a fifth of the data and teaches little, so it is drawn a third as often, except
/// waiting at a red light, the frames that pair with the starts at green to teach the lamp;
/// starting from standstill, slowing down for a light, a sign or a road user, turns, lane
/// changes and perturbed frames (recoveries) are rare and decide closed-loop driving, so they
/// are drawn more often, stop signs and walkers most ([`STOP_SIGN_WEIGHT`],
/// [`WALKER_BRAKE_WEIGHT`]), and so are the frames of episodes the learner drove
/// ([`LEARNER_DROVE_WEIGHT`]).
pub fn sampling_weight(frame: &FrameRecord, learner_drove: bool) -> f32 {
    let still = frame.speed < 0.1;
    let starting = frame.speed < 1.0 && frame.control.throttle > 0.1;
    let slowing = !still && frame.control.brake > 0.0;
    let at_light = frame.brake_reason == Some(BrakeReason::TrafficLight);
    let mut weight: f32 = if starting {
        3.0
    } else if slowing {
        2.0
    } else if still && !at_light {
        0.3
    } else {
        1.0
    };
    weight *= match RoadOption::from_value(frame.command) {
        Some(RoadOption::Left | RoadOption::Right) => 2.0,
        Some(option) if option.is_lane_change() => 4.0,
        _ => 1.0,
    };
    if frame.noise {
        weight *= 1.5;
    }
    weight *= match frame.brake_reason {
        Some(BrakeReason::StopSign) => STOP_SIGN_WEIGHT,
        Some(BrakeReason::Walker) => WALKER_BRAKE_WEIGHT,
        _ => 1.0,
    };
    if learner_drove {
        weight *= LEARNER_DROVE_WEIGHT;
    }
    weight
}

/// TCP's action of a control: [acceleration (throttle, or minus the brake), steer].
pub fn action_of(control: &Control) -> [f32; 2] {
    let acceleration = if control.brake > 0.0 {
        -control.brake
    } else {
        control.throttle
    };
    [acceleration, control.steer]
}

/// A prepared batch on the CPU.
#[derive(Debug, Default)]
pub struct Batch {
    /// Samples in the batch (B).
    pub size: usize,
    /// Cameras per sample.
    pub cameras: usize,
    /// `[B * cameras, 3, H, W]` the current frames.
    current_images: Vec<f32>,
    /// `[2B * cameras, 3, H, W]` history frames (zeros where none) then future frames.
    context_images: Vec<f32>,
    /// `[B * cameras, 3, H, W]` the history frames' own history frames (zeros where none).
    deep_images: Vec<f32>,
    current_geometry: Vec<SampleGeometry>,
    context_geometry: Vec<SampleGeometry>,
    deep_geometry: Vec<SampleGeometry>,
    /// The speed label, m/s.
    speed: Vec<f32>,
    /// The speed the network is shown (0 without ego status).
    shown_speed: Vec<f32>,
    target_point: Vec<f32>,
    command: Vec<f32>,
    /// `[B, P, 2]` expert waypoints, ego frame.
    pub waypoints: Vec<f32>,
    /// `[B, P + 1, 2]` expert actions now and at each future step.
    pub actions: Vec<f32>,
    /// The expert's control now.
    pub expert: Vec<Control>,
    /// Why the expert brakes now, if it does.
    brake_reasons: Vec<Option<BrakeReason>>,
    /// The actors around the ego now (`None`: the frame records none).
    actors: Vec<Option<Vec<ActorRecord>>>,
    /// The actors around the ego at the future frame, in the current frame's ego frame (`None`:
    /// that frame records none).
    future_actors: Vec<Option<Vec<ActorRecord>>>,
    /// The light ahead of each sample (`None`: the frame records none).
    lights: Vec<Option<LightAhead>>,
}

impl Batch {
    /// Each sample's command one-hot.
    pub fn commands(&self) -> Vec<&[f32]> {
        self.command.chunks(COMMANDS).collect()
    }

    /// Sample `i`'s speed label, m/s.
    pub fn speed_label(&self, i: usize) -> f32 {
        self.speed[i]
    }

    /// Why the expert brakes in sample `i`, if it does.
    pub fn brake_reason(&self, i: usize) -> Option<BrakeReason> {
        self.brake_reasons[i]
    }

    /// What the expert brakes for in each sample: the hazard head's labels.
    pub fn hazards(&self) -> Vec<Hazard> {
        self.brake_reasons.iter().map(|&r| Hazard::of(r)).collect()
    }

    /// The actors around the ego in each sample: the occupancy head's labels.
    pub fn actors(&self) -> &[Option<Vec<ActorRecord>>] {
        &self.actors
    }

    /// The light ahead of each sample: the light head's labels.
    pub fn lights(&self) -> &[Option<LightAhead>] {
        &self.lights
    }

    /// Where the actors are at each sample's future frame, in the sample's ego frame: the
    /// motion head's labels.
    pub fn future_actors(&self) -> &[Option<Vec<ActorRecord>>] {
        &self.future_actors
    }

    fn input(
        &self,
        config: &SsrConfig,
        images: &[f32],
        geometry: &[SampleGeometry],
        previous_bev: Tensor<3>,
        device: &Device,
    ) -> ModelInput {
        let b = geometry.len();
        let repeat = b / self.size;
        let repeated = |values: &[f32], width: usize| {
            let mut out = Vec::with_capacity(values.len() * repeat);
            for _ in 0..repeat {
                out.extend_from_slice(values);
            }
            float_tensor(out, [b, width], device)
        };
        ModelInput {
            images: float_tensor(
                images.to_vec(),
                [b * self.cameras, 3, config.image_height, config.image_width],
                device,
            ),
            cameras: self.cameras,
            geometry: GeometryTensors::batch(
                geometry,
                &config.bev.grid,
                config.bev.pillar_heights.len(),
                device,
            ),
            previous_bev,
            navigation: Navigation {
                speed: repeated(&self.shown_speed, 1),
                target_point: repeated(&self.target_point, 2),
                command: repeated(&self.command, COMMANDS),
            },
        }
    }

    /// The B history frames' own history frames, without a previous BEV: their BEVs are the
    /// history of the history frames.
    pub fn deep_input(&self, config: &SsrConfig, device: &Device) -> ModelInput {
        let zeros = Tensor::zeros(
            [self.size, config.bev.grid.cells(), config.channels],
            device,
        );
        self.input(
            config,
            &self.deep_images,
            &self.deep_geometry,
            zeros,
            device,
        )
    }

    /// The context frames: the B history frames attending to `deep_bev` `[B, Q, C]` (their
    /// BEVs are the current frames' history), then, with `futures`, the B future frames without
    /// history (the FFP's targets).
    pub fn context_input(
        &self,
        config: &SsrConfig,
        deep_bev: Tensor<3>,
        futures: bool,
        device: &Device,
    ) -> ModelInput {
        let count = if futures { 2 * self.size } else { self.size };
        let previous = if futures {
            let zeros = Tensor::zeros(
                [self.size, config.bev.grid.cells(), config.channels],
                device,
            );
            Tensor::cat(vec![deep_bev, zeros], 0)
        } else {
            deep_bev
        };
        let per_sample = self.context_images.len() / (2 * self.size);
        self.input(
            config,
            &self.context_images[..count * per_sample],
            &self.context_geometry[..count],
            previous,
            device,
        )
    }

    /// The current frames, attending to `previous_bev` `[B, Q, C]` where they have history.
    pub fn current_input(
        &self,
        config: &SsrConfig,
        previous_bev: Tensor<3>,
        device: &Device,
    ) -> ModelInput {
        self.input(
            config,
            &self.current_images,
            &self.current_geometry,
            previous_bev,
            device,
        )
    }

    /// The imitation labels as tensors.
    pub fn targets(
        &self,
        pred_len: usize,
        concentration: f32,
        device: &Device,
    ) -> ImitationTargets {
        ImitationTargets {
            waypoints: float_tensor(self.waypoints.clone(), [self.size, pred_len, 2], device),
            actions: BetaTargets::new(
                &self.actions,
                self.size,
                pred_len + 1,
                concentration,
                device,
            ),
            speed: float_tensor(self.speed.clone(), [self.size, 1], device),
        }
    }
}
