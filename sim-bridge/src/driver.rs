//! The interface between the simulator and whatever drives the ego: an [`Observation`] in, a
//! [`Control`] out, every 20 Hz tick. The privileged expert, a remote gRPC agent and scripted
//! test agents all implement [`Agent`]; scoring never knows which one drives.
//!
//! Conventions: world frame = OpenDRIVE map frame (x east, y north, z up); ego frame = x
//! forward, y left, z up (ISO 8855) with the origin at the vehicle box centre; steer +1 = full
//! right (CARLA); commands are CARLA RoadOption values.

use glam::{DVec2, DVec3};
use ssrdrive_proto::camera::Rig;
use ssrdrive_proto::command::RoadOption;
use ssrdrive_proto::control::Control;
use ssrdrive_proto::v1;

use crate::map::Map;
use crate::route::DenseRoute;
use crate::route::plan::{PlanNode, to_ego_frame};
use crate::world::World;
use crate::world::state::EgoState;

/// One camera image, rendered through the agent's rig.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct CameraFrame {
    /// The rig's camera id.
    pub camera: String,
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// Row-major RGB8 pixels.
    pub rgb: Vec<u8>,
}

impl CameraFrame {
    /// The frame on the wire, as an uncompressed RGB8 image.
    pub fn to_proto(&self) -> v1::Image {
        v1::Image {
            camera_id: self.camera.clone(),
            width: self.width,
            height: self.height,
            encoding: v1::ImageEncoding::Rgb8 as i32,
            data: self.rgb.clone(),
        }
    }
}

/// What an agent is told each tick.
#[derive(Debug, Clone, PartialEq)]
pub struct Observation {
    /// Simulation time, s.
    pub time: f64,
    /// Tick index from 0.
    pub frame: u64,
    /// Forward speed, m/s.
    pub speed: f64,
    /// Ego box centre, world frame.
    pub position: DVec3,
    /// Ego heading, rad counter-clockwise from +x (world frame).
    pub yaw: f64,
    /// CARLA compass: rad clockwise from north (= CARLA yaw + 90 degrees), in [0, 2 pi).
    pub compass: f64,
    /// The route follower's command.
    pub command: RoadOption,
    /// The route follower's target point in the ego frame (x forward, y left), m.
    pub target_point: DVec2,
    /// Camera images in the order of the agent's [`Agent::sensors`] rig; empty for an agent
    /// without sensors and on ticks [`Agent::wants_frames`] declines.
    pub frames: Vec<CameraFrame>,
}

impl Observation {
    /// What the ego at `ego` is told on tick `frame` at `time`: its state, and the route
    /// follower's `node` as command and target point in the ego frame.
    pub fn of_ego(
        time: f64,
        frame: u64,
        ego: &EgoState,
        node: &PlanNode,
        frames: Vec<CameraFrame>,
    ) -> Self {
        Self {
            time,
            frame,
            speed: ego.speed,
            position: ego.position,
            yaw: ego.yaw,
            compass: Self::compass_of(ego.yaw),
            command: node.option,
            target_point: to_ego_frame(node.position, ego.position, ego.yaw).truncate(),
            frames,
        }
    }

    /// CARLA's compass for a world-frame yaw.
    pub fn compass_of(yaw: f64) -> f64 {
        (std::f64::consts::FRAC_PI_2 - yaw).rem_euclid(std::f64::consts::TAU)
    }

    /// The observation as a step request on the wire (its frames in rig order, uncompressed).
    pub fn step_request(&self, episode_id: &str) -> v1::StepRequest {
        v1::StepRequest {
            episode_id: episode_id.to_string(),
            frame_index: self.frame,
            timestamp_s: self.time,
            images: self.frames.iter().map(CameraFrame::to_proto).collect(),
            speed_mps: self.speed,
            pose: Some(v1::Pose {
                x: self.position.x,
                y: self.position.y,
                z: self.position.z,
                yaw: self.yaw,
            }),
            command: self.command.value(),
            target_point: Some(v1::EgoPoint {
                x: self.target_point.x,
                y: self.target_point.y,
            }),
            debug: false,
        }
    }
}

/// What an agent learns at the start of a route.
#[derive(Debug, Clone, Copy)]
pub struct RouteContext<'a> {
    /// The map.
    pub map: &'a Map,
    /// The dense route (privileged: the leaderboard gives agents only the plan).
    pub route: &'a DenseRoute,
    /// The downsampled global plan, as the leaderboard hands it to agents.
    pub plan: &'a [PlanNode],
    /// The route's id in its set (for logs).
    pub route_id: &'a str,
    /// Repetition of the route, from 0 (for logs).
    pub repetition: usize,
    /// The world seed (for logs).
    pub seed: u64,
    /// The ego's half length and half width, metres.
    pub ego_half_extent: DVec2,
}

/// An agent that cannot go on (a lost server connection, a refused request). The route ends
/// as the leaderboard ends it when an agent raises: "Failed - Agent crashed".
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{0}")]
pub struct AgentError(pub String);

/// Something that drives the ego.
pub trait Agent {
    /// A short name for results and logs.
    fn name(&self) -> String;
    /// What drives, wherever it is served (a served agent's model, config, checkpoint and
    /// version, not its address): results files of one campaign agree on it
    /// (`sim-bridge results merge`).
    fn identity(&self) -> String {
        self.name()
    }
    /// Called once before the first tick of a route.
    fn start_route(&mut self, ctx: &RouteContext<'_>) -> Result<(), AgentError>;
    /// Called once after the last tick of a route (CARLA's `destroy`), crashed or not.
    fn end_route(&mut self) {}
    /// The cameras this agent drives from (CARLA's `sensors()`); `None` renders nothing.
    fn sensors(&self) -> Option<Rig> {
        None
    }
    /// Whether to render frames on tick `frame` (every tick by default; a recorder that keeps
    /// 2 Hz declines the others and saves their rendering).
    fn wants_frames(&self, frame: u64) -> bool {
        let _ = frame;
        true
    }
    /// The trajectory planned on the last tick, ego frame (x forward, y left), metres, every
    /// 0.5 s; empty for agents that plan none.
    fn planned_trajectory(&self) -> Vec<DVec2> {
        Vec::new()
    }
    /// Decide this tick's control. `world` is privileged ground truth: only in-process agents
    /// such as the expert may read it; sensor-based agents use `obs` alone.
    fn run_step(&mut self, obs: &Observation, world: &World<'_>) -> Result<Control, AgentError>;
}

/// Makes one worker's agent (each worker thread drives its own, e.g. its own connection), or
/// says why it cannot.
pub type AgentFactory<'a> = &'a (dyn Fn() -> Result<Box<dyn Agent>, String> + Sync);
