//! CARLA's RoadOption: the high-level command attached to each route point, the command an
//! agent is given every tick, and its one-hot encoding as the network reads it.

use serde::{Deserialize, Serialize};

/// Length of [`RoadOption::one_hot`]: the six commands the network tells apart.
pub const COMMANDS: usize = 6;

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

    /// Position of the command's 1 in [`RoadOption::one_hot`]: CARLA's value minus one, with
    /// [`RoadOption::Void`] read as [`RoadOption::LaneFollow`] (TCP's convention).
    pub fn one_hot_index(self) -> usize {
        match self {
            RoadOption::Void => RoadOption::LaneFollow.one_hot_index(),
            other => other.value() as usize - 1,
        }
    }

    /// The command as the network reads it.
    pub fn one_hot(self) -> [f32; COMMANDS] {
        let mut encoded = [0.0; COMMANDS];
        encoded[self.one_hot_index()] = 1.0;
        encoded
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
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn void_is_encoded_as_lane_follow() {
        assert_eq!(RoadOption::Void.one_hot(), RoadOption::LaneFollow.one_hot());
        assert_eq!(RoadOption::Left.one_hot(), [1.0, 0.0, 0.0, 0.0, 0.0, 0.0]);
        assert_eq!(RoadOption::ChangeLaneRight.one_hot_index(), COMMANDS - 1);
        for value in [-1, 1, 2, 3, 4, 5, 6] {
            let option = RoadOption::from_value(value).expect("a CARLA RoadOption value");
            assert_eq!(option.value(), value);
            assert_eq!(option.one_hot().iter().sum::<f32>(), 1.0);
        }
    }

    #[test]
    fn values_carla_does_not_define_are_refused() {
        for value in [0, 7, -2, i32::MAX, i32::MIN] {
            assert_eq!(RoadOption::from_value(value), None, "{value}");
        }
    }
}
