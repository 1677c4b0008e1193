//! Outside route lanes (the "Off-road infractions" row), LB1.0 `OutsideRouteLanesTest`.
//!
//! Two flags are evaluated every tick:
//! - *outside lane*: take the nearest Driving-lane centre and the nearest Parking-lane centre
//!   (3-D distance from the ego centre), keep the nearer (Parking on a tie) and set the flag when
//!   that distance exceeds its lane's width / 2 + 1.3 m.
//! - *wrong lane*: off whenever the nearest driving lane is a junction connector. Otherwise,
//!   when its (road id, lane id) differs from the previous tick's: if the previous lane was in a
//!   junction, wrong = the ego heading is 120 degrees or more off the lane heading; else a lane
//!   heading jump of 150-210 degrees toggles wrong (entering or leaving an opposite lane), and
//!   any other change clears it.
//!
//! Distance bookkeeping runs on its own route index with a window of 3 points past the current
//! one, using the same pass test as route completion: each passed point adds the 3-D distance
//! from the current point to `total`, and to `wrong` while either flag is set. When the route
//! closes, one event is emitted with percentage = 100 * wrong / total, and IS is multiplied by
//! (1 - percentage / 100).

use glam::DVec3;

use crate::map::waypoint::{FAR_RADIUS, Waypoint};
use crate::map::{LaneKind, Map, angle_diff};
use crate::route::DenseRoute;
use crate::world::state::EgoState;

use super::completion::passed;
use super::{Infraction, InfractionKind, ScoringConfig, py_round};

/// State of the outside-route-lanes criterion.
#[derive(Debug, Clone)]
pub(crate) struct OutsideRouteLanes {
    /// Whether the map has parking lanes at all (skips a futile search every tick).
    has_parking: bool,
    outside: bool,
    wrong: bool,
    /// (road id, lane id) of the driving lane last tick.
    last_lane: Option<(String, i32)>,
    /// The driving waypoint last tick.
    previous: Option<Waypoint>,
    index: usize,
    total: f64,
    wrong_distance: f64,
}

impl OutsideRouteLanes {
    pub fn new(map: &Map) -> Self {
        Self {
            has_parking: map.lanes.iter().any(|l| l.kind == LaneKind::Parking),
            outside: false,
            wrong: false,
            last_lane: None,
            previous: None,
            index: 0,
            total: 0.0,
            wrong_distance: 0.0,
        }
    }

    /// Evaluate the flags and advance the distance bookkeeping; `driving` is the nearest
    /// driving-lane waypoint of the ego.
    pub fn update(
        &mut self,
        map: &Map,
        route: &DenseRoute,
        ego: &EgoState,
        driving: Option<&Waypoint>,
        cfg: &ScoringConfig,
    ) {
        self.outside = self.is_outside(map, ego.position, driving, cfg);
        if let Some(current) = driving {
            self.update_wrong_lane(map, ego, current, cfg);
        }

        let n = route.points.len();
        let end = (self.index + cfg.lane_window + 1).min(n);
        for j in self.index + 1..end {
            if passed(&route.points[j], ego.position) {
                let d = (route.points[j].position - route.points[self.index].position).length();
                self.index = j;
                self.total += d;
                if self.outside || self.wrong {
                    self.wrong_distance += d;
                }
            }
        }
    }

    fn is_outside(
        &self,
        map: &Map,
        p: DVec3,
        driving: Option<&Waypoint>,
        cfg: &ScoringConfig,
    ) -> bool {
        let measure = |w: Option<&Waypoint>| {
            w.map(|w| (w.distance, map.lane(w.lane).width))
                .unwrap_or((f64::INFINITY, 0.0))
        };
        let (d_drive, w_drive) = measure(driving);
        // Only a parking lane at least as near as the driving lane matters; its plan distance
        // is at most its 3-D distance, so searching within `d_drive` in plan finds it.
        let parking = if self.has_parking {
            let radius = d_drive.min(FAR_RADIUS);
            map.waypoint_within(p, radius, |l| l.kind == LaneKind::Parking)
        } else {
            None
        };
        let (d_park, w_park) = measure(parking.as_ref());
        let (distance, width) = if d_drive >= d_park {
            (d_park, w_park)
        } else {
            (d_drive, w_drive)
        };
        distance > width / 2.0 + cfg.outside_lane_margin
    }

    fn update_wrong_lane(
        &mut self,
        map: &Map,
        ego: &EgoState,
        current: &Waypoint,
        cfg: &ScoringConfig,
    ) {
        let lane = map.lane(current.lane);
        let changed = self
            .last_lane
            .as_ref()
            .is_none_or(|(road, id)| *road != lane.road_id || *id != lane.lane_id);
        if lane.in_junction() {
            self.wrong = false;
        } else if changed {
            // LB1.0 seeds the previous waypoint at the spawn point, i.e. the first tick's.
            let previous = self.previous.unwrap_or(*current);
            if map.lane(previous.lane).in_junction() {
                let angle = angle_diff(current.yaw, ego.yaw).abs().to_degrees();
                self.wrong = angle >= cfg.wrong_lane_vehicle_angle;
            } else {
                let jump = angle_diff(previous.yaw, current.yaw).abs().to_degrees();
                self.wrong = jump >= cfg.wrong_lane_waypoint_angle && !self.wrong;
            }
        }
        if changed {
            self.last_lane = Some((lane.road_id.clone(), lane.lane_id));
        }
        self.previous = Some(*current);
    }

    /// The share of the driven route spent outside the route lanes so far, percent.
    pub fn percentage(&self) -> f64 {
        if self.total > 0.0 {
            100.0 * self.wrong_distance / self.total
        } else {
            0.0
        }
    }

    /// The single end-of-route event, if any distance was driven outside the route lanes.
    pub fn finish(&mut self, time: f64, location: DVec3) -> Option<Infraction> {
        if self.wrong_distance <= 0.0 {
            return None;
        }
        let percentage = self.percentage();
        let text = format!(
            "Agent went outside its route lanes for about {} meters ({}% of the completed route)",
            py_round(self.wrong_distance, 3),
            py_round(percentage, 2)
        );
        self.wrong_distance = 0.0;
        Some(Infraction {
            kind: InfractionKind::OutsideRouteLanes,
            time,
            location,
            text,
            factor: 1.0 - percentage / 100.0,
            detail: None,
        })
    }
}
