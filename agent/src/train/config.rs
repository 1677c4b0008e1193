//! Training settings: optimiser, schedule, loss weights, ablations, cadence. Saved beside every
//! run and inside every checkpoint, so a run can be resumed and a checkpoint traced back.

use serde::{Deserialize, Serialize};

use super::data::Labels;
use super::loss::LossWeights;
use crate::history::History;
use crate::model::config::SsrConfig;

/// How the learning rate decays after the warm-up.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case", tag = "kind")]
pub enum Schedule {
    /// Cosine from `lr` down to `lr * final_ratio` at the last step.
    Cosine {
        /// The final learning rate as a fraction of the peak.
        final_ratio: f64,
    },
    /// Multiply by `gamma` every `every` steps (TCP halves its rate on a fixed schedule).
    Step {
        /// Steps between two decays (counted after the warm-up).
        every: u64,
        /// Factor applied at each decay.
        gamma: f64,
    },
}

/// A head of the network that a run can train alone ([`TrainConfig::train_only`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "kebab-case")]
pub enum Head {
    /// What the expert brakes for.
    Hazard,
    /// Where the road users are.
    Occupancy,
    /// Where they will be.
    Motion,
    /// The state of the light ahead.
    Light,
}

impl Head {
    /// Whether `model` has this head.
    pub fn in_model(self, model: &SsrConfig) -> bool {
        match self {
            Head::Hazard => model.hazard_head,
            Head::Occupancy => model.occupancy_head,
            Head::Motion => model.motion_head,
            Head::Light => model.light_head,
        }
    }
}

/// Everything a run is defined by (the dataset path is given separately).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TrainConfig {
    /// The network being trained.
    pub model: SsrConfig,
    /// Samples per optimiser step.
    pub batch_size: usize,
    /// Optimiser steps of the whole run (the schedule spans them).
    pub steps: u64,
    /// Peak learning rate (AdamW).
    pub lr: f64,
    /// AdamW's decoupled weight decay.
    pub weight_decay: f32,
    /// Linear warm-up from 0, steps.
    pub warmup_steps: u64,
    /// How the learning rate decays after the warm-up.
    pub schedule: Schedule,
    /// Each parameter's gradient is clipped to this L2 norm (burn's per-parameter clipping).
    pub clip_norm: f32,
    /// Weights of the loss terms.
    pub loss: LossWeights,
    /// Ablation "no FFP": no future-BEV prediction and no BEV loss.
    pub future_bev: bool,
    /// Photometric jitter strength (0 = none).
    pub augment: f32,
    /// Share of samples trained on the first-frame path: no history BEV and no ego motion, as
    /// on an episode's first tick. Against the copycat shortcut (a network that reads what the
    /// expert was just doing from the history instead of the scene); 0 = never.
    #[serde(default)]
    pub history_dropout: f64,
    /// Share of samples shown a later frame's target point
    /// ([`super::data::SampleDraw::later_target`]): against driving the straight line to the
    /// target; 0 = never.
    #[serde(default)]
    pub later_target: f64,
    /// The history the network trains with, and is then served with: the frame 0.5 s back
    /// attending to the frame 1 s back ([`History::Chain`], three BEV passes a sample) or
    /// encoded on its own ([`History::Link`], two).
    #[serde(default)]
    pub history: History,
    /// Where the waypoint labels come from (runs from before the switch: driven positions).
    #[serde(default = "Labels::of_configs_before_plans")]
    pub labels: Labels,
    /// Draw training samples by [`super::data::sampling_weight`] (fewer standstills; more
    /// starts, turns, lane changes and recoveries) instead of uniformly.
    #[serde(default)]
    pub balanced: bool,
    /// The checkpoint the weights start from (fine-tuning); `None` = fresh weights from `seed`.
    #[serde(default)]
    pub init: Option<std::path::PathBuf>,
    /// The checkpoint whose perception (backbone, BEV encoder and occupancy head) the fresh
    /// network starts from, the rest drawn from `seed`: the ablations' shared start, for
    /// networks whose tokens, gate or head differ from the checkpoint's. Exclusive with `init`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub init_perception: Option<std::path::PathBuf>,
    /// Train only these heads; the rest of the network keeps the weights `init` gave it (its
    /// driving stays that checkpoint's, the heads feed the controller). Empty: everything
    /// trains.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub train_only: Vec<Head>,
    /// Fraction of routes held out for validation.
    pub validation_fraction: f64,
    /// Validate every this many steps (and at the end); 0 = only at the end.
    pub validate_every: u64,
    /// Validation samples used (evenly spaced over the held-out set); 0 = all.
    pub validation_samples: usize,
    /// Write a checkpoint and the resume state every this many steps (and at the end).
    pub checkpoint_every: u64,
    /// Seeds the initial weights, the shuffle and the augmentation.
    pub seed: u64,
}

impl TrainConfig {
    /// Defaults: AdamW at 3e-4 with 300 warm-up steps and a cosine decay to 5 %, batch 8,
    /// per-parameter clipping at 1.0, TCP/SSR loss weights, FFP on, the expert's plan as
    /// waypoint labels, balanced sampling.
    pub fn new(model: SsrConfig, steps: u64) -> Self {
        Self {
            model,
            batch_size: 8,
            steps,
            lr: 3e-4,
            weight_decay: 1e-2,
            warmup_steps: 300,
            schedule: Schedule::Cosine { final_ratio: 0.05 },
            clip_norm: 1.0,
            loss: LossWeights::default(),
            future_bev: true,
            augment: 1.0,
            history_dropout: 0.0,
            later_target: 0.0,
            history: History::Chain,
            labels: Labels::Plan,
            balanced: true,
            init: None,
            init_perception: None,
            train_only: Vec::new(),
            validation_fraction: 0.05,
            validate_every: 1000,
            validation_samples: 1024,
            checkpoint_every: 500,
            seed: 0,
        }
    }

    /// The learning rate of optimiser step `step` (0-based).
    pub fn lr_at(&self, step: u64) -> f64 {
        if step < self.warmup_steps {
            return self.lr * (step + 1) as f64 / self.warmup_steps as f64;
        }
        match self.schedule {
            Schedule::Cosine { final_ratio } => {
                let span = self.steps.saturating_sub(self.warmup_steps).max(1) as f64;
                let done = ((step - self.warmup_steps) as f64 / span).min(1.0);
                let cosine = 0.5 * (1.0 + (std::f64::consts::PI * done).cos());
                self.lr * (final_ratio + (1.0 - final_ratio) * cosine)
            }
            Schedule::Step { every, gamma } => {
                self.lr * gamma.powf(((step - self.warmup_steps) / every.max(1)) as f64)
            }
        }
    }

    /// Checks every setting; the message names the field.
    pub fn validate(&self) -> Result<(), String> {
        self.model.validate().map_err(|e| e.to_string())?;
        let positive = [
            ("batch_size", self.batch_size as f64),
            ("steps", self.steps as f64),
            ("lr", self.lr),
            ("checkpoint_every", self.checkpoint_every as f64),
        ];
        for (field, value) in positive {
            if !(value.is_finite() && value > 0.0) {
                return Err(format!("{field} must be positive, got {value}"));
            }
        }
        for (field, share) in [
            ("history_dropout", self.history_dropout),
            ("later_target", self.later_target),
        ] {
            if !(0.0..=1.0).contains(&share) {
                return Err(format!("{field} must be in [0, 1], got {share}"));
            }
        }
        if self.init.is_some() && self.init_perception.is_some() {
            return Err(
                "init and init_perception are exclusive: a run starts from one checkpoint".into(),
            );
        }
        if !self.train_only.is_empty() && self.init.is_none() {
            return Err("train_only needs init: the rest of the network keeps its weights".into());
        }
        if let Some(head) = self.train_only.iter().find(|h| !h.in_model(&self.model)) {
            return Err(format!(
                "train_only names the {head:?} head, which the network does not have (give its \
                 loss a weight)"
            ));
        }
        if self.history == History::Recursive {
            return Err("history must be chain or link: training gives no recursion".into());
        }
        if !(0.0..1.0).contains(&self.validation_fraction) {
            return Err(format!(
                "validation_fraction must be in [0, 1), got {}",
                self.validation_fraction
            ));
        }
        let finite = [
            ("weight_decay", self.weight_decay),
            ("clip_norm", self.clip_norm),
            ("augment", self.augment),
            ("loss.hazard", self.loss.hazard),
            ("loss.occupancy", self.loss.occupancy),
            ("loss.motion", self.loss.motion),
            ("loss.light", self.loss.light),
        ];
        if let Some((field, value)) = finite.iter().find(|(_, v)| !v.is_finite() || *v < 0.0) {
            return Err(format!("{field} must be finite and >= 0, got {value}"));
        }
        for (head, weight, has) in [
            ("occupancy", self.loss.occupancy, self.model.occupancy_head),
            ("hazard", self.loss.hazard, self.model.hazard_head),
            ("motion", self.loss.motion, self.model.motion_head),
            ("light", self.loss.light, self.model.light_head),
        ] {
            if (weight > 0.0) != has {
                return Err(format!(
                    "loss.{head} = {weight} but model.{head}_head = {has}: the head trains exactly \
                     when its loss has a weight (an untrained head would ship in the checkpoints)"
                ));
            }
        }
        Ok(())
    }
}
