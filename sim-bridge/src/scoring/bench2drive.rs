//! Bench2Drive's figures beside DS, RC and IS (its `merge_route_json.py` and
//! `efficiency_smoothness_benchmark.py`):
//!
//! - **success**: the route was completed with no infraction but minimum speed (Bench2Drive's
//!   rule; only `--scoring lb2` records minimum speed); the success rate is the share of
//!   successful runs.
//! - **efficiency**: Leaderboard 2.0's `MinimumSpeedRouteTest` with Bench2Drive's 20
//!   checkpoints ([`SpeedRatio`]): the route is cut into 20 equal stretches of progress, and at
//!   the end of each the ego's mean speed is divided by the mean speed of the background
//!   vehicles (every one in the world, no radius, on the ticks where there are any), in
//!   percent, 100 when no background vehicle moved; a route's efficiency is the mean of its
//!   values up to 1000 %, the campaign's the mean over the routes that have one.
//! - **comfort**: the share of 2 s windows within nuPlan's comfort bounds ([`super::comfort`]),
//!   in percent; the campaign's is the mean over routes.
//!
//! Scenario vehicles (those that run red lights on purpose) are not background traffic.
//! [`SpeedRatio`] with 4 checkpoints is also Leaderboard 2.0's minimum-speed penalty
//! ([`super::Rules::Lb2`]).

use serde::{Deserialize, Serialize};

use super::RouteRecord;

/// Checkpoints of the efficiency test (Bench2Drive).
pub const EFFICIENCY_CHECKPOINTS: usize = 20;
/// Checkpoints of Leaderboard 2.0's minimum-speed penalty (`--scoring lb2`).
pub const MIN_SPEED_CHECKPOINTS: usize = 4;
/// Checkpoint values above this (percent) are left out of a route's efficiency.
const EFFICIENCY_CAP: f64 = 1000.0;
/// Progress (fraction of the route) past which the end of the route adds a last checkpoint.
const LAST_CHECKPOINT_PROGRESS: f64 = 0.95;

/// A run's Bench2Drive figures (`meta.bench2drive` of a record).
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct RouteFigures {
    /// Completed with no infraction.
    pub success: bool,
    /// Mean speed relative to the background traffic, percent; absent when no checkpoint was
    /// reached or every value exceeded 1000 %.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub efficiency: Option<f64>,
    /// Share of comfortable 2 s windows, percent; absent for runs under 0.3 s.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub comfort: Option<f64>,
}

/// A campaign's Bench2Drive figures (`meta.bench2drive` of the global record).
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct CampaignFigures {
    /// Successful runs over all runs, percent.
    pub success_rate: f64,
    /// Mean of the runs' efficiencies, percent (absent when none has one).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub efficiency: Option<f64>,
    /// Mean of the runs' comforts, percent (absent when none has one).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub comfort: Option<f64>,
}

impl CampaignFigures {
    /// The figures over `records`; records without figures (files written before they existed,
    /// unplannable routes) count as failures and add no efficiency or comfort.
    pub fn of(records: &[RouteRecord]) -> Self {
        let figures: Vec<RouteFigures> = records
            .iter()
            .map(|r| r.meta.bench2drive.unwrap_or_default())
            .collect();
        let mean = |values: Vec<f64>| {
            (!values.is_empty()).then(|| values.iter().sum::<f64>() / values.len() as f64)
        };
        Self {
            success_rate: if records.is_empty() {
                0.0
            } else {
                100.0 * figures.iter().filter(|f| f.success).count() as f64 / records.len() as f64
            },
            efficiency: mean(figures.iter().filter_map(|f| f.efficiency).collect()),
            comfort: mean(figures.iter().filter_map(|f| f.comfort).collect()),
        }
    }
}

/// Whether a finished record counts as a Bench2Drive success: completed, no infraction but
/// minimum speed (Bench2Drive's rule).
pub fn success(record: &RouteRecord) -> bool {
    record.completed()
        && super::InfractionKind::ALL
            .iter()
            .filter(|kind| **kind != super::InfractionKind::MinSpeed)
            .all(|kind| record.infractions.count(*kind) == 0)
}

/// Leaderboard 2.0's `MinimumSpeedRouteTest`: the ego's mean speed over a stretch of progress
/// against the background traffic's, once per stretch.
#[derive(Debug, Clone)]
pub struct SpeedRatio {
    stretch_m: f64,
    route_m: f64,
    last_checkpoint_m: f64,
    ego_sum: f64,
    traffic_sum: f64,
    samples: usize,
    values: Vec<f64>,
}

impl SpeedRatio {
    /// A test over a route of `route_m` metres with `checkpoints` equal stretches.
    pub fn new(route_m: f64, checkpoints: usize) -> Self {
        Self {
            stretch_m: route_m / checkpoints.max(1) as f64,
            route_m,
            last_checkpoint_m: 0.0,
            ego_sum: 0.0,
            traffic_sum: 0.0,
            samples: 0,
            values: Vec::new(),
        }
    }

    /// One tick: the ego at `progress_m` along the route at `ego_speed`, the background
    /// vehicles' mean speed `traffic_speed` (`None` when there are none), m/s. Returns the
    /// value of the checkpoint this tick reached, if any.
    pub fn update(
        &mut self,
        progress_m: f64,
        ego_speed: f64,
        traffic_speed: Option<f64>,
    ) -> Option<f64> {
        if let Some(traffic) = traffic_speed {
            self.ego_sum += ego_speed;
            self.traffic_sum += traffic;
            self.samples += 1;
        }
        (progress_m - self.last_checkpoint_m > self.stretch_m).then(|| {
            self.last_checkpoint_m = progress_m;
            self.checkpoint()
        })
    }

    /// The route ended at `progress_m`: a last checkpoint when past 95 % of it; returns its
    /// value, percent.
    pub fn finish(&mut self, progress_m: f64) -> Option<f64> {
        (self.route_m > 0.0 && progress_m / self.route_m > LAST_CHECKPOINT_PROGRESS)
            .then(|| self.checkpoint())
    }

    /// Every checkpoint's value so far, percent.
    pub fn values(&self) -> &[f64] {
        &self.values
    }

    fn checkpoint(&mut self) -> f64 {
        let value = if self.samples == 0 || self.traffic_sum <= 0.0 {
            100.0
        } else {
            (self.ego_sum / self.traffic_sum * 100.0 * 100.0).round() / 100.0
        };
        self.values.push(value);
        self.ego_sum = 0.0;
        self.traffic_sum = 0.0;
        self.samples = 0;
        value
    }
}

/// A route's efficiency from its checkpoint values: the mean of those up to 1000 %.
pub fn efficiency(values: &[f64]) -> Option<f64> {
    let kept: Vec<f64> = values
        .iter()
        .copied()
        .filter(|v| *v <= EFFICIENCY_CAP)
        .collect();
    (!kept.is_empty()).then(|| kept.iter().sum::<f64>() / kept.len() as f64)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn checkpoints_compare_mean_speeds_per_stretch() {
        // 100 m in 4 stretches: the ego at half the traffic's speed over the first half, no
        // traffic over the third stretch, the ego as fast as the traffic over the last.
        let mut ratio = SpeedRatio::new(100.0, 4);
        let mut progress = 0.0;
        while progress < 100.0 {
            let (ego, traffic) = match progress {
                p if p < 50.0 => (4.0, Some(8.0)),
                p if p < 77.0 => (8.0, None),
                _ => (8.0, Some(8.0)),
            };
            ratio.update(progress, ego, traffic);
            progress += 0.5;
        }
        assert_eq!(ratio.finish(99.5), Some(100.0));
        let values = ratio.values();
        assert_eq!(values.len(), 4, "{values:?}");
        assert_eq!(&values[..2], &[50.0, 50.0]);
        // No traffic: 100; the last checkpoint is the end's (past 95 % of the route).
        assert_eq!(&values[2..], &[100.0, 100.0]);
        assert_eq!(efficiency(values), Some(75.0));
    }

    #[test]
    fn a_route_ended_early_has_no_last_checkpoint_and_outliers_are_dropped() {
        let mut ratio = SpeedRatio::new(100.0, 4);
        assert_eq!(ratio.update(10.0, 1.0, Some(0.05)), None);
        assert_eq!(ratio.finish(10.0), None);
        assert!(ratio.values().is_empty());
        assert_eq!(efficiency(&[2000.0, 80.0]), Some(80.0));
        assert_eq!(efficiency(&[2000.0]), None);
    }

    #[test]
    fn success_needs_completion_and_no_infraction() {
        let mut record = RouteRecord {
            status: "Completed".into(),
            ..RouteRecord::default()
        };
        assert!(success(&record));
        record.infractions.red_light.push("ran a red light".into());
        assert!(!success(&record));
        record.infractions.red_light.clear();
        record.status = "Failed - Agent timed out".into();
        assert!(!success(&record));
    }

    #[test]
    fn campaign_figures_average_what_runs_have() {
        let run = |success, efficiency, comfort| RouteRecord {
            meta: super::super::RouteMeta {
                bench2drive: Some(RouteFigures {
                    success,
                    efficiency,
                    comfort,
                }),
                ..Default::default()
            },
            ..RouteRecord::default()
        };
        let records = [
            run(true, Some(90.0), Some(100.0)),
            run(false, None, Some(50.0)),
            RouteRecord::default(),
            run(true, Some(110.0), None),
        ];
        let figures = CampaignFigures::of(&records);
        assert_eq!(figures.success_rate, 50.0);
        assert_eq!(figures.efficiency, Some(100.0));
        assert_eq!(figures.comfort, Some(75.0));
    }
}
