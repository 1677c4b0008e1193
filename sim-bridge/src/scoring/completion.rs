//! Route completion (RC), LB1.0 `RouteCompletionTest`.
//!
//! A route index `k` starts at 0. Each tick the points `k..=k+2` are tested in order; a point is
//! passed when the ego lies ahead of it along its forward vector, `(p - P[j]) . f[j] > 0`, and `k`
//! moves to it. So progress is along-track only (a lateral offset does not stop it) and at most
//! two points (about 2 m) per tick. `RC = 100 * A[k] / A[last]` with A the cumulative 3-D arc
//! length. When RC > 99 and the ego is within 10 m (3-D) of the last point, the route is
//! completed and RC becomes 100.
//!
//! Differs from LB1.0 only in using the plan forward vector of the route point (CARLA takes
//! the 3-D forward vector of the lane waypoint there, pitch included).

use glam::DVec3;

use crate::route::{DenseRoute, RoutePoint};

use super::ScoringConfig;

/// Whether the ego at `p` is past `point` along the route point's forward vector.
pub(crate) fn passed(point: &RoutePoint, p: DVec3) -> bool {
    (p - point.position).truncate().dot(point.forward()) > 0.0
}

/// State of the completion criterion.
#[derive(Debug, Clone, Default)]
pub(crate) struct RouteCompletion {
    /// The last route point passed.
    pub index: usize,
    /// RC in percent.
    pub percentage: f64,
    /// Whether ROUTE_COMPLETED fired.
    pub completed: bool,
}

impl RouteCompletion {
    /// Advance with the ego at `p`; returns whether the route is completed.
    pub fn update(&mut self, route: &DenseRoute, p: DVec3, cfg: &ScoringConfig) -> bool {
        let n = route.points.len();
        if n == 0 || self.completed {
            return self.completed;
        }
        let total = route.length();
        let end = (self.index + cfg.completion_window + 1).min(n);
        for j in self.index..end {
            if passed(&route.points[j], p) {
                self.index = j;
                self.percentage = if total > 0.0 {
                    100.0 * route.cum[j] / total
                } else {
                    100.0
                };
            }
        }
        let target = route.points[n - 1].position;
        if self.percentage > cfg.completion_percentage
            && (p - target).length() < cfg.completion_distance
        {
            self.completed = true;
            self.percentage = 100.0;
        }
        self.completed
    }
}
