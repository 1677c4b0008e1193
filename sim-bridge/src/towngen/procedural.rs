//! Procedurally varied training towns, `ssr_proc_NNN`: one grid family whose every number
//! comes from a seed, so that training data covers many geometries instead of a few hand-made
//! towns (`sim-bridge towns procedural --seeds 1-24 --out DIR`).
//!
//! A town is a grid of 3-5 columns by 3-5 rows inside a loop with rounded corners, turned by a
//! random angle. What varies with the seed:
//! - spacing (60-130 m between lines) and each inner junction's place (up to 12 % of the
//!   spacing off the grid), so junctions meet at other than right angles;
//! - each column's and row's cross-section: 1-3 lanes each way, 3.1-3.7 m wide, with or without
//!   parking, 30-50 km/h; the loop's likewise;
//! - gaps: some inner stretches are left out, turning four-way junctions into T-junctions;
//! - bends: some inner stretches curve through an offset midpoint;
//! - control: lights at most multi-lane crossings and some others, stop signs on the minor
//!   approaches of others, some junctions free; in about a third of the towns the file carries
//!   no light at all and the simulator places its own, as on CARLA maps without signals.
//!
//! The tight family, `ssr_tight_NNN` ([`Bends::Tight`]), is the same grid with the bends of
//! small towns: mostly one lane each way, the loop's corners drawn with the inner kerb 3.5-8.5 m
//! from the centre of the turn (the innermost lane turning on about 5-10 m, as most corners of
//! CARLA's Town01 and Town04), and some inner stretches taking a detour of four right-angle
//! corners that tight. The first family's corners (18-40 m) are
//! wider than any of the CARLA towns' usual corners; agents trained on it alone cut tight ones.
//!
//! Either family comes with its lights across the junction (the default) or at the kerb before
//! the stop line ([`LightPlacement::Kerb`], as CARLA's Town01 and Town02 post them):
//! `ssr_proc_kerb_NNN`, `ssr_tight_kerb_NNN`, the same grid as the seed's other town, every
//! light in the file (none left to the simulator, which would place it across the junction).
//! No other training town posts every light beside its stop line, where a camera loses the
//! lamp as the car comes up to it. `--lights kerb-set-back` stands them 2-7 m before the line
//! (`ssr_tight_kerbback_NNN`): a car at the line has the head beside or behind it.
//!
//! Nothing else is random: the same seed and family give the same bytes. None of these towns is
//! an evaluation town; the held-out radial town is of another layout family.

use std::collections::BTreeSet;

use glam::DVec2;
use rand::{Rng, RngExt as _, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::builder::{JunctionId, RoadId, TownBuilder};
use super::geometry::Frame;
use super::profile::{Profile, Side, setback};
pub use super::signals::LightPlacement;
use super::town::Town;

/// Straight road kept beyond a junction's setback before a bend begins, metres.
const STRAIGHT: f64 = 3.0;

/// How the roads away from junctions bend: the family of a procedural town.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Bends {
    /// `ssr_proc_NNN`: loop corners of 18-40 m, some inner stretches gently bent.
    Gentle,
    /// `ssr_tight_NNN`: loop corners with the inner kerb 3.5-8.5 m from the turn's centre,
    /// some inner stretches detouring through four right-angle corners as tight.
    Tight,
}

/// A family of procedural towns: how their roads bend and where their lights stand.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Family {
    /// The bends.
    pub bends: Bends,
    /// Where the lights stand.
    pub lights: LightPlacement,
}

/// The name of the town of `seed` in `family`.
pub fn name(seed: u64, family: Family) -> String {
    let bends = match family.bends {
        Bends::Gentle => "proc",
        Bends::Tight => "tight",
    };
    match family.lights {
        LightPlacement::Across => format!("ssr_{bends}_{seed:03}"),
        LightPlacement::Kerb => format!("ssr_{bends}_kerb_{seed:03}"),
        LightPlacement::KerbSetBack => format!("ssr_{bends}_kerbback_{seed:03}"),
    }
}

/// A tight corner's radius for a road of `profile`: its inner sidewalk's back 0.5-5.5 m from
/// the centre of the turn, by `share` (0 to 1) of that range.
fn tight_radius(profile: &Profile, share: f64) -> f64 {
    profile.half_width() + 0.5 + 5.0 * share
}

/// A random cross-section: 1-3 lanes each way (2 most often; 1 most often in the tight
/// family, as in small towns), maybe parking, a speed for its size, lanes 3.1-3.7 m wide.
fn random_profile(rng: &mut impl Rng, bends: Bends) -> Profile {
    let lanes = match (bends, rng.random_range(0..20)) {
        (Bends::Gentle, 0..=6) | (Bends::Tight, 0..=9) => 1,
        (Bends::Gentle, 7..=15) | (Bends::Tight, 10..=17) => 2,
        _ => 3,
    };
    let parking = rng.random_bool(0.3);
    let speed = [30, 40, 50][lanes - 1 + usize::from(lanes == 1 && rng.random_bool(0.3))];
    Profile::street(lanes, parking, speed).with_lane_width(rng.random_range(3.1..3.7))
}

/// A junction being laid out: where it is and the streets that reach it.
struct Node {
    id: JunctionId,
    /// In layout axes.
    at: DVec2,
    /// How far its streets stop short of its centre.
    setback: f64,
    /// (street, whether it is a multi-lane street).
    legs: Vec<(RoadId, bool)>,
}

/// The town being laid out.
struct Layout {
    bends: Bends,
    /// The least distance between parallel lines (the next column or row, or the loop), nodes
    /// moved towards each other: what a detour and the street beyond share.
    line_gap: f64,
    /// Nodes a detour starts at (one per node).
    detoured: BTreeSet<usize>,
    b: TownBuilder,
    nodes: Vec<Node>,
}

impl Layout {
    fn node(&mut self, name: String, at: DVec2, profiles: &[&Profile]) -> usize {
        let setback = setback(profiles) + 1.0;
        let id = self.b.junction(name, at, setback);
        self.nodes.push(Node {
            id,
            at,
            setback,
            legs: Vec::new(),
        });
        self.nodes.len() - 1
    }

    /// A street from node `a` to node `b` through the corners `via`, rounded with `radius`.
    fn street(&mut self, a: usize, b: usize, via: &[DVec2], radius: f64, profile: &Profile) {
        let road = self
            .b
            .street_via(self.nodes[a].id, via, radius, self.nodes[b].id, profile);
        let multi_lane = profile.driving(Side::Right) >= 2;
        self.nodes[a].legs.push((road, multi_lane));
        self.nodes[b].legs.push((road, multi_lane));
    }

    /// An inner stretch from node `a` to node `b`: in the tight family a detour half the time
    /// ([`Self::detour`]), else straight; in the gentle family straight or bent through a
    /// midpoint moved sideways by up to a fifth of its length, where the bend leaves room for
    /// the junctions' setbacks.
    /// `beyond` is the profile of the next parallel line in +x or +y (a detour's side).
    fn street_maybe_bent(
        &mut self,
        rng: &mut impl Rng,
        (a, b): (usize, usize),
        profile: &Profile,
        beyond: &Profile,
    ) {
        if self.bends == Bends::Tight {
            if !(rng.random_bool(0.6) && self.detour(rng, (a, b), profile, beyond)) {
                self.street(a, b, &[], 0.0, profile);
            }
            return;
        }
        let (pa, pb) = (self.nodes[a].at, self.nodes[b].at);
        let half = (pb - pa).length() / 2.0;
        let room = half - setback(&[profile]) - 1.0 - STRAIGHT - 5.0;
        if room > 10.0 && rng.random_bool(0.3) {
            let offset =
                rng.random_range(0.08..0.2) * half * if rng.random_bool(0.5) { 1.0 } else { -1.0 };
            let normal = (pb - pa).perp().normalize();
            let corner = (pa + pb) / 2.0 + normal * offset;
            let turn = 2.0 * (offset.abs() / half).atan();
            // The rounding takes radius * tan(turn / 2) of each straight half.
            let radius = ((room - 2.0) / (turn / 2.0).tan()).min(600.0);
            self.street(a, b, &[corner], radius, profile);
        } else {
            self.street(a, b, &[], 0.0, profile);
        }
    }

    /// A street from node `a` to node `b` that leaves their line at a right angle, runs beside
    /// it and comes back: four right-angle corners of [`tight_radius`], each end keeping its
    /// junction's setback and a straight. It turns towards +x or +y of the layout, into the
    /// block whose south-west corner is `a`, so no two detours share a block (each node starts
    /// at most one) and none faces another; it stays a metre clear of the next line (of
    /// profile `beyond`). False, with nothing built, where the stretch or the block is too small.
    fn detour(
        &mut self,
        rng: &mut impl Rng,
        (a, b): (usize, usize),
        profile: &Profile,
        beyond: &Profile,
    ) -> bool {
        let (pa, pb) = (self.nodes[a].at, self.nodes[b].at);
        let length = (pb - pa).length();
        let along = (pb - pa) / length;
        let radius = tight_radius(profile, rng.random_range(0.0..1.0));
        let middle = 2.0 * radius + rng.random_range(2.0..12.0);
        let side = 2.0 * radius + rng.random_range(1.0..4.0);
        let before = self.nodes[a].setback + STRAIGHT + radius;
        let spare = length - before - middle - (self.nodes[b].setback + STRAIGHT + radius);
        if spare < 0.0
            || side + profile.half_width() + 1.0 + beyond.half_width() > self.line_gap
            || !self.detoured.insert(a)
        {
            return false;
        }
        let normal = if along.perp().x + along.perp().y < 0.0 {
            -along.perp()
        } else {
            along.perp()
        };
        let first = pa + along * (before + rng.random_range(0.0..=spare));
        let last = first + along * middle;
        let via = [first, first + normal * side, last + normal * side, last];
        self.street(a, b, &via, radius, profile);
        true
    }

    /// Lights (with chance `lights`) or else stop signs on the minor approaches (with chance
    /// `stops`; a junction whose streets are all alike gets them on a random pair), or nothing.
    fn control(&mut self, rng: &mut impl Rng, n: usize, lights: f64, stops: f64) {
        let node = &self.nodes[n];
        if rng.random_bool(lights) {
            self.b.lights(node.id);
            return;
        }
        if !rng.random_bool(stops) {
            return;
        }
        let minor: Vec<RoadId> = node.legs.iter().filter(|l| !l.1).map(|l| l.0).collect();
        let roads = if minor.is_empty() || minor.len() == node.legs.len() {
            let k = rng.random_range(0..node.legs.len());
            vec![node.legs[k].0]
        } else {
            minor
        };
        self.b.stop_signs(node.id, &roads);
    }
}

/// Positions from the middle outwards: `n` lines 60-130 m apart, centred on 0.
fn lines(rng: &mut impl Rng, n: usize) -> Vec<f64> {
    let steps: Vec<f64> = (1..n).map(|_| rng.random_range(60.0..130.0)).collect();
    let total: f64 = steps.iter().sum();
    let mut at = vec![-total / 2.0];
    for step in steps {
        at.push(at[at.len() - 1] + step);
    }
    at
}

/// Build the town of `seed` in `family`.
pub fn build(seed: u64, family: Family) -> Town {
    let bends = family.bends;
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let (cols, rows) = (rng.random_range(3..=5usize), rng.random_range(3..=5usize));
    let xs = lines(&mut rng, cols);
    let ys = lines(&mut rng, rows);
    let col_profiles: Vec<Profile> = (0..cols).map(|_| random_profile(&mut rng, bends)).collect();
    let row_profiles: Vec<Profile> = (0..rows).map(|_| random_profile(&mut rng, bends)).collect();
    let loop_profile = random_profile(&mut rng, bends);
    let loop_x = xs[cols - 1] + rng.random_range(55.0..100.0);
    let loop_y = ys[rows - 1] + rng.random_range(55.0..100.0);
    let corner_radius = match (bends, rng.random_range(18.0..40.0)) {
        (Bends::Gentle, radius) => radius,
        (Bends::Tight, radius) => tight_radius(&loop_profile, (radius - 18.0) / 22.0),
    };
    let rotation = rng.random_range(0.0..360.0);

    let min_step = |v: &[f64]| v.windows(2).map(|w| w[1] - w[0]).fold(f64::MAX, f64::min);
    let step = min_step(&xs).min(min_step(&ys));
    let jitter = 0.12 * step;
    let mut t = Layout {
        bends,
        line_gap: (step - 2.0 * jitter).min(55.0 - jitter),
        detoured: BTreeSet::new(),
        b: TownBuilder::new(name(seed, family), Frame::new(rotation, 0.0, 0.0)),
        nodes: Vec::new(),
    };
    t.b.place_lights(family.lights);
    // Drawn in every family, so that a seed's towns share their grid.
    let leave_lights = rng.random_bool(0.35);
    if leave_lights && family.lights == LightPlacement::Across {
        t.b.leave_lights_to_simulator();
    }

    // Inner junctions (node c * rows + r), each moved off the grid a little.
    for c in 0..cols {
        for r in 0..rows {
            let off = DVec2::new(
                rng.random_range(-jitter..jitter),
                rng.random_range(-jitter..jitter),
            );
            let profiles = [&col_profiles[c], &row_profiles[r]];
            t.node(
                format!("C{c}R{r}"),
                DVec2::new(xs[c], ys[r]) + off,
                &profiles,
            );
        }
    }
    let inner = |c: usize, r: usize| c * rows + r;
    // T-junctions on the loop where the columns and rows end.
    let side = |t: &mut Layout, name: &str, ats: Vec<(DVec2, &Profile)>| -> Vec<usize> {
        ats.into_iter()
            .enumerate()
            .map(|(i, (at, p))| t.node(format!("{name}{i}"), at, &[&loop_profile, p]))
            .collect()
    };
    let column_ends = |y: f64| {
        (0..cols)
            .map(|c| (DVec2::new(xs[c], y), &col_profiles[c]))
            .collect()
    };
    let row_ends = |x: f64| {
        (0..rows)
            .map(|r| (DVec2::new(x, ys[r]), &row_profiles[r]))
            .collect()
    };
    let south = side(&mut t, "S", column_ends(-loop_y));
    let north = side(&mut t, "N", column_ends(loop_y));
    let west = side(&mut t, "W", row_ends(-loop_x));
    let east = side(&mut t, "E", row_ends(loop_x));

    let gaps = left_out_stretches(&mut rng, cols, rows);

    for c in 0..cols {
        let p = &col_profiles[c];
        t.street(south[c], inner(c, 0), &[], 0.0, p);
        for r in 1..rows {
            if !gaps.contains(&(inner(c, r - 1), inner(c, r))) {
                let beyond = col_profiles.get(c + 1).unwrap_or(&loop_profile);
                t.street_maybe_bent(&mut rng, (inner(c, r - 1), inner(c, r)), p, beyond);
            }
        }
        t.street(inner(c, rows - 1), north[c], &[], 0.0, p);
    }
    for r in 0..rows {
        let p = &row_profiles[r];
        t.street(west[r], inner(0, r), &[], 0.0, p);
        for c in 1..cols {
            if !gaps.contains(&(inner(c - 1, r), inner(c, r))) {
                let beyond = row_profiles.get(r + 1).unwrap_or(&loop_profile);
                t.street_maybe_bent(&mut rng, (inner(c - 1, r), inner(c, r)), p, beyond);
            }
        }
        t.street(inner(cols - 1, r), east[r], &[], 0.0, p);
    }
    let ring = Ring {
        sides: [east, north, west, south],
        half_size: DVec2::new(loop_x, loop_y),
        corner_radius,
    };
    ring.lay(&mut t, &loop_profile);

    control_junctions(&mut t, &mut rng, cols * rows);
    t.b.build()
}

/// Inner stretches left out of a `cols` x `rows` grid (pairs of node indices, column-major):
/// each drawn with chance 0.15 where both its junctions still have four legs, so every junction
/// keeps three or more.
fn left_out_stretches(rng: &mut ChaCha8Rng, cols: usize, rows: usize) -> BTreeSet<(usize, usize)> {
    let inner = |c: usize, r: usize| c * rows + r;
    let mut legs = vec![4usize; cols * rows];
    let mut gaps = BTreeSet::new();
    for (a, b) in (0..cols)
        .flat_map(|c| (0..rows).map(move |r| (c, r)))
        .flat_map(|(c, r)| [((c, r), (c, r + 1)), ((c, r), (c + 1, r))])
        .filter(|&(_, (c2, r2))| c2 < cols && r2 < rows)
    {
        let (a, b) = (inner(a.0, a.1), inner(b.0, b.1));
        if rng.random_bool(0.15) && legs[a] == 4 && legs[b] == 4 {
            legs[a] = 3;
            legs[b] = 3;
            gaps.insert((a, b));
        }
    }
    gaps
}

/// The loop road around the grid: its T-junction nodes per side (east, north, west, south,
/// each in increasing coordinate), its half size and its corners' radius.
struct Ring {
    sides: [Vec<usize>; 4],
    half_size: DVec2,
    corner_radius: f64,
}

impl Ring {
    /// The loop, counter-clockwise: up the east side, west along the north, down the west
    /// side, east along the south, corners rounded.
    fn lay(&self, t: &mut Layout, profile: &Profile) {
        let corner = |x: f64, y: f64| DVec2::new(x, y) * self.half_size;
        let reversed = |v: &[usize]| v.iter().rev().copied().collect::<Vec<_>>();
        let [east, north, west, south] = &self.sides;
        let sides = [
            (east.clone(), corner(1.0, 1.0)),
            (reversed(north), corner(-1.0, 1.0)),
            (reversed(west), corner(-1.0, -1.0)),
            (south.clone(), corner(1.0, -1.0)),
        ];
        for (k, (nodes, turn)) in sides.iter().enumerate() {
            for w in nodes.windows(2) {
                t.street(w[0], w[1], &[], 0.0, profile);
            }
            let next = sides[(k + 1) % sides.len()].0[0];
            t.street(
                nodes[nodes.len() - 1],
                next,
                &[*turn],
                self.corner_radius,
                profile,
            );
        }
    }
}

/// Traffic control at every junction: the `inner` grid junctions get lights more often where
/// they have four legs and more lanes; the loop's T-junctions rarely.
fn control_junctions(t: &mut Layout, rng: &mut ChaCha8Rng, inner: usize) {
    for n in 0..inner {
        let multi_lane = t.nodes[n].legs.iter().any(|l| l.1);
        let lights = match (t.nodes[n].legs.len(), multi_lane) {
            (4, true) => 0.75,
            (4, false) => 0.35,
            _ => 0.3,
        };
        t.control(rng, n, lights, 0.75);
    }
    for n in inner..t.nodes.len() {
        t.control(rng, n, 0.2, 0.65);
    }
}
