//! The hazard head: from the scene tokens the control branch reads, what the car must wait for
//! now ([`Hazard`]: nothing, a light, a stop sign, a road user or traffic on the lane it
//! changes into).
//!
//! In training it asks the tokens for the cause of each expert stop (imitation alone gives a
//! red lamp of one or two pixels a weak, indirect gradient: the brake label is also explained
//! by the speed, the history and the junction ahead; LAV and TransFuser++ use such auxiliary
//! labels for the same reason; labels and loss are the trainer's, [`crate::train::hazard`]).
//! At serving it tells the controller when a stopped car has nothing to wait for: the unstick
//! rule creeps early while the head says [`Hazard::Clear`] (or [`Hazard::Sign`], which a car
//! that has stopped has served; `ssr_control::unstick`). It is in
//! the network, and in its checkpoints, when [`super::config::SsrConfig::hazard_head`] says so:
//! a [`super::classifier::TokenClassifier`] with a logit per [`Hazard`].

use ssrdrive_proto::dataset::BrakeReason;

/// What the car waits for: the head's classes, in logit order.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Hazard {
    /// Nothing: it drives on (or brakes only to follow its speed profile).
    Clear,
    /// A red light, or a yellow one it can still stop for.
    Light,
    /// A stop sign it has not yet stopped at.
    Sign,
    /// A vehicle, walker, obstacle or forecast collision.
    RoadUser,
    /// Traffic on the lane it must change into.
    LaneChange,
}

impl Hazard {
    /// Every class, in logit order.
    pub const ALL: [Hazard; 5] = [
        Hazard::Clear,
        Hazard::Light,
        Hazard::Sign,
        Hazard::RoadUser,
        Hazard::LaneChange,
    ];

    /// The class of a frame whose expert brakes for `reason` (if anything).
    pub fn of(reason: Option<BrakeReason>) -> Self {
        match reason {
            None => Hazard::Clear,
            Some(BrakeReason::TrafficLight) => Hazard::Light,
            Some(BrakeReason::StopSign) => Hazard::Sign,
            Some(BrakeReason::LaneChange) => Hazard::LaneChange,
            Some(
                BrakeReason::Vehicle
                | BrakeReason::Walker
                | BrakeReason::Obstacle
                | BrakeReason::PredictedCollision,
            ) => Hazard::RoadUser,
        }
    }

    /// The logit index.
    pub fn index(self) -> usize {
        self as usize
    }

    /// The validation group of frames braking for this hazard (`brake:light`, ...); `None`
    /// for [`Hazard::Clear`].
    pub fn situation(self) -> Option<&'static str> {
        match self {
            Hazard::Clear => None,
            Hazard::Light => Some("brake:light"),
            Hazard::Sign => Some("brake:sign"),
            Hazard::RoadUser => Some("brake:road-user"),
            Hazard::LaneChange => Some("brake:lane-change"),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_brake_reason_has_a_class_and_a_group() {
        for reason in [
            BrakeReason::Vehicle,
            BrakeReason::Walker,
            BrakeReason::Obstacle,
            BrakeReason::TrafficLight,
            BrakeReason::StopSign,
            BrakeReason::LaneChange,
            BrakeReason::PredictedCollision,
        ] {
            let hazard = Hazard::of(Some(reason));
            assert_ne!(hazard, Hazard::Clear);
            assert!(hazard.situation().unwrap().starts_with("brake:"));
        }
        assert_eq!(Hazard::of(None), Hazard::Clear);
        assert_eq!(Hazard::Clear.situation(), None);
        for (i, hazard) in Hazard::ALL.iter().enumerate() {
            assert_eq!(hazard.index(), i);
        }
    }
}
