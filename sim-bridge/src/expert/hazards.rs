//! What the expert must slow or stop for, read from the true world state: the nearest obstacle
//! on its path (lead actor, red/yellow stop line, unserved stop sign, where a walker or cyclist
//! will cross), walkers and cyclists heading into it, and a constant-velocity collision
//! forecast.

use glam::DVec2;
use ssrdrive_proto::dataset::BrakeReason;

use super::{along, route_dir};
use crate::map::{LaneIdx, TrafficLight};
use crate::route::DenseRoute;
use crate::scoring::lights::tail_segment;
use crate::world::lights::YELLOW_S;
use crate::world::state::{ActorKind, LightState, Obb};
use crate::world::{ActorView, World};

/// How far ahead the path is scanned, m.
const SCAN_AHEAD: f64 = 50.0;
/// Extra half width of the corridor the ego sweeps, m.
const CORRIDOR_MARGIN: f64 = 0.6;
/// Stop this far before a stop line, m.
const STOP_LINE_MARGIN: f64 = 1.0;
/// The expert stops for a red or yellow light with its front at least this far short of the
/// light's head, m, where the head stands before the stop line (CARLA's Town01 and Town02
/// post theirs at the kerb a few metres before the line): a camera agent stopped there still
/// sees the lamp that tells it when to go. TCP's camera (1.5 m behind the centre, 2 m up, 100
/// degrees across a 320x96 frame, so about 20 degrees above its axis) loses a 3 m head when
/// the front is about 1 m from it; 4 m keeps the lamp in view for a learner that stops a metre
/// or two late. A head beside or past the line leaves the stop point where the line puts it.
/// A head far to the side (at the kerb beside a multi-lane approach, the ego in an inner lane)
/// holds the ego farther back still: [`HEAD_ACROSS_VIEW`].
const HEAD_IN_VIEW: f64 = 4.0;
/// How far ahead of the front a head must stand for every metre it stands beside the ego's
/// lane, less [`CAMERA_BEHIND_FRONT`], so that it stays within 45 degrees of the camera's axis
/// (TCP's camera sees 50 degrees to either side): a head 10 m to the right holds the ego 6 m
/// short of it.
const HEAD_ACROSS_VIEW: f64 = 1.0;
/// How far TCP's camera stands behind the ego's front, m (1.5 m behind the centre of a 4.9 m
/// car).
const CAMERA_BEHIND_FRONT: f64 = 3.95;
/// How far past its [`HEAD_IN_VIEW`] point a stopping ego still holds there rather than going
/// on to the line, m (the IDM may come to rest a little past it).
const HEAD_SLACK: f64 = 1.5;
/// How far beside its approach's end a light head may stand and still hold the ego short of it,
/// m: a kerb-side head (Town01, Town02) stands a few metres to the right of its lane.
const HEAD_ASIDE: f64 = 12.0;
/// The firmest braking the expert plans on to stop for a yellow light, a red light under it or
/// its turn at a junction, m/s^2 (beyond that it goes on).
const STOP_DECEL: f64 = 6.0;
/// Time kept in hand when the expert counts on clearing a stop line before yellow turns red, s.
const YELLOW_CLEAR_MARGIN: f64 = 0.5;
/// A vehicle on a lane change's target lane this close along it (centre to centre) is
/// alongside the ego, m.
const LANE_CHANGE_ALONGSIDE: f64 = 5.0;
/// Reaction time and comfortable braking assumed of a car behind on the target lane (s, m/s^2).
const FOLLOWER_REACTION: f64 = 1.0;
const FOLLOWER_DECEL: f64 = 3.0;
/// After waiting this long for a gap, s, the ego noses into a queue moving slower than
/// [`NOSE_IN_SPEED`] (m/s), at walking pace: traffic brakes for a box on its path.
const LANE_CHANGE_PATIENCE: f64 = 8.0;
const NOSE_IN_SPEED: f64 = 3.0;

/// A moving walker or cyclist that, going on at its velocity, enters the corridor on the next
/// [`WALKER_AHEAD`] m of the path in the next [`WALKER_TRACK_S`] s is waited for where it will
/// cross (a driver yields to someone stepping onto the road); one that only comes within
/// [`WALKER_TRACK_MARGIN`] m of the corridor slows the expert to walking pace. One walking
/// along the sidewalk does neither: the rule before (walking pace for any moving walker less
/// than 10 m to the side and 20 m ahead) held the expert at walking pace in 18.5 % of its
/// frames with 20 background walkers, and the learner crept at 2 m/s on empty roads. Nor does
/// one the ego passes first ([`WALKER_PASS_S`]).
const WALKER_AHEAD: f64 = 20.0;
const WALKER_TRACK_S: f64 = 3.0;
const WALKER_TRACK_MARGIN: f64 = 1.0;
/// How far ahead in time a track is followed to see whether the ego passes first: a walker or
/// cyclist whose track enters the corridor only after the ego's rear, at its speed now, has
/// cleared that point by [`PASS_FIRST_MARGIN_S`] changes nothing (a walker starting to cross a
/// wide road 11 m to the side takes 5 s to reach the ego's lane; slowing for it only put the ego
/// in its way when it got there).
const WALKER_PASS_S: f64 = 8.0;
/// See [`WALKER_PASS_S`].
const PASS_FIRST_MARGIN_S: f64 = 1.5;
/// The track is checked every `TRACK_STEP_S` s (0.9 m at walking pace).
const TRACK_STEP_S: f64 = 0.5;

/// What the scan remembers between ticks: stop signs already served on this route, and since
/// when it has been waiting for a gap to change lanes.
#[derive(Debug, Default)]
pub struct HazardMemory {
    served_signs: Vec<usize>,
    lane_change_wait: Option<f64>,
}

/// The result of a scan.
#[derive(Debug, Default, Clone, Copy)]
pub struct HazardView {
    /// Nearest obstacle on the path: (free gap in metres, its speed along the path).
    pub obstacle: Option<(f64, f64)>,
    /// What the nearest obstacle is.
    pub cause: Option<BrakeReason>,
    /// A walker or cyclist is on the path ahead or heading into it ([`WALKER_AHEAD`]).
    pub walker_near: bool,
    /// Changing lanes into a slow queue, nosing in at walking pace.
    pub nosing_in: bool,
    /// The forecast predicts a collision.
    pub collision_predicted: bool,
    /// The nearest light whose stop line ends a lane of the path ahead, whatever its colour.
    /// A training label.
    pub light_ahead: Option<NearestLight>,
}

/// The light ahead ([`HazardView::light_ahead`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NearestLight {
    /// Free gap from the ego's front to its stop line, m.
    pub gap: f64,
    /// Its state.
    pub state: LightState,
    /// The light, in [`crate::map::Map::lights`].
    pub id: usize,
}

impl HazardView {
    fn obstacle(&mut self, gap: f64, speed: f64, cause: BrakeReason) {
        if self.obstacle.is_none_or(|(g, _)| gap < g) {
            self.obstacle = Some((gap, speed));
            self.cause = Some(cause);
        }
    }
}

/// Scan the world from route index `index`.
pub fn scan(
    world: &World<'_>,
    route: &DenseRoute,
    index: usize,
    memory: &mut HazardMemory,
) -> HazardView {
    let ego = world.ego_state();
    let mut view = HazardView::default();
    let end = ahead_end(route, index, SCAN_AHEAD);
    let actors = world.actors();
    let corridor = ego.half_extent.y + CORRIDOR_MARGIN;
    // The path starts at the ego's front: a car touching its flank or rear is a contact, not
    // something to wait behind (waiting for the car that ran into it would hold it for good).
    let front = (index..=end)
        .find(|&j| along(route, index, j) >= ego.half_extent.x)
        .unwrap_or(end);
    let walker_end = ahead_end(route, index, WALKER_AHEAD);
    // Nosing into a lane ahead of cars that stop for it: those are behind, not in its way.
    let nosing_ahead_of = lane_change_gap(world, route, index, end, memory, &mut view);
    for a in &actors {
        let rel = a.obb.centre - ego.position.truncate();
        if rel.length() > SCAN_AHEAD + 10.0 || (a.z - ego.position.z).abs() > 3.0 {
            continue;
        }
        let on_path = (front..=end)
            .find(|&j| a.obb.distance_to(route.points[j].position.truncate()) < corridor);
        if let Some(j) = on_path.filter(|_| !nosing_ahead_of.contains(&a.id)) {
            let gap = along(route, index, j) - ego.half_extent.x;
            let speed = a.velocity.dot(route_dir(route, j)).max(0.0);
            view.obstacle(gap, speed, brake_reason(a.kind));
        }
        let track = track(a, route, front, walker_end, corridor);
        // Passing first: the ego's rear, at its speed now, clears the crossing point well
        // before the walker gets there.
        let passes_first = track.crossing.is_some_and(|(j, enters)| {
            let rear_clears = (along(route, index, j) + ego.half_extent.x) / ego.speed.max(0.1);
            rear_clears + PASS_FIRST_MARGIN_S < enters
        });
        if passes_first {
            continue;
        }
        view.walker_near |= track.near;
        if let Some((j, _)) = track
            .crossing
            .filter(|(_, enters)| *enters <= WALKER_TRACK_S)
        {
            let gap = along(route, index, j) - ego.half_extent.x;
            view.obstacle(gap, 0.0, brake_reason(a.kind));
        }
    }
    let lanes_ahead: Vec<(LaneIdx, usize)> = last_index_per_lane(route, index, end);
    stop_lines(world, route, index, &lanes_ahead, memory, &mut view);
    red_light_under_ego(world, &mut view);
    junction_turn(world, route, index, &mut view);
    view.collision_predicted = forecast(world, route, index, &actors);
    view
}

/// What the expert brakes for when an actor of `kind` is in its way.
fn brake_reason(kind: ActorKind) -> BrakeReason {
    match kind {
        ActorKind::Vehicle | ActorKind::Cyclist => BrakeReason::Vehicle,
        ActorKind::Walker => BrakeReason::Walker,
        ActorKind::Static | ActorKind::Debris => BrakeReason::Obstacle,
    }
}

/// How a walker's or cyclist's track meets the path (see [`WALKER_AHEAD`]).
#[derive(Debug, Default)]
struct Track {
    /// It comes within [`WALKER_TRACK_MARGIN`] of the corridor in the next [`WALKER_TRACK_S`].
    near: bool,
    /// It enters the corridor in the next [`WALKER_PASS_S`]: first at this route point, after
    /// this many seconds.
    crossing: Option<(usize, f64)>,
}

/// The track of `actor` over the next [`WALKER_PASS_S`] at its velocity against the corridor
/// (half width `corridor`) along route points `from..=to`.
fn track(actor: &ActorView, route: &DenseRoute, from: usize, to: usize, corridor: f64) -> Track {
    let mut out = Track::default();
    if !matches!(actor.kind, ActorKind::Walker | ActorKind::Cyclist)
        || actor.velocity.length() <= 0.1
    {
        return out;
    }
    let reach = corridor + WALKER_TRACK_MARGIN;
    let travel = WALKER_PASS_S * actor.velocity.length();
    // Nothing on this stretch of the path can come near.
    let start = route.points[from].position.truncate();
    if actor.obb.centre.distance(start) > WALKER_AHEAD + travel + reach {
        return out;
    }
    let steps = (WALKER_PASS_S / TRACK_STEP_S).round() as usize;
    for k in 0..=steps {
        let seconds = TRACK_STEP_S * k as f64;
        let moved = Obb {
            centre: actor.obb.centre + actor.velocity * seconds,
            ..actor.obb
        };
        for j in from..=to {
            let distance = moved.distance_to(route.points[j].position.truncate());
            if distance < corridor {
                out.crossing = Some((j, seconds));
                out.near |= seconds <= WALKER_TRACK_S;
                return out;
            }
            out.near |= distance < reach && seconds <= WALKER_TRACK_S;
        }
    }
    out
}

/// Before a lane change on the path, wait at its start while a vehicle on the target lane is
/// alongside ([`LANE_CHANGE_ALONGSIDE`] either side of the ego) or closing in from behind;
/// after [`LANE_CHANGE_PATIENCE`], nose in (a zip merge) when each of them is slower than
/// [`NOSE_IN_SPEED`] or could stop comfortably short of the ego's nose: traffic stops for the
/// box on its path, and a moving queue with car-length gaps never leaves a gap a standing car
/// can take. Returns the vehicles it noses in ahead of (those whose front is behind its nose),
/// which are then behind it, not in its way.
fn lane_change_gap(
    world: &World<'_>,
    route: &DenseRoute,
    index: usize,
    end: usize,
    memory: &mut HazardMemory,
    view: &mut HazardView,
) -> Vec<u32> {
    let map = world.map;
    let Some(switch) = (index.max(1)..=end).find(|&j| {
        let (a, b) = (map.lane(route.points[j - 1].lane), route.points[j].lane);
        a.left == Some(b) || a.right == Some(b)
    }) else {
        memory.lane_change_wait = None;
        return Vec::new();
    };
    let start = (index..=switch)
        .find(|&j| route.points[j].option.is_lane_change())
        .unwrap_or(switch);
    if start <= index {
        memory.lane_change_wait = None;
        return Vec::new(); // already changing: carry on
    }
    let ego = world.ego_state();
    let target = map.lane(route.points[switch].lane);
    let ego_s = target.project(ego.position.truncate()).s;
    let impatient = memory
        .lane_change_wait
        .is_some_and(|since| world.time - since > LANE_CHANGE_PATIENCE);
    // Each vehicle on the target lane with its arc length there (measured on the target lane).
    let on_target = world.traffic.vehicles.iter().filter_map(|v| {
        if v.lane == target.idx {
            Some((v, v.s))
        } else if target.predecessors.contains(&v.lane) {
            Some((v, v.s - map.lane(v.lane).length()))
        } else {
            None
        }
    });
    let stopping = |v: &crate::world::vehicle::Vehicle| {
        v.speed * FOLLOWER_REACTION + v.speed * v.speed / (2.0 * FOLLOWER_DECEL)
    };
    // Behind, a car blocks the change while it could not stop comfortably (after a second's
    // reaction) short of the ego.
    let blockers: Vec<_> = on_target
        .filter(|(v, s)| {
            let behind = ego_s - s;
            let alongside = behind.abs() < LANE_CHANGE_ALONGSIDE;
            let closing = behind > 0.0 && behind < LANE_CHANGE_ALONGSIDE + stopping(v);
            alongside || closing
        })
        .collect();
    if blockers.is_empty() {
        return Vec::new();
    }
    memory.lane_change_wait.get_or_insert(world.time);
    let nose = ego_s + ego.half_extent.x;
    let yields = |(v, s): &(&crate::world::vehicle::Vehicle, f64)| {
        v.speed < NOSE_IN_SPEED || nose - (s + v.half.x) > stopping(v)
    };
    if impatient && blockers.iter().all(yields) {
        // Nose in at walking pace, as in a zip merge. The cars behind brake for the box on
        // their path, and the scan along the ego's path keeps it off the one ahead.
        view.nosing_in = true;
        return blockers
            .iter()
            .filter(|(v, s)| s + v.half.x < nose)
            .map(|(v, _)| v.id)
            .collect();
    }
    let gap = along(route, index, start) - ego.half_extent.x;
    view.obstacle(gap, 0.0, BrakeReason::LaneChange);
    Vec::new()
}

/// Index of the last route point within `distance` of `index`.
fn ahead_end(route: &DenseRoute, index: usize, distance: f64) -> usize {
    let limit = route.cum[index] + distance;
    route
        .cum
        .partition_point(|&c| c <= limit)
        .saturating_sub(1)
        .max(index)
}

/// For each lane on the route between `from` and `to`, the last route index on it.
fn last_index_per_lane(route: &DenseRoute, from: usize, to: usize) -> Vec<(LaneIdx, usize)> {
    let mut out: Vec<(LaneIdx, usize)> = Vec::new();
    for j in from..=to {
        let lane = route.points[j].lane;
        match out.last_mut() {
            Some((l, last)) if *l == lane => *last = j,
            _ => out.push((lane, j)),
        }
    }
    out
}

/// Red and yellow lights and unserved stop signs whose stop line ends a lane on the path ahead
/// of the ego's front (a red light whose line is under the ego is [`red_light_under_ego`]'s).
fn stop_lines(
    world: &World<'_>,
    route: &DenseRoute,
    index: usize,
    lanes_ahead: &[(LaneIdx, usize)],
    memory: &mut HazardMemory,
    view: &mut HazardView,
) {
    let ego = world.ego_state();
    let map = world.map;
    // The route reaches a lane's end, where its stop line is, when it goes on to one of the
    // lane's successors or into a junction (its first point there may lie past a successor a
    // few centimetres long: Town03 cuts connectors into 3 cm pieces that no route point falls
    // on): leaving it sideways along the road (a lane change) is not reaching its end, and the
    // last lane ahead may continue past the scan window.
    let ends_in_window = |lane: LaneIdx, j: usize| {
        route.points.get(j + 1).is_some_and(|next| {
            map.lane(lane).successors.contains(&next.lane)
                || (map.lane(next.lane).in_junction() && !map.lane(lane).in_junction())
        })
    };
    let gap_to = |j: usize| along(route, index, j) - ego.half_extent.x - STOP_LINE_MARGIN;
    // Only the next stop line, with no junction before it, may hold the ego short of its head.
    let mut next_line = true;
    for &(lane, j) in lanes_ahead {
        if map.lane(lane).in_junction() {
            next_line = false;
        }
        if !ends_in_window(lane, j) {
            continue;
        }
        let gap = gap_to(j);
        let front_past = along(route, index, j) < ego.half_extent.x;
        for light in map
            .lights
            .iter()
            .filter(|l| l.stop_lines.iter().any(|s| s.lane == lane))
        {
            let state = world.light_states()[light.id];
            if !front_past && view.light_ahead.is_none_or(|nearest| gap < nearest.gap) {
                view.light_ahead = Some(NearestLight {
                    gap: gap.max(0.0),
                    state,
                    id: light.id,
                });
            }
            let head_gap = next_line
                .then(|| head_in_view_gap(world, light, lane, gap))
                .flatten();
            let stop_gap = head_gap.map_or(gap, |g| g.min(gap));
            match state {
                LightState::Red if front_past => {}
                LightState::Red => view.obstacle(stop_gap, 0.0, BrakeReason::TrafficLight),
                LightState::Yellow if stops_at_yellow(world, light, lane) => {
                    view.obstacle(stop_gap.max(0.0), 0.0, BrakeReason::TrafficLight)
                }
                _ => {}
            }
        }
        for sign in map
            .stop_signs
            .iter()
            .filter(|s| s.stop_lines.iter().any(|l| l.lane == lane))
        {
            if memory.served_signs.contains(&sign.id) {
                continue;
            }
            if ego.speed < 0.1 && gap < super::IDM.min_gap + 1.5 {
                memory.served_signs.push(sign.id);
            } else {
                view.obstacle(gap.max(0.0), 0.0, BrakeReason::StopSign);
            }
        }
    }
}

/// The obstacle gap (as for a stop line) that stops the ego [`HEAD_IN_VIEW`] short of
/// `light`'s head (farther for a head far beside its lane, [`HEAD_ACROSS_VIEW`]), for a head
/// that stands before the stop line ending `lane` (`line_gap` ahead, as [`stop_lines`]
/// measures it) and beside that approach (within [`HEAD_ASIDE`]), while the ego can still stop
/// there comfortably ([`STOP_DECEL`], give or take [`HEAD_SLACK`]); `None` past that point, or
/// for a head elsewhere (the line decides). The head is measured along the approach's end, not
/// the ego's heading: on a turning route a head off to the side would otherwise project a few
/// metres ahead of the ego.
fn head_in_view_gap(
    world: &World<'_>,
    light: &TrafficLight,
    lane: LaneIdx,
    line_gap: f64,
) -> Option<f64> {
    let ego = world.ego_state();
    let approach = world.map.lane(lane);
    let end = approach.pose_at(approach.length());
    let from_line = light.head.truncate() - end.position.truncate();
    let along_approach = DVec2::from_angle(end.yaw);
    let before_line = -from_line.dot(along_approach);
    let aside = from_line.perp_dot(along_approach).abs();
    if before_line <= 0.0 || aside > HEAD_ASIDE {
        return None;
    }
    let head_ahead = line_gap + STOP_LINE_MARGIN - before_line;
    let short = HEAD_IN_VIEW.max(aside * HEAD_ACROSS_VIEW - CAMERA_BEHIND_FRONT);
    // The IDM holds the ego its standstill gap short of an obstacle.
    let gap = head_ahead - short + super::IDM.min_gap;
    let stopping = ego.speed * ego.speed / (2.0 * STOP_DECEL);
    (head_ahead - short + HEAD_SLACK >= stopping).then_some(gap.max(0.0))
}

/// Before a junction without a light on its approach, the ego takes its turn as traffic does:
/// it holds at the entry while a conflicting connector is occupied or a conflicting vehicle
/// that arrived earlier waits ([`crate::world::traffic::Traffic::ego_may_enter`]), unless it
/// could no longer stop short of the junction. Entering out of turn ends in a deadlock inside the junction: each
/// waiting for the other's box on its path.
fn junction_turn(world: &World<'_>, route: &DenseRoute, index: usize, view: &mut HazardView) {
    let Some((connector, arrival)) = world.ego_junction_request() else {
        return;
    };
    if world
        .traffic
        .ego_may_enter(world.map, world.light_states(), connector, arrival)
    {
        return;
    }
    let Some(entry) = (index..route.points.len()).find(|&j| route.points[j].lane == connector)
    else {
        return;
    };
    let ego = world.ego_state();
    let gap = along(route, index, entry) - ego.half_extent.x - STOP_LINE_MARGIN;
    if gap > ego.speed * ego.speed / (2.0 * STOP_DECEL) {
        view.obstacle(gap, 0.0, BrakeReason::Vehicle);
    }
}

/// Whether the ego stops for `light` turning yellow on `lane`: when it can stop comfortably
/// ([`STOP_DECEL`]) short of the stop line, and also when it could not clear the line with
/// the tail segment of the red-light criterion before the yellow ends at its speed yet can
/// still stop with full braking (a crawl through yellow ends on red).
fn stops_at_yellow(world: &World<'_>, light: &TrafficLight, lane: LaneIdx) -> bool {
    let ego = world.ego_state();
    let Some(line) = light.stop_lines.iter().find(|s| s.lane == lane) else {
        return false;
    };
    let to_line =
        (line.position.truncate() - ego.position.truncate()).dot(ego.forward()) - ego.half_extent.x;
    let v2 = ego.speed * ego.speed;
    let comfortable = to_line - STOP_LINE_MARGIN > v2 / (2.0 * STOP_DECEL);
    // The far end of the criterion's tail segment must pass the line.
    let (_, tail_far) = tail_segment(&ego);
    let tail_to_line = (line.position.truncate() - tail_far).dot(ego.forward());
    let clear_time = tail_to_line / ego.speed.max(0.1);
    let clears = clear_time < YELLOW_S - YELLOW_CLEAR_MARGIN;
    let can_stop = to_line > v2 / (2.0 * world.ego.params.max_brake);
    comfortable || (!clears && can_stop)
}

/// A red light whose stop line lies under the ego, past its front but not yet reached by the
/// red-light criterion's tail segment ([`tail_segment`]; the line's lane is the one under the
/// segment's far end as the scorer finds it, whether or not the route includes it: a route
/// may start with the ego across a stop line), holds the ego while it can stop before the
/// segment reaches the line: the leaderboard counts the tail crossing on red. Past that point
/// braking would only leave it in the junction.
fn red_light_under_ego(world: &World<'_>, view: &mut HazardView) {
    let ego = world.ego_state();
    let map = world.map;
    let forward = ego.forward();
    let (tail_close, tail_far) = tail_segment(&ego);
    let front_to_tail = (ego.position.truncate() - tail_close).dot(forward) + ego.half_extent.x;
    let Some((tail_lane, _)) = map.lane_for_pose(tail_far.extend(ego.position.z), ego.yaw) else {
        return;
    };
    let tail = map.lane(tail_lane);
    let stopping = ego.speed * ego.speed / (2.0 * STOP_DECEL);
    let holds = map
        .lights
        .iter()
        .filter(|light| world.light_states()[light.id] == LightState::Red)
        .flat_map(|light| &light.stop_lines)
        .any(|line| {
            let lane = map.lane(line.lane);
            let ahead_of_tail = (line.position.truncate() - tail_close).dot(forward);
            lane.road_id == tail.road_id
                && lane.lane_id == tail.lane_id
                && ahead_of_tail > stopping
                && ahead_of_tail < front_to_tail
        });
    if holds {
        view.obstacle(0.0, 0.0, BrakeReason::TrafficLight);
    }
}

/// Whether the ego, driving its route at a brisk speed, would overlap an actor that moves at
/// constant velocity across or against its path, within 2 s (4 s near junctions).
fn forecast(world: &World<'_>, route: &DenseRoute, index: usize, actors: &[ActorView]) -> bool {
    let ego = world.ego_state();
    let junction_ahead = (index..=ahead_end(route, index, 20.0))
        .any(|j| world.map.lane(route.points[j].lane).in_junction());
    let horizon = if junction_ahead { 4.0 } else { 2.0 };
    let speed = ego.speed.max(if junction_ahead { 4.0 } else { 2.0 });
    let relevant: Vec<&ActorView> = actors
        .iter()
        .filter(|a| {
            a.velocity.length() > 0.3 && (a.obb.centre - ego.position.truncate()).length() < 45.0
        })
        .filter(|a| {
            let ahead =
                (a.obb.centre - ego.position.truncate()).dot(ego.forward()) > -ego.half_extent.x;
            let crossing = a.velocity.normalize_or_zero().dot(ego.forward()) < 0.85;
            ahead && (crossing || matches!(a.kind, ActorKind::Walker | ActorKind::Cyclist))
        })
        .collect();
    if relevant.is_empty() {
        return false;
    }
    let mut t = 0.25;
    while t <= horizon + 1e-9 {
        let s = route.cum[index] + speed * t;
        let j = route
            .cum
            .partition_point(|&c| c < s)
            .min(route.points.len() - 1);
        let p = route.points[j];
        // The front half of the ego, slightly widened.
        let front = Obb {
            centre: p.position.truncate() + p.forward() * (ego.half_extent.x * 0.5),
            yaw: p.yaw,
            half: DVec2::new(ego.half_extent.x * 0.75, ego.half_extent.y + 0.3),
        };
        for a in &relevant {
            let moved = Obb {
                centre: a.obb.centre + a.velocity * t,
                ..a.obb
            };
            if moved.overlaps(&front) {
                return true;
            }
        }
        t += 0.25;
    }
    false
}
