//! The unstick rule: an imitation agent that has stopped tends to stay stopped (its inputs say
//! "standing still", and standing still is what the expert did next in most such frames: the
//! inertia problem). After [`Unstick::after_s`] seconds below [`STOPPED_SPEED`], or after
//! [`Unstick::clear_after_s`] seconds below it during which the network's hazard head kept
//! saying "nothing to wait for" (probability at least [`Unstick::clear_probability`]; a stop
//! sign counts as nothing for a stopped car, [`Unstick::served_stop_signs`]), the car
//! creeps along its plan for [`Unstick::creep_s`] seconds at up to [`Unstick::creep_speed`],
//! then the counts start again.
//!
//! A light the network sees red or yellow (the light head's [`Beliefs::light`], probability at
//! least [`Unstick::light_hold_probability`]) holds the car: no creep starts and both waits
//! count again from the last tick it saw one, for at most [`Unstick::after_s`] of seeing it in
//! one standstill (no light stays red that long; on Town02 a green lamp cut by the top of the
//! frame held a car for good). The plain wait is for the network's inertia, not
//! for a light: a car that did not start on green, held past [`Unstick::after_s`], would
//! otherwise creep into the next red (seen on Town02, where the head stands beside the line in
//! full view). A standstill ends when the car drives faster than the creep, and a creep that
//! has started runs to its end (stopped at the first tick it moved, a creep never got a car
//! anywhere). The other way round, a light the light head sees green counts as nothing to
//! wait for: the hazard head's "light" weighs in [`Unstick::free_to_go`] by the probability of
//! green. Without the light head the rule is as before.
//!
//! TransFuser++'s rule creeps only when a LiDAR safety box is empty; here the [`super::safety`]
//! stop, where it is on, plays that part from the network's own occupancy head, and overrides
//! the creep. The plain wait is set longer than the longest red light of a four-way junction
//! (about 45 s in sim-bridge and CARLA), so a car held at a light is not pushed over its line,
//! and well under the leaderboard's 180 s "agent blocked". The early creep needs the hazard head
//! (`ssr_agent::model::hazard`), which tells a red light from a free road
//! (its "clear" on the frames where the expert starts from standstill: 96.7 %, and 96.0 % of
//! light stops named as such, in validation); without it only the plain wait acts. While
//! creeping, the trajectory's steer follows the plan (or the target point when the plan gives
//! no direction).

use serde::{Deserialize, Serialize};
use ssrdrive_proto::control::Control;

use super::Beliefs;

/// Below this speed (m/s) the car counts as stopped (the leaderboard's "blocked" speed).
pub const STOPPED_SPEED: f32 = 0.1;
/// Control ticks per second (the contract's tick, the leaderboard's 20 Hz).
pub const TICKS_PER_SECOND: f32 = ssrdrive_proto::TICK_HZ as f32;

/// Settings of the rule.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct Unstick {
    /// Whether the rule acts.
    pub enabled: bool,
    /// Seconds stopped before creeping.
    pub after_s: f32,
    /// Seconds stopped, with the hazard head saying "clear" every tick, before creeping.
    pub clear_after_s: f32,
    /// The hazard head's probability of "clear" from which a tick counts as clear.
    pub clear_probability: f32,
    /// Whether the head's "stop sign" counts as clear: a car that has stopped has served the
    /// sign (the leaderboard's criterion: below 0.1 m/s inside the sign's area), and the
    /// network, with 0.5 s of history, cannot tell a served sign from one still to serve.
    pub served_stop_signs: bool,
    /// Seconds of creeping.
    pub creep_s: f32,
    /// Speed the creep does not exceed, m/s.
    pub creep_speed: f32,
    /// Throttle while below the creep speed.
    pub creep_throttle: f32,
    /// The light head's probability of a red or yellow light ahead from which the car holds
    /// (no creep; the waits count from the last such tick), for at most [`Unstick::after_s`]
    /// of seeing it in one standstill.
    pub light_hold_probability: f32,
}

impl Default for Unstick {
    fn default() -> Self {
        Self {
            enabled: true,
            after_s: 50.0,
            clear_after_s: 3.0,
            clear_probability: 0.9,
            served_stop_signs: true,
            creep_s: 2.0,
            creep_speed: 2.0,
            creep_throttle: 0.5,
            light_hold_probability: 0.5,
        }
    }
}

impl Unstick {
    /// Checks ranges; the message names the field.
    pub fn validate(&self) -> Result<(), String> {
        let fields = [
            ("unstick.after_s", self.after_s, 0.05, 3600.0),
            ("unstick.clear_after_s", self.clear_after_s, 0.05, 3600.0),
            (
                "unstick.clear_probability",
                self.clear_probability,
                0.0,
                1.0,
            ),
            ("unstick.creep_s", self.creep_s, 0.05, 60.0),
            ("unstick.creep_speed", self.creep_speed, 0.1, 10.0),
            ("unstick.creep_throttle", self.creep_throttle, 0.0, 1.0),
            (
                "unstick.light_hold_probability",
                self.light_hold_probability,
                0.0,
                1.0,
            ),
        ];
        super::check_ranges(&fields)
    }

    /// The probability, for a stopped car, that nothing holds it: the hazard head's "clear",
    /// plus its "stop sign" where [`Unstick::served_stop_signs`] says so, plus its "light"
    /// times the light head's "green"; `None` without the hazard head.
    pub fn free_to_go(&self, beliefs: &Beliefs) -> Option<f32> {
        let served = beliefs
            .stop_sign
            .filter(|_| self.served_stop_signs)
            .unwrap_or(0.0);
        let green = beliefs
            .light_hazard
            .zip(beliefs.light)
            .map_or(0.0, |(hazard, light)| hazard * light.green);
        beliefs.clear.map(|p| p + served + green)
    }

    /// Whether the light head sees a light ahead that the car must stop at or stay behind.
    pub fn light_holds(&self, beliefs: &Beliefs) -> bool {
        beliefs
            .light
            .is_some_and(|light| light.stop >= self.light_hold_probability)
    }
}

/// The rule's per-episode state.
#[derive(Debug, Clone, Default)]
pub struct UnstickState {
    stopped_ticks: u32,
    clear_ticks: u32,
    creep_ticks_left: u32,
    /// Ticks of this standstill in which the light head saw a light to stop for.
    light_ticks: u32,
}

impl UnstickState {
    /// The control to apply given the controller's `control` this tick, the speed (m/s), the
    /// steer that follows the plan and what the network believes of the scene; and whether
    /// the rule overrode it.
    pub fn apply(
        &mut self,
        control: Control,
        speed: f32,
        plan_steer: f32,
        beliefs: &Beliefs,
        rule: &Unstick,
    ) -> (Control, bool) {
        if !rule.enabled {
            return (control, false);
        }
        // A light seen red for longer than the plain wait in one standstill (flicker or not)
        // is longer than any light stays red: a lamp half out of the frame, or another
        // approach's; the waits then go on.
        let holds = rule.light_holds(beliefs);
        let creeping = self.creep_ticks_left > 0;
        self.light_ticks = if speed >= rule.creep_speed {
            0
        } else {
            self.light_ticks + u32::from(holds)
        };
        if holds && !creeping && (self.light_ticks as f32) < rule.after_s * TICKS_PER_SECOND {
            *self = Self {
                light_ticks: self.light_ticks,
                ..Self::default()
            };
            return (control, false);
        }
        if !creeping {
            let stopped = speed < STOPPED_SPEED;
            let clear = stopped
                && rule
                    .free_to_go(beliefs)
                    .is_some_and(|p| p >= rule.clear_probability);
            self.stopped_ticks = if stopped { self.stopped_ticks + 1 } else { 0 };
            self.clear_ticks = if clear { self.clear_ticks + 1 } else { 0 };
            let waited = |ticks: u32, seconds: f32| ticks as f32 >= seconds * TICKS_PER_SECOND;
            if !waited(self.stopped_ticks, rule.after_s)
                && !waited(self.clear_ticks, rule.clear_after_s)
            {
                return (control, false);
            }
            self.stopped_ticks = 0;
            self.clear_ticks = 0;
            self.creep_ticks_left = (rule.creep_s * TICKS_PER_SECOND).ceil() as u32;
        }
        self.creep_ticks_left -= 1;
        let creep = super::along_plan(plan_steer, speed, rule.creep_speed, rule.creep_throttle);
        (creep, true)
    }
}
