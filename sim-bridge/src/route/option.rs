//! CARLA's RoadOption: the high-level command attached to each route point.

use serde::{Deserialize, Serialize};

/// The navigation command of a route point, with CARLA's numeric values.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum RoadOption {
    /// No command (-1); the model treats it as [`RoadOption::LaneFollow`].
    Void,
    /// Turn left at the junction (1).
    Left,
    /// Turn right at the junction (2).
    Right,
    /// Go straight through the junction (3).
    Straight,
    /// Follow the lane (4).
    LaneFollow,
    /// Change to the left lane (5).
    ChangeLaneLeft,
    /// Change to the right lane (6).
    ChangeLaneRight,
}

impl RoadOption {
    /// CARLA's integer value.
    pub fn value(self) -> i32 {
        match self {
            RoadOption::Void => -1,
            RoadOption::Left => 1,
            RoadOption::Right => 2,
            RoadOption::Straight => 3,
            RoadOption::LaneFollow => 4,
            RoadOption::ChangeLaneLeft => 5,
            RoadOption::ChangeLaneRight => 6,
        }
    }

    /// From CARLA's integer value; `None` for anything else.
    pub fn from_value(v: i32) -> Option<Self> {
        Some(match v {
            -1 => RoadOption::Void,
            1 => RoadOption::Left,
            2 => RoadOption::Right,
            3 => RoadOption::Straight,
            4 => RoadOption::LaneFollow,
            5 => RoadOption::ChangeLaneLeft,
            6 => RoadOption::ChangeLaneRight,
            _ => return None,
        })
    }

    /// CARLA's name, as written in route files and logs.
    pub fn name(self) -> &'static str {
        match self {
            RoadOption::Void => "VOID",
            RoadOption::Left => "LEFT",
            RoadOption::Right => "RIGHT",
            RoadOption::Straight => "STRAIGHT",
            RoadOption::LaneFollow => "LANEFOLLOW",
            RoadOption::ChangeLaneLeft => "CHANGELANELEFT",
            RoadOption::ChangeLaneRight => "CHANGELANERIGHT",
        }
    }

    /// Whether it is a lane change.
    pub fn is_lane_change(self) -> bool {
        matches!(
            self,
            RoadOption::ChangeLaneLeft | RoadOption::ChangeLaneRight
        )
    }

    /// Whether it is a junction manoeuvre (left, right or straight).
    pub fn is_junction(self) -> bool {
        matches!(
            self,
            RoadOption::Left | RoadOption::Right | RoadOption::Straight
        )
    }
}
