//! One background vehicle: where it is on its lane, how fast it goes and where it goes next.
//! [`super::traffic`] moves the vehicles; [`super::ego_watch`] reads them to decide how they
//! treat the ego.

use glam::{DVec2, DVec3};

use super::state::Obb;
use crate::map::{LaneIdx, Map};

/// One background vehicle.
#[derive(Debug, Clone)]
pub struct Vehicle {
    /// Actor id (unique in the world).
    pub id: u32,
    /// Current lane.
    pub lane: LaneIdx,
    /// Arc length along it.
    pub s: f64,
    /// Lateral offset from the lane centre (left positive), non-zero during a lane change.
    pub lateral: f64,
    /// Forward speed, m/s.
    pub speed: f64,
    /// Cruise speed, m/s.
    pub desired_speed: f64,
    /// The lanes it will take next (at least one unless at a dead end).
    pub next: Vec<LaneIdx>,
    /// Half length and half width, m.
    pub half: DVec2,
    /// Seconds spent (nearly) stopped in a row.
    pub stopped_for: f64,
    /// When it asked to enter the junction ahead.
    pub arrival: Option<f64>,
    /// Whether it already stopped at the stop sign ending its current lane.
    pub stopped_at_sign: bool,
    /// What it does besides following the traffic rules (scenario vehicles).
    pub script: Script,
    /// Paint colour index, for renderers.
    pub colour: u8,
}

/// A vehicle's part: background traffic, or a scenario's vehicle.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub enum Script {
    /// Background traffic: lights, signs, right of way.
    #[default]
    Traffic,
    /// Runs red lights and takes junctions whatever their right of way (the S7-S9 red-light
    /// runner, the S10 crossing vehicle).
    RunsReds,
    /// Stands until its scenario starts (Scenario5's vehicles).
    Waits,
    /// Stops this many metres short of the next junction on its path and stays (Scenario2's
    /// leading vehicle).
    StopsShortOfJunction(f64),
}

impl Vehicle {
    /// Whether it runs red lights and ignores right of way ([`Script::RunsReds`]).
    pub fn ignores_lights(&self) -> bool {
        self.script == Script::RunsReds
    }

    /// Whether it is background traffic rather than a scenario's vehicle.
    pub fn is_background(&self) -> bool {
        self.script == Script::Traffic
    }

    /// World position and heading.
    pub fn pose(&self, map: &Map) -> (DVec3, f64) {
        let pose = map.lane(self.lane).pose_at(self.s);
        let left = DVec2::from_angle(pose.yaw).perp() * self.lateral;
        (pose.position + left.extend(0.0), pose.yaw)
    }

    /// Ground box.
    pub fn obb(&self, map: &Map) -> Obb {
        let (p, yaw) = self.pose(map);
        Obb {
            centre: p.truncate(),
            yaw,
            half: self.half,
        }
    }
}
