//! A uniform grid over lane centre-line segments, for "which lane is nearest this point" queries
//! that the world, the expert and the scorer ask every tick.
//!
//! A query visits the cells in growing square rings around the point and stops once no unvisited
//! cell can hold anything nearer than the best hit, so its cost tracks the local lane density.

use std::collections::HashMap;

use glam::DVec2;

use super::lanes::{Lane, LaneIdx, Projection};

/// Edge of a grid cell, metres.
const CELL: f64 = 8.0;

/// The segment index: (lane, segment) pairs bucketed by the cells their padded box touches.
#[derive(Debug, Default)]
pub struct SegmentGrid {
    cells: HashMap<(i32, i32), Vec<(LaneIdx, u32)>>,
    /// The cells that hold segments lie within these, inclusive (`None` when there are none).
    bounds: Option<((i32, i32), (i32, i32))>,
}

fn cell_of(p: DVec2) -> (i32, i32) {
    ((p.x / CELL).floor() as i32, (p.y / CELL).floor() as i32)
}

impl SegmentGrid {
    /// Index every segment of `lanes`.
    pub fn build(lanes: &[Lane]) -> Self {
        let mut cells: HashMap<(i32, i32), Vec<(LaneIdx, u32)>> = HashMap::new();
        let (mut lo, mut hi) = ((i32::MAX, i32::MAX), (i32::MIN, i32::MIN));
        for lane in lanes {
            for (i, w) in lane.points.windows(2).enumerate() {
                let (a, b) = (w[0].truncate(), w[1].truncate());
                let (c0, c1) = (cell_of(a.min(b)), cell_of(a.max(b)));
                for cx in c0.0..=c1.0 {
                    for cy in c0.1..=c1.1 {
                        cells
                            .entry((cx, cy))
                            .or_default()
                            .push((lane.idx, i as u32));
                    }
                }
                lo = (lo.0.min(c0.0), lo.1.min(c0.1));
                hi = (hi.0.max(c1.0), hi.1.max(c1.1));
            }
        }
        let bounds = (!cells.is_empty()).then_some((lo, hi));
        Self { cells, bounds }
    }

    /// The ring around `centre` beyond which no cell holds a segment.
    fn last_ring(&self, centre: (i32, i32)) -> i32 {
        self.bounds.map_or(-1, |(lo, hi)| {
            [
                centre.0 - lo.0,
                hi.0 - centre.0,
                centre.1 - lo.1,
                hi.1 - centre.1,
            ]
            .into_iter()
            .max()
            .unwrap_or(0)
            .max(0)
        })
    }

    /// The lane accepted by `keep` whose centre line is nearest `p` in plan, with the projection,
    /// searching no further than `max_distance` metres.
    pub fn nearest(
        &self,
        lanes: &[Lane],
        p: DVec2,
        max_distance: f64,
        keep: impl Fn(&Lane) -> bool,
    ) -> Option<(LaneIdx, Projection)> {
        if !p.is_finite() {
            return None;
        }
        let centre = cell_of(p);
        let mut best: Option<(LaneIdx, Projection)> = None;
        let max_ring = self
            .last_ring(centre)
            .min(((max_distance / CELL).ceil() as i32).saturating_add(1));
        for ring in 0..=max_ring {
            // Every point of ring r is at least (r - 1) * CELL away.
            let reach = (ring - 1).max(0) as f64 * CELL;
            if best.is_some_and(|(_, b)| b.distance < reach) {
                break;
            }
            for cell in ring_cells(centre, ring) {
                for (lane, proj) in self.projections(lanes, cell, p, &keep) {
                    if proj.distance <= max_distance
                        && best.is_none_or(|(bl, b)| {
                            proj.distance < b.distance || (proj.distance == b.distance && lane < bl)
                        })
                    {
                        best = Some((lane, proj));
                    }
                }
            }
        }
        best
    }

    /// Projections of `p` onto the segments indexed in `cell` whose lane `keep` accepts.
    fn projections<'a>(
        &'a self,
        lanes: &'a [Lane],
        cell: (i32, i32),
        p: DVec2,
        keep: &'a impl Fn(&Lane) -> bool,
    ) -> impl Iterator<Item = (LaneIdx, Projection)> + 'a {
        self.cells
            .get(&cell)
            .into_iter()
            .flatten()
            .filter_map(move |&(lane, seg)| {
                let l = &lanes[lane.get()];
                keep(l).then(|| (lane, l.project_segment(seg as usize, p)))
            })
    }

    /// Every lane accepted by `keep` with a segment within `radius` of `p`, each once with its
    /// nearest projection, nearest first.
    pub fn within(
        &self,
        lanes: &[Lane],
        p: DVec2,
        radius: f64,
        keep: impl Fn(&Lane) -> bool,
    ) -> Vec<(LaneIdx, Projection)> {
        let mut found: Vec<(LaneIdx, Projection)> = Vec::new();
        let (c0, c1) = (
            cell_of(p - DVec2::splat(radius)),
            cell_of(p + DVec2::splat(radius)),
        );
        for cx in c0.0..=c1.0 {
            for cy in c0.1..=c1.1 {
                for (lane, proj) in self.projections(lanes, (cx, cy), p, &keep) {
                    if proj.distance > radius {
                        continue;
                    }
                    match found.iter_mut().find(|(f, _)| *f == lane) {
                        Some((_, f)) if proj.distance < f.distance => *f = proj,
                        Some(_) => {}
                        None => found.push((lane, proj)),
                    }
                }
            }
        }
        found.sort_by(|a, b| a.1.distance.total_cmp(&b.1.distance).then(a.0.cmp(&b.0)));
        found
    }
}

/// The cells on the square ring `ring` around `c`.
fn ring_cells(c: (i32, i32), ring: i32) -> impl Iterator<Item = (i32, i32)> {
    let r = ring;
    (-r..=r).flat_map(move |dx| {
        (-r..=r)
            .filter_map(move |dy| (dx.abs() == r || dy.abs() == r).then_some((c.0 + dx, c.1 + dy)))
    })
}
