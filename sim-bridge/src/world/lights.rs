//! Traffic-light controllers: one per signalized junction, giving green to one approach at a
//! time in a fixed cycle, as CARLA's default light groups do.
//!
//! Timing per approach: green [`GREEN_S`], yellow [`YELLOW_S`], then an all-red clearance of
//! [`ALL_RED_S`] before the next approach turns green. Each junction's cycle starts at an offset
//! drawn from the world seed, so lights are not synchronised across the town.

use rand::{Rng, RngExt as _};

use super::state::LightState;
use crate::map::Map;

/// Green time per approach, s.
pub const GREEN_S: f64 = 10.0;
/// Yellow time, s.
pub const YELLOW_S: f64 = 3.0;
/// All-red clearance between approaches, s.
pub const ALL_RED_S: f64 = 2.0;

/// The lights of a whole map.
#[derive(Debug, Clone)]
pub struct LightController {
    /// Per junction with lights: the light ids in cycle order and the cycle's time offset.
    groups: Vec<(Vec<usize>, f64)>,
    states: Vec<LightState>,
    /// Lights forced to a state by a scenario, with the time the force ends.
    forced: Vec<Option<(LightState, f64)>>,
}

impl LightController {
    /// Controllers for every signalized junction of `map`.
    pub fn new(map: &Map, rng: &mut impl Rng) -> Self {
        let mut groups = Vec::new();
        for j in map.junctions.iter().filter(|j| j.signalized) {
            let lights: Vec<usize> = j.approaches.iter().filter_map(|a| a.light).collect();
            if lights.is_empty() {
                continue;
            }
            let cycle = lights.len() as f64 * (GREEN_S + YELLOW_S + ALL_RED_S);
            groups.push((lights, rng.random_range(0.0..cycle)));
        }
        let n = map.lights.len();
        let mut c = Self {
            groups,
            states: vec![LightState::Red; n],
            forced: vec![None; n],
        };
        c.update(0.0);
        c
    }

    /// Set every light for sim time `t`.
    pub fn update(&mut self, t: f64) {
        let slot = GREEN_S + YELLOW_S + ALL_RED_S;
        for (lights, offset) in &self.groups {
            let cycle = lights.len() as f64 * slot;
            let phase = (t + offset).rem_euclid(cycle);
            let active = (phase / slot) as usize;
            let within = phase - active as f64 * slot;
            for (k, &id) in lights.iter().enumerate() {
                self.states[id] = if k != active {
                    LightState::Red
                } else if within < GREEN_S {
                    LightState::Green
                } else if within < GREEN_S + YELLOW_S {
                    LightState::Yellow
                } else {
                    LightState::Red
                };
            }
        }
        for (id, force) in self.forced.iter_mut().enumerate() {
            match *force {
                Some((state, until)) if t < until => self.states[id] = state,
                // A light held green that its cycle has moved past shows yellow first, as
                // any green does before red.
                Some((LightState::Green, until)) if self.states[id] != LightState::Green => {
                    *force = Some((LightState::Yellow, until + YELLOW_S));
                    self.states[id] = LightState::Yellow;
                }
                Some(_) => *force = None,
                None => {}
            }
        }
    }

    /// Hold light `id` at `state` until sim time `until` (scenarios S7-S9 do this); a green
    /// hold that ends while the cycle shows red ends with [`YELLOW_S`] of yellow.
    pub fn force(&mut self, id: usize, state: LightState, until: f64) {
        if let Some(f) = self.forced.get_mut(id) {
            *f = Some((state, until));
        }
    }

    /// Current states, indexed like `Map::lights`.
    pub fn states(&self) -> &[LightState] {
        &self.states
    }
}
