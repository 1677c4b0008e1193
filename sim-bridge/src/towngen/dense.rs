//! `ssr_train_dense`, a training town of wide streets: a 3 x 3 grid inside
//! a rounded rectangular loop, about 350 x 300 m in its own axes and turned
//! 20 degrees so that no street lines up with the test town's. The middle
//! column and row are three-lane avenues, the other streets have two lanes
//! (the outer rows with parking). Every inner junction and every avenue end
//! has traffic lights; the other loop junctions have stop signs.

use glam::DVec2;

use super::builder::{JunctionId, RoadId, TownBuilder};
use super::geometry::Frame;
use super::profile::{Profile, setback};
use super::town::Town;

/// How far the grid is turned, in degrees counter-clockwise.
const ROTATION: f64 = 20.0;
/// Grid column x and row y in the town's own axes.
const COLS: [f64; 3] = [-85.0, 0.0, 85.0];
const ROWS: [f64; 3] = [-70.0, 0.0, 70.0];
/// The loop's centre line: x = ±LOOP_X, y = ±LOOP_Y.
const LOOP_X: f64 = 165.0;
const LOOP_Y: f64 = 140.0;
/// The radius of the loop's corners.
const CORNER: f64 = 30.0;
/// The index of the avenue among the columns and among the rows.
const AVENUE: usize = 1;

struct Profiles {
    avenue: Profile,
    side: Profile,
    parked: Profile,
    perimeter: Profile,
}

impl Profiles {
    fn new() -> Self {
        Self {
            avenue: Profile::street(3, false, 50),
            side: Profile::street(2, false, 40),
            parked: Profile::street(2, true, 40),
            perimeter: Profile::street(2, false, 40),
        }
    }

    fn column(&self, c: usize) -> &Profile {
        if c == AVENUE {
            &self.avenue
        } else {
            &self.side
        }
    }

    fn row(&self, r: usize) -> &Profile {
        if r == AVENUE {
            &self.avenue
        } else {
            &self.parked
        }
    }
}

/// Something on each side of the loop: its T-junctions, or the grid
/// streets that end in them, by column (south, north) or row (west, east).
struct Sides<T> {
    south: Vec<T>,
    north: Vec<T>,
    west: Vec<T>,
    east: Vec<T>,
}

impl<T> Sides<T> {
    fn all(&self) -> [&Vec<T>; 4] {
        [&self.south, &self.north, &self.west, &self.east]
    }
}

/// Build the town.
pub fn build() -> Town {
    let p = Profiles::new();
    let mut b = TownBuilder::new("ssr_train_dense", Frame::new(ROTATION, 0.0, 0.0));
    let grid = grid_junctions(&mut b, &p);
    let edges = edge_junctions(&mut b, &p);
    let stems = grid_streets(&mut b, &p, &grid, &edges);
    perimeter(&mut b, &p.perimeter, &edges);
    control(&mut b, &grid, &edges, &stems);
    b.build()
}

/// `grid[c][r]`.
fn grid_junctions(b: &mut TownBuilder, p: &Profiles) -> Vec<Vec<JunctionId>> {
    (0..COLS.len())
        .map(|c| {
            (0..ROWS.len())
                .map(|r| {
                    let at = DVec2::new(COLS[c], ROWS[r]);
                    let sb = setback(&[p.column(c), p.row(r)]);
                    b.junction(format!("C{c}R{r}"), at, sb)
                })
                .collect()
        })
        .collect()
}

fn edge_junctions(b: &mut TownBuilder, p: &Profiles) -> Sides<JunctionId> {
    let mut side = |name: &str, points: Vec<(DVec2, &Profile)>| -> Vec<JunctionId> {
        let edge = |(i, (at, cross)): (usize, (DVec2, &Profile))| {
            b.junction(format!("{name}{i}"), at, setback(&[&p.perimeter, cross]))
        };
        points.into_iter().enumerate().map(edge).collect()
    };
    let columns = |y: f64| (0..COLS.len()).map(move |c| (DVec2::new(COLS[c], y), p.column(c)));
    let rows = |x: f64| (0..ROWS.len()).map(move |r| (DVec2::new(x, ROWS[r]), p.row(r)));
    Sides {
        south: side("S", columns(-LOOP_Y).collect()),
        north: side("N", columns(LOOP_Y).collect()),
        west: side("W", rows(-LOOP_X).collect()),
        east: side("E", rows(LOOP_X).collect()),
    }
}

/// The columns from the south edge to the north and the rows from the west
/// edge to the east; the stretches that end on each edge.
fn grid_streets(
    b: &mut TownBuilder,
    p: &Profiles,
    grid: &[Vec<JunctionId>],
    edges: &Sides<JunctionId>,
) -> Sides<RoadId> {
    let mut line = |stops: Vec<JunctionId>, profile: &Profile| -> (RoadId, RoadId) {
        let roads: Vec<RoadId> = stops
            .windows(2)
            .map(|w| b.street(w[0], w[1], profile))
            .collect();
        (roads[0], roads[roads.len() - 1])
    };
    let mut stems = Sides {
        south: Vec::new(),
        north: Vec::new(),
        west: Vec::new(),
        east: Vec::new(),
    };
    for (c, column) in grid.iter().enumerate() {
        let mut stops = vec![edges.south[c]];
        stops.extend(column);
        stops.push(edges.north[c]);
        let (first, last) = line(stops, p.column(c));
        stems.south.push(first);
        stems.north.push(last);
    }
    for r in 0..ROWS.len() {
        let mut stops = vec![edges.west[r]];
        stops.extend(grid.iter().map(|column| column[r]));
        stops.push(edges.east[r]);
        let (first, last) = line(stops, p.row(r));
        stems.west.push(first);
        stems.east.push(last);
    }
    stems
}

/// The loop, counter-clockwise: up the east side, west along the north,
/// down the west side, east along the south, corners rounded.
fn perimeter(b: &mut TownBuilder, profile: &Profile, edges: &Sides<JunctionId>) {
    let corner = |x: f64, y: f64| DVec2::new(x * LOOP_X, y * LOOP_Y);
    let reversed = |v: &Vec<JunctionId>| v.iter().rev().copied().collect::<Vec<_>>();
    let sides = [
        (edges.east.clone(), corner(1.0, 1.0)),
        (reversed(&edges.north), corner(-1.0, 1.0)),
        (reversed(&edges.west), corner(-1.0, -1.0)),
        (edges.south.clone(), corner(1.0, -1.0)),
    ];
    for (k, (side, turn)) in sides.iter().enumerate() {
        for w in side.windows(2) {
            b.street(w[0], w[1], profile);
        }
        let next = sides[(k + 1) % sides.len()].0[0];
        b.street_via(side[side.len() - 1], &[*turn], CORNER, next, profile);
    }
}

fn control(
    b: &mut TownBuilder,
    grid: &[Vec<JunctionId>],
    edges: &Sides<JunctionId>,
    stems: &Sides<RoadId>,
) {
    for &j in grid.iter().flatten() {
        b.lights(j);
    }
    for (junctions, roads) in edges.all().into_iter().zip(stems.all()) {
        for (i, (&j, &stem)) in junctions.iter().zip(roads).enumerate() {
            if i == AVENUE {
                b.lights(j);
            } else {
                b.stop_signs(j, &[stem]);
            }
        }
    }
}
