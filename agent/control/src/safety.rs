//! The safety stop: brake when the network itself believes the path just ahead is occupied.
//!
//! An imitation agent copies the expert's slowing near a road user but not always the moment
//! it must stop: the learner crept at the expert's 2 m/s into walkers it had slowed for, and
//! drove into stopped cars it had seen for two seconds. The network's occupancy head
//! (`ssr_agent::model::occupancy`) says per BEV cell how likely a road user covers it; the
//! caller hands this rule the centres of the cells at or above [`SafetyStop::threshold`]. When
//! one lies on the planned path (within [`SafetyStop::half_width`] of it) closer than the
//! stopping distance (the ego's front, then [`SafetyStop::margin`], the distance covered in
//! [`SafetyStop::reaction_s`] and the braking distance at [`SafetyStop::decel`]), the car
//! brakes fully, whatever the fusion or the unstick rule said. This is InterFuser's safety
//! controller on a learned occupancy map, and the safety box of TransFuser++'s creep rule; it
//! uses nothing the network does not see.
//!
//! With [`SafetyStop::motion`], the cells the network's motion head believes a road user will
//! cover 1.5 s later (at [`SafetyStop::motion_threshold`]) count as well: a car crossing towards
//! the path is braked for before it is on it, which the current cells see too late (a
//! red-light runner seen from the side by one front camera).
//!
//! With [`SafetyStop::hold_s`], a stop lasts that long after the last tick the path looked
//! blocked. The occupancy head's belief in a car it has seen for seconds hovers about the
//! threshold, most of all for one standing across a bend: on Town02 route 10 (held out) the
//! stop fired for one to five ticks at a time while the car crept, each time released it, and
//! the car crept into a queue's last car standing in a corner, then round it into the
//! oncoming lane. Held, the car stands behind such a car until the path has looked clear for
//! `hold_s`.
//!
//! Where the plan is shorter than the distance checked (a car planning to stand still), the
//! path goes on straight along its last direction (straight ahead for a plan without one).
//!
//! The stop never turns a wait into a block: once it has held a stopped car for
//! [`SafetyStop::yield_after_s`] (the controller counts from the first tick it held the car,
//! until the car moves, so a cell that flickers about the threshold does not restart the
//! count), it lets the unstick rule's creep through. The leaderboard ends a route after 180 s
//! stopped ("agent blocked", the rest of the route lost), while a contact at a crawl costs a
//! penalty and the route goes on; a bundled agent stood for good at a right turn of the home
//! routes, held by cells beside its path.

use serde::{Deserialize, Serialize};
use ssrdrive_proto::control::Control;

use super::unstick::{STOPPED_SPEED, TICKS_PER_SECOND};

/// Settings of the rule.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct SafetyStop {
    /// Whether the rule acts.
    pub enabled: bool,
    /// Occupancy probability from which a cell counts as occupied. The default, 0.98, found
    /// 94 % of the validation frames with a vehicle 1-14 m ahead within 2 m of the axis, and 81 %
    /// of the frames where it saw one had one (an early checkpoint of the closed-loop recipe;
    /// the model card has the figures).
    pub threshold: f32,
    /// Distance from the ego origin (the box centre) to its front bumper, m (by default the
    /// sedan's half length; checkpoints written before it carry 2.4).
    pub front: f32,
    /// Half width of the corridor around the path, m (the ego's half width plus a margin).
    pub half_width: f32,
    /// Free distance always kept ahead of the bumper, m.
    pub margin: f32,
    /// Seconds of travel before the brakes act.
    pub reaction_s: f32,
    /// Deceleration the braking distance assumes, m/s^2.
    pub decel: f32,
    /// Seconds the stop may hold a stopped car before it lets the unstick rule's creep
    /// through.
    pub yield_after_s: f32,
    /// Seconds the stop goes on braking after the last tick the path looked blocked (0: it
    /// releases on the first clear tick).
    pub hold_s: f32,
    /// Whether the motion head's cells (where road users will be) count too; needs a network
    /// with that head.
    pub motion: bool,
    /// Probability from which a motion-head cell counts as occupied.
    pub motion_threshold: f32,
}

impl Default for SafetyStop {
    fn default() -> Self {
        Self {
            enabled: false,
            threshold: 0.98,
            front: ssrdrive_proto::vehicle::SEDAN.half_length as f32,
            half_width: 1.6,
            margin: 1.5,
            reaction_s: 0.5,
            decel: 5.0,
            yield_after_s: 100.0,
            hold_s: 0.0,
            motion: false,
            motion_threshold: 0.9,
        }
    }
}

impl SafetyStop {
    /// Checks ranges; the message names the field.
    pub fn validate(&self) -> Result<(), String> {
        let fields = [
            ("safety.threshold", self.threshold, 0.0, 1.0),
            ("safety.front", self.front, 0.0, 20.0),
            ("safety.half_width", self.half_width, 0.1, 10.0),
            ("safety.margin", self.margin, 0.0, 20.0),
            ("safety.reaction_s", self.reaction_s, 0.0, 5.0),
            ("safety.decel", self.decel, 0.5, 20.0),
            ("safety.yield_after_s", self.yield_after_s, 0.05, 3600.0),
            ("safety.hold_s", self.hold_s, 0.0, 10.0),
            ("safety.motion_threshold", self.motion_threshold, 0.0, 1.0),
        ];
        super::check_ranges(&fields)
    }

    /// How far along the path from the ego origin the corridor is checked at `speed` m/s.
    pub fn reach(&self, speed: f32) -> f32 {
        let speed = speed.max(0.0);
        self.front + self.margin + speed * self.reaction_s + speed * speed / (2.0 * self.decel)
    }

    /// Whether one of the `occupied` points (ego frame) lies on the path `waypoints` (ego
    /// frame, starting after the origin) within [`SafetyStop::reach`] at `speed`.
    pub fn blocked(&self, waypoints: &[[f32; 2]], speed: f32, occupied: &[[f32; 2]]) -> bool {
        if !self.enabled || occupied.is_empty() {
            return false;
        }
        let reach = self.reach(speed);
        let path = corridor_path(waypoints, reach);
        occupied.iter().any(|&point| {
            let mut start = 0.0;
            path.windows(2).enumerate().any(|(i, segment)| {
                let length = distance(segment[0], segment[1]);
                let along = along(point, segment[0], segment[1], length);
                // Behind the origin is behind the car; elsewhere the nearest point of the
                // segment counts, its end included, so the outside of a bend is covered.
                let nearest = along.clamp(0.0, length);
                let hit = (i > 0 || along >= 0.0)
                    && start + nearest <= reach
                    && distance(point, lerp(segment[0], segment[1], nearest / length))
                        <= self.half_width;
                start += length;
                hit
            })
        })
    }
}

/// The stop's per-episode state.
#[derive(Debug, Clone, Default)]
pub struct SafetyState {
    /// Ticks stopped since the stop first held the car in this standstill.
    held_ticks: u32,
    /// Whether the stop lets the current creep through (it held the car too long).
    yielding: bool,
    /// Ticks the stop goes on holding after the path last looked blocked.
    hold_ticks_left: u32,
}

impl SafetyState {
    /// The control to apply given the controller's `control` this tick (after the other
    /// rules; `unsticking` says whether the unstick rule is creeping), and whether the stop
    /// overrode it: full brake, steer kept.
    pub fn apply(
        &mut self,
        control: Control,
        waypoints: &[[f32; 2]],
        speed: f32,
        occupied: &[[f32; 2]],
        unsticking: bool,
        rule: &SafetyStop,
    ) -> (Control, bool) {
        let blocked = if rule.blocked(waypoints, speed, occupied) {
            self.hold_ticks_left = (rule.hold_s * TICKS_PER_SECOND).round() as u32;
            true
        } else if self.hold_ticks_left > 0 {
            self.hold_ticks_left -= 1;
            true
        } else {
            false
        };
        // Counted from the first tick it blocks a stopped car until the car moves: an
        // occupancy cell near the threshold comes and goes, and must not restart the count.
        self.held_ticks = if speed >= STOPPED_SPEED {
            0
        } else if blocked || self.held_ticks > 0 {
            self.held_ticks + 1
        } else {
            0
        };
        let held_too_long = self.held_ticks as f32 >= rule.yield_after_s * TICKS_PER_SECOND;
        // Once it yields, the stop lets the whole creep through, not just its first tick.
        self.yielding = unsticking && (self.yielding || held_too_long);
        if blocked && !self.yielding {
            let stop = Control {
                steer: control.steer,
                throttle: 0.0,
                brake: 1.0,
            };
            (stop, true)
        } else {
            (control, false)
        }
    }
}

/// The path from the origin through `waypoints`, extended straight along its last direction
/// until it is at least `reach` long.
fn corridor_path(waypoints: &[[f32; 2]], reach: f32) -> Vec<[f32; 2]> {
    let mut path = vec![[0.0, 0.0]];
    for &point in waypoints {
        // Repeated points (a plan to stand still) add no direction.
        if point.iter().all(|v| v.is_finite()) && distance(point, path[path.len() - 1]) > 0.1 {
            path.push(point);
        }
    }
    let length: f32 = path.windows(2).map(|s| distance(s[0], s[1])).sum();
    let last = path[path.len() - 1];
    let direction = match path.len() {
        1 => [1.0, 0.0],
        n => {
            let before = path[n - 2];
            let d = distance(before, last);
            [(last[0] - before[0]) / d, (last[1] - before[1]) / d]
        }
    };
    let extra = (reach - length).max(0.0) + 1.0;
    path.push([
        last[0] + direction[0] * extra,
        last[1] + direction[1] * extra,
    ]);
    path
}

fn distance(a: [f32; 2], b: [f32; 2]) -> f32 {
    (a[0] - b[0]).hypot(a[1] - b[1])
}

/// How far along the segment `a`-`b` (`length` apart, more than 0.1 m) from `a` the foot of
/// `point` lies (negative before `a`, beyond `length` after `b`).
fn along(point: [f32; 2], a: [f32; 2], b: [f32; 2], length: f32) -> f32 {
    ((point[0] - a[0]) * (b[0] - a[0]) + (point[1] - a[1]) * (b[1] - a[1])) / length
}

/// The point a fraction `t` of the way from `a` to `b`.
fn lerp(a: [f32; 2], b: [f32; 2], t: f32) -> [f32; 2] {
    [a[0] + (b[0] - a[0]) * t, a[1] + (b[1] - a[1]) * t]
}
