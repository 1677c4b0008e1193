//! The sedan sim-bridge simulates as the ego, which the agent's controller is set up for by
//! default (its pure pursuit and safety stop): one home for its geometry. Another vehicle (CARLA's
//! Lincoln MKZ 2017: 2.87 m wheelbase, 70-degree `max_steer_angle`) is given to the controller
//! as settings (`ssr-agent control --set`).

/// A vehicle's geometry.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct VehicleGeometry {
    /// Axle distance, m.
    pub wheelbase: f64,
    /// Half the box's length, from its centre (the ego origin) to the front bumper, m.
    pub half_length: f64,
    /// Half the box's width, m.
    pub half_width: f64,
    /// Front-wheel angle at |steer| = 1, degrees.
    pub max_wheel_angle_deg: f64,
}

/// sim-bridge's ego: a 4.90 x 2.12 m box, the axles 2.85 m apart about its centre, a 35-degree
/// lock.
pub const SEDAN: VehicleGeometry = VehicleGeometry {
    wheelbase: 2.85,
    half_length: 2.45,
    half_width: 1.06,
    max_wheel_angle_deg: 35.0,
};
