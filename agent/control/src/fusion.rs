//! Situation-based fusion (TCP's agent): when the vehicle has been turning (more than
//! `turn_count` of the last `turn_window` fused steers above `turn_steer` in magnitude) the
//! control branch gets weight 1 - alpha, otherwise the trajectory does. The status is updated
//! after each fused control, so it takes effect on the next tick.

use std::collections::VecDeque;

use ssrdrive_proto::control::Control;

use super::ControlConfig;

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
        let (weak, strong) = if self.turning {
            (trajectory, branch)
        } else {
            (branch, trajectory)
        };
        let a = config.alpha;
        let mix = |w: f32, s: f32| a * w + (1.0 - a) * s;
        let steer = mix(weak.steer, strong.steer).clamp(-1.0, 1.0);
        let brake = mix(weak.brake, strong.brake).clamp(0.0, 1.0);
        let throttle = mix(weak.throttle, strong.throttle).clamp(0.0, config.max_throttle);
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
