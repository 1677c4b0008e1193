//! Routes: CARLA route files ([`xml`]), the dense 1 m route over the lane graph with a
//! RoadOption per point ([`planner`]), the leaderboard's downsampled global plan and the
//! TCP-style route follower that yields the target point and command every tick ([`plan`]), and
//! the bundled route sets ([`sets`]), the leaderboard's scenario files matched to a route
//! ([`scenario_file`]) and scenario triggers placed by rule on a town no file covers
//! ([`scenario_triggers`]).

pub mod plan;
pub mod planner;
pub mod scenario_file;
pub mod scenario_triggers;
pub mod sets;
pub mod xml;

use glam::{DVec2, DVec3};
use ssrdrive_proto::command::RoadOption;

use crate::map::LaneIdx;
use crate::route::planner::PlanError;
use crate::route::xml::RouteSpec;

/// A selected route and its dense route, or why it could not be planned.
pub type RoutePlan = (RouteSpec, Result<DenseRoute, PlanError>);

/// One point of a dense route.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RoutePoint {
    /// Position on the lane centre (world frame).
    pub position: DVec3,
    /// Heading of travel, radians.
    pub yaw: f64,
    /// The command at this point.
    pub option: RoadOption,
    /// The lane it lies on.
    pub lane: LaneIdx,
}

impl RoutePoint {
    /// Unit forward vector of the lane here.
    pub fn forward(&self) -> DVec2 {
        DVec2::from_angle(self.yaw)
    }
}

/// A route densified to about 1 m over the lane graph.
#[derive(Debug, Clone)]
pub struct DenseRoute {
    /// The points, in driving order.
    pub points: Vec<RoutePoint>,
    /// Cumulative 3-D arc length at each point.
    pub cum: Vec<f64>,
    /// Polyline length of the route file's keypoints (the leaderboard's `route_length` meta).
    pub keypoint_length: f64,
}

impl DenseRoute {
    /// Build from points, computing the arc lengths.
    pub fn new(points: Vec<RoutePoint>, keypoint_length: f64) -> Self {
        let positions: Vec<DVec3> = points.iter().map(|p| p.position).collect();
        let cum = crate::map::lanes::cumulative_length(&positions);
        Self {
            points,
            cum,
            keypoint_length,
        }
    }

    /// Dense length in metres.
    pub fn length(&self) -> f64 {
        *self.cum.last().unwrap_or(&0.0)
    }

    /// The ground position at arc length `s` (clamped to the route), interpolated between
    /// points; beyond the last point the route is extended along its final heading.
    pub fn position_at(&self, s: f64) -> DVec2 {
        let Some(last) = self.points.last() else {
            return DVec2::ZERO;
        };
        if s >= self.length() {
            return last.position.truncate() + last.forward() * (s - self.length());
        }
        let i = self
            .cum
            .partition_point(|&c| c <= s)
            .clamp(1, self.points.len() - 1);
        let (a, b) = (&self.points[i - 1], &self.points[i]);
        let span = self.cum[i] - self.cum[i - 1];
        let t = if span > 1e-9 {
            ((s - self.cum[i - 1]) / span).clamp(0.0, 1.0)
        } else {
            0.0
        };
        a.position.truncate().lerp(b.position.truncate(), t)
    }

    /// The arc length of a ground position near point `index`: that point's arc length plus
    /// the position's offset along the route there.
    pub fn arc_near(&self, index: usize, p: DVec2) -> f64 {
        let point = &self.points[index];
        (self.cum[index] + (p - point.position.truncate()).dot(point.forward())).max(0.0)
    }
}

impl DenseRoute {
    /// Track a position along the route: starting from index `k`, the index of the nearest point
    /// in plan among the next `window` points (never behind `k`).
    pub fn advance_index(&self, k: usize, p: DVec2, window: usize) -> usize {
        let end = (k + window).min(self.points.len().saturating_sub(1));
        (k..=end)
            .min_by(|&a, &b| {
                let da = (self.points[a].position.truncate() - p).length_squared();
                let db = (self.points[b].position.truncate() - p).length_squared();
                da.total_cmp(&db)
            })
            .unwrap_or(k)
    }
}
