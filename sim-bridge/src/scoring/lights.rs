//! Red lights and stop signs, LB1.0 `RunningRedLightTest` and `RunningStopTest`.
//!
//! **Red light.** Each tick, for every light that is Red (yellow does not count), whose trigger
//! centre (the mean of its stop lines, [`TrafficLight::trigger_centre`]) is within 15 m of the
//! ego in plan, and that is not the last light penalised: find the lane under the ego's rear
//! probe point, half length + 1 m behind the centre ([`Map::lane_for_pose`] with the ego
//! heading). For each stop line of the light whose lane has the same road id and lane id, and
//! whose heading agrees with the ego's (dot product > 0), test whether the ego's tail segment,
//! from 0.8 * half length to half length + 1 m behind the centre, touches the stop line spanning
//! +-0.4 lane width ([`StopLine::ends`] at 0.8). A crossing is one infraction (0.70), located at
//! the light head; the light is remembered so it cannot fire again until another light does.
//! LB1.0 builds its stop-line waypoints from the light's trigger volume; ours come from the
//! map, at the end of each incoming lane, where those waypoints end up.
//!
//! **Stop sign.** Our maps carry no CARLA trigger volumes, so a stop sign's trigger area is
//! defined here: for each of its stop lines, a box aligned with the stop line's lane covering
//! the last 6 m of that lane before the line, one lane width wide. A sign *affects* the ego when
//! one of its stop lines is within 50 m (plan) and one of the ego's horizon points lies in one
//! of its boxes; the horizon is the ego location plus 20 points 1 m apart along the ego's lane
//! (its nearest driving lane, CARLA's waypoint) and that lane's first successors. While no sign
//! is targeted, signs are scanned (in map order) only when the ego heading agrees with its
//! lane; the first that affects the ego becomes the target. On later ticks: the ego counts as
//! stopped once its speed drops below 0.1 m/s, and as inside once its centre is in one of the
//! sign's boxes; when the sign no longer affects the ego, an infraction (0.80) is emitted if the
//! ego was inside but never stopped, and the target is released. LB1.0 tests its boxes
//! axis-aligned around the sign actor (a quirk of `point_inside_boundingbox`); ours are
//! lane-aligned.

use glam::{DVec2, DVec3};
use ssrdrive_proto::camera::Rig;
use ssrdrive_proto::frames::world_to_ego;

use crate::map::{Lane, Map, StopLine, TrafficLight};
use crate::world::state::{EgoState, LightState, Obb};

use super::sightings::LampSightings;
use super::{Infraction, InfractionKind, ScoringConfig, fmt_location};
use crate::map::waypoint::Waypoint;

/// State of the red-light criterion.
#[derive(Debug, Clone, Default)]
pub(crate) struct RedLights {
    /// The last light penalised.
    last: Option<usize>,
    /// What the agent's frames showed of each light (none for an agent without cameras).
    sightings: Option<LampSightings>,
}

impl RedLights {
    /// Note which lights' heads `rig` frames from `ego` at time `t` ([`LampSightings`]).
    pub fn frame_lamps(
        &mut self,
        map: &Map,
        t: f64,
        ego: &EgoState,
        lights: &[LightState],
        rig: &Rig,
    ) {
        self.sightings
            .get_or_insert_with(Default::default)
            .observe(map, t, ego, lights, rig);
    }

    /// Test every nearby red light against the ego's tail.
    pub fn update(
        &mut self,
        map: &Map,
        t: f64,
        ego: &EgoState,
        lights: &[LightState],
        cfg: &ScoringConfig,
        out: &mut Vec<Infraction>,
    ) {
        let p = ego.position.truncate();
        let forward = ego.forward();
        let (tail_close, tail_far) = tail_segment(ego);
        let mut tail_lane = None;
        for light in &map.lights {
            if self.last == Some(light.id)
                || light.trigger_centre().distance(p) > cfg.light_distance
                || lights.get(light.id) != Some(&LightState::Red)
            {
                continue;
            }
            let tail = *tail_lane.get_or_insert_with(|| {
                map.lane_for_pose(tail_far.extend(ego.position.z), ego.yaw)
                    .map(|(l, _)| l)
            });
            let Some(tail) = tail.map(|l| map.lane(l)) else {
                continue;
            };
            let crossed = light.stop_lines.iter().any(|line| {
                let lane = map.lane(line.lane);
                lane.road_id == tail.road_id
                    && lane.lane_id == tail.lane_id
                    && forward.dot(DVec2::from_angle(line.yaw)) > 0.0
                    && {
                        let (a, b) = line.ends(0.8);
                        segments_intersect(tail_close, tail_far, a, b)
                    }
            });
            if crossed {
                let mut event = red_light_event(light, t, cfg);
                let seen = self.sightings.as_ref().map(|s| s.describe(light.id, t));
                event.detail = Some(red_light_context(map, light, ego, tail, seen));
                out.push(event);
                self.last = Some(light.id);
            }
        }
    }
}

/// The ego's tail segment the red-light criterion tests against stop lines: from 0.8 half
/// lengths to a half length plus 1 m behind the centre, as (near end, far end).
pub(crate) fn tail_segment(ego: &EgoState) -> (DVec2, DVec2) {
    let (p, forward, half_length) = (ego.position.truncate(), ego.forward(), ego.half_extent.x);
    (
        p - forward * (0.8 * half_length),
        p - forward * (half_length + 1.0),
    )
}

/// Where a red light was run from (ours, for failure analysis): whose light it is (the map
/// file's or placed by the simulator), what the agent's frames last showed of it (`seen`, from
/// [`LampSightings::describe`]; none for an agent without cameras), which of the approach's
/// lanes the ego was in (1 is the leftmost), and where its head stood from the ego (ego frame,
/// m), e.g. "placed light, lamp last in frame red, 0.0 s before, lane 1 of 3, head 2 m ahead
/// 9 m right, ego 7.5 m/s".
fn red_light_context(
    map: &Map,
    light: &TrafficLight,
    ego: &EgoState,
    tail: &Lane,
    seen: Option<String>,
) -> String {
    let lanes = light.stop_lines.len();
    // Stop lines are per incoming lane; count from the left by their offset across the road.
    let left_of = |a: DVec2| {
        let normal = DVec2::from_angle(ego.yaw).perp();
        a.dot(normal)
    };
    let mut order: Vec<(f64, bool)> = light
        .stop_lines
        .iter()
        .map(|line| {
            let lane = map.lane(line.lane);
            let mine = lane.road_id == tail.road_id && lane.lane_id == tail.lane_id;
            (left_of(line.position.truncate()), mine)
        })
        .collect();
    order.sort_by(|a, b| b.0.total_cmp(&a.0));
    let lane = order
        .iter()
        .position(|&(_, mine)| mine)
        .map_or("?".to_string(), |k| (k + 1).to_string());
    let d = light.head.truncate() - ego.position.truncate();
    let [ahead, left] = world_to_ego([d.x, d.y], ego.yaw);
    let side = if left >= 0.0 { "left" } else { "right" };
    let seen = seen.map(|s| s + ", ").unwrap_or_default();
    format!(
        "{} light, {seen}lane {lane} of {lanes}, head {ahead:.0} m ahead {:.0} m {side}, ego {:.1} m/s",
        if light.from_map { "map" } else { "placed" },
        left.abs(),
        ego.speed
    )
}

fn red_light_event(light: &TrafficLight, t: f64, cfg: &ScoringConfig) -> Infraction {
    Infraction {
        kind: InfractionKind::RedLight,
        time: t,
        location: light.head,
        text: format!(
            "Agent ran a red light {} at {}",
            light.id,
            fmt_location(light.head)
        ),
        factor: cfg.penalties.red_light,
        detail: None,
    }
}

/// Whether two closed segments share a point (shapely's non-empty intersection).
pub(crate) fn segments_intersect(a1: DVec2, a2: DVec2, b1: DVec2, b2: DVec2) -> bool {
    let cross = |o: DVec2, a: DVec2, b: DVec2| (a - o).perp_dot(b - o);
    let on_segment = |p: DVec2, a: DVec2, b: DVec2| {
        p.x >= a.x.min(b.x) && p.x <= a.x.max(b.x) && p.y >= a.y.min(b.y) && p.y <= a.y.max(b.y)
    };
    let d1 = cross(b1, b2, a1);
    let d2 = cross(b1, b2, a2);
    let d3 = cross(a1, a2, b1);
    let d4 = cross(a1, a2, b2);
    if ((d1 > 0.0 && d2 < 0.0) || (d1 < 0.0 && d2 > 0.0))
        && ((d3 > 0.0 && d4 < 0.0) || (d3 < 0.0 && d4 > 0.0))
    {
        return true;
    }
    (d1 == 0.0 && on_segment(a1, b1, b2))
        || (d2 == 0.0 && on_segment(a2, b1, b2))
        || (d3 == 0.0 && on_segment(b1, a1, a2))
        || (d4 == 0.0 && on_segment(b2, a1, a2))
}

/// Our trigger box of one stop line: the last `length` metres of its lane before the line,
/// lane-aligned, one lane width wide.
pub(crate) fn stop_box(line: &StopLine, length: f64) -> Obb {
    let forward = DVec2::from_angle(line.yaw);
    Obb {
        centre: line.position.truncate() - forward * (length / 2.0),
        yaw: line.yaw,
        half: DVec2::new(length / 2.0, line.half_width),
    }
}

/// State of the stop-sign criterion.
#[derive(Debug, Clone)]
pub(crate) struct StopSigns {
    /// Trigger boxes per sign, indexed like `map.stop_signs`.
    boxes: Vec<Vec<Obb>>,
    target: Option<usize>,
    stopped: bool,
    inside: bool,
}

impl StopSigns {
    pub fn new(map: &Map, cfg: &ScoringConfig) -> Self {
        let boxes = map
            .stop_signs
            .iter()
            .map(|s| {
                s.stop_lines
                    .iter()
                    .map(|l| stop_box(l, cfg.stop_box_length))
                    .collect()
            })
            .collect();
        Self {
            boxes,
            target: None,
            stopped: false,
            inside: false,
        }
    }

    /// One tick of the stop-sign state machine; `driving` is the ego's driving waypoint.
    pub fn update(
        &mut self,
        map: &Map,
        t: f64,
        ego: &EgoState,
        driving: Option<&Waypoint>,
        cfg: &ScoringConfig,
        out: &mut Vec<Infraction>,
    ) {
        if self.boxes.is_empty() {
            return;
        }
        let Some(target) = self.target else {
            self.target = self.scan(map, ego, driving, cfg);
            return;
        };
        if !self.stopped && ego.speed < cfg.stop_speed {
            self.stopped = true;
        }
        let p = ego.position.truncate();
        if !self.inside && self.boxes[target].iter().any(|b| b.contains(p)) {
            self.inside = true;
        }
        let horizon = horizon(map, ego.position, driving, cfg);
        if !self.affects(map, target, p, &horizon, cfg) {
            if self.inside && !self.stopped {
                let sign = &map.stop_signs[target];
                out.push(Infraction {
                    kind: InfractionKind::StopSign,
                    time: t,
                    location: sign.position,
                    text: format!(
                        "Agent ran a stop with id={} at {}",
                        sign.id,
                        fmt_location(sign.position)
                    ),
                    factor: cfg.penalties.stop,
                    detail: None,
                });
            }
            self.target = None;
            self.stopped = false;
            self.inside = false;
        }
    }

    /// The first sign affecting the ego, scanned only while its heading agrees with its lane.
    fn scan(
        &self,
        map: &Map,
        ego: &EgoState,
        driving: Option<&Waypoint>,
        cfg: &ScoringConfig,
    ) -> Option<usize> {
        let lane_heading = DVec2::from_angle(driving?.yaw);
        if ego.forward().dot(lane_heading) <= 0.0 {
            return None;
        }
        let p = ego.position.truncate();
        let mut near = (0..self.boxes.len())
            .filter(|&id| is_near(map, id, p, cfg))
            .peekable();
        near.peek()?;
        let horizon = horizon(map, ego.position, driving, cfg);
        near.find(|&id| self.covers(id, &horizon))
    }

    /// Whether sign `id` affects the ego at `p` with this horizon.
    fn affects(
        &self,
        map: &Map,
        id: usize,
        p: DVec2,
        horizon: &[DVec2],
        cfg: &ScoringConfig,
    ) -> bool {
        is_near(map, id, p, cfg) && self.covers(id, horizon)
    }

    /// Whether a horizon point lies in one of sign `id`'s boxes.
    fn covers(&self, id: usize, horizon: &[DVec2]) -> bool {
        horizon
            .iter()
            .any(|h| self.boxes[id].iter().any(|b| b.contains(*h)))
    }
}

/// The coarse test: one of sign `id`'s stop lines is within the proximity threshold of `p`.
fn is_near(map: &Map, id: usize, p: DVec2, cfg: &ScoringConfig) -> bool {
    let lines = &map.stop_signs[id].stop_lines;
    lines
        .iter()
        .any(|l| l.position.truncate().distance(p) <= cfg.stop_proximity)
}

/// The ego location followed by up to `stop_horizon_points` points `stop_horizon_step` apart
/// along its lane from its waypoint, continuing into each lane's first successor.
pub(crate) fn horizon(
    map: &Map,
    ego: DVec3,
    driving: Option<&Waypoint>,
    cfg: &ScoringConfig,
) -> Vec<DVec2> {
    let mut points = vec![ego.truncate()];
    let Some(start) = driving else { return points };
    let mut lane = map.lane(start.lane);
    let mut s = start.s;
    'steps: for _ in 0..cfg.stop_horizon_points {
        s += cfg.stop_horizon_step;
        while s > lane.length() {
            let Some(&next) = lane.successors.first() else {
                break 'steps;
            };
            s -= lane.length();
            lane = map.lane(next);
        }
        points.push(lane.pose_at(s).position.truncate());
    }
    points
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn segment_intersection_counts_touching_and_collinear_overlap() {
        let p = |x: f64, y: f64| DVec2::new(x, y);
        assert!(segments_intersect(
            p(0.0, 0.0),
            p(2.0, 0.0),
            p(1.0, -1.0),
            p(1.0, 1.0)
        ));
        assert!(segments_intersect(
            p(0.0, 0.0),
            p(1.0, 0.0),
            p(1.0, -1.0),
            p(1.0, 1.0)
        ));
        assert!(segments_intersect(
            p(0.0, 0.0),
            p(2.0, 0.0),
            p(1.0, 0.0),
            p(3.0, 0.0)
        ));
        assert!(!segments_intersect(
            p(0.0, 0.0),
            p(0.9, 0.0),
            p(1.0, -1.0),
            p(1.0, 1.0)
        ));
        assert!(!segments_intersect(
            p(0.0, 0.0),
            p(2.0, 0.0),
            p(1.0, 0.5),
            p(1.0, 1.0)
        ));
        assert!(!segments_intersect(
            p(0.0, 0.0),
            p(2.0, 0.0),
            p(0.0, 1.0),
            p(2.0, 1.0)
        ));
    }

    #[test]
    fn stop_box_covers_the_lane_before_the_line() {
        let line = StopLine {
            lane: crate::map::LaneIdx(0),
            position: DVec3::new(100.0, -1.75, 0.0),
            yaw: 0.0,
            half_width: 1.75,
        };
        let b = stop_box(&line, 6.0);
        assert!(b.contains(DVec2::new(97.0, -1.75)));
        assert!(b.contains(DVec2::new(94.5, -0.5)));
        assert!(!b.contains(DVec2::new(100.5, -1.75)));
        assert!(!b.contains(DVec2::new(93.5, -1.75)));
        assert!(!b.contains(DVec2::new(97.0, 0.5)));
    }
}
