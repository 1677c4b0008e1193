//! The two frames every part shares and the rules that relate them, in one place.
//!
//! World: the OpenDRIVE map frame (x east, y north, z up, metres); headings in radians,
//! counter-clockwise from +x. Ego: x forward, y left, z up, origin at the centre of the vehicle
//! box. The rules are generic over `f32` (the agent) and `f64` (the simulator), so each side
//! keeps its own precision and gets the same arithmetic.

use std::ops::{Add, Mul, Neg, Rem, Sub};

/// The floating-point types the rules work in.
pub trait Real:
    Copy
    + PartialOrd
    + Add<Output = Self>
    + Sub<Output = Self>
    + Mul<Output = Self>
    + Rem<Output = Self>
    + Neg<Output = Self>
{
    /// Half a turn, radians.
    const PI: Self;
    /// A whole turn, radians.
    const TAU: Self;
    /// Sine and cosine.
    fn sin_cos(self) -> (Self, Self);
}

impl Real for f32 {
    const PI: Self = std::f32::consts::PI;
    const TAU: Self = std::f32::consts::TAU;
    fn sin_cos(self) -> (Self, Self) {
        f32::sin_cos(self)
    }
}

impl Real for f64 {
    const PI: Self = std::f64::consts::PI;
    const TAU: Self = std::f64::consts::TAU;
    fn sin_cos(self) -> (Self, Self) {
        f64::sin_cos(self)
    }
}

/// `angle` (radians) wrapped into (-pi, pi]: an angle already there comes back unchanged, any
/// other is moved by whole turns.
pub fn wrap_angle<T: Real>(angle: T) -> T {
    let turn = angle % T::TAU;
    if turn > T::PI {
        turn - T::TAU
    } else if turn <= -T::PI {
        turn + T::TAU
    } else {
        turn
    }
}

/// A world-frame vector (a point minus the ego's position) in the ego frame of an ego heading
/// `yaw`: `[forward, left]`.
pub fn world_to_ego<T: Real>(offset: [T; 2], yaw: T) -> [T; 2] {
    let (s, c) = yaw.sin_cos();
    [
        c * offset[0] + s * offset[1],
        -s * offset[0] + c * offset[1],
    ]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn angles_wrap_into_one_half_open_turn() {
        use std::f64::consts::PI;
        assert_eq!(wrap_angle(0.3_f64), 0.3);
        assert_eq!(wrap_angle(PI), PI, "pi stays");
        assert_eq!(wrap_angle(-PI), PI, "-pi is pi");
        assert!((wrap_angle(3.0 * PI / 2.0) + PI / 2.0).abs() < 1e-12);
        assert!((wrap_angle(-7.0 * PI / 2.0) - PI / 2.0).abs() < 1e-12);
        assert_eq!(wrap_angle(1e-3_f32), 1e-3, "f32 in range is exact");
    }

    #[test]
    fn a_point_ahead_and_left_of_an_ego_facing_north() {
        let [forward, left] = world_to_ego([-1.0_f64, 2.0], std::f64::consts::FRAC_PI_2);
        assert!((forward - 2.0).abs() < 1e-12 && (left - 1.0).abs() < 1e-12);
    }
}
