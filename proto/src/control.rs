//! [`Control`]: what a driver sends the vehicle each tick, CARLA's `VehicleControl` subset in
//! its units and precision (32-bit floats, steer +1 = full right). The simulator applies it, the
//! expert and the agent's controller produce it, datasets store it as the label.

use serde::{Deserialize, Serialize};

/// A control command (CARLA convention).
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct Control {
    /// Steering in [-1, 1], +1 = full right.
    pub steer: f32,
    /// Throttle in [0, 1].
    pub throttle: f32,
    /// Brake in [0, 1].
    pub brake: f32,
}

impl Control {
    /// Full brake, wheels straight.
    pub const STOP: Control = Control {
        steer: 0.0,
        throttle: 0.0,
        brake: 1.0,
    };

    /// The same control with every field clamped to its range; any NaN gives [`Control::STOP`],
    /// so a broken driver stops rather than drives off.
    pub fn sanitized(self) -> Control {
        if self.steer.is_nan() || self.throttle.is_nan() || self.brake.is_nan() {
            return Control::STOP;
        }
        Control {
            steer: self.steer.clamp(-1.0, 1.0),
            throttle: self.throttle.clamp(0.0, 1.0),
            brake: self.brake.clamp(0.0, 1.0),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sanitized_clamps_and_stops_on_nan() {
        let wild = Control {
            steer: -3.0,
            throttle: 2.0,
            brake: -1.0,
        };
        assert_eq!(
            wild.sanitized(),
            Control {
                steer: -1.0,
                throttle: 1.0,
                brake: 0.0
            }
        );
        let broken = Control {
            throttle: f32::NAN,
            ..Control::default()
        };
        assert_eq!(broken.sanitized(), Control::STOP);
    }
}
