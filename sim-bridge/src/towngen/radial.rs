//! `ssr_heldout_radial`, a held-out town of a layout family no training town has: two rings
//! round a centre, about 480 m across, joined by spokes, with no right angle anywhere. The
//! inner ring (radius 95 m, one lane each way with parking) and the outer ring (radius 230 m,
//! two lanes) are curved the whole way round; six two-lane spokes join them, and three more
//! run from every other inner junction to a three-way junction at the centre. Junctions meet
//! at 60, 90 and 120 degrees: four-way crossings on the inner ring, T-junctions on the outer
//! ring and a Y at the centre. The inner crossings and three outer T-junctions have traffic
//! lights; the Y is an all-way stop, and the other T-junctions have stop signs on their spokes.
//!
//! No training set drives it (`TownStyle::is_held_out`): it is part of the held-out suite
//! (`sim-bridge eval --suite unseen`), so that generalization is measured on a town that no
//! data, checkpoint choice or controller constant has touched.

use std::f64::consts::TAU;

use glam::DVec2;

use super::builder::{JunctionId, TownBuilder};
use super::geometry::Frame;
use super::profile::{Profile, setback};
use super::town::Town;

/// Junctions on each ring, evenly spaced.
const SPOKES: usize = 6;
/// The rings' radii, metres.
const INNER: f64 = 95.0;
const OUTER: f64 = 230.0;
/// Straight road a ring street keeps beyond each junction's setback before its arc begins,
/// metres: the arc's radius is what is left of the corner.
const STRAIGHT: f64 = 3.0;
/// A turned layout, so that no street lines up with the map axes.
const ROTATION: f64 = 15.0;
/// Outer T-junctions (by spoke) with lights; the others have stop signs on the spoke.
const SIGNALIZED_OUTER: [usize; 3] = [0, 2, 5];

/// Build the town.
pub fn build() -> Town {
    let inner_ring = Profile::street(1, true, 30);
    let outer_ring = Profile::street(2, false, 50);
    let spoke = Profile::street(2, false, 40);
    let mut b = TownBuilder::new("ssr_heldout_radial", Frame::new(ROTATION, 0.0, 0.0));

    let at = |radius: f64, k: usize| {
        let angle = TAU * k as f64 / SPOKES as f64;
        DVec2::new(radius * angle.cos(), radius * angle.sin())
    };
    // Junctions where three roads meet at 60 degrees need more room than a crossing.
    let wide = |profiles: &[&Profile]| setback(profiles) * 1.3;
    let centre = b.junction("C", DVec2::ZERO, wide(&[&spoke]));
    let inner: Vec<JunctionId> = (0..SPOKES)
        .map(|k| b.junction(format!("I{k}"), at(INNER, k), wide(&[&inner_ring, &spoke])))
        .collect();
    let outer: Vec<JunctionId> = (0..SPOKES)
        .map(|k| {
            b.junction(
                format!("O{k}"),
                at(OUTER, k),
                setback(&[&outer_ring, &spoke]),
            )
        })
        .collect();

    // Each ring street: an arc through the corner where the tangents at its two junctions meet.
    let half_step = TAU / SPOKES as f64 / 2.0;
    let ring_streets = [
        (&inner, INNER, &inner_ring, wide(&[&inner_ring, &spoke])),
        (&outer, OUTER, &outer_ring, setback(&[&outer_ring, &spoke])),
    ];
    for (ring, radius, profile, junction_setback) in ring_streets {
        // From a junction to the corner is radius * tan(half_step); the arc takes all of it
        // but the setback and a short straight.
        let arc = (radius * half_step.tan() - junction_setback - STRAIGHT) / half_step.tan();
        for k in 0..SPOKES {
            let corner_angle = TAU * k as f64 / SPOKES as f64 + half_step;
            let corner =
                DVec2::new(corner_angle.cos(), corner_angle.sin()) * (radius / half_step.cos());
            b.street_via(ring[k], &[corner], arc, ring[(k + 1) % SPOKES], profile);
        }
    }
    let mut spokes = Vec::with_capacity(SPOKES);
    let mut to_centre = Vec::new();
    for k in 0..SPOKES {
        spokes.push(b.street(inner[k], outer[k], &spoke));
        if k % 2 == 0 {
            to_centre.push(b.street(centre, inner[k], &spoke));
        }
    }

    b.stop_signs(centre, &to_centre);
    for k in (0..SPOKES).step_by(2) {
        b.lights(inner[k]);
    }
    for k in (1..SPOKES).step_by(2) {
        b.stop_signs(inner[k], &[spokes[k]]);
    }
    for (k, &j) in outer.iter().enumerate() {
        if SIGNALIZED_OUTER.contains(&k) {
            b.lights(j);
        } else {
            b.stop_signs(j, &[spokes[k]]);
        }
    }
    b.build()
}
