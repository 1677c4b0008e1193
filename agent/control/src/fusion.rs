//! Situation-based fusion (TCP's agent): when the vehicle has been turning (more than
//! `turn_count` of the last `turn_window` fused steers above `turn_steer` in magnitude) the
//! control branch gets weight 1 - alpha, otherwise the trajectory does. The status is updated
//! after each fused control, so it takes effect on the next tick.
//!
//! # What leads in turns
//! TCP hands turns to the control branch because its turn PID lagged there. Here the plan is
//! followed by pure pursuit derived for the vehicle, exact in turns (the oracle-plan agent
//! drives the home routes at DS 100 from the expert's plans), while the branch imitates the
//! expert's steer and under-steered the tight corners of a town the network never saw: at a
//! Town02 corner the branch asked -0.25 where pursuit on the plan asked -0.53, the fused -0.34
//! took the car out of its lane into a prop. [`TurnLead`] chooses what leads while turning;
//! the default stays TCP's (the bundled checkpoint drives worse with the plan leading), and a
//! checkpoint carries its own choice (`ssr-agent control CKPT --set '{"turn_lead": "plan"}'`).

use std::collections::VecDeque;

use serde::{Deserialize, Serialize};
use ssrdrive_proto::control::Control;

use super::ControlConfig;

/// Which source leads (weight 1 - alpha) the fused control while the car turns; on a straight
/// road the trajectory leads whatever this says.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum TurnLead {
    /// The control branch leads steer, throttle and brake (TCP).
    #[default]
    Branch,
    /// The plan leads the steer, the control branch throttle and brake.
    PlanSteer,
    /// The plan leads everything, as on a straight road.
    Plan,
}

/// TCP's situation-based fusion of the trajectory and control-branch controls; keeps the recent
/// fused steers that decide "turning".
#[derive(Debug, Clone)]
pub struct Fusion {
    recent_steers: VecDeque<f32>,
    turning: bool,
}

impl Fusion {
    /// A fusion that starts "not turning", remembering up to `window` fused steers.
    pub fn new(window: usize) -> Self {
        Self {
            recent_steers: VecDeque::with_capacity(window),
            turning: false,
        }
    }

    /// The status the next [`Fusion::fuse`] uses.
    pub fn turning(&self) -> bool {
        self.turning
    }

    /// Mixes the two controls (the weaker source weighted `config.alpha`), clamps them, and updates
    /// the turning status for the next tick from the fused steer.
    pub fn fuse(
        &mut self,
        trajectory: Control,
        branch: Control,
        config: &ControlConfig,
    ) -> Control {
        let branch_steers = self.turning && config.turn_lead == TurnLead::Branch;
        let branch_speeds = self.turning && config.turn_lead != TurnLead::Plan;
        let a = config.alpha;
        let mix = |branch_leads: bool, from_plan: f32, from_branch: f32| {
            if branch_leads {
                a * from_plan + (1.0 - a) * from_branch
            } else {
                a * from_branch + (1.0 - a) * from_plan
            }
        };
        let steer = mix(branch_steers, trajectory.steer, branch.steer).clamp(-1.0, 1.0);
        let brake = mix(branch_speeds, trajectory.brake, branch.brake).clamp(0.0, 1.0);
        let throttle = mix(branch_speeds, trajectory.throttle, branch.throttle)
            .clamp(0.0, config.max_throttle);
        let throttle = if brake > 0.5 { 0.0 } else { throttle };

        if self.recent_steers.len() >= config.turn_window {
            self.recent_steers.pop_front();
        }
        self.recent_steers.push_back(steer.abs());
        self.turning = self
            .recent_steers
            .iter()
            .filter(|s| **s > config.turn_steer)
            .count()
            > config.turn_count;
        Control {
            steer,
            throttle,
            brake,
        }
    }
}
