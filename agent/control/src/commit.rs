//! Going on through the light the car started on (off by default). A car that a light held
//! (the hazard head's "light" at least [`Commit::held_probability`] while it stood) and that
//! the network itself then starts (its "clear" at least [`Commit::start_probability`] on the
//! first tick it moves; not the unstick rule's creep) saw that light turn green. A light stays
//! green 10 s and yellow 3 s after that (sim-bridge and CARLA), so for [`Commit::within_s`]
//! after the start it cannot be red at the line the car waited at.
//!
//! Why: where the light's head stands beside the stop line (CARLA's Town01 and Town02), the
//! lamp leaves the top of the frame a metre or two after the car starts; the network then puts
//! the scene down to "a light" again and brakes, and the car stands at the line, blind, through
//! the rest of the green and the next red (`sim-bridge replay LOG --ticks`, Town02 route 10: the
//! bundled network at 247.5 s, v13L at 204 s; the plain 50 s wait of [`super::unstick`] then
//! creeps it on, into a red as often as not). While the commitment lasts, a tick on which the
//! hazard head puts the scene down to a light is driven on at up to [`Commit::speed`] instead;
//! the [`super::safety`] stop still acts on whatever the occupancy head sees on the path.
//!
//! A variant that committed a moving car for up to a yellow's length after a light head last
//! saw its lamp green was tried and removed: on held-out Town02 the committed car rolled on
//! through yellow into red (`agent/models/candidates/README.md`, v9-v19-blend-50-lh).

use serde::{Deserialize, Serialize};
use ssrdrive_proto::control::Control;

use super::Beliefs;
use super::unstick::{STOPPED_SPEED, TICKS_PER_SECOND};

/// Settings of the rule.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct Commit {
    /// Whether the rule acts.
    pub enabled: bool,
    /// The hazard head's "light" from which a standing car counts as held by a light, and a
    /// moving one as braking for it.
    pub held_probability: f32,
    /// The hazard head's "clear" on the first moving tick from which the start counts as the
    /// network's own (it saw green).
    pub start_probability: f32,
    /// Seconds after the start during which the car goes on through "a light".
    pub within_s: f32,
    /// Speed the car goes on at, at most, m/s.
    pub speed: f32,
    /// Throttle while below that speed.
    pub throttle: f32,
}

impl Default for Commit {
    fn default() -> Self {
        Self {
            enabled: false,
            held_probability: 0.5,
            start_probability: 0.9,
            within_s: 5.0,
            speed: 4.0,
            throttle: 0.5,
        }
    }
}

impl Commit {
    /// Checks ranges; the message names the field. `within_s` stays under a light's 10 s of
    /// green.
    pub fn validate(&self) -> Result<(), String> {
        super::check_ranges(&[
            ("commit.held_probability", self.held_probability, 0.0, 1.0),
            ("commit.start_probability", self.start_probability, 0.0, 1.0),
            ("commit.within_s", self.within_s, 0.05, 9.0),
            ("commit.speed", self.speed, 0.1, 10.0),
            ("commit.throttle", self.throttle, 0.0, 1.0),
        ])
    }
}

/// The rule's per-episode state.
#[derive(Debug, Clone, Default)]
pub struct CommitState {
    /// A light held the car in its current (or last) standstill.
    held: bool,
    /// Ticks of commitment left after a start on green.
    ticks_left: u32,
}

impl CommitState {
    /// The control to apply given the controller's `control` this tick (after the unstick
    /// rule; `unsticking` says whether its creep drives), the speed (m/s), the steer that
    /// follows the plan and what the network believes; and whether the rule overrode it.
    pub fn apply(
        &mut self,
        control: Control,
        speed: f32,
        plan_steer: f32,
        beliefs: &Beliefs,
        unsticking: bool,
        rule: &Commit,
    ) -> (Control, bool) {
        let (Some(light), Some(clear)) = (beliefs.light_hazard, beliefs.clear) else {
            return (control, false);
        };
        if !rule.enabled {
            return (control, false);
        }
        if speed < STOPPED_SPEED {
            self.ticks_left = 0;
            self.held |= light >= rule.held_probability;
            return (control, false);
        }
        if std::mem::take(&mut self.held) && !unsticking && clear >= rule.start_probability {
            self.ticks_left = (rule.within_s * TICKS_PER_SECOND).round() as u32;
        }
        if self.ticks_left == 0 {
            return (control, false);
        }
        self.ticks_left = self.ticks_left.saturating_sub(1);
        if unsticking || light < rule.held_probability {
            return (control, false);
        }
        let go = super::along_plan(plan_steer, speed, rule.speed, rule.throttle);
        (go, true)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const BRAKE: Control = Control {
        steer: 0.1,
        throttle: 0.0,
        brake: 1.0,
    };
    const DRIVE: Control = Control {
        steer: 0.1,
        throttle: 0.6,
        brake: 0.0,
    };

    fn hazard(clear: f32, light: f32) -> Beliefs<'static> {
        Beliefs {
            clear: Some(clear),
            light_hazard: Some(light),
            ..Beliefs::default()
        }
    }

    fn on() -> Commit {
        Commit {
            enabled: true,
            ..Commit::default()
        }
    }

    /// Stands 5 s with the hazard head's "light" at `light`, then moves off with its "clear" at
    /// `clear` (`crept`: the unstick rule's creep moves it); returns the rule's answer then.
    fn stand_then_start(
        state: &mut CommitState,
        rule: &Commit,
        light: f32,
        clear: f32,
        crept: bool,
    ) -> (Control, bool) {
        for _ in 0..100 {
            state.apply(BRAKE, 0.0, 0.0, &hazard(0.05, light), false, rule);
        }
        state.apply(DRIVE, 0.5, 0.0, &hazard(clear, 1.0 - clear), crept, rule)
    }

    /// Held by a light, then started by the network on "clear".
    fn started_on_green(state: &mut CommitState, rule: &Commit) {
        let start = stand_then_start(state, rule, 0.9, 0.98, false);
        assert_eq!(start, (DRIVE, false), "its own start stands");
    }

    /// The rule's answer to a brake for "a light" at 1 m/s.
    fn brake_for_a_light(state: &mut CommitState, rule: &Commit) -> (Control, bool) {
        state.apply(BRAKE, 1.0, 0.0, &hazard(0.3, 0.6), false, rule)
    }

    #[test]
    fn a_car_that_started_on_green_goes_on_when_its_lamp_leaves_the_frame() {
        let rule = on();
        let mut state = CommitState::default();
        started_on_green(&mut state, &rule);
        let (control, overridden) = state.apply(BRAKE, 2.0, 0.2, &hazard(0.34, 0.63), false, &rule);
        assert!(overridden);
        assert_eq!(
            (control.steer, control.brake),
            (0.2, 0.0),
            "plan steer, no brake"
        );
        assert_eq!(control.throttle, rule.throttle);
        let (fast, _) = state.apply(BRAKE, 5.0, 0.2, &hazard(0.34, 0.63), false, &rule);
        assert_eq!(fast.throttle, 0.0, "no faster than the rule's speed");
    }

    #[test]
    fn the_commitment_ends_after_its_window() {
        let rule = on();
        let mut state = CommitState::default();
        started_on_green(&mut state, &rule);
        // The start tick used one tick of the window.
        let window = (rule.within_s * TICKS_PER_SECOND) as usize;
        for _ in 1..window {
            assert!(brake_for_a_light(&mut state, &rule).1);
        }
        assert_eq!(brake_for_a_light(&mut state, &rule), (BRAKE, false));
    }

    #[test]
    fn only_a_brake_for_a_light_after_the_networks_own_start_is_overridden() {
        let rule = on();
        // A brake put down to something else (a vehicle: neither clear nor light).
        let mut state = CommitState::default();
        started_on_green(&mut state, &rule);
        let other = state.apply(BRAKE, 2.0, 0.0, &hazard(0.1, 0.2), false, &rule);
        assert_eq!(other, (BRAKE, false));
        // Starts that prove no green: the unstick rule's creep, a start the network was unsure
        // of, a start from a standstill no light held (behind a car).
        for (light, clear, crept) in [(0.9, 0.98, true), (0.9, 0.6, false), (0.1, 0.98, false)] {
            let mut state = CommitState::default();
            stand_then_start(&mut state, &rule, light, clear, crept);
            assert_eq!(
                brake_for_a_light(&mut state, &rule),
                (BRAKE, false),
                "light {light}, clear {clear}, crept {crept}"
            );
        }
    }

    #[test]
    fn off_by_default_and_without_the_hazard_head() {
        let mut state = CommitState::default();
        let rule = Commit::default();
        assert!(!rule.enabled);
        started_on_green(&mut state, &rule);
        assert_eq!(brake_for_a_light(&mut state, &rule), (BRAKE, false));
        let mut blind = CommitState::default();
        let none = Beliefs::default();
        assert_eq!(
            blind.apply(BRAKE, 0.0, 0.0, &none, false, &on()),
            (BRAKE, false)
        );
    }

    #[test]
    fn settings_outside_their_ranges_are_refused_by_name() {
        let long = Commit {
            within_s: 12.0,
            ..Commit::default()
        };
        assert!(long.validate().unwrap_err().contains("commit.within_s"));
        assert!(Commit::default().validate().is_ok());
    }
}
