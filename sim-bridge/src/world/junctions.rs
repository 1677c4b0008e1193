//! Which junction connectors conflict: a vehicle may enter a junction on one only while no
//! conflicting one is occupied (see [`super::traffic`]). Two connectors conflict when their
//! paths through the junction cross in plan or end in the same lane; both follow a connector
//! through the further pieces of the same junction that CARLA's files cut some into.

use std::collections::{BTreeMap, HashMap};

use glam::{DVec2, DVec3};

use crate::map::{LaneIdx, Map};

/// Most pieces a junction connector is followed through when looking for where it leads.
const MAX_CONNECTOR_PIECES: usize = 4;

/// Connector lanes that conflict: their paths through the junction (the lane and the further
/// pieces of the same junction it leads into) cross or end in the same lane. Comparing whole
/// paths matters where CARLA cuts connectors into pieces: a vehicle asking for the first
/// piece of its path must see the ego on a later piece of another that its path crosses.
pub fn conflicts(map: &Map) -> HashMap<LaneIdx, Vec<LaneIdx>> {
    let mut out: BTreeMap<LaneIdx, Vec<LaneIdx>> = BTreeMap::new();
    for j in &map.junctions {
        let exits: HashMap<LaneIdx, Vec<LaneIdx>> =
            j.lanes.iter().map(|&l| (l, exits(map, l))).collect();
        let path = |lane: LaneIdx| {
            std::iter::once(lane).chain(
                exits[&lane]
                    .iter()
                    .copied()
                    .filter(|&e| map.lane(e).junction == Some(j.idx)),
            )
        };
        let paths_cross = |a: LaneIdx, b: LaneIdx| {
            path(a).any(|pa| {
                path(b).any(|pb| polylines_cross(&map.lane(pa).points, &map.lane(pb).points))
            })
        };
        for (a_i, &a) in j.lanes.iter().enumerate() {
            for &b in &j.lanes[a_i + 1..] {
                let (la, lb) = (map.lane(a), map.lane(b));
                let (ea, eb) = (&exits[&a], &exits[&b]);
                // One path cut into pieces (a connector whose lane id changes at a section
                // seam) does not conflict with itself.
                let chained = ea.contains(&b) || eb.contains(&a);
                let same_start = la.predecessors.iter().any(|p| lb.predecessors.contains(p));
                let merge = !chained && ea.iter().any(|e| eb.contains(e));
                if merge || (!chained && !same_start && paths_cross(a, b)) {
                    out.entry(a).or_default().push(b);
                    out.entry(b).or_default().push(a);
                }
            }
        }
    }
    out.into_iter().collect()
}

/// The lanes a junction lane leads into, through any further pieces of the same junction
/// (CARLA's files cut some connectors at section seams, down to pieces of half a metre): those
/// pieces themselves, then the first lanes beyond the junction. Two connectors whose paths end
/// in the same lane merge there even when one reaches it through such a piece.
fn exits(map: &Map, lane: LaneIdx) -> Vec<LaneIdx> {
    let junction = map.lane(lane).junction;
    let mut out = Vec::new();
    let mut frontier = map.lane(lane).successors.clone();
    for _ in 0..MAX_CONNECTOR_PIECES {
        let mut next = Vec::new();
        for l in frontier {
            if out.contains(&l) {
                continue;
            }
            out.push(l);
            if map.lane(l).junction == junction && junction.is_some() {
                next.extend(map.lane(l).successors.iter().copied());
            }
        }
        frontier = next;
    }
    out
}

fn polylines_cross(a: &[DVec3], b: &[DVec3]) -> bool {
    a.windows(2).any(|sa| {
        b.windows(2).any(|sb| {
            segments_cross(
                sa[0].truncate(),
                sa[1].truncate(),
                sb[0].truncate(),
                sb[1].truncate(),
            )
        })
    })
}

/// Proper intersection of two plan segments.
fn segments_cross(p1: DVec2, p2: DVec2, q1: DVec2, q2: DVec2) -> bool {
    let d1 = (p2 - p1).perp_dot(q1 - p1);
    let d2 = (p2 - p1).perp_dot(q2 - p1);
    let d3 = (q2 - q1).perp_dot(p1 - q1);
    let d4 = (q2 - q1).perp_dot(p2 - q1);
    d1 * d2 < 0.0 && d3 * d4 < 0.0
}
