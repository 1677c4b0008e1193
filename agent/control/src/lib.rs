//! From a planned trajectory and TCP's control branch to vehicle control: pure pursuit and a
//! speed PID that follow the waypoints ([`trajectory`]), the control branch's Beta distributions
//! turned into actions ([`beta`]), TCP's situation-based fusion of the two ([`fusion`]), a
//! timed rule that gets a car going again after a long stop ([`unstick`]), a rule that drives on
//! through the light the car started on ([`commit`]), a full stop where the network brakes for
//! a stop sign ([`stop_sign`]), and a stop when the network believes the path just ahead
//! occupied ([`safety`]), with the per-episode state all of them keep ([`EpisodeController`]).
//!
//! A crate of its own so that the agent server and the simulator's oracle-plan agent (which
//! feeds it the expert's plan) drive through the same code; it depends on the contract crate
//! (for [`Control`]) and serde.
//!
//! Control follows CARLA: steer in [-1, 1] with +1 full right, throttle and brake in [0, 1].
//! Waypoints and target points are in the ego frame: x forward, y left, metres, origin at the
//! centre of the vehicle box.

#![forbid(unsafe_code)]

pub mod beta;
pub mod commit;
pub mod fusion;
pub mod pid;
pub mod safety;
pub mod stop_sign;
pub mod trajectory;
pub mod unstick;

pub use commit::Commit;
use commit::CommitState;
use fusion::Fusion;
pub use fusion::TurnLead;
use safety::SafetyState;
pub use safety::SafetyStop;
use serde::{Deserialize, Serialize};
use ssrdrive_proto::control::Control;
use ssrdrive_proto::vehicle::SEDAN;
use ssrdrive_support::ranges::first_outside;
pub use stop_sign::FullStop;
use stop_sign::FullStopState;
use trajectory::TrajectoryFollower;
pub use unstick::Unstick;
use unstick::UnstickState;

/// The geometry of the vehicle being steered: what pure pursuit needs to turn a path into a
/// steer value. Defaults are sim-bridge's sedan ([`SEDAN`]); CARLA's Lincoln MKZ 2017 has a
/// 2.87 m wheelbase and a 70-degree `max_steer_angle`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Vehicle {
    /// Axle distance, m.
    pub wheelbase: f32,
    /// How far the rear axle sits behind the ego origin (the box centre), m.
    pub rear_axle: f32,
    /// Front-wheel angle at |steer| = 1, degrees.
    pub max_wheel_angle: f32,
}

impl Default for Vehicle {
    fn default() -> Self {
        Self {
            wheelbase: SEDAN.wheelbase as f32,
            rear_axle: (SEDAN.wheelbase / 2.0) as f32,
            max_wheel_angle: SEDAN.max_wheel_angle_deg as f32,
        }
    }
}

/// Controller settings. Speed PID, brake rules and fusion are TCP's; the lateral law is pure
/// pursuit for [`Vehicle`] (see [`trajectory`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct ControlConfig {
    /// The vehicle being steered.
    pub vehicle: Vehicle,
    /// Look-ahead beyond the box centre at standstill, m: the look-ahead is
    /// `lookahead_base + lookahead_gain * speed`, at most `lookahead_max`.
    pub lookahead_base: f32,
    /// Look-ahead added per m/s of speed, s.
    pub lookahead_gain: f32,
    /// Longest look-ahead, m.
    pub lookahead_max: f32,
    /// Speed PID proportional gain (throttle per m/s of speed error).
    pub speed_kp: f32,
    /// Speed PID integral gain, on the mean error over the window.
    pub speed_ki: f32,
    /// Speed PID derivative gain, on the difference of the last two errors.
    pub speed_kd: f32,
    /// PID error window length (ticks).
    pub pid_window: usize,
    /// Brake when the desired speed is below this (m/s) ...
    pub brake_speed: f32,
    /// ... or when speed / desired speed exceeds this.
    pub brake_ratio: f32,
    /// Largest speed error handed to the speed PID, m/s.
    pub clip_delta: f32,
    /// Largest throttle the trajectory and the fusion give, in [0, 1].
    pub max_throttle: f32,
    /// Weight of the weaker source in the fusion (TCP's alpha).
    pub alpha: f32,
    /// What leads the fused control while the car turns ([`fusion`]; TCP's control branch by
    /// default).
    pub turn_lead: TurnLead,
    /// Fusion status window: how many of the last fused steers are counted, ticks.
    pub turn_window: usize,
    /// A fused |steer| above this counts as a turning tick.
    pub turn_steer: f32,
    /// More turning ticks than this in the window mean "turning".
    pub turn_count: usize,
    /// The timed unstick rule (on by default).
    pub unstick: Unstick,
    /// Going on through the light the car started on (off by default).
    pub commit: Commit,
    /// The full stop where the network brakes for a stop sign (off by default).
    pub full_stop: FullStop,
    /// The safety stop on the network's occupancy (off by default).
    pub safety: SafetyStop,
}

impl Default for ControlConfig {
    fn default() -> Self {
        Self {
            vehicle: Vehicle::default(),
            lookahead_base: 3.0,
            lookahead_gain: 0.3,
            lookahead_max: 10.0,
            speed_kp: 5.0,
            speed_ki: 0.5,
            speed_kd: 1.0,
            pid_window: 40,
            brake_speed: 0.4,
            brake_ratio: 1.1,
            clip_delta: 0.25,
            max_throttle: 0.75,
            alpha: 0.3,
            turn_lead: TurnLead::default(),
            turn_window: 20,
            turn_steer: 0.1,
            turn_count: 10,
            unstick: Unstick::default(),
            commit: Commit::default(),
            full_stop: FullStop::default(),
            safety: SafetyStop::default(),
        }
    }
}

impl ControlConfig {
    /// Checks every field's range; the message names the first field outside it.
    pub fn validate(&self) -> Result<(), String> {
        let windows = [
            ("pid_window", self.pid_window, 2),
            ("turn_window", self.turn_window, 1),
        ];
        for (name, value, low) in windows {
            if !(low..=MAX_WINDOW).contains(&value) {
                return Err(format!(
                    "{name} = {value} is outside {low}..{MAX_WINDOW} ticks"
                ));
            }
        }
        if self.turn_count > self.turn_window {
            return Err(format!(
                "turn_count = {} is above turn_window = {}",
                self.turn_count, self.turn_window
            ));
        }
        let v = &self.vehicle;
        check_ranges(&[
            ("alpha", self.alpha, 0.0, 1.0),
            ("max_throttle", self.max_throttle, 0.0, 1.0),
            ("speed_kp", self.speed_kp, 0.0, 100.0),
            ("speed_ki", self.speed_ki, 0.0, 100.0),
            ("speed_kd", self.speed_kd, 0.0, 100.0),
            ("brake_speed", self.brake_speed, 0.0, 50.0),
            ("brake_ratio", self.brake_ratio, 0.0, 10.0),
            ("clip_delta", self.clip_delta, 0.001, 50.0),
            ("turn_steer", self.turn_steer, 0.0, 1.0),
            ("lookahead_base", self.lookahead_base, 0.01, 100.0),
            ("lookahead_gain", self.lookahead_gain, 0.0, 10.0),
            (
                "lookahead_max",
                self.lookahead_max,
                self.lookahead_base,
                100.0,
            ),
            ("vehicle.wheelbase", v.wheelbase, 0.5, 20.0),
            ("vehicle.rear_axle", v.rear_axle, -10.0, 10.0),
            ("vehicle.max_wheel_angle", v.max_wheel_angle, 1.0, 89.0),
        ])?;
        self.unstick.validate()?;
        self.commit.validate()?;
        self.full_stop.validate()?;
        self.safety.validate()
    }
}

/// Driving along the plan at up to `max_speed` (m/s): the plan's steer, `throttle` below that
/// speed, no brake. What the unstick rule's creep and the commit rule drive with.
pub(crate) fn along_plan(plan_steer: f32, speed: f32, max_speed: f32, throttle: f32) -> Control {
    Control {
        steer: plan_steer,
        throttle: if speed < max_speed { throttle } else { 0.0 },
        brake: 0.0,
    }
}

/// The longest PID or fusion window a config may ask for, ticks (500 s at 20 Hz): each episode
/// allocates its windows up front.
const MAX_WINDOW: usize = 10_000;

/// Checks that each `(name, value, low, high)` has `value` in `low..=high`; the message names
/// the first field outside its range.
pub(crate) fn check_ranges(fields: &[(&str, f32, f32, f32)]) -> Result<(), String> {
    first_outside(fields.iter().copied()).map_or(Ok(()), |out| Err(out.to_string()))
}

/// The three controls of one tick: what the vehicle gets and where it came from.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct ControlDecision {
    /// What the vehicle gets: the fused control, or the unstick rule's override.
    pub control: Control,
    /// From the waypoints through the PIDs.
    pub trajectory: Control,
    /// From the control branch's Beta distributions.
    pub branch: Control,
    /// Whether the fusion trusted the control branch more this tick ("turning").
    pub turning: bool,
    /// Whether the unstick rule overrode the fused control this tick.
    #[serde(default)]
    pub unsticking: bool,
    /// Whether the commit rule drove on through a light this tick.
    #[serde(default)]
    pub committed: bool,
    /// Whether the full stop braked for a stop sign this tick.
    #[serde(default)]
    pub full_stop: bool,
    /// Whether the safety stop overrode the control this tick.
    #[serde(default)]
    pub safety_stop: bool,
}

/// What the network believes of the scene beyond its plan, read by the rules that may override
/// the plan: the [`safety`] stop, the [`unstick`], [`commit`] and [`stop_sign`] rules. The default
/// believes nothing (an agent without those heads, or an oracle).
#[derive(Debug, Clone, Copy, Default)]
pub struct Beliefs<'a> {
    /// Ego-frame points the occupancy head believes occupied.
    pub occupied: &'a [[f32; 2]],
    /// The hazard head's probability that nothing holds the car ("clear"); `None` without
    /// the head.
    pub clear: Option<f32>,
    /// The hazard head's probability that a stop sign holds it; `None` without the head.
    pub stop_sign: Option<f32>,
    /// The hazard head's probability that a light holds it; `None` without the head.
    pub light_hazard: Option<f32>,
    /// What the light head sees of the light ahead; `None` without the head.
    pub light: Option<LightBelief>,
}

/// The light head's probabilities for the light that governs the route ahead.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct LightBelief {
    /// That it is green.
    pub green: f32,
    /// That it is red or yellow: the car is to stop at, or stay behind, its line.
    pub stop: f32,
}

/// Everything the control side remembers about one episode.
#[derive(Debug, Clone)]
pub struct EpisodeController {
    follower: TrajectoryFollower,
    fusion: Fusion,
    unstick: UnstickState,
    commit: CommitState,
    full_stop: FullStopState,
    safety: SafetyState,
    config: ControlConfig,
}

impl EpisodeController {
    /// The settings this episode is driven under.
    pub fn config(&self) -> &ControlConfig {
        &self.config
    }

    /// The state of a new episode driven under `config`.
    pub fn new(config: ControlConfig) -> Self {
        Self {
            follower: TrajectoryFollower::new(&config),
            fusion: Fusion::new(config.turn_window),
            unstick: UnstickState::default(),
            commit: CommitState::default(),
            full_stop: FullStopState::default(),
            safety: SafetyState::default(),
            config,
        }
    }

    /// One tick: `waypoints` ego frame (x forward, y left), `target_point` likewise, `speed`
    /// m/s, the control branch's Beta parameters for [acceleration, steer], and what the
    /// network believes of the scene (for the [`safety`] stop and the [`unstick`] rule).
    pub fn act(
        &mut self,
        waypoints: &[[f32; 2]],
        target_point: [f32; 2],
        speed: f32,
        alpha: [f32; 2],
        beta: [f32; 2],
        beliefs: Beliefs,
    ) -> ControlDecision {
        let branch = beta::control_from_beta(alpha, beta);
        self.act_with_branch(waypoints, target_point, speed, Some(branch), beliefs)
    }

    /// [`EpisodeController::act`] with the control branch's control already decided (an oracle
    /// that knows the right control, for example), or with none: then the waypoints alone
    /// drive.
    pub fn act_with_branch(
        &mut self,
        waypoints: &[[f32; 2]],
        target_point: [f32; 2],
        speed: f32,
        branch: Option<Control>,
        beliefs: Beliefs,
    ) -> ControlDecision {
        let trajectory = self
            .follower
            .control(waypoints, target_point, speed, &self.config);
        let branch = branch.unwrap_or(trajectory);
        let turning = self.fusion.turning();
        let fused = self.fusion.fuse(trajectory, branch, &self.config);
        let (control, unsticking) = self.unstick.apply(
            fused,
            speed,
            trajectory.steer,
            &beliefs,
            &self.config.unstick,
        );
        let (control, committed) = self.commit.apply(
            control,
            speed,
            trajectory.steer,
            &beliefs,
            unsticking,
            &self.config.commit,
        );
        let (control, full_stop) =
            self.full_stop
                .apply(control, speed, &beliefs, &self.config.full_stop);
        let (control, safety_stop) = self.safety.apply(
            control,
            waypoints,
            speed,
            beliefs.occupied,
            unsticking,
            &self.config.safety,
        );
        ControlDecision {
            control,
            trajectory,
            branch,
            turning,
            unsticking,
            committed,
            full_stop,
            safety_stop,
        }
    }
}
