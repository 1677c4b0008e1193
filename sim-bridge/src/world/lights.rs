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

    /// Hold light `id` at `state` until sim time `until`; a green hold that ends while the
    /// cycle shows red ends with [`YELLOW_S`] of yellow.
    pub fn force(&mut self, id: usize, state: LightState, until: f64) {
        if let Some(f) = self.forced.get_mut(id) {
            *f = Some((state, until));
        }
    }

    /// Give light `id`'s junction a phase of its own until sim time `until` (scenarios S7-S9):
    /// `id` green, and every other light of the junction red until `id` has shown its yellow
    /// and the all-red clearance has passed, so that only the red-light runner crosses the
    /// ego's way, never traffic on a green of its own (scenario_runner's standalone runner
    /// scenario, `OppositeVehicleRunningRedLight`, holds the runner's light red the same way).
    pub fn hold_green(&mut self, id: usize, until: f64) {
        let others: Vec<usize> = self
            .groups
            .iter()
            .find(|(lights, _)| lights.contains(&id))
            .map(|(lights, _)| lights.iter().copied().filter(|&l| l != id).collect())
            .unwrap_or_default();
        for other in others {
            self.force(other, LightState::Red, until + YELLOW_S + ALL_RED_S);
        }
        self.force(id, LightState::Green, until);
    }

    /// Current states, indexed like `Map::lights`.
    pub fn states(&self) -> &[LightState] {
        &self.states
    }
}

#[cfg(test)]
mod tests {
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    use super::*;
    use crate::map::MapOptions;
    use crate::towngen::{TownStyle, bundled};

    #[test]
    fn a_green_hold_keeps_the_junctions_other_lights_red_until_it_has_turned_red() {
        let xml = bundled(TownStyle::DenseMultiLane);
        let map = Map::from_str("ssr_train_dense", xml, MapOptions::default()).unwrap();
        let held = &map.lights[0];
        let others: Vec<usize> = (map.lights.iter())
            .filter(|l| l.junction == held.junction && l.id != held.id)
            .map(|l| l.id)
            .collect();
        assert!(!others.is_empty(), "the junction has one light");
        let (hold, end) = (7.0, 7.0 + YELLOW_S + ALL_RED_S);
        let mut cycle_would_turn_one_green = 0;
        for seed in 0..8 {
            let new = || LightController::new(&map, &mut ChaCha8Rng::seed_from_u64(seed));
            let (mut free, mut lights) = (new(), new());
            lights.hold_green(held.id, hold);
            for tick in 0..(end / 0.05) as usize {
                let t = tick as f64 * 0.05;
                free.update(t);
                lights.update(t);
                let green = |c: &LightController, id: usize| c.states()[id] == LightState::Green;
                if others.iter().any(|&o| green(&free, o)) {
                    cycle_would_turn_one_green += 1;
                }
                if t < hold {
                    assert!(green(&lights, held.id), "seed {seed}, t = {t:.2}");
                }
                for &other in &others {
                    assert_eq!(
                        lights.states()[other],
                        LightState::Red,
                        "seed {seed}, t = {t:.2}"
                    );
                }
            }
        }
        // The hold is what keeps them red: their own cycles would have shown a green.
        assert!(cycle_would_turn_one_green > 0);
    }
}
