//! Open-loop validation metrics over the held-out routes: the loss, the L2 of the planned
//! waypoints at 1, 2 and 3 s, the control branch's errors, and the same per situation (each
//! command, start-ups from standstill, and what the expert brakes for), since a mean over a
//! validation set that is half lane following hides the turns, starts and stops closed-loop
//! driving depends on; with the hazard head on, how often it names that cause; with the
//! occupancy head on, its balanced accuracy on the BEV cells, and the motion head's on the
//! future frame's cells.

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};
use ssrdrive_proto::dataset::BrakeReason;

use super::data::{Batch, SampleRef};
use super::occupancy::{Confusion, OCCUPANCY_CHANNELS};
use crate::control::beta::control_from_beta;
use crate::model::float_values;
use crate::model::hazard::Hazard;
use crate::model::tcp_head::HeadOutput;

/// Horizons of the open-loop L2, seconds.
pub const L2_HORIZONS_S: [f64; 3] = [1.0, 2.0, 3.0];

/// Errors over one set of validation samples.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct GroupMetrics {
    /// Validation samples in the group.
    pub samples: usize,
    /// L2 of the planned waypoint at [`L2_HORIZONS_S`] to the label, metres (`None` where the
    /// model plans less far).
    pub l2_m: Vec<Option<f32>>,
    /// Mean absolute error of the control branch's steer against the expert's.
    pub steer_mae: f32,
    /// Mean absolute error of the control branch's throttle against the expert's.
    pub throttle_mae: f32,
    /// Mean absolute error of the control branch's brake against the expert's.
    pub brake_mae: f32,
    /// Share of the samples whose cause of braking ([`Hazard`], `clear` included) the hazard
    /// head names; `None` in runs without the head.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub hazard_accuracy: Option<f32>,
}

/// Open-loop metrics over the validation routes.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ValidationMetrics {
    /// Optimiser steps done when the validation ran.
    pub step: u64,
    /// Mean total loss over the validation samples.
    pub loss: f32,
    /// Over every sample (flattened: the metrics lines keep their earlier shape).
    #[serde(flatten)]
    pub all: GroupMetrics,
    /// The same per situation ([`situations`]); empty in runs from before it was reported.
    #[serde(default)]
    pub by_situation: BTreeMap<String, GroupMetrics>,
    /// Per occupancy channel ([`OCCUPANCY_CHANNELS`]) with occupied and empty cells, the
    /// occupancy head's balanced accuracy ([`Confusion::balanced_accuracy`]) over the samples
    /// that record their actors; empty without the head.
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub occupancy_accuracy: BTreeMap<String, f32>,
    /// The same for the motion head, against the future frame's actors; empty without it.
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub motion_accuracy: BTreeMap<String, f32>,
    /// The share of the samples recording a light ahead whose state the light head names;
    /// `None` without the head or such samples.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub light_accuracy: Option<f32>,
    /// The share of the samples with a red light ahead that it calls red.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub light_red_recall: Option<f32>,
}

impl ValidationMetrics {
    /// One line: L2 and steer error over all samples, then the 2 s L2 per situation, then
    /// the hazard head's accuracy (with the head).
    pub fn summary(&self) -> String {
        let per: Vec<String> = self
            .by_situation
            .iter()
            .map(|(name, g)| {
                let l2 = g.l2_m.get(1).copied().flatten();
                format!("{name} {}", l2.map_or("-".into(), |v| format!("{v:.2}")))
            })
            .collect();
        let probe = self.all.hazard_accuracy.map_or(String::new(), |all| {
            let lights = self
                .by_situation
                .get("brake:light")
                .and_then(|g| g.hazard_accuracy);
            format!(
                "; hazard head right on {:.0} % ({} of light stops)",
                100.0 * all,
                lights.map_or("-".into(), |v| format!("{:.0} %", 100.0 * v))
            )
        });
        let occupancy: String = self
            .occupancy_accuracy
            .iter()
            .map(|(channel, a)| format!("; {channel} occupancy {:.0} %", 100.0 * a))
            .chain(
                self.motion_accuracy
                    .iter()
                    .map(|(channel, a)| format!("; {channel} motion {:.0} %", 100.0 * a)),
            )
            .chain(
                self.light_accuracy
                    .map(|a| format!("; light state right on {:.0} %", 100.0 * a)),
            )
            .chain(
                self.light_red_recall
                    .map(|r| format!(" ({:.0} % of red lights)", 100.0 * r)),
            )
            .collect();
        format!(
            "L2 {} m, steer MAE {:.3}; L2 at 2 s by situation: {}{probe}{occupancy}",
            format_l2(&self.all.l2_m),
            self.all.steer_mae,
            per.join(", ")
        )
    }
}

/// The situations a validation sample counts in: its command (`left`, `right`, `straight`,
/// `follow`, `change-lane`); `start` when the car stands (below 1 m/s) and the expert
/// accelerates; and, when the expert brakes or holds, what for: `brake:light` (a red or
/// yellow light), `brake:sign`, `brake:road-user` (a vehicle, walker, obstacle or forecast
/// collision) or `brake:lane-change`, so the brake error shows which causes the network reads.
pub fn situations(
    command: &[f32],
    speed: f32,
    expert_throttle: f32,
    brake_reason: Option<BrakeReason>,
) -> Vec<&'static str> {
    let index = command
        .iter()
        .position(|&v| v > 0.5)
        .expect("a one-hot command");
    let mut out = vec![match index {
        0 => "left",
        1 => "right",
        2 => "straight",
        3 => "follow",
        _ => "change-lane",
    }];
    if speed < 1.0 && expert_throttle > 0.1 {
        out.push("start");
    }
    out.extend(Hazard::of(brake_reason).situation());
    out
}

/// Up to `limit` samples spread evenly over `samples` (all when `limit` is 0).
pub fn spread(samples: &[SampleRef], limit: usize) -> Vec<SampleRef> {
    if limit == 0 || samples.len() <= limit {
        return samples.to_vec();
    }
    (0..limit)
        .map(|i| samples[i * samples.len() / limit])
        .collect()
}

/// Waypoints up to `horizon_s` (waypoints are 0.5 s apart): the horizon's waypoint is the
/// one before this index.
pub fn waypoints_until(horizon_s: f64) -> usize {
    (horizon_s / ssrdrive_proto::dataset::FUTURE_STEP).round() as usize
}

/// Running sums of one group's errors.
#[derive(Default, Clone)]
struct GroupSums {
    samples: usize,
    l2: [f64; L2_HORIZONS_S.len()],
    steer: f64,
    throttle: f64,
    brake: f64,
    /// Samples the hazard head named the cause of (counted only with the head).
    hazard_hits: Option<usize>,
}

impl GroupSums {
    fn accumulate(&mut self, other: &GroupSums) {
        self.samples += other.samples;
        for (sum, value) in self.l2.iter_mut().zip(other.l2) {
            *sum += value;
        }
        self.steer += other.steer;
        self.throttle += other.throttle;
        self.brake += other.brake;
        if let Some(hits) = other.hazard_hits {
            *self.hazard_hits.get_or_insert(0) += hits;
        }
    }

    fn finish(&self, p: usize) -> GroupMetrics {
        let n = self.samples.max(1) as f64;
        let mean = |sum: f64| (sum / n) as f32;
        GroupMetrics {
            samples: self.samples,
            l2_m: L2_HORIZONS_S
                .iter()
                .zip(self.l2)
                .map(|(horizon, sum)| {
                    (waypoints_until(*horizon) <= p && self.samples > 0).then(|| mean(sum))
                })
                .collect(),
            steer_mae: mean(self.steer),
            throttle_mae: mean(self.throttle),
            brake_mae: mean(self.brake),
            hazard_accuracy: self.hazard_hits.map(|hits| mean(hits as f64)),
        }
    }
}

/// Running sums of the validation metrics.
#[derive(Default)]
pub struct ValidationSums {
    loss: f64,
    all: GroupSums,
    by_situation: BTreeMap<&'static str, GroupSums>,
    /// Per occupancy channel: how the occupancy head's cells (then the motion head's) compare
    /// with the labels.
    cells: [[Confusion; OCCUPANCY_CHANNELS.len()]; 2],
    /// The light head's hits: right, labelled, red called red, red.
    light: Option<[usize; 4]>,
}

/// What a batch's optional heads said, each where the run has the head.
#[derive(Default)]
pub struct HeadVerdicts {
    /// The hazard head's class per sample.
    pub hazards: Option<Vec<Hazard>>,
    /// The occupancy head's, then the motion head's, [`Confusion`] per channel.
    pub cells: [Option<[Confusion; OCCUPANCY_CHANNELS.len()]>; 2],
    /// The light head's hits: right, labelled, red called red, red.
    pub light: Option<[usize; 4]>,
}

impl ValidationSums {
    /// Adds a batch's head output (with `p` waypoints), what its optional heads said and its
    /// mean loss.
    pub fn add(
        &mut self,
        batch: &Batch,
        head: &HeadOutput,
        verdicts: HeadVerdicts,
        p: usize,
        loss: f32,
    ) {
        let HeadVerdicts {
            hazards,
            cells,
            light,
        } = verdicts;
        if let Some(hits) = light {
            let sum = self.light.get_or_insert([0; 4]);
            for (s, h) in sum.iter_mut().zip(hits) {
                *s += h;
            }
        }
        for (sums, batch) in self.cells.iter_mut().zip(cells) {
            for (sum, batch) in sums.iter_mut().zip(batch.unwrap_or_default()) {
                sum.add(&batch);
            }
        }
        let waypoints = float_values(head.waypoints.clone());
        let alpha = float_values(head.alpha.clone());
        let beta = float_values(head.beta.clone());
        let commands = batch.commands();
        for i in 0..batch.size {
            let mut one = GroupSums {
                samples: 1,
                ..GroupSums::default()
            };
            for (h, horizon) in L2_HORIZONS_S.iter().enumerate() {
                let k = waypoints_until(*horizon) - 1;
                if k < p {
                    let at = (i * p + k) * 2;
                    let dx = waypoints[at] - batch.waypoints[at];
                    let dy = waypoints[at + 1] - batch.waypoints[at + 1];
                    one.l2[h] = (dx * dx + dy * dy).sqrt() as f64;
                }
            }
            let control = control_from_beta(
                [alpha[2 * i], alpha[2 * i + 1]],
                [beta[2 * i], beta[2 * i + 1]],
            );
            let expert = &batch.expert[i];
            one.steer = f64::from((control.steer - expert.steer).abs());
            one.throttle = f64::from((control.throttle - expert.throttle).abs());
            one.brake = f64::from((control.brake - expert.brake).abs());
            one.hazard_hits = hazards
                .as_ref()
                .map(|h| usize::from(h[i] == Hazard::of(batch.brake_reason(i))));
            self.all.accumulate(&one);
            let speed = batch.speed_label(i);
            for group in situations(commands[i], speed, expert.throttle, batch.brake_reason(i)) {
                self.by_situation.entry(group).or_default().accumulate(&one);
            }
        }
        self.loss += loss as f64 * batch.size as f64;
    }

    /// The means, at optimiser step `step`.
    pub fn finish(self, step: u64, p: usize) -> ValidationMetrics {
        ValidationMetrics {
            step,
            loss: (self.loss / self.all.samples.max(1) as f64) as f32,
            all: self.all.finish(p),
            by_situation: self
                .by_situation
                .iter()
                .map(|(name, sums)| (name.to_string(), sums.finish(p)))
                .collect(),
            occupancy_accuracy: accuracies(&self.cells[0]),
            motion_accuracy: accuracies(&self.cells[1]),
            light_accuracy: self
                .light
                .filter(|h| h[1] > 0)
                .map(|h| h[0] as f32 / h[1] as f32),
            light_red_recall: self
                .light
                .filter(|h| h[3] > 0)
                .map(|h| h[2] as f32 / h[3] as f32),
        }
    }
}

/// Each channel's balanced accuracy, where it has occupied and empty cells.
fn accuracies(cells: &[Confusion; OCCUPANCY_CHANNELS.len()]) -> BTreeMap<String, f32> {
    OCCUPANCY_CHANNELS
        .iter()
        .zip(cells)
        .filter_map(|(channel, c)| Some((channel.to_string(), c.balanced_accuracy()?)))
        .collect()
}

/// "0.41 / 0.93 / 1.62" for the horizons, "-" where not planned.
pub fn format_l2(l2: &[Option<f32>]) -> String {
    l2.iter()
        .map(|v| v.map_or("-".into(), |v| format!("{v:.2}")))
        .collect::<Vec<_>>()
        .join(" / ")
}
