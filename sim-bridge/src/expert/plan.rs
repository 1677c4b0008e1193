//! The expert's plan: where it means to be every 0.5 s for the next 3 s, as ego-frame
//! waypoints. It is the ground truth a planning agent should predict, and what the oracle-plan
//! agent drives with.
//!
//! The plan rolls the expert's own longitudinal rule forward along the dense route: from the
//! ego's arc position and speed, 20 Hz steps of the IDM towards the speed target at each
//! point ahead (cruise, curves, junctions, walkers), with this tick's obstacle moving at its
//! current speed, and full braking while a collision is forecast. Laterally the waypoints lie
//! on the route's centre line, so a plan from a state off the lane leads back onto it (the
//! label a recovering agent needs), whatever the car did to get there.

use glam::DVec2;

use super::hazards::HazardView;
use super::{IDM, target_speed};
use crate::map::Map;
use crate::route::DenseRoute;
use crate::world::state::EgoState;

/// Seconds between plan waypoints.
pub const PLAN_STEP: f64 = 0.5;
/// Waypoints in a plan (3 s).
pub const PLAN_POINTS: usize = 6;
/// Integration step of the rollout, s (the simulator's tick).
const DT: f64 = crate::world::DT;

/// What the rollout starts from.
pub(crate) struct PlanStart<'a> {
    pub map: &'a Map,
    pub route: &'a DenseRoute,
    /// The ego's route index.
    pub index: usize,
    pub ego: &'a EgoState,
    /// This tick's hazard scan.
    pub view: &'a HazardView,
    /// Strongest braking the ego can do, m/s^2.
    pub max_brake: f64,
}

/// The plan: [`PLAN_POINTS`] waypoints in the ego frame (x forward, y left), [`PLAN_STEP`] apart.
pub(crate) fn plan(start: &PlanStart<'_>) -> Vec<DVec2> {
    let PlanStart {
        map, route, ego, ..
    } = *start;
    let s0 = route.arc_near(start.index, ego.position.truncate());
    let (mut s, mut v, mut index) = (0.0, ego.speed, start.index);
    let ticks_per_point = (PLAN_STEP / DT).round() as usize;
    let mut waypoints = Vec::with_capacity(PLAN_POINTS);
    for tick in 1..=PLAN_POINTS * ticks_per_point {
        let t = (tick - 1) as f64 * DT;
        while index + 1 < route.points.len() && route.cum[index + 1] <= s0 + s {
            index += 1;
        }
        let accel = if start.view.collision_predicted {
            -start.max_brake
        } else {
            let target = target_speed(map, route, index, start.view);
            let obstacle = start
                .view
                .obstacle
                .map(|(gap, lead)| (gap + lead * t - s, lead));
            IDM.acceleration(v, target, obstacle).max(-start.max_brake)
        };
        let v1 = (v + accel * DT).max(0.0);
        s += 0.5 * (v + v1) * DT;
        v = v1;
        if tick % ticks_per_point == 0 {
            let d = route.position_at(s0 + s) - ego.position.truncate();
            let forward = ego.forward();
            waypoints.push(DVec2::new(d.dot(forward), forward.perp_dot(d)));
        }
    }
    waypoints
}
