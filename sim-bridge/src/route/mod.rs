//! Routes: CARLA route files ([`xml`]), the dense 1 m route over the lane graph with a
//! [`RoadOption`] per point ([`planner`]), the leaderboard's downsampled global plan and the
//! TCP-style route follower that yields the target point and command every tick ([`plan`]), and
//! the bundled route sets ([`sets`]).

pub mod option;
pub mod plan;
pub mod planner;
pub mod sets;
pub mod xml;

use glam::{DVec2, DVec3};

use crate::map::LaneIdx;
pub use option::RoadOption;

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
