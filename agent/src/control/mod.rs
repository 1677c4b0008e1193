//! From network outputs to vehicle control, as TCP's agent does it: PID controllers that follow
//! the predicted waypoints ([`trajectory`]), the control branch's Beta distributions turned into
//! actions ([`beta`]), and the situation-based fusion of the two ([`fusion`]), with the
//! per-episode state all of them keep ([`EpisodeController`]).
//!
//! Control follows CARLA: steer in [-1, 1] with +1 full right, throttle and brake in [0, 1].

pub mod beta;
pub mod fusion;
pub mod pid;
pub mod trajectory;

use serde::{Deserialize, Serialize};

use fusion::Fusion;
use trajectory::TrajectoryFollower;

/// A control command (CARLA convention).
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct Control {
    pub steer: f32,
    pub throttle: f32,
    pub brake: f32,
}

/// Controller settings; defaults are TCP's.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ControlConfig {
    pub turn_kp: f32,
    pub turn_ki: f32,
    pub turn_kd: f32,
    pub speed_kp: f32,
    pub speed_ki: f32,
    pub speed_kd: f32,
    /// PID error window length (ticks).
    pub pid_window: usize,
    /// Distance of the aim point along the trajectory, m.
    pub aim_dist: f32,
    /// Steer to the target point when its angle departs from the trajectory's end by more than
    /// this (normalised angle, 1 = 90 degrees) and it is nearer than `dist_thresh` metres.
    pub angle_thresh: f32,
    pub dist_thresh: f32,
    /// Brake when the desired speed is below this (m/s) ...
    pub brake_speed: f32,
    /// ... or when speed / desired speed exceeds this.
    pub brake_ratio: f32,
    /// Largest speed error handed to the speed PID, m/s.
    pub clip_delta: f32,
    pub max_throttle: f32,
    /// Weight of the weaker source in the fusion (TCP's alpha).
    pub alpha: f32,
    /// Fusion status window (ticks) and the steer magnitude and count that mean "turning".
    pub turn_window: usize,
    pub turn_steer: f32,
    pub turn_count: usize,
}

impl Default for ControlConfig {
    fn default() -> Self {
        Self {
            turn_kp: 0.75,
            turn_ki: 0.75,
            turn_kd: 0.3,
            speed_kp: 5.0,
            speed_ki: 0.5,
            speed_kd: 1.0,
            pid_window: 40,
            aim_dist: 4.0,
            angle_thresh: 0.3,
            dist_thresh: 10.0,
            brake_speed: 0.4,
            brake_ratio: 1.1,
            clip_delta: 0.25,
            max_throttle: 0.75,
            alpha: 0.3,
            turn_window: 20,
            turn_steer: 0.1,
            turn_count: 10,
        }
    }
}

impl ControlConfig {
    /// Checks ranges; the message names the field.
    pub fn validate(&self) -> Result<(), String> {
        if !(0.0..=1.0).contains(&self.alpha) {
            return Err(format!("alpha = {} is outside 0..1", self.alpha));
        }
        if self.pid_window < 2 || self.turn_window == 0 {
            return Err("pid_window must be >= 2 and turn_window >= 1".into());
        }
        if !(0.0..=1.0).contains(&self.max_throttle) {
            return Err(format!(
                "max_throttle = {} is outside 0..1",
                self.max_throttle
            ));
        }
        Ok(())
    }
}

/// The three controls of one tick: what the vehicle gets and where it came from.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct ControlDecision {
    pub control: Control,
    /// From the waypoints through the PIDs.
    pub trajectory: Control,
    /// From the control branch's Beta distributions.
    pub branch: Control,
    /// Whether the fusion trusted the control branch more this tick ("turning").
    pub turning: bool,
}

/// Everything the control side remembers about one episode.
#[derive(Debug, Clone)]
pub struct EpisodeController {
    follower: TrajectoryFollower,
    fusion: Fusion,
    config: ControlConfig,
}

impl EpisodeController {
    pub fn new(config: ControlConfig) -> Self {
        Self {
            follower: TrajectoryFollower::new(&config),
            fusion: Fusion::new(config.turn_window),
            config,
        }
    }

    /// One tick: `waypoints` ego frame (x forward, y left), `target_point` likewise, `speed`
    /// m/s, and the control branch's Beta parameters for [acceleration, steer].
    pub fn act(
        &mut self,
        waypoints: &[[f32; 2]],
        target_point: [f32; 2],
        speed: f32,
        alpha: [f32; 2],
        beta: [f32; 2],
    ) -> ControlDecision {
        let trajectory = self
            .follower
            .control(waypoints, target_point, speed, &self.config);
        let branch = beta::control_from_beta(alpha, beta);
        let turning = self.fusion.turning();
        let control = self.fusion.fuse(trajectory, branch, &self.config);
        ControlDecision {
            control,
            trajectory,
            branch,
            turning,
        }
    }
}
