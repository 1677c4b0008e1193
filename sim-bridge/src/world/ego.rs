//! The ego vehicle: a kinematic bicycle model of a mid-size sedan (CARLA's Lincoln MKZ class).
//!
//! Numbers (documented in sim-bridge/README.md; the geometry is `ssrdrive_proto::vehicle::SEDAN`,
//! which the agent's controller defaults to): wheelbase 2.85 m, box 4.90 x 2.12 m, front-wheel lock
//! 35 degrees reached at steer = 1 (steer +1 is full RIGHT, CARLA's convention), steering rate
//! limited to full lock in 0.4 s; drive force gives 3.5 m/s^2 at rest falling linearly to 0 at
//! 60 m/s (so ~2.9 m/s^2 at 10 m/s, 0-100 km/h in about 9 s); brake = 1 gives 8.0 m/s^2 (dry
//! asphalt); rolling resistance 0.15 m/s^2 and drag 0.0004 v^2. No reversing: speed stays >= 0.
//! The reference point is the box centre; the rear axle sits 1.42 m behind it.

use glam::{DVec2, DVec3};
use ssrdrive_proto::control::Control;
use ssrdrive_proto::vehicle::SEDAN;

use super::state::EgoState;
use ssrdrive_proto::frames::wrap_angle;

/// Physical parameters of the ego.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EgoParams {
    /// Axle distance, m.
    pub wheelbase: f64,
    /// Half length, half width of the box, m.
    pub half_extent: DVec2,
    /// Front-wheel angle at |steer| = 1, rad.
    pub max_wheel_angle: f64,
    /// Seconds from centre to full lock.
    pub steer_time: f64,
    /// Drive acceleration at rest with full throttle, m/s^2.
    pub max_accel: f64,
    /// Speed at which the drive force vanishes, m/s.
    pub top_speed: f64,
    /// Deceleration at full brake, m/s^2.
    pub max_brake: f64,
    /// Rolling resistance, m/s^2.
    pub rolling: f64,
    /// Aerodynamic drag coefficient (per metre), a = drag * v^2.
    pub drag: f64,
}

impl Default for EgoParams {
    fn default() -> Self {
        Self {
            wheelbase: SEDAN.wheelbase,
            half_extent: DVec2::new(SEDAN.half_length, SEDAN.half_width),
            max_wheel_angle: SEDAN.max_wheel_angle_deg.to_radians(),
            steer_time: 0.4,
            max_accel: 3.5,
            top_speed: 60.0,
            max_brake: 8.0,
            rolling: 0.15,
            drag: 0.0004,
        }
    }
}

/// The ego's dynamic state.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Ego {
    /// Parameters.
    pub params: EgoParams,
    /// Box centre, world frame.
    pub position: DVec3,
    /// Heading, rad.
    pub yaw: f64,
    /// Forward speed, m/s.
    pub speed: f64,
    /// Current steer (after the rate limit), [-1, 1].
    pub steer: f64,
    /// Last applied control.
    pub control: Control,
}

impl Ego {
    /// An ego at rest.
    pub fn new(params: EgoParams, position: DVec3, yaw: f64) -> Self {
        Self {
            params,
            position,
            yaw,
            speed: 0.0,
            steer: 0.0,
            control: Control::default(),
        }
    }

    /// Integrate one step of `dt` seconds under `control`.
    pub fn step(&mut self, control: Control, dt: f64) {
        let p = self.params;
        let c = control.sanitized();
        self.control = c;
        let max_delta = dt / p.steer_time;
        let (steer, throttle, brake) = (
            f64::from(c.steer),
            f64::from(c.throttle),
            f64::from(c.brake),
        );
        self.steer += (steer - self.steer).clamp(-max_delta, max_delta);
        let drive = throttle * p.max_accel * (1.0 - self.speed / p.top_speed).max(0.0);
        let resist = if self.speed > 0.0 {
            p.rolling + p.drag * self.speed * self.speed
        } else {
            0.0
        };
        let accel = drive - brake * p.max_brake - resist;
        let v0 = self.speed;
        let v1 = (v0 + accel * dt).max(0.0);
        let v = 0.5 * (v0 + v1);
        // Steer +1 is right, i.e. a negative (clockwise) wheel angle in our right-handed frame.
        let wheel = -self.steer * p.max_wheel_angle;
        let lr = p.wheelbase / 2.0;
        let beta = (lr / p.wheelbase * wheel.tan()).atan();
        let heading = self.yaw + beta;
        self.position.x += v * heading.cos() * dt;
        self.position.y += v * heading.sin() * dt;
        self.yaw = wrap_angle(self.yaw + v / lr * beta.sin() * dt);
        self.speed = v1;
    }

    /// The published state.
    pub fn state(&self) -> EgoState {
        EgoState {
            position: self.position,
            yaw: self.yaw,
            speed: self.speed,
            half_extent: self.params.half_extent,
        }
    }
}
