//! Open-loop metrics of predicted trajectories against what happened next in a step log, as
//! the SSR paper reports them (after ST-P3/UniAD), for horizons of 1, 2 and 3 s:
//!
//! - **L2 at h** (UniAD's convention: the error *at* h; ST-P3 and VAD average the errors up to
//!   h): distance between the predicted waypoint at h and where the recorded ego actually was h
//!   later, both in the ego frame of the prediction's tick; the mean over ticks that have both
//!   (a model whose plan ends before h has no value there; non-finite plans are skipped).
//! - **Collision rate at h**: the share of predictions whose ego box, placed at any predicted
//!   waypoint up to h (heading along the path), overlaps a recorded actor box at the matching
//!   time.

use glam::DVec2;
use ssrdrive_proto::v1;

use super::log::StepLog;
use crate::route::plan::to_ego_frame;
use crate::world::state::Obb;

/// Horizons reported, seconds.
pub const HORIZONS: [f64; 3] = [1.0, 2.0, 3.0];
/// Spacing of planned waypoints, seconds.
pub const WAYPOINT_STEP_S: f64 = 0.5;

/// Metrics at one horizon.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct HorizonMetrics {
    /// The horizon, s.
    pub horizon_s: f64,
    /// Mean L2, metres (`None` without samples).
    pub l2_m: Option<f64>,
    /// Share of predictions in collision, 0..1 (`None` without samples).
    pub collision_rate: Option<f64>,
    /// Predictions that reached the horizon and had a recorded pose there.
    pub samples: usize,
}

/// A recorded pose as (position, yaw); `None` when missing or not finite.
fn pose(p: &Option<v1::Pose>) -> Option<(DVec2, f64)> {
    let p = p.as_ref()?;
    let pose = (DVec2::new(p.x, p.y), p.yaw);
    (pose.0.is_finite() && pose.1.is_finite()).then_some(pose)
}

fn to_world(point: DVec2, origin: DVec2, yaw: f64) -> DVec2 {
    origin + DVec2::from_angle(yaw).rotate(point)
}

/// Open-loop metrics of `predictions` (one per log tick, ego frame of that tick; empty where
/// the step failed) against `log`.
pub fn open_loop(log: &StepLog, predictions: &[Vec<DVec2>]) -> Vec<HorizonMetrics> {
    let tick_s = if log.header.tick_s > 0.0 {
        log.header.tick_s
    } else {
        crate::world::DT
    };
    let half = DVec2::new(log.header.ego_half_length, log.header.ego_half_width);
    HORIZONS
        .iter()
        .map(|&horizon| {
            let steps = (horizon / WAYPOINT_STEP_S).round() as usize;
            let (mut l2_sum, mut collisions, mut samples) = (0.0, 0usize, 0usize);
            for (t, plan) in predictions.iter().enumerate() {
                let ahead = (horizon / tick_s).round() as usize;
                if plan.len() < steps
                    || t + ahead >= log.ticks.len()
                    || !plan[..steps].iter().all(|p| p.is_finite())
                {
                    continue;
                }
                let (Some((origin, yaw)), Some((truth, _))) =
                    (pose(&log.ticks[t].ego), pose(&log.ticks[t + ahead].ego))
                else {
                    continue;
                };
                l2_sum += plan[steps - 1]
                    .distance(to_ego_frame(truth.extend(0.0), origin.extend(0.0), yaw).truncate());
                samples += 1;
                let collided = (0..steps).any(|k| {
                    let at = to_world(plan[k], origin, yaw);
                    let previous = if k == 0 {
                        origin
                    } else {
                        to_world(plan[k - 1], origin, yaw)
                    };
                    let heading = if at.distance(previous) > 0.05 {
                        (at - previous).to_angle()
                    } else {
                        yaw
                    };
                    let ego = Obb {
                        centre: at,
                        yaw: heading,
                        half,
                    };
                    let index = t + ((k + 1) as f64 * WAYPOINT_STEP_S / tick_s).round() as usize;
                    log.ticks[index].actors.iter().any(|a| {
                        ego.overlaps(&Obb {
                            centre: DVec2::new(a.x, a.y),
                            yaw: a.yaw,
                            half: DVec2::new(a.half_length, a.half_width),
                        })
                    })
                });
                collisions += usize::from(collided);
            }
            HorizonMetrics {
                horizon_s: horizon,
                l2_m: (samples > 0).then(|| l2_sum / samples as f64),
                collision_rate: (samples > 0).then(|| collisions as f64 / samples as f64),
                samples,
            }
        })
        .collect()
}
