//! Planar ego poses in the world frame and the ego motion between two ticks.
//!
//! World frame: the OpenDRIVE map frame (x east, y north, z up, metres); yaw in radians,
//! counter-clockwise from +x. Ego frame: x forward, y left.

use serde::{Deserialize, Serialize};
use ssrdrive_proto::frames::{world_to_ego, wrap_angle};

/// The ego's planar pose in the world frame.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Pose2 {
    /// Position east, world frame, m.
    pub x: f32,
    /// Position north, world frame, m.
    pub y: f32,
    /// Heading, rad counter-clockwise from +x (east).
    pub yaw: f32,
}

impl Pose2 {
    /// The pose at (`x`, `y`) m with heading `yaw` rad, world frame.
    pub fn new(x: f32, y: f32, yaw: f32) -> Self {
        Self { x, y, yaw }
    }
}

/// How the ego moved from the previous tick to this one, in the previous ego frame.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct EgoMotion {
    /// Forward translation of the ego origin, previous ego frame (x forward), m.
    pub dx: f32,
    /// Leftward translation of the ego origin, previous ego frame (y left), m.
    pub dy: f32,
    /// Heading change, radians, counter-clockwise positive.
    pub dyaw: f32,
}

impl EgoMotion {
    /// The motion that takes the ego from `previous` to `current`.
    pub fn between(previous: Pose2, current: Pose2) -> Self {
        let offset = [current.x - previous.x, current.y - previous.y];
        let [dx, dy] = world_to_ego(offset, previous.yaw);
        Self {
            dx,
            dy,
            dyaw: wrap_angle(current.yaw - previous.yaw),
        }
    }

    /// Where a point of the current ego frame lies in the previous ego frame.
    pub fn to_previous(&self, point: [f32; 2]) -> [f32; 2] {
        let (s, c) = self.dyaw.sin_cos();
        [
            c * point[0] - s * point[1] + self.dx,
            s * point[0] + c * point[1] + self.dy,
        ]
    }
}
