//! Background traffic: vehicles that follow lanes with the Intelligent Driver Model, pick a random
//! successor at each junction, stop for red (and, when they can, yellow) lights and at stop signs,
//! give way inside junctions, and now and then change lanes.
//!
//! Junction rule: a connector lane conflicts with another if their centre lines cross or they end
//! in the same lane (through any further pieces of the junction; [`super::junctions`]). A vehicle
//! within [`REQUEST_DISTANCE`] of a junction may enter when no conflicting connector is occupied
//! (by a vehicle or the ego) and no conflicting vehicle that arrived earlier is waiting to enter;
//! otherwise it holds at the stop line. It also needs room to leave the junction, CARLA's
//! traffic-manager junction exit check ([`EXIT_GAP`] beyond its own length past the junction's end,
//! behind the last vehicle there and those ahead of it inside; see [`has_exit_room`]): without it,
//! it holds at the stop line without a request, so it keeps no one waiting, and takes another way
//! through the junction that has room, if there is one. A vehicle that entered without room stopped
//! inside the junction, holding every connector that conflicts with its own, and queues spilling
//! back from junction to junction closed into cycles that never cleared (gridlock around Town02's
//! T-junctions). The ego waiting to enter a junction from an approach without a light takes its
//! turn among those requests ([`EgoPresence::junction_request`]), and the expert asks
//! [`Traffic::ego_may_enter`] before it goes: out of turn, both would end up inside the junction,
//! each waiting for the other. A vehicle whose path runs into a lane that ends (a lane drop, as on
//! CARLA's Town06 highways) merges into a neighbour that goes on, as CARLA's traffic manager does.
//! Near the ego, vehicles also keep clear of its box whatever lane it is on, and let it into a
//! lane it waits to change into ([`super::ego_watch`]; the courtesies, giving the ego its turn
//! and way included, are off in [`TrafficMode::Carla`]). Vehicles stuck for [`RESPAWN_AFTER_S`] out of the
//! ego's sight (more than [`RESPAWN_CLEARANCE`] away), or at such a lane end anywhere, are moved to
//! a free place elsewhere, as a stand-in for CARLA's traffic manager clearing jams.

use std::collections::HashMap;

use glam::DVec2;
use rand::{Rng, RngExt as _};

use super::ego_watch::{EgoPresence, TrafficMode, courtesy_hold, ego_on_path};
use super::idm::Idm;
use super::state::LightState;
use super::vehicle::{Script, Vehicle};
use crate::map::{LaneIdx, LaneKind, Map};

/// How background vehicles follow: gentler than the expert, with a longer headway, and slower
/// in curves than it (2.5 m/s^2 of lateral acceleration on junction connectors).
const IDM: Idm = Idm {
    accel: 2.0,
    decel: 3.0,
    min_gap: 2.5,
    headway: 1.2,
    lateral_accel: 2.5,
};
/// Hardest braking a background vehicle uses, m/s^2.
const MAX_DECEL: f64 = 8.0;
/// How far ahead a vehicle looks for leaders and stop lines, m.
const LOOKAHEAD: f64 = 60.0;
/// Distance to a junction at which a vehicle asks to enter it, m.
pub const REQUEST_DISTANCE: f64 = 10.0;
/// Stuck time before a vehicle is moved elsewhere, s.
pub const RESPAWN_AFTER_S: f64 = 40.0;
/// A stuck vehicle is moved only when farther than this from the ego, m.
pub const RESPAWN_CLEARANCE: f64 = 50.0;
/// Chance per second that a vehicle on a multi-lane road starts a lane change.
const LANE_CHANGE_RATE: f64 = 0.01;
/// Length over which connectors leaving the same lane still overlap, m.
const DIVERGE_LENGTH: f64 = 12.0;
/// Speed at which a lane change moves across, m/s.
const LATERAL_SPEED: f64 = 1.0;
/// The id the ego goes by in junction requests (vehicles have ids from 1000).
const EGO_ID: u32 = 0;
/// Gap a vehicle entering a junction wants past it, behind the last vehicle on its exit and
/// behind each vehicle ahead of it in the junction, m (CARLA's traffic manager keeps 4 m:
/// `SAFE_DISTANCE_AFTER_JUNCTION`).
const EXIT_GAP: f64 = 4.0;
/// Speed under which a vehicle or the ego counts as standing, m/s.
pub const STANDING_SPEED: f64 = 0.1;

/// Seconds stood in a row after a step of `dt` at `speed`, from `before`.
pub fn standing_time(before: f64, speed: f64, dt: f64) -> f64 {
    if speed < STANDING_SPEED {
        before + dt
    } else {
        0.0
    }
}

/// Occupants per lane: (arc length, half length, speed, id).
type Occupancy = HashMap<LaneIdx, Vec<(f64, f64, f64, u32)>>;

/// The background traffic of a world.
#[derive(Debug, Clone)]
pub struct Traffic {
    /// The vehicles.
    pub vehicles: Vec<Vehicle>,
    conflicts: HashMap<LaneIdx, Vec<LaneIdx>>,
    light_at_end: HashMap<LaneIdx, usize>,
    stop_at_end: HashMap<LaneIdx, usize>,
}

impl Traffic {
    /// Precompute junction conflicts and spawn `count` vehicles on free driving lanes, keeping
    /// `keep_clear` (the ego's start) free within 25 m.
    pub fn new(
        map: &Map,
        count: usize,
        keep_clear: DVec2,
        first_id: u32,
        rng: &mut impl Rng,
    ) -> Self {
        let mut light_at_end = HashMap::new();
        for light in &map.lights {
            for line in &light.stop_lines {
                light_at_end.insert(line.lane, light.id);
            }
        }
        let mut stop_at_end = HashMap::new();
        for sign in &map.stop_signs {
            for line in &sign.stop_lines {
                stop_at_end.insert(line.lane, sign.id);
            }
        }
        let mut traffic = Traffic {
            vehicles: Vec::new(),
            conflicts: super::junctions::conflicts(map),
            light_at_end,
            stop_at_end,
        };
        for k in 0..count {
            let Some((lane, s)) = traffic.free_spot(map, keep_clear, 25.0, rng) else {
                break;
            };
            let v = new_vehicle(map, first_id + k as u32, lane, s, rng);
            traffic.vehicles.push(v);
        }
        traffic
    }

    /// A random free place on a non-junction driving lane, at least `clearance` from `avoid`.
    fn free_spot(
        &self,
        map: &Map,
        avoid: DVec2,
        clearance: f64,
        rng: &mut impl Rng,
    ) -> Option<(LaneIdx, f64)> {
        let candidates: Vec<&crate::map::Lane> = map
            .lanes
            .iter()
            .filter(|l| {
                l.kind == LaneKind::Driving
                    && !l.in_junction()
                    && l.length() > 12.0
                    && !l.successors.is_empty()
            })
            .collect();
        if candidates.is_empty() {
            return None;
        }
        for _ in 0..200 {
            let lane = candidates[rng.random_range(0..candidates.len())];
            let s = rng.random_range(3.0..lane.length() - 3.0);
            let p = lane.pose_at(s).position.truncate();
            if (p - avoid).length() < clearance {
                continue;
            }
            let free = self
                .vehicles
                .iter()
                .all(|v| (v.pose(map).0.truncate() - p).length() > 9.0);
            if free {
                return Some((lane.idx, s));
            }
        }
        None
    }

    /// Add a scenario's vehicle on `lane` at `s`: (its script, its speed now, its cruise
    /// speed in m/s).
    pub fn spawn_scenario_vehicle(
        &mut self,
        map: &Map,
        id: u32,
        (lane, s): (LaneIdx, f64),
        (script, speed, cruise): (Script, f64, f64),
        rng: &mut impl Rng,
    ) {
        let mut v = new_vehicle(map, id, lane, s, rng);
        v.script = script;
        v.speed = speed;
        v.desired_speed = cruise;
        self.vehicles.push(v);
    }

    /// Send vehicle `id` through `connector` (a successor of its lane), then on at random.
    pub fn set_path(&mut self, map: &Map, id: u32, connector: LaneIdx, rng: &mut impl Rng) {
        if let Some(v) = self.vehicles.iter_mut().find(|v| v.id == id) {
            v.next = vec![connector];
            extend_path(map, v, rng);
        }
    }

    /// Advance every vehicle by `dt` at sim time `t`.
    pub fn step(
        &mut self,
        map: &Map,
        lights: &[LightState],
        ego: &EgoPresence,
        t: f64,
        dt: f64,
        rng: &mut impl Rng,
    ) {
        let occupancy = self.occupancy(map, Some(ego));
        self.avoid_full_exits(map, &occupancy, rng);
        let grants = self.junction_grants(map, lights, ego, &occupancy);
        let mut accels = Vec::with_capacity(self.vehicles.len());
        for (i, v) in self.vehicles.iter().enumerate() {
            let mut gap = self.free_distance(map, lights, &occupancy, i, grants[i]);
            if let Some(ego_gap) = ego_on_path(map, v, ego) {
                gap = gap.min_by_gap(ego_gap);
            }
            if let Some(hold) = courtesy_hold(map, v, ego) {
                gap = gap.min_by_gap((hold, 0.0));
            }
            accels.push(follow(v, gap.0, gap.1, map));
        }
        for (i, a) in accels.into_iter().enumerate() {
            self.advance(map, i, a, t, dt, rng);
        }
        self.lane_changes(map, &occupancy, dt, rng);
        self.respawn_stuck(map, ego, rng);
    }

    /// Vehicles (and the ego, when given) per lane: (s, half length, speed, id). Near the start
    /// of a junction connector, where connectors from one lane still overlap before they
    /// diverge, an occupant is listed on every sibling connector too, so followers keep their
    /// distance.
    fn occupancy(&self, map: &Map, ego: Option<&EgoPresence>) -> Occupancy {
        let mut occ: Occupancy = HashMap::new();
        let ego_entry = ego
            .and_then(|ego| ego.on_lane.map(|on_lane| (on_lane, ego)))
            .map(|((lane, s), ego)| (lane, s, ego.obb.half.x, ego.speed, EGO_ID));
        let entries = self
            .vehicles
            .iter()
            .map(|v| (v.lane, v.s, v.half.x, v.speed, v.id))
            .chain(ego_entry);
        for (lane, s, half, speed, id) in entries {
            occ.entry(lane).or_default().push((s, half, speed, id));
            let l = map.lane(lane);
            if l.in_junction() && s < DIVERGE_LENGTH {
                let siblings = l
                    .predecessors
                    .iter()
                    .flat_map(|p| map.lane(*p).successors.iter())
                    .filter(|x| **x != lane);
                for &sibling in siblings {
                    occ.entry(sibling).or_default().push((s, half, speed, id));
                }
            }
        }
        occ
    }

    /// Distance to the nearest thing to stop behind along the vehicle's path, and its speed.
    fn free_distance(
        &self,
        map: &Map,
        lights: &[LightState],
        occ: &Occupancy,
        i: usize,
        granted: bool,
    ) -> (f64, f64) {
        let v = &self.vehicles[i];
        let mut best = (f64::INFINITY, 0.0);
        let mut offset = -v.s;
        let path = std::iter::once(v.lane).chain(v.next.iter().copied());
        for (k, lane) in path.enumerate() {
            if offset > LOOKAHEAD {
                break;
            }
            let from = if k == 0 { v.s } else { f64::NEG_INFINITY };
            if let Some(list) = occ.get(&lane) {
                for &(s, half, speed, id) in list {
                    if id != v.id && s > from {
                        let gap = offset + s - half - v.half.x;
                        if gap < best.0 {
                            best = (gap, speed);
                        }
                    }
                }
            }
            let length = map.lane(lane).length();
            let to_end = offset + length - v.half.x;
            if k == 0 && to_end > -0.5 && self.must_stop_at_end(map, lights, v, to_end, granted) {
                best = best.min_by_gap((to_end.max(0.0), 0.0));
            }
            if k == 0 && v.next.is_empty() {
                best = best.min_by_gap((to_end.max(0.0) + 2.0, 0.0));
            }
            offset += length;
        }
        match v.script {
            Script::Waits => best.min_by_gap((0.0, 0.0)),
            Script::StopsShortOfJunction(short) => match junction_ahead(map, v) {
                Some(d) => best.min_by_gap(((d - short - v.half.x).max(0.0), 0.0)),
                None => best,
            },
            Script::Traffic | Script::RunsReds => best,
        }
    }

    /// Whether the vehicle must hold at the end of its current lane.
    fn must_stop_at_end(
        &self,
        map: &Map,
        lights: &[LightState],
        v: &Vehicle,
        to_end: f64,
        granted: bool,
    ) -> bool {
        if !approaching_junction(map, v) {
            return false;
        }
        if !v.ignores_lights()
            && let Some(&light) = self.light_at_end.get(&v.lane)
        {
            match lights[light] {
                LightState::Red => return true,
                LightState::Yellow if to_end > v.speed * v.speed / (2.0 * IDM.decel) => {
                    return true;
                }
                _ => {}
            }
        }
        if self.stop_at_end.contains_key(&v.lane) && !v.stopped_at_sign {
            return true;
        }
        to_end < REQUEST_DISTANCE && !granted
    }

    /// Which vehicles may enter the junction ahead now.
    fn junction_grants(
        &self,
        map: &Map,
        lights: &[LightState],
        ego: &EgoPresence,
        occ: &Occupancy,
    ) -> Vec<bool> {
        let mut occupied = self.junction_occupants(map);
        // The ego blocks the connector it is on, and, while it approaches a junction at speed,
        // every connector it could take: courteous traffic gives way to an ego about to enter.
        if let Some((lane, s)) = ego.on_lane {
            let l = map.lane(lane);
            if l.in_junction() {
                occupied.push(lane);
            } else if ego.mode == TrafficMode::Courteous
                && l.length() - s < REQUEST_DISTANCE + 2.0 * ego.speed
                && ego.speed > 1.0
            {
                occupied.extend(l.successors.iter().filter(|c| map.lane(**c).in_junction()));
            }
        }
        let requests = self.junction_requests(map, lights, occ);
        // The ego waiting to enter takes its turn among them.
        let ego_request = ego
            .junction_request
            .map(|(connector, arrival)| (connector, arrival, EGO_ID));
        let all: Vec<(LaneIdx, f64, u32)> = requests
            .iter()
            .flatten()
            .copied()
            .chain(ego_request)
            .collect();
        // Red-light runners (scenario vehicles) go regardless; a vehicle without room past the
        // junction holds, without a request.
        self.vehicles
            .iter()
            .zip(&requests)
            .map(|(v, request)| match *request {
                _ if v.ignores_lights() => true,
                Some(request) => self.may_go(request, &occupied, &all),
                None => !approaching_junction(map, v) || has_exit_room(map, v, occ),
            })
            .collect()
    }

    /// Whether the ego, waiting since `arrival` to enter the junction connector `connector`, may
    /// go now by the rule traffic follows (see the module doc): no conflicting connector is
    /// occupied and no conflicting vehicle that arrived earlier (with room past the junction,
    /// judged without the ego) waits to enter.
    pub fn ego_may_enter(
        &self,
        map: &Map,
        lights: &[LightState],
        connector: LaneIdx,
        arrival: f64,
    ) -> bool {
        let occupancy = self.occupancy(map, None);
        let requests: Vec<(LaneIdx, f64, u32)> = self
            .junction_requests(map, lights, &occupancy)
            .into_iter()
            .flatten()
            .collect();
        self.may_go(
            (connector, arrival, EGO_ID),
            &self.junction_occupants(map),
            &requests,
        )
    }

    /// Connectors (junction lanes) with a vehicle on them.
    fn junction_occupants(&self, map: &Map) -> Vec<LaneIdx> {
        self.vehicles
            .iter()
            .map(|v| v.lane)
            .filter(|l| map.lane(*l).in_junction())
            .collect()
    }

    /// Per vehicle, its request to enter the junction ahead: (connector, arrival, id), when it
    /// has arrived within [`REQUEST_DISTANCE`], no light holds it and it has room past the
    /// junction ([`has_exit_room`]; a vehicle that cannot leave the junction does not
    /// keep others waiting).
    fn junction_requests(
        &self,
        map: &Map,
        lights: &[LightState],
        occ: &Occupancy,
    ) -> Vec<Option<(LaneIdx, f64, u32)>> {
        self.vehicles
            .iter()
            .map(|v| {
                let connector = *v.next.first()?;
                let held_by_light = !v.ignores_lights()
                    && self
                        .light_at_end
                        .get(&v.lane)
                        .is_some_and(|&l| lights[l] != LightState::Green);
                let arrival = v.arrival.filter(|_| {
                    map.lane(connector).in_junction()
                        && !held_by_light
                        && (v.ignores_lights() || has_exit_room(map, v, occ))
                })?;
                Some((connector, arrival, v.id))
            })
            .collect()
    }

    /// The junction rule for one request among `requests` (which may include it).
    fn may_go(
        &self,
        (connector, arrival, id): (LaneIdx, f64, u32),
        occupied: &[LaneIdx],
        requests: &[(LaneIdx, f64, u32)],
    ) -> bool {
        let conflicts = self
            .conflicts
            .get(&connector)
            .map(Vec::as_slice)
            .unwrap_or(&[]);
        let busy = occupied.iter().any(|o| conflicts.contains(o));
        let earlier = requests.iter().any(|&(c, a, other)| {
            other != id && conflicts.contains(&c) && (a, other) < (arrival, id)
        });
        !busy && !earlier
    }

    /// A vehicle held at a junction for want of room past it ([`has_exit_room`]) takes another
    /// way through the junction that has room, when there is one, as a driver turns off a
    /// jammed street: without it a ring of full lanes (round a block) waits on itself for ever.
    fn avoid_full_exits(&mut self, map: &Map, occ: &Occupancy, rng: &mut impl Rng) {
        for v in &mut self.vehicles {
            let at_entry = map.lane(v.lane).length() - v.s < REQUEST_DISTANCE;
            if v.ignores_lights()
                || !at_entry
                || !approaching_junction(map, v)
                || has_exit_room(map, v, occ)
            {
                continue;
            }
            let mut ways: Vec<Vec<LaneIdx>> = map
                .lane(v.lane)
                .successors
                .iter()
                .filter(|&&c| c != v.next[0] && map.lane(c).kind == LaneKind::Driving)
                .map(|&c| {
                    let mut way = v.clone();
                    way.next = vec![c];
                    extend_path(map, &mut way, rng);
                    way
                })
                .filter(|way| has_exit_room(map, way, occ))
                .map(|way| way.next)
                .collect();
            if !ways.is_empty() {
                v.next = ways.swap_remove(rng.random_range(0..ways.len()));
            }
        }
    }

    /// Integrate one vehicle and move it across lane ends.
    fn advance(&mut self, map: &Map, i: usize, accel: f64, t: f64, dt: f64, rng: &mut impl Rng) {
        let v = &mut self.vehicles[i];
        let v1 = (v.speed + accel * dt).max(0.0);
        v.s += 0.5 * (v.speed + v1) * dt;
        v.speed = v1;
        v.stopped_for = standing_time(v.stopped_for, v.speed, dt);
        if v.lateral != 0.0 {
            let step = LATERAL_SPEED * dt;
            v.lateral = if v.lateral.abs() <= step {
                0.0
            } else {
                v.lateral - step * v.lateral.signum()
            };
        }
        let to_end = map.lane(v.lane).length() - v.s;
        if approaching_junction(map, v) && to_end < REQUEST_DISTANCE {
            v.arrival.get_or_insert(t);
        }
        if self.stop_at_end.contains_key(&v.lane)
            && to_end < v.half.x + IDM.min_gap + 1.5
            && v.speed < STANDING_SPEED
        {
            v.stopped_at_sign = true;
        }
        while v.s > map.lane(v.lane).length() {
            let Some(&next) = v.next.first() else {
                v.s = map.lane(v.lane).length();
                v.speed = 0.0;
                break;
            };
            v.s -= map.lane(v.lane).length();
            v.lane = next;
            v.next.remove(0);
            v.arrival = None;
            v.stopped_at_sign = false;
            extend_path(map, v, rng);
        }
    }

    /// Start a few lane changes where the target lane has room.
    fn lane_changes(&mut self, map: &Map, occ: &Occupancy, dt: f64, rng: &mut impl Rng) {
        for v in &mut self.vehicles {
            let lane = map.lane(v.lane);
            if lane.in_junction() || v.lateral != 0.0 {
                continue;
            }
            // A path into a lane end must merge before it; other changes are rare and need room.
            let must_merge = runs_into_lane_end(map, v) && lane.length() - v.s < MERGE_AHEAD;
            if !must_merge
                && (v.speed < 3.0
                    || lane.length() - v.s < 40.0
                    || rng.random_range(0.0..1.0) > LANE_CHANGE_RATE * dt)
            {
                continue;
            }
            let sides = if rng.random_range(0.0..1.0) < 0.5 {
                [lane.left, lane.right]
            } else {
                [lane.right, lane.left]
            };
            let goes_on = |t: &LaneIdx| !must_merge || !map.lane(*t).successors.is_empty();
            let target = sides
                .into_iter()
                .flatten()
                .find(|t| map.lane(*t).kind == LaneKind::Driving && goes_on(t));
            let Some(target) = target else {
                continue;
            };
            let (pos, _) = v.pose(map);
            let proj = map.lane(target).project(pos.truncate());
            let room = occ.get(&target).is_none_or(|list| {
                list.iter()
                    .all(|&(s, _, _, _)| !(proj.s - 12.0..proj.s + 18.0).contains(&s))
            });
            if !room || (!must_merge && map.lane(target).length() - proj.s < 30.0) {
                continue;
            }
            v.lane = target;
            v.s = proj.s;
            v.lateral = proj.offset;
            v.next.clear();
            extend_path(map, v, rng);
        }
    }

    /// Move vehicles stuck out of the ego's sight.
    fn respawn_stuck(&mut self, map: &Map, ego: &EgoPresence, rng: &mut impl Rng) {
        for i in 0..self.vehicles.len() {
            let v = &self.vehicles[i];
            let far = (v.pose(map).0.truncate() - ego.position()).length() > RESPAWN_CLEARANCE;
            let at_lane_end = v.next.is_empty() && map.lane(v.lane).successors.is_empty();
            // A scenario's vehicle that stands on purpose stays for its scenario.
            let stands_by_script =
                matches!(v.script, Script::Waits | Script::StopsShortOfJunction(_));
            if v.stopped_for < RESPAWN_AFTER_S || !(far || at_lane_end) || stands_by_script {
                continue;
            }
            if let Some((lane, s)) = self.free_spot(map, ego.position(), 80.0, rng) {
                let id = self.vehicles[i].id;
                self.vehicles[i] = new_vehicle(map, id, lane, s, rng);
            }
        }
    }
}

/// How far along its path from its centre a vehicle outside a junction reaches the next one, m.
fn junction_ahead(map: &Map, v: &Vehicle) -> Option<f64> {
    if map.lane(v.lane).in_junction() {
        return None;
    }
    let mut offset = map.lane(v.lane).length() - v.s;
    for &lane in &v.next {
        if map.lane(lane).in_junction() {
            return Some(offset);
        }
        offset += map.lane(lane).length();
    }
    None
}

/// Whether the vehicle is on a non-junction lane and its path enters a junction next.
fn approaching_junction(map: &Map, v: &Vehicle) -> bool {
    !map.lane(v.lane).in_junction() && v.next.first().is_some_and(|n| map.lane(*n).in_junction())
}

/// The junction exit check of CARLA's traffic manager: whether there is room for a vehicle
/// [`approaching_junction`] past the junction its path enters, so that it does not stop inside.
/// The room is the free length from the junction's end along the path up to where the first
/// occupant there could stop at the earliest (its rear plus its braking distance at
/// [`IDM`]'s comfortable deceleration: one standing or crawling there blocks, one driving
/// off does not), less what the occupants ahead inside the junction on the path will take
/// (their length and [`EXIT_GAP`] each). The vehicle needs its own length and [`EXIT_GAP`].
/// A path that ends before that much of it is seen counts as having room.
fn has_exit_room(map: &Map, v: &Vehicle, occ: &Occupancy) -> bool {
    let others = |lane: &LaneIdx| occ.get(lane).into_iter().flatten().filter(|o| o.3 != v.id);
    let inside = v
        .next
        .iter()
        .take_while(|l| map.lane(**l).in_junction())
        .count();
    let (through, beyond) = v.next.split_at(inside);
    let committed: f64 = through
        .iter()
        .flat_map(others)
        .map(|&(_, half, _, _)| 2.0 * half + EXIT_GAP)
        .sum();
    let needed = committed + 2.0 * v.half.x + EXIT_GAP;
    let mut offset = 0.0;
    for lane in beyond {
        if offset >= needed {
            break;
        }
        let blocked = others(lane).any(|&(s, half, speed, _)| {
            offset + s - half + speed * speed / (2.0 * IDM.decel) < needed
        });
        if blocked {
            return false;
        }
        offset += map.lane(*lane).length();
    }
    true
}

trait MinByGap {
    fn min_by_gap(self, other: (f64, f64)) -> (f64, f64);
}
impl MinByGap for (f64, f64) {
    fn min_by_gap(self, other: (f64, f64)) -> (f64, f64) {
        if other.0 < self.0 { other } else { self }
    }
}

fn new_vehicle(map: &Map, id: u32, lane: LaneIdx, s: f64, rng: &mut impl Rng) -> Vehicle {
    let mut v = Vehicle {
        id,
        lane,
        s,
        lateral: 0.0,
        speed: 0.0,
        desired_speed: rng.random_range(7.0..10.0),
        next: Vec::new(),
        half: DVec2::new(rng.random_range(2.1..2.6), rng.random_range(0.9..1.05)),
        stopped_for: 0.0,
        arrival: None,
        stopped_at_sign: false,
        script: Script::Traffic,
        colour: rng.random_range(0..16),
    };
    extend_path(map, &mut v, rng);
    v
}

/// How far before the end of a lane that ends a vehicle tries to merge, m.
const MERGE_AHEAD: f64 = 80.0;

/// Lanes of a vehicle's path ahead that count towards [`PATH_LANES`]: those at least this long,
/// m. Real maps have lane sections a few centimetres long (three in a row on one of Town03's
/// junction connectors); counted, they would fill the path and hide what lies beyond them.
const PATH_LANE_MIN: f64 = 1.0;
/// Lanes of path a vehicle keeps planned ahead (see [`PATH_LANE_MIN`]).
const PATH_LANES: usize = 3;

/// How many lanes of `v`'s planned path count towards [`PATH_LANES`].
fn path_lanes(map: &Map, v: &Vehicle) -> usize {
    v.next
        .iter()
        .filter(|&&lane| map.lane(lane).length() >= PATH_LANE_MIN)
        .count()
}

/// Whether the vehicle's path ends in a lane with no successor.
fn runs_into_lane_end(map: &Map, v: &Vehicle) -> bool {
    let last = *v.next.last().unwrap_or(&v.lane);
    path_lanes(map, v) < PATH_LANES
        && map.lane(last).successors.is_empty()
        && !map.lane(v.lane).in_junction()
}

/// Keep [`PATH_LANES`] lanes of path ahead, choosing successors at random (at most four times
/// as many lanes in all, should short lanes ever form a loop).
pub(crate) fn extend_path(map: &Map, v: &mut Vehicle, rng: &mut impl Rng) {
    while path_lanes(map, v) < PATH_LANES && v.next.len() < 4 * PATH_LANES {
        let last = *v.next.last().unwrap_or(&v.lane);
        let options: Vec<LaneIdx> = map
            .lane(last)
            .successors
            .iter()
            .copied()
            .filter(|s| map.lane(*s).kind == LaneKind::Driving)
            .collect();
        if options.is_empty() {
            break;
        }
        v.next.push(options[rng.random_range(0..options.len())]);
    }
}

/// IDM acceleration towards a leader `gap` metres ahead (infinite: none) moving at `lead_speed`.
fn follow(v: &Vehicle, gap: f64, lead_speed: f64, map: &Map) -> f64 {
    let desired = curve_limited_speed(map, v).min(v.desired_speed).max(0.5);
    let leader = gap.is_finite().then_some((gap, lead_speed));
    IDM.acceleration(v.speed, desired, leader)
        .clamp(-MAX_DECEL, IDM.accel)
}

/// Speed that keeps lateral acceleration under the limit on the current and next lane.
fn curve_limited_speed(map: &Map, v: &Vehicle) -> f64 {
    let mut limit = f64::INFINITY;
    for lane in std::iter::once(v.lane).chain(v.next.first().copied()) {
        let l = map.lane(lane);
        if l.in_junction() {
            let turn = crate::map::angle_diff(l.pose_at(l.length()).yaw, l.pose_at(0.0).yaw).abs();
            if turn > 0.3 {
                let radius = l.length() / turn;
                limit = limit.min(IDM.curve_speed(radius));
            }
        }
    }
    limit
}
