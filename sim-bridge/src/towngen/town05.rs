//! `ssr_town05`, the evaluation town, modelled on CARLA Town05: a 5 x 4
//! grid of two-lane streets (the middle columns with parking) inside a
//! three-lane ring road with rounded corners. The grid's columns meet the
//! ring's north and south sides and its rows the east side in T-junctions;
//! the rows' west ends are T-junctions on the westmost column, which leaves
//! the ring's west side free of junctions for an elevated stretch that
//! climbs to 8 m. Most inner four-way junctions have traffic lights; the
//! rest of the junctions have stop signs on their minor approaches or none.

use glam::DVec2;

use super::builder::{JunctionId, RoadId, TownBuilder};
use super::elevation;
use super::geometry::Frame;
use super::profile::{Profile, setback};
use super::town::Town;

/// Grid column x, west to east.
const COLS: [f64; 5] = [-150.0, -75.0, 0.0, 75.0, 150.0];
/// Grid row y, south to north.
const ROWS: [f64; 4] = [-120.0, -40.0, 40.0, 120.0];
/// The ring's centre line: x = ±RING_X, y = ±RING_Y.
const RING_X: f64 = 224.5;
const RING_Y: f64 = 189.5;
/// The radius of the ring's corners.
const CORNER: f64 = 35.0;
/// The elevated stretch: its height and the length of each ramp.
const BRIDGE_HEIGHT: f64 = 8.0;
const BRIDGE_RAMP: f64 = 100.0;
/// Inner junctions left without lights, as (column, row).
const UNSIGNALIZED: [(usize, usize); 2] = [(1, 3), (4, 0)];
/// East ring T-junctions (by row) with lights.
const SIGNALIZED_EAST: [usize; 2] = [1, 2];

struct Profiles {
    ring: Profile,
    street: Profile,
    parked: Profile,
}

impl Profiles {
    fn new() -> Self {
        Self {
            ring: Profile::street(3, false, 50),
            street: Profile::street(2, false, 40),
            parked: Profile::street(2, true, 40),
        }
    }

    /// The middle three columns have parking lanes.
    fn column(&self, c: usize) -> &Profile {
        if (1..=3).contains(&c) {
            &self.parked
        } else {
            &self.street
        }
    }
}

/// The junctions, by place.
struct Junctions {
    /// `grid[c][r]`.
    grid: Vec<Vec<JunctionId>>,
    /// Ring T-junctions on the south side, by column.
    south: Vec<JunctionId>,
    /// On the north side, by column.
    north: Vec<JunctionId>,
    /// On the east side, by row.
    east: Vec<JunctionId>,
}

/// The grid streets, by place.
struct Streets {
    /// `columns[c][k]`: the k-th stretch of column c from the south ring.
    columns: Vec<Vec<RoadId>>,
    /// `rows[r][k]`: the k-th stretch of row r from the west.
    rows: Vec<Vec<RoadId>>,
}

/// Build the town.
pub fn build() -> Town {
    let p = Profiles::new();
    let mut b = TownBuilder::new("ssr_town05", Frame::IDENTITY);
    let j = junctions(&mut b, &p);
    let streets = grid_streets(&mut b, &p, &j);
    ring_roads(&mut b, &p, &j);
    control(&mut b, &j, &streets);
    b.build()
}

fn junctions(b: &mut TownBuilder, p: &Profiles) -> Junctions {
    let grid = (0..COLS.len())
        .map(|c| {
            (0..ROWS.len())
                .map(|r| {
                    let at = DVec2::new(COLS[c], ROWS[r]);
                    b.junction(format!("C{c}R{r}"), at, setback(&[p.column(c), &p.street]))
                })
                .collect()
        })
        .collect();
    let mut side =
        |name: &str, at: DVec2, street: &Profile| b.junction(name, at, setback(&[&p.ring, street]));
    let south = (0..COLS.len())
        .map(|c| side(&format!("S{c}"), DVec2::new(COLS[c], -RING_Y), p.column(c)))
        .collect();
    let north = (0..COLS.len())
        .map(|c| side(&format!("N{c}"), DVec2::new(COLS[c], RING_Y), p.column(c)))
        .collect();
    let east = (0..ROWS.len())
        .map(|r| side(&format!("E{r}"), DVec2::new(RING_X, ROWS[r]), &p.street))
        .collect();
    Junctions {
        grid,
        south,
        north,
        east,
    }
}

/// Streets along `chain` of junctions, one per consecutive pair.
fn chain(b: &mut TownBuilder, chain: &[JunctionId], profile: &Profile) -> Vec<RoadId> {
    chain
        .windows(2)
        .map(|w| b.street(w[0], w[1], profile))
        .collect()
}

fn grid_streets(b: &mut TownBuilder, p: &Profiles, j: &Junctions) -> Streets {
    let columns = (0..COLS.len())
        .map(|c| {
            let mut stops = vec![j.south[c]];
            stops.extend(&j.grid[c]);
            stops.push(j.north[c]);
            chain(b, &stops, p.column(c))
        })
        .collect();
    let rows = (0..ROWS.len())
        .map(|r| {
            let mut stops: Vec<JunctionId> = (0..COLS.len()).map(|c| j.grid[c][r]).collect();
            stops.push(j.east[r]);
            chain(b, &stops, &p.street)
        })
        .collect();
    Streets { columns, rows }
}

/// The ring, counter-clockwise from the east side's southmost junction.
fn ring_roads(b: &mut TownBuilder, p: &Profiles, j: &Junctions) {
    let corner = |x: f64, y: f64| DVec2::new(x * RING_X, y * RING_Y);
    chain(b, &j.east, &p.ring);
    let last_east = *j.east.last().expect("rows");
    let last_north = *j.north.last().expect("columns");
    b.street_via(last_east, &[corner(1.0, 1.0)], CORNER, last_north, &p.ring);
    let westward: Vec<JunctionId> = j.north.iter().rev().copied().collect();
    chain(b, &westward, &p.ring);
    let west = b.street_via(
        j.north[0],
        &[corner(-1.0, 1.0), corner(-1.0, -1.0)],
        CORNER,
        j.south[0],
        &p.ring,
    );
    elevate_west_side(b, west);
    chain(b, &j.south, &p.ring);
    b.street_via(
        last_south(j),
        &[corner(1.0, -1.0)],
        CORNER,
        j.east[0],
        &p.ring,
    );
}

fn last_south(j: &Junctions) -> JunctionId {
    *j.south.last().expect("columns")
}

/// Raise the ring's west side: level round the corners, then up to
/// [`BRIDGE_HEIGHT`] and back down along the straight.
fn elevate_west_side(b: &mut TownBuilder, west: RoadId) {
    let length = b.length(west);
    let straight = 2.0 * RING_Y - 2.0 * CORNER;
    let start = (length - straight) / 2.0;
    b.set_elevation(
        west,
        elevation::hill(length, start, BRIDGE_RAMP, BRIDGE_HEIGHT),
    );
}

fn control(b: &mut TownBuilder, j: &Junctions, s: &Streets) {
    for c in 1..COLS.len() {
        for r in 0..ROWS.len() {
            if UNSIGNALIZED.contains(&(c, r)) {
                let column = [s.columns[c][r], s.columns[c][r + 1]];
                b.stop_signs(j.grid[c][r], &column);
            } else {
                b.lights(j.grid[c][r]);
            }
        }
    }
    for c in 0..COLS.len() {
        b.stop_signs(j.south[c], &[s.columns[c][0]]);
        b.stop_signs(j.north[c], &[*s.columns[c].last().expect("stretches")]);
    }
    for r in 0..ROWS.len() {
        if SIGNALIZED_EAST.contains(&r) {
            b.lights(j.east[r]);
        } else {
            b.stop_signs(j.east[r], &[*s.rows[r].last().expect("stretches")]);
        }
    }
}
