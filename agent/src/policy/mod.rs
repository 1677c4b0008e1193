//! The inference API: an [`SsrPolicy`] (network + controller settings on a device) steps
//! episodes, each with its own [`EpisodeState`] (its recent BEVs and poses, PID windows, fusion
//! history). A step plans from the history its network trained with: on [`History::Chain`]
//! (the default) its BEV attends to the BEV of the step [`HISTORY_TICKS`] before it (0.5 s at
//! 20 Hz), which attended to the first-frame BEV of the step [`HISTORY_TICKS`] before that, and
//! to nothing older; on [`History::Link`] it attends to the first-frame BEV of the step
//! [`HISTORY_TICKS`] before it; checkpoints validated before the chain are served as they were
//! ([`History::Recursive`]: each step's BEV is the history of the step 0.5 s later).
//! [`SsrPolicy::step_batch`] runs several episodes in one forward pass.
//!
//! Every input is checked before anything runs; a bad input returns a [`StepError`] naming the
//! episode and the field, and leaves every episode's state as it was. [`outputs`] reads a
//! group's forward pass back into per-episode views.

mod outputs;

use std::collections::VecDeque;

use burn::module::Module;
use burn::tensor::{Device, Tensor};
use ssrdrive_proto::camera::{Rig, RigError};
use ssrdrive_proto::command::{COMMANDS, RoadOption};
use ssrdrive_proto::image::RgbImage;

use crate::control::{Beliefs, ControlConfig, ControlDecision, EpisodeController, LightBelief};
use crate::history::History;
use crate::model::backbone::frame_to_input;
use crate::model::bev::{GeometryTensors, HISTORY_TICKS, ImageFeatures, SampleGeometry};
use crate::model::config::SsrConfig;
use crate::model::hazard::Hazard;
use crate::model::{Navigation, SsrModel, float_tensor};
use crate::pose::{EgoMotion, Pose2};
use outputs::{EpisodeOutputs, GroupOutputs, Needs, occupied_cells};

/// Largest target-point distance accepted, metres.
const MAX_TARGET_DISTANCE: f32 = 1000.0;
/// Largest speed accepted, m/s.
const MAX_SPEED: f32 = 100.0;
/// Largest world coordinate accepted, metres (a town is a few km across).
const MAX_POSITION: f32 = 1e7;
/// Largest |yaw| accepted, radians (any angle is wrapped; this only refuses nonsense).
const MAX_YAW: f32 = 1e3;

/// Everything the network needs at one tick of one episode.
#[derive(Debug, Clone)]
pub struct StepInput {
    /// One frame per rig camera, in rig order.
    pub frames: Vec<RgbImage>,
    /// The cameras the frames come from (checked against the frames).
    pub rig: Rig,
    /// Ego pose in the world frame; consecutive poses give the ego motion.
    pub pose: Pose2,
    /// m/s.
    pub speed: f32,
    /// The route's command (VOID is read as LANEFOLLOW).
    pub command: RoadOption,
    /// Ego frame (x forward, y left), metres.
    pub target_point: [f32; 2],
    /// Return token attention maps and both control sources.
    pub debug: bool,
}

/// What is wrong with one step input.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum InputError {
    /// The rig itself is invalid.
    #[error(transparent)]
    Rig(#[from] RigError),
    /// The number of frames is not the number of rig cameras.
    #[error("the rig has {expected} cameras but {got} frames came")]
    FrameCount {
        /// Cameras in the rig.
        expected: usize,
        /// Frames given.
        got: usize,
    },
    /// A frame's size is not its camera's.
    #[error("camera '{camera}': frame is {got_w}x{got_h} but the rig says {want_w}x{want_h}")]
    FrameSize {
        /// The camera's id.
        camera: String,
        /// Width the rig gives the camera, pixels.
        want_w: u32,
        /// Height the rig gives the camera, pixels.
        want_h: u32,
        /// Width of the frame, pixels.
        got_w: u32,
        /// Height of the frame, pixels.
        got_h: u32,
    },
    /// A frame's pixel buffer is not `w * h * 3` bytes long.
    #[error("camera '{camera}': a {w}x{h} RGB8 frame needs {want} bytes, got {got}")]
    FrameBytes {
        /// The camera's id.
        camera: String,
        /// Frame width, pixels.
        w: u32,
        /// Frame height, pixels.
        h: u32,
        /// Bytes the frame needs.
        want: usize,
        /// Bytes the frame has.
        got: usize,
    },
    /// Speed, target point or pose is not finite or out of its range.
    #[error("{field} = {value} is not a finite number in {low}..{high}")]
    BadNumber {
        /// The field, e.g. `speed` or `target_point.x`.
        field: &'static str,
        /// Its value.
        value: f32,
        /// The smallest value accepted.
        low: f32,
        /// The largest value accepted.
        high: f32,
    },
}

/// Why a (batched) step was refused before anything ran.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum StepError {
    /// A bad input, naming the episode (its index in the batch).
    #[error("episode {episode}: {source}")]
    Input {
        /// Index of the episode in the batch.
        episode: usize,
        /// What is wrong with its input.
        source: InputError,
    },
    /// The batch has a different number of episode states and inputs.
    #[error("step_batch got {episodes} episode states for {inputs} inputs")]
    BatchShape {
        /// Episode states given.
        episodes: usize,
        /// Inputs given.
        inputs: usize,
    },
}

/// The BEVs one step leaves for the step [`HISTORY_TICKS`] after it: the links of training's
/// history (`crate::train::data::Batch::deep_input`, `context_input`).
#[derive(Debug, Clone)]
struct ChainLinks {
    /// `[1, Q, C]` the step's BEV without history (training's "deep" BEV): the history of the
    /// later step's context BEV ([`History::Chain`]) or of the BEV it plans from
    /// ([`History::Link`]); not read for [`History::Recursive`] episodes.
    deep: Tensor<3>,
    /// `[1, Q, C]` the step's BEV attending to the deep BEV before it (training's "context"
    /// BEV; with [`History::Recursive`], the BEV the step planned from): the history the later
    /// step plans from (not read for [`History::Link`] episodes).
    context: Tensor<3>,
    /// The ego pose of the step.
    pose: Pose2,
}

/// What one episode remembers between ticks.
#[derive(Debug, Clone)]
pub struct EpisodeState {
    /// The chain links of the last [`HISTORY_TICKS`] steps, oldest first: the oldest is the
    /// history of the next step once the queue is full.
    recent: VecDeque<ChainLinks>,
    /// How the network gets its history in this episode.
    history: History,
    controller: EpisodeController,
    ticks: u64,
}

impl EpisodeState {
    /// Ticks stepped so far.
    pub fn ticks(&self) -> u64 {
        self.ticks
    }

    /// Whether the next step has a history BEV (from [`HISTORY_TICKS`] steps before it) to
    /// attend to; the first steps of an episode have none.
    pub fn has_previous_bev(&self) -> bool {
        self.previous_links().is_some()
    }

    fn previous_links(&self) -> Option<&ChainLinks> {
        self.recent
            .front()
            .filter(|_| self.recent.len() == HISTORY_TICKS)
    }

    /// Keeps a step's links (dropping the oldest once [`HISTORY_TICKS`] are kept) and counts
    /// the step.
    fn remember(&mut self, links: ChainLinks) {
        if self.recent.len() == HISTORY_TICKS {
            self.recent.pop_front();
        }
        self.recent.push_back(links);
        self.ticks += 1;
    }
}

/// Debug outputs of one step.
#[derive(Debug, Clone, PartialEq)]
pub struct StepDebug {
    /// `[tokens][rows * cols]` TokenLearner attention over the BEV (each row sums to 1); empty
    /// for a network without STL.
    pub token_attention: Vec<Vec<f32>>,
    /// Rows of the BEV grid (for reshaping `token_attention`).
    pub bev_rows: usize,
    /// Columns of the BEV grid.
    pub bev_cols: usize,
    /// Control branch Beta alpha parameters for [acceleration, steer].
    pub alpha: [f32; 2],
    /// Control branch Beta beta parameters for [acceleration, steer].
    pub beta: [f32; 2],
    /// The speed head's prediction, m/s.
    pub predicted_speed: f32,
    /// `[channels][rows * cols]` the occupancy head's probabilities (vehicle, walker; see
    /// `OCCUPANCY_CHANNELS`); empty for a network without the head.
    pub occupancy: Vec<Vec<f32>>,
    /// The hazard head's probability of each class, in [`Hazard::ALL`]'s order; `None` for
    /// a network without the head.
    pub hazard: Option<[f32; Hazard::ALL.len()]>,
    /// The light head's belief; `None` for a network without the head.
    pub light: Option<LightBelief>,
}

/// What one step returns.
#[derive(Debug, Clone, PartialEq)]
pub struct StepOutput {
    /// The control the vehicle gets, with both sources and the fusion status.
    pub decision: ControlDecision,
    /// Time spent in this episode's PID and fusion (the rest of a step is the shared forward
    /// pass).
    pub control_time: std::time::Duration,
    /// Planned waypoints, ego frame, 0.5 s apart.
    pub waypoints: Vec<[f32; 2]>,
    /// Debug outputs, when the input asked for them.
    pub debug: Option<StepDebug>,
}

/// The network on a device with the controller settings.
#[derive(Debug, Clone)]
pub struct SsrPolicy {
    model: SsrModel,
    config: SsrConfig,
    control: ControlConfig,
    history: History,
    device: Device,
}

fn check_input(input: &StepInput) -> Result<(), InputError> {
    input.rig.validate()?;
    if input.frames.len() != input.rig.cameras.len() {
        return Err(InputError::FrameCount {
            expected: input.rig.cameras.len(),
            got: input.frames.len(),
        });
    }
    for (frame, camera) in input.frames.iter().zip(&input.rig.cameras) {
        if (frame.width, frame.height) != (camera.width, camera.height) {
            return Err(InputError::FrameSize {
                camera: camera.id.clone(),
                want_w: camera.width,
                want_h: camera.height,
                got_w: frame.width,
                got_h: frame.height,
            });
        }
        let want = frame.width as usize * frame.height as usize * 3;
        if frame.rgb.len() != want {
            return Err(InputError::FrameBytes {
                camera: camera.id.clone(),
                w: frame.width,
                h: frame.height,
                want,
                got: frame.rgb.len(),
            });
        }
    }
    let numbers = [
        // The forward speed: TCP's speed input was never negative.
        ("speed", input.speed, 0.0, MAX_SPEED),
        (
            "target_point.x",
            input.target_point[0],
            -MAX_TARGET_DISTANCE,
            MAX_TARGET_DISTANCE,
        ),
        (
            "target_point.y",
            input.target_point[1],
            -MAX_TARGET_DISTANCE,
            MAX_TARGET_DISTANCE,
        ),
        ("pose.x", input.pose.x, -MAX_POSITION, MAX_POSITION),
        ("pose.y", input.pose.y, -MAX_POSITION, MAX_POSITION),
        ("pose.yaw", input.pose.yaw, -MAX_YAW, MAX_YAW),
    ];
    for (field, value, low, high) in numbers {
        if !(low..=high).contains(&value) {
            return Err(InputError::BadNumber {
                field,
                value,
                low,
                high,
            });
        }
    }
    Ok(())
}

impl SsrPolicy {
    /// Wraps a network for inference (batch norm in evaluation mode, no autodiff), fed its
    /// history as [`History::Chain`] (see [`SsrPolicy::with_history`]).
    pub fn new(model: SsrModel, config: SsrConfig, control: ControlConfig, device: Device) -> Self {
        Self {
            model: model.valid(),
            config,
            control,
            history: History::default(),
            device,
        }
    }

    /// The same policy feeding its network the history as `history` (a checkpoint's mode,
    /// [`crate::checkpoint::history`]).
    pub fn with_history(self, history: History) -> Self {
        Self { history, ..self }
    }

    /// The network's model config.
    pub fn config(&self) -> &SsrConfig {
        &self.config
    }

    /// The controller settings new episodes get.
    pub fn control(&self) -> &ControlConfig {
        &self.control
    }

    /// A fresh episode: no previous BEV, empty controller windows.
    pub fn new_episode(&self) -> EpisodeState {
        self.new_episode_with(self.control.clone())
    }

    /// A fresh episode with its own controller settings (e.g. another fusion alpha).
    pub fn new_episode_with(&self, control: ControlConfig) -> EpisodeState {
        EpisodeState {
            recent: VecDeque::with_capacity(HISTORY_TICKS),
            history: self.history,
            controller: EpisodeController::new(control),
            ticks: 0,
        }
    }

    /// A fresh episode fed its history as `history` (to compare the modes on one network).
    pub fn new_episode_with_history(&self, history: History) -> EpisodeState {
        EpisodeState {
            history,
            ..self.new_episode()
        }
    }

    /// Checks one input as [`SsrPolicy::step_batch`] does, so a caller batching independent
    /// requests can refuse a bad one alone.
    pub fn check(&self, input: &StepInput) -> Result<(), InputError> {
        check_input(input)
    }

    /// Bytes of tensor state one episode keeps (two BEVs of each of its last
    /// [`HISTORY_TICKS`] steps).
    pub fn episode_state_bytes(&self) -> usize {
        2 * HISTORY_TICKS
            * self.config.bev.grid.cells()
            * self.config.channels
            * std::mem::size_of::<f32>()
    }

    /// One tick of one episode.
    pub fn step(
        &self,
        episode: &mut EpisodeState,
        input: &StepInput,
    ) -> Result<StepOutput, StepError> {
        Ok(self
            .step_batch(&mut [episode], std::slice::from_ref(input))?
            .remove(0))
    }

    /// One tick of several episodes in as few forward passes as camera counts allow. Outputs
    /// come back in input order.
    pub fn step_batch(
        &self,
        episodes: &mut [&mut EpisodeState],
        inputs: &[StepInput],
    ) -> Result<Vec<StepOutput>, StepError> {
        if episodes.len() != inputs.len() {
            return Err(StepError::BatchShape {
                episodes: episodes.len(),
                inputs: inputs.len(),
            });
        }
        for (episode, input) in inputs.iter().enumerate() {
            check_input(input).map_err(|source| StepError::Input { episode, source })?;
        }
        let mut outputs: Vec<Option<StepOutput>> = vec![None; inputs.len()];
        let mut camera_counts: Vec<usize> = inputs.iter().map(|i| i.rig.cameras.len()).collect();
        camera_counts.sort_unstable();
        camera_counts.dedup();
        for cameras in camera_counts {
            let members: Vec<usize> = (0..inputs.len())
                .filter(|&i| inputs[i].rig.cameras.len() == cameras)
                .collect();
            let group_inputs: Vec<&StepInput> = members.iter().map(|&i| &inputs[i]).collect();
            let mut group_states: Vec<&mut EpisodeState> = Vec::with_capacity(members.len());
            for (index, state) in episodes.iter_mut().enumerate() {
                if members.contains(&index) {
                    group_states.push(&mut **state);
                }
            }
            let group_outputs = self.run_group(&mut group_states, &group_inputs, cameras);
            for (index, output) in members.into_iter().zip(group_outputs) {
                outputs[index] = Some(output);
            }
        }
        Ok(outputs
            .into_iter()
            .map(|o| o.expect("every input belongs to a group"))
            .collect())
    }

    /// Images `[B * cameras, 3, H, W]` at the network's input size, normalised.
    fn images(&self, inputs: &[&StepInput]) -> Tensor<4> {
        let (width, height) = (self.config.image_width, self.config.image_height);
        let frames: Vec<&RgbImage> = inputs.iter().flat_map(|input| &input.frames).collect();
        let values = frames
            .iter()
            .flat_map(|f| {
                frame_to_input(&f.rgb, f.width as usize, f.height as usize, width, height)
            })
            .collect();
        float_tensor(values, [frames.len(), 3, height, width], &self.device)
    }

    /// One forward pass for a group of episodes with the same number of cameras, then each
    /// episode's control and its links for later steps: navigation inputs, BEV passes, plan,
    /// the optional heads the group needs, per-episode decisions.
    fn run_group(
        &self,
        states: &mut [&mut EpisodeState],
        inputs: &[&StepInput],
        cameras: usize,
    ) -> Vec<StepOutput> {
        let geometries: Vec<SampleGeometry> = inputs
            .iter()
            .zip(states.iter())
            .map(|(input, state)| {
                let motion = state
                    .previous_links()
                    .map(|links| EgoMotion::between(links.pose, input.pose));
                self.geometry(input, motion)
            })
            .collect();
        let navigation = self.navigation(inputs);
        let features = self.model.image_features(self.images(inputs));
        let bevs = self.encode(states, inputs, features, cameras, geometries);
        let (scene, head) = self.model.plan(bevs.plan.clone(), &navigation);
        let needs = Needs {
            debug: inputs.iter().any(|i| i.debug),
            occupancy: states.iter().any(|s| s.controller.config().safety.enabled),
            motion: states.iter().any(|s| {
                let safety = &s.controller.config().safety;
                safety.enabled && safety.motion
            }),
            hazard: states.iter().any(|s| s.controller.config().unstick.enabled),
        };
        let outputs = GroupOutputs::read(
            &self.model,
            &self.config.bev.grid,
            &bevs.plan,
            &scene,
            &head,
            needs,
        );
        let mut results = Vec::with_capacity(inputs.len());
        for (i, (state, input)) in states.iter_mut().zip(inputs).enumerate() {
            results.push(self.decide(state, input, outputs.episode(i)));
            state.remember(bevs.links(i, state.history, input.pose));
        }
        results
    }

    /// The BEV each episode plans from, and the links it keeps for later steps: one, two or
    /// three BEV passes ([`SsrPolicy::encode_passes`]), as the group's histories need.
    fn encode(
        &self,
        states: &[&mut EpisodeState],
        inputs: &[&StepInput],
        features: Tensor<4>,
        cameras: usize,
        geometries: Vec<SampleGeometry>,
    ) -> GroupBevs {
        let b = inputs.len();
        let (q, c) = (self.config.bev.grid.cells(), self.config.channels);
        let zeros = || Tensor::zeros([1, q, c], &self.device);
        let history = |link: fn(&ChainLinks) -> &Tensor<3>| {
            let bevs = states
                .iter()
                .map(|s| s.previous_links().map_or_else(zeros, |l| link(l).clone()));
            Tensor::cat(bevs.collect(), 0)
        };
        // The history the BEV each step plans from attends to (zeros before there is one).
        let previous_bev = Tensor::cat(
            states
                .iter()
                .map(|s| match s.previous_links() {
                    Some(links) => match s.history {
                        History::Chain | History::Recursive => links.context.clone(),
                        History::Link => links.deep.clone(),
                    },
                    None => zeros(),
                })
                .collect(),
            0,
        );
        let with_history = |mode: History| {
            states
                .iter()
                .any(|s| s.has_previous_bev() && s.history == mode)
        };
        // Chained episodes keep the context BEV (the step's BEV attending to the deep one
        // before it); chained and linked ones the deep BEV (the step's first-frame BEV).
        let context_pass = with_history(History::Chain);
        let deep_pass = context_pass || with_history(History::Link);
        let mut passes = vec![(geometries.clone(), previous_bev)];
        if deep_pass {
            let first_frames = inputs
                .iter()
                .map(|input| self.geometry(input, None))
                .collect();
            passes.push((first_frames, Tensor::zeros([b, q, c], &self.device)));
        }
        if context_pass {
            passes.push((geometries, history(|links| &links.deep)));
        }
        let bevs = self.encode_passes(features, cameras, passes);
        // Without a pass of its own, a link is the planning BEV: the first-frame BEV of an
        // episode without history yet, or a recursive episode's.
        GroupBevs {
            deep: bevs.get(1).unwrap_or(&bevs[0]).clone(),
            context: bevs.get(2).unwrap_or(&bevs[0]).clone(),
            plan: bevs[0].clone(),
        }
    }

    /// An episode's geometry for this step: its rig, the ego motion since its history
    /// (`None`: a first-frame BEV) and the speed the network is shown.
    fn geometry(&self, input: &StepInput, motion: Option<EgoMotion>) -> SampleGeometry {
        let speed = self.config.shown_speed(input.speed);
        let bev = &self.config.bev;
        SampleGeometry::new(&bev.grid, &bev.pillar_heights, &input.rig, motion, speed)
    }

    /// The controller's decision for one episode from its share of the group's outputs.
    fn decide(
        &self,
        state: &mut EpisodeState,
        input: &StepInput,
        out: EpisodeOutputs<'_>,
    ) -> StepOutput {
        let control_started = std::time::Instant::now();
        let safety = &state.controller.config().safety;
        let grid = &self.config.bev.grid;
        let mut occupied = match out.occupancy {
            Some(p) if safety.enabled => occupied_cells(p, grid, safety.threshold),
            _ => Vec::new(),
        };
        if let Some(p) = out.motion.filter(|_| safety.enabled && safety.motion) {
            occupied.extend(occupied_cells(p, grid, safety.motion_threshold));
        }
        let beliefs = Beliefs {
            occupied: &occupied,
            clear: out.hazard(Hazard::Clear),
            stop_sign: out.hazard(Hazard::Sign),
            light_hazard: out.hazard(Hazard::Light),
            light: out.light(),
        };
        let decision = state.controller.act(
            &out.path,
            input.target_point,
            input.speed,
            out.alpha,
            out.beta,
            beliefs,
        );
        let control_time = control_started.elapsed();
        let debug = input.debug.then(|| StepDebug {
            token_attention: out.attention.clone().unwrap_or_default(),
            bev_rows: grid.rows,
            bev_cols: grid.cols,
            alpha: out.alpha,
            beta: out.beta,
            predicted_speed: out.predicted_speed,
            occupancy: out.occupancy_maps(),
            hazard: out.hazards.copied(),
            light: out.light(),
        });
        StepOutput {
            decision,
            control_time,
            waypoints: out.path,
            debug,
        }
    }
    /// The planner's inputs besides the BEV: the speed it is shown, target points, commands.
    fn navigation(&self, inputs: &[&StepInput]) -> Navigation {
        let b = inputs.len();
        let command: Vec<f32> = inputs.iter().flat_map(|i| i.command.one_hot()).collect();
        Navigation {
            speed: float_tensor(
                inputs
                    .iter()
                    .map(|i| self.config.shown_speed(i.speed).unwrap_or(0.0))
                    .collect(),
                [b, 1],
                &self.device,
            ),
            target_point: float_tensor(
                inputs.iter().flat_map(|i| i.target_point).collect(),
                [b, 2],
                &self.device,
            ),
            command: float_tensor(command, [b, COMMANDS], &self.device),
        }
    }
}

/// A group's BEVs, `[B, Q, C]` each: the one each episode plans from, and the links
/// ([`ChainLinks`]) its later steps read.
struct GroupBevs {
    plan: Tensor<3>,
    deep: Tensor<3>,
    context: Tensor<3>,
}

impl GroupBevs {
    /// Episode `i`'s links, for an episode on `history` at `pose`.
    fn links(&self, i: usize, history: History, pose: Pose2) -> ChainLinks {
        let context = match history {
            History::Chain => &self.context,
            History::Recursive | History::Link => &self.plan,
        };
        ChainLinks {
            deep: self.deep.clone().narrow(0, i, 1),
            context: context.clone().narrow(0, i, 1),
            pose,
        }
    }
}

impl SsrPolicy {
    /// The BEVs of the current frames under several histories, in one pass of `passes.len()`
    /// times B samples: each pass is B geometries (the ego motion since the history's frame,
    /// none for a first-frame BEV) and the `[B, Q, C]` history BEVs they attend to. A chained
    /// step needs three (the BEV it plans from, attending to the context BEV 0.5 s back; its
    /// first-frame "deep" BEV; its context BEV, attending to the deep BEV 0.5 s back), a linked
    /// one two, a recursive one one: so the BEV the head reads has the history training gave
    /// it (`crate::train::data::Batch`) instead of a recursion of unbounded depth, whose
    /// history BEVs training never showed the network (a learner served on the recursion stopped
    /// and started every second in a period-two cycle of it).
    ///
    /// # Shapes
    /// - features: `[B * cameras, C, h, w]` (the backbone's)
    /// - output: one `[B, Q, C]` a pass, in the order given
    fn encode_passes(
        &self,
        features: Tensor<4>,
        cameras: usize,
        passes: Vec<(Vec<SampleGeometry>, Tensor<3>)>,
    ) -> Vec<Tensor<3>> {
        let (count, b) = (passes.len(), passes[0].0.len());
        let features = self.model.bev.image_features(features, cameras);
        let repeated = ImageFeatures {
            values: Tensor::cat(vec![features.values.clone(); count], 0),
            ..features
        };
        let (geometries, previous): (Vec<Vec<SampleGeometry>>, Vec<Tensor<3>>) =
            passes.into_iter().unzip();
        let geometry = GeometryTensors::batch(
            &geometries.concat(),
            &self.config.bev.grid,
            self.config.bev.pillar_heights.len(),
            &self.device,
        );
        let bevs = self
            .model
            .bev
            .forward(&repeated, &geometry, Tensor::cat(previous, 0));
        (0..count)
            .map(|k| bevs.clone().narrow(0, k * b, b))
            .collect()
    }
}
