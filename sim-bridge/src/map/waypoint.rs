//! CARLA's `map.get_waypoint(location, project_to_road=True, lane_type=...)`, as the
//! leaderboard's criteria and the route planner use it: the nearest lane centre line of a kind,
//! compared in 3-D among the lanes near in plan so that a bridge resolves to its own level.

use glam::DVec3;

use super::{Lane, LaneIdx, Map};

/// A place on a lane centre line found for a point: CARLA's `map.get_waypoint(location,
/// project_to_road=True, lane_type=...)`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Waypoint {
    /// The lane.
    pub lane: LaneIdx,
    /// Arc length along it.
    pub s: f64,
    /// The centre-line point.
    pub position: DVec3,
    /// Heading of travel there, radians.
    pub yaw: f64,
    /// 3-D distance from the queried point.
    pub distance: f64,
}

/// Lanes within this plan distance are compared in 3-D.
const NEAR_RADIUS: f64 = 10.0;
/// Beyond it, the plan-nearest lane within this distance is taken.
pub const FAR_RADIUS: f64 = 100.0;

impl Map {
    /// The lane accepted by `keep` whose centre line is nearest `p`: in 3-D among the lanes
    /// within 10 m in plan, else the plan-nearest within 100 m.
    pub fn waypoint(&self, p: DVec3, keep: impl Fn(&Lane) -> bool) -> Option<Waypoint> {
        self.waypoint_within(p, FAR_RADIUS, keep)
    }

    /// [`Map::waypoint`] searching no further than `radius` in plan.
    pub fn waypoint_within(
        &self,
        p: DVec3,
        radius: f64,
        keep: impl Fn(&Lane) -> bool,
    ) -> Option<Waypoint> {
        let mut candidates = self.lanes_near(p.truncate(), radius.min(NEAR_RADIUS), &keep);
        if candidates.is_empty() && radius > NEAR_RADIUS {
            candidates.extend(self.nearest(p.truncate(), radius, &keep));
        }
        candidates
            .into_iter()
            .map(|(lane, proj)| {
                let pose = self.lane(lane).pose_at(proj.s);
                let distance = (pose.position - p).length();
                Waypoint {
                    lane,
                    s: proj.s,
                    position: pose.position,
                    yaw: pose.yaw,
                    distance,
                }
            })
            .min_by(|a, b| a.distance.total_cmp(&b.distance))
    }
}
