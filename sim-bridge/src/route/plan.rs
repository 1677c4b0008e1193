//! What an agent is told about its route: the leaderboard's downsampled global plan (LB1.0's
//! `downsample_route`, 50 m) and the TCP-style [`RouteFollower`]
//! (`RoutePlanner(4, 50)`) that turns the ego pose into the target point and command each
//! tick.

use std::collections::VecDeque;

use glam::{DVec2, DVec3};
use ssrdrive_proto::command::RoadOption;
use ssrdrive_proto::frames::world_to_ego;

use super::DenseRoute;

/// Longest stretch between plan nodes in LB1.0, metres.
pub const PLAN_SPACING: f64 = 50.0;
/// TCP's route follower: nodes nearer than this are passed.
pub const FOLLOWER_MIN_DISTANCE: f64 = 4.0;
/// TCP's route follower: how far ahead it looks along the plan.
pub const FOLLOWER_MAX_DISTANCE: f64 = 50.0;
/// A node the plan reaches heading more than this far from the ego's heading (cosine -0.5:
/// 120 degrees) is not passed however near it lies: the far side of a U-turn.
pub const FOLLOWER_MIN_HEADING_COSINE: f64 = -0.5;

/// One node of the global plan.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PlanNode {
    /// Position, OpenDRIVE frame.
    pub position: DVec3,
    /// The command at the node.
    pub option: RoadOption,
}

/// The indices of the dense route the leaderboard hands the agent: every lane-change point,
/// every point whose option differs from the previous one (unless that one was a lane change),
/// a point after more than `spacing` metres, and the last point.
pub fn downsample(route: &DenseRoute, spacing: f64) -> Vec<usize> {
    let mut keep = Vec::new();
    let mut prev: Option<RoadOption> = None;
    let mut dist = 0.0;
    let last = route.points.len().saturating_sub(1);
    for (i, p) in route.points.iter().enumerate() {
        let option = p.option;
        let changed = prev != Some(option) && !prev.is_some_and(RoadOption::is_lane_change);
        if option.is_lane_change() || changed || dist > spacing || i == last {
            keep.push(i);
            dist = 0.0;
        } else {
            dist += (p.position - route.points[i - 1].position).length();
        }
        prev = Some(option);
    }
    keep
}

/// The global plan of a dense route.
pub fn global_plan(route: &DenseRoute) -> Vec<PlanNode> {
    downsample(route, PLAN_SPACING)
        .into_iter()
        .map(|i| PlanNode {
            position: route.points[i].position,
            option: route.points[i].option,
        })
        .collect()
}

/// TCP's `RoutePlanner`: a queue of plan nodes, popped as the ego passes them.
#[derive(Debug, Clone)]
pub struct RouteFollower {
    nodes: VecDeque<PlanNode>,
    min_distance: f64,
    max_distance: f64,
}

impl RouteFollower {
    /// Follow `plan` with TCP's thresholds (4 m / 50 m).
    pub fn new(plan: Vec<PlanNode>) -> Self {
        Self::with_thresholds(plan, FOLLOWER_MIN_DISTANCE, FOLLOWER_MAX_DISTANCE)
    }

    /// Follow `plan` with other thresholds.
    pub fn with_thresholds(plan: Vec<PlanNode>, min_distance: f64, max_distance: f64) -> Self {
        Self {
            nodes: plan.into(),
            min_distance,
            max_distance,
        }
    }

    /// Advance with the ego's pose (position, and heading in rad counter-clockwise from +x) and
    /// return the next target node (its position and command). Of the nodes within
    /// `max_distance` of plan length ahead, the farthest one that is within `min_distance` of
    /// the ego is passed, with everything before it; at least two nodes are always kept.
    ///
    /// One departure from TCP: a node that the plan reaches heading against the ego (more than
    /// 120 degrees off, [`FOLLOWER_MIN_HEADING_COSINE`]) is not passed. At the neck of a U-turn
    /// loop the way back runs a lane's width beside the way in, and TCP's follower, which
    /// measures "ahead" in straight lines between sparse nodes, skips the whole loop there: the
    /// target jumps 50 m behind the ego.
    pub fn step(&mut self, ego: DVec2, yaw: f64) -> PlanNode {
        if self.nodes.len() <= 1 {
            return self.nodes[0];
        }
        let heading = DVec2::from_angle(yaw);
        let mut to_pop = 0;
        let mut farthest = f64::NEG_INFINITY;
        let mut along = 0.0;
        for i in 1..self.nodes.len() {
            if along > self.max_distance {
                break;
            }
            let arrival = (self.nodes[i].position - self.nodes[i - 1].position).truncate();
            along += arrival.length();
            let against = arrival.dot(heading) < FOLLOWER_MIN_HEADING_COSINE * arrival.length();
            let d = (self.nodes[i].position.truncate() - ego).length();
            if d <= self.min_distance && d > farthest && !against {
                farthest = d;
                to_pop = i;
            }
        }
        for _ in 0..to_pop {
            if self.nodes.len() > 2 {
                self.nodes.pop_front();
            }
        }
        self.nodes[1]
    }

    /// Nodes still queued.
    pub fn remaining(&self) -> usize {
        self.nodes.len()
    }
}

/// A world point in the ego frame (x forward, y left, z up), ego at `position` heading `yaw`.
pub fn to_ego_frame(point: DVec3, position: DVec3, yaw: f64) -> DVec3 {
    let d = point - position;
    let [forward, left] = world_to_ego([d.x, d.y], yaw);
    DVec3::new(forward, left, d.z)
}
