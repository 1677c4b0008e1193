//! The full stop at a stop sign (off by default). An imitation agent slows where the expert
//! stopped but does not always come to rest: it rolls over the line at a walking pace, and the
//! leaderboard counts a stop sign as served only once the car's speed drops below
//! [`STOPPED_SPEED`] (0.1 m/s) near the sign (`RunningStopTest`, 0.8 penalty). While the
//! network's hazard head puts what it brakes for down to a stop sign (probability at least
//! [`FullStop::probability`]) and the car has not stopped for that sign yet, this rule brakes
//! fully (steer as planned) until the car stands, whatever the head says meanwhile (its "sign"
//! flickers about the threshold as the car slows: on the radial town's route 8 a car braked on
//! and off from 7 m/s and rolled over the line at 0.5 m/s). The sign then counts as served, and
//! the rule rests until the head has not named a sign for [`FullStop::rearm_s`] seconds (the
//! car has left that sign behind). A car that stops on its own while the head names a sign
//! serves it the same way.
//!
//! The rule reads only what the network believes (the same head the [`super::unstick`] rule
//! reads), and acts where the network itself is braking for a sign, so it turns a roll into a
//! stop rather than adding stops of its own; without the hazard head it never acts.

use serde::{Deserialize, Serialize};
use ssrdrive_proto::control::Control;

use super::Beliefs;
use super::unstick::{STOPPED_SPEED, TICKS_PER_SECOND};

/// Settings of the rule.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct FullStop {
    /// Whether the rule acts.
    pub enabled: bool,
    /// The hazard head's "stop sign" from which the network counts as braking for a sign.
    pub probability: f32,
    /// Seconds without the head naming a sign after which the next sign needs its own stop.
    pub rearm_s: f32,
}

impl Default for FullStop {
    fn default() -> Self {
        Self {
            enabled: false,
            probability: 0.5,
            rearm_s: 3.0,
        }
    }
}

impl FullStop {
    /// Checks ranges; the message names the field.
    pub fn validate(&self) -> Result<(), String> {
        super::check_ranges(&[
            ("full_stop.probability", self.probability, 0.0, 1.0),
            ("full_stop.rearm_s", self.rearm_s, 0.05, 60.0),
        ])
    }
}

/// The rule's per-episode state.
#[derive(Debug, Clone, Default)]
pub struct FullStopState {
    /// The car has stood since the head last named a sign.
    served: bool,
    /// The rule is braking the car to a standstill.
    stopping: bool,
    /// Ticks since the head last named a sign.
    ticks_without_sign: u32,
}

impl FullStopState {
    /// The control to apply given the controller's `control` this tick, and whether this rule
    /// braked.
    pub fn apply(
        &mut self,
        control: Control,
        speed: f32,
        beliefs: &Beliefs,
        rule: &FullStop,
    ) -> (Control, bool) {
        let sign = rule.enabled && beliefs.stop_sign.is_some_and(|p| p >= rule.probability);
        if sign {
            self.ticks_without_sign = 0;
        } else {
            self.ticks_without_sign = self.ticks_without_sign.saturating_add(1);
            if self.ticks_without_sign as f32 >= rule.rearm_s * TICKS_PER_SECOND {
                self.served = false;
            }
        }
        self.stopping |= sign && !self.served;
        if speed < STOPPED_SPEED {
            self.served |= self.stopping;
            self.stopping = false;
            return (control, false);
        }
        if self.stopping {
            let stop = Control {
                steer: control.steer,
                throttle: 0.0,
                brake: 1.0,
            };
            return (stop, true);
        }
        (control, false)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const GO: Control = Control {
        steer: 0.1,
        throttle: 0.5,
        brake: 0.0,
    };

    fn beliefs(sign: f32) -> Beliefs<'static> {
        Beliefs {
            stop_sign: Some(sign),
            ..Beliefs::default()
        }
    }

    fn on() -> FullStop {
        FullStop {
            enabled: true,
            ..FullStop::default()
        }
    }

    #[test]
    fn brakes_for_a_sign_until_the_car_stands_then_lets_it_go() {
        let (rule, mut state) = (on(), FullStopState::default());
        let (control, braked) = state.apply(GO, 2.0, &beliefs(0.9), &rule);
        assert!(braked);
        assert_eq!(
            (control.steer, control.throttle, control.brake),
            (0.1, 0.0, 1.0)
        );
        // Standing: served; the network's own start goes through while it still sees the sign.
        assert_eq!(state.apply(GO, 0.05, &beliefs(0.9), &rule), (GO, false));
        assert_eq!(state.apply(GO, 1.0, &beliefs(0.9), &rule), (GO, false));
    }

    #[test]
    fn once_braking_for_a_sign_it_brakes_to_a_standstill_through_a_flicker() {
        let (rule, mut state) = (on(), FullStopState::default());
        assert!(state.apply(GO, 5.0, &beliefs(0.7), &rule).1);
        assert!(state.apply(GO, 0.5, &beliefs(0.3), &rule).1);
        assert!(!state.apply(GO, 0.0, &beliefs(0.3), &rule).1);
        assert!(!state.apply(GO, 1.0, &beliefs(0.7), &rule).1, "served");
    }

    #[test]
    fn the_next_sign_needs_its_own_stop_once_the_head_forgot_the_last() {
        let (rule, mut state) = (on(), FullStopState::default());
        state.apply(GO, 0.0, &beliefs(0.9), &rule);
        let ticks = (rule.rearm_s * TICKS_PER_SECOND) as usize;
        for _ in 0..ticks - 1 {
            assert!(!state.apply(GO, 5.0, &beliefs(0.1), &rule).1);
        }
        // One tick short of the re-arm, a sign is still the served one.
        assert!(!state.apply(GO, 5.0, &beliefs(0.9), &rule).1);
        for _ in 0..ticks {
            state.apply(GO, 5.0, &beliefs(0.1), &rule);
        }
        assert!(state.apply(GO, 5.0, &beliefs(0.9), &rule).1);
    }

    #[test]
    fn acts_on_nothing_when_off_below_its_probability_or_without_the_head() {
        let mut state = FullStopState::default();
        assert!(!state.apply(GO, 3.0, &beliefs(0.9), &FullStop::default()).1);
        assert!(!state.apply(GO, 3.0, &beliefs(0.4), &on()).1);
        assert!(!state.apply(GO, 3.0, &Beliefs::default(), &on()).1);
    }

    #[test]
    fn ranges_are_checked() {
        let bad = FullStop {
            probability: 1.5,
            ..on()
        };
        assert!(
            bad.validate()
                .unwrap_err()
                .contains("full_stop.probability")
        );
        assert!(on().validate().is_ok());
    }
}
