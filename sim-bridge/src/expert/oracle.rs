//! The oracle-plan agent: the served agent's own controller (crate `ssr-control`: pure pursuit,
//! speed PID and TCP's fusion) fed the expert's plan as its waypoints and, as served, the
//! expert's control as its control branch (or no branch: the waypoints alone). It measures the
//! controller: if perfect waypoints do not drive, no network will.

use glam::DVec2;
use ssr_control::{Beliefs, ControlConfig, EpisodeController, Vehicle};
use ssrdrive_proto::control::Control;

use super::Expert;
use crate::driver::{Agent, AgentError, Observation, RouteContext};
use crate::world::World;
use crate::world::ego::EgoParams;

/// The controller's view of the simulator's ego.
pub fn vehicle_of(params: &EgoParams) -> Vehicle {
    Vehicle {
        wheelbase: params.wheelbase as f32,
        // The kinematic model's reference point is the box centre, half a wheelbase ahead of
        // the rear axle.
        rear_axle: (params.wheelbase / 2.0) as f32,
        max_wheel_angle: params.max_wheel_angle.to_degrees() as f32,
    }
}

/// Drives with the agent's controller on the expert's plan.
#[derive(Debug)]
pub struct OraclePlan {
    expert: Expert,
    config: ControlConfig,
    controller: EpisodeController,
    with_branch: bool,
}

impl OraclePlan {
    /// An oracle whose controller has `config` (its vehicle should be the simulated ego's) and
    /// fuses the plan with the expert's control, as the server fuses the network's two outputs.
    pub fn new(config: ControlConfig) -> Self {
        Self {
            expert: Expert::new(),
            controller: EpisodeController::new(config.clone()),
            config,
            with_branch: true,
        }
    }

    /// The same, driven by the plan alone (no control branch to lean on in turns).
    pub fn plan_only(config: ControlConfig) -> Self {
        Self {
            with_branch: false,
            ..Self::new(config)
        }
    }
}

/// The default controller settings for the simulator's own ego.
pub fn sim_control_config() -> ControlConfig {
    ControlConfig {
        vehicle: vehicle_of(&EgoParams::default()),
        ..ControlConfig::default()
    }
}

fn to_f32(v: DVec2) -> [f32; 2] {
    [v.x as f32, v.y as f32]
}

impl Agent for OraclePlan {
    fn name(&self) -> String {
        "oracle-plan".into()
    }

    fn start_route(&mut self, ctx: &RouteContext<'_>) -> Result<(), AgentError> {
        self.controller = EpisodeController::new(self.config.clone());
        self.expert.start_route(ctx)
    }

    fn planned_trajectory(&self) -> Vec<DVec2> {
        self.expert.planned_trajectory()
    }

    fn run_step(&mut self, obs: &Observation, world: &World<'_>) -> Result<Control, AgentError> {
        let expert = self.expert.run_step(obs, world)?;
        let waypoints: Vec<[f32; 2]> = self.expert.plan.iter().copied().map(to_f32).collect();
        let branch = self.with_branch.then_some(expert);
        let decision = self.controller.act_with_branch(
            &waypoints,
            to_f32(obs.target_point),
            obs.speed as f32,
            branch,
            Beliefs::default(),
        );
        Ok(decision.control)
    }
}
