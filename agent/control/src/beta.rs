//! TCP's rules for acting on Beta(alpha, beta) distributions over [acceleration, steer], both
//! mapped from [0, 1] to [-1, 1].

use ssrdrive_proto::control::Control;

/// The value TCP acts on: the mode when both parameters exceed 1; 0 or 1 when only one does
/// (the density piles up at that end); the mean when neither does. Returned in [0, 1].
pub fn beta_point(alpha: f32, beta: f32) -> f32 {
    match (alpha > 1.0, beta > 1.0) {
        (true, true) => (alpha - 1.0) / (alpha + beta - 2.0),
        (false, true) => 0.0,
        (true, false) => 1.0,
        (false, false) => alpha / (alpha + beta).max(1e-5),
    }
}

/// Acceleration and steer in [-1, 1] to a control: positive acceleration is throttle, negative
/// is brake; a brake under 0.05 or below the throttle is dropped (TCP's agent).
pub fn control_from_action(acceleration: f32, steer: f32) -> Control {
    let (throttle, brake) = if acceleration >= 0.0 {
        (acceleration, 0.0)
    } else {
        (0.0, -acceleration)
    };
    let brake = if brake < 0.05 || throttle > brake {
        0.0
    } else {
        brake
    };
    Control {
        steer: steer.clamp(-1.0, 1.0),
        throttle: throttle.clamp(0.0, 1.0),
        brake: brake.clamp(0.0, 1.0),
    }
}

/// The control branch's control from its Beta parameters for [acceleration, steer].
pub fn control_from_beta(alpha: [f32; 2], beta: [f32; 2]) -> Control {
    let action = |i: usize| 2.0 * beta_point(alpha[i], beta[i]) - 1.0;
    control_from_action(action(0), action(1))
}
