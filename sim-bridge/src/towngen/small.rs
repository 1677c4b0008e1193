//! `ssr_train_small`, a training town like CARLA Town01/02: about 300 x 250 m
//! of one-lane streets. A rounded rectangular loop holds two north-south
//! streets, and short east-west streets join them to each other and to the
//! loop, so nearly every junction is a T. Three junctions have lights; the
//! stems of the others have stop signs.

use glam::DVec2;

use super::builder::{JunctionId, RoadId, TownBuilder};
use super::geometry::Frame;
use super::profile::{Profile, setback};
use super::town::Town;

/// The loop's centre line: x = ±LOOP_X, y = ±LOOP_Y.
const LOOP_X: f64 = 145.0;
const LOOP_Y: f64 = 120.0;
/// The radius of the loop's corners.
const CORNER: f64 = 25.0;
/// The two north-south streets' x.
const WEST_ST: f64 = -50.0;
const EAST_ST: f64 = 60.0;

/// Build the town.
pub fn build() -> Town {
    let street = Profile::street(1, false, 30);
    let parked = Profile::street(1, true, 30);
    let mut b = TownBuilder::new("ssr_train_small", Frame::IDENTITY);
    let mut at = |name: &str, x: f64, y: f64, cross: &Profile| {
        b.junction(name, DVec2::new(x, y), setback(&[&street, cross]))
    };
    // The west street has parking, so its junctions are wider.
    let w_s = at("WS", WEST_ST, -LOOP_Y, &parked);
    let w_60 = at("W-60", WEST_ST, -60.0, &parked);
    let w_10 = at("W-10", WEST_ST, -10.0, &parked);
    let w30 = at("W30", WEST_ST, 30.0, &parked);
    let w_n = at("WN", WEST_ST, LOOP_Y, &parked);
    let e_s = at("ES", EAST_ST, -LOOP_Y, &street);
    let e_70 = at("E-70", EAST_ST, -70.0, &street);
    let e_10 = at("E-10", EAST_ST, -10.0, &street);
    let e50 = at("E50", EAST_ST, 50.0, &street);
    let e_n = at("EN", EAST_ST, LOOP_Y, &street);
    let lw30 = at("LW30", -LOOP_X, 30.0, &street);
    let lw_10 = at("LW-10", -LOOP_X, -10.0, &street);
    let lw_60 = at("LW-60", -LOOP_X, -60.0, &street);
    let le50 = at("LE50", LOOP_X, 50.0, &street);
    let le_70 = at("LE-70", LOOP_X, -70.0, &street);

    let corner = |x: f64, y: f64| DVec2::new(x * LOOP_X, y * LOOP_Y);
    // The loop, counter-clockwise from the east side.
    b.street(le_70, le50, &street);
    b.street_via(le50, &[corner(1.0, 1.0)], CORNER, e_n, &street);
    b.street(e_n, w_n, &street);
    b.street_via(w_n, &[corner(-1.0, 1.0)], CORNER, lw30, &street);
    b.street(lw30, lw_10, &street);
    b.street(lw_10, lw_60, &street);
    b.street_via(lw_60, &[corner(-1.0, -1.0)], CORNER, w_s, &street);
    b.street(w_s, e_s, &street);
    b.street_via(e_s, &[corner(1.0, -1.0)], CORNER, le_70, &street);

    // The north-south streets.
    let west: Vec<RoadId> = [w_s, w_60, w_10, w30, w_n]
        .windows(2)
        .map(|w| b.street(w[0], w[1], &parked))
        .collect();
    let east: Vec<RoadId> = [e_s, e_70, e_10, e50, e_n]
        .windows(2)
        .map(|w| b.street(w[0], w[1], &street))
        .collect();

    // The east-west streets.
    let r_60 = b.street(lw_60, w_60, &street);
    let r_10w = b.street(lw_10, w_10, &street);
    b.street(w_10, e_10, &street);
    let r30 = b.street(lw30, w30, &street);
    let r_70 = b.street(e_70, le_70, &street);
    let r50 = b.street(e50, le50, &street);

    for j in [w_10, e_10, e50] {
        b.lights(j);
    }
    let stops: [(JunctionId, RoadId); 12] = [
        (w_s, west[0]),
        (w_n, west[3]),
        (e_s, east[0]),
        (e_n, east[3]),
        (lw_60, r_60),
        (lw_10, r_10w),
        (lw30, r30),
        (le_70, r_70),
        (le50, r50),
        (w_60, r_60),
        (w30, r30),
        (e_70, r_70),
    ];
    for (j, stem) in stops {
        b.stop_signs(j, &[stem]);
    }
    b.build()
}
