//! The criteria that end a route without a penalty: route deviation (LB1.0 `InRouteTest`),
//! agent blocked (`ActorSpeedAboveThresholdTest`) and the route timeout (route_scenario
//! `_estimate_route_timeout` and the TimeOut node).
//!
//! **Deviation.** Each tick the route point nearest the ego in plan is sought in the window
//! k..=k+5 (ties go to the later point). A nearest distance of 30 m or more is a deviation.
//! While the last distance under 30 m was 15 m or more, the arc length advanced to the new
//! nearest point is added to an out-of-route sum; once that sum exceeds 30 % of the route length
//! it is a deviation too. A deviation ends the route ("Failed - Agent deviated from the route").
//!
//! **Blocked.** The time of the last tick with speed at or above 0.1 m/s is remembered (the
//! first tick counts as such); a tick below 0.1 m/s more than 180 s after it blocks the agent
//! and ends the route ("Failed - Agent got blocked").
//!
//! **Timeout.** int(0.8 s/m * dense route length + 5 s) of simulation time; the route ends at
//! the first tick whose time since the start reaches it ("Failed - Agent timed out").

use glam::DVec3;

use crate::route::DenseRoute;

use super::ScoringConfig;

/// LB1.0 route timeout in seconds: `int(0.8 * dense_length + 5)` with the configured factors.
pub fn route_timeout(dense_length: f64, cfg: &ScoringConfig) -> f64 {
    (cfg.timeout_per_meter * dense_length + cfg.timeout_delay).trunc()
}

/// State of the route-deviation criterion.
#[derive(Debug, Clone)]
pub(crate) struct InRoute {
    index: usize,
    out_distance: f64,
    in_safe_route: bool,
}

impl Default for InRoute {
    fn default() -> Self {
        Self {
            index: 0,
            out_distance: 0.0,
            in_safe_route: true,
        }
    }
}

impl InRoute {
    /// Track the nearest route point; returns whether the ego deviated.
    pub fn update(&mut self, route: &DenseRoute, p: DVec3, cfg: &ScoringConfig) -> bool {
        let n = route.points.len();
        if n == 0 {
            return false;
        }
        let p = p.truncate();
        let end = (self.index + cfg.deviation_window + 1).min(n);
        let mut shortest = f64::INFINITY;
        let mut closest = self.index;
        for j in self.index..end {
            let d = route.points[j].position.truncate().distance(p);
            if d <= shortest {
                shortest = d;
                closest = j;
            }
        }
        if !shortest.is_finite() {
            return false;
        }
        let mut off_route = true;
        if shortest < cfg.deviation_max {
            off_route = false;
            self.in_safe_route = shortest < cfg.deviation_min;
        }
        if closest != self.index {
            let advanced = route.cum[closest] - route.cum[self.index];
            if !self.in_safe_route {
                self.out_distance += advanced;
                let total = route.length();
                if total > 0.0 && self.out_distance / total > cfg.out_route_fraction {
                    off_route = true;
                }
            }
            self.index = closest;
        }
        off_route
    }
}

/// State of the blocked criterion.
#[derive(Debug, Clone, Default)]
pub(crate) struct Blocked {
    last_moving: Option<f64>,
}

impl Blocked {
    /// Returns whether the agent is blocked at time `t` with this speed.
    pub fn update(&mut self, t: f64, speed: f64, cfg: &ScoringConfig) -> bool {
        match self.last_moving {
            Some(last) if speed < cfg.blocked_speed => t - last > cfg.blocked_seconds,
            _ => {
                self.last_moving = Some(t);
                false
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn timeout_is_truncated_like_python_int() {
        let cfg = ScoringConfig::default();
        assert_eq!(route_timeout(200.0, &cfg), 165.0);
        assert_eq!(route_timeout(201.3, &cfg), 166.0);
        assert_eq!(route_timeout(0.0, &cfg), 5.0);
    }

    #[test]
    fn blocked_needs_more_than_the_limit() {
        let cfg = ScoringConfig::default();
        let mut b = Blocked::default();
        assert!(!b.update(0.0, 0.0, &cfg));
        assert!(!b.update(180.0, 0.0, &cfg));
        assert!(b.update(180.05, 0.0, &cfg));
        let mut b = Blocked::default();
        b.update(0.0, 0.0, &cfg);
        b.update(100.0, 0.2, &cfg);
        assert!(!b.update(280.0, 0.0, &cfg));
        assert!(b.update(280.1, 0.0, &cfg));
    }
}
