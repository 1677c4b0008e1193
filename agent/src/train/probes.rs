//! The auxiliary outputs a run trains beside the imitation losses: the training-only hazard
//! probe on the scene tokens ([`super::hazard`], never in a checkpoint, its own resume file),
//! and the network's occupancy head on the BEV ([`crate::model::occupancy`], part of the
//! network; labels and loss in [`super::occupancy`]); their outputs and losses on a batch.

use std::path::Path;

use burn::module::Module;
use burn::store::{BurnpackStore, ModuleSnapshot};
use burn::tensor::{Device, Tensor};

use super::config::TrainConfig;
use super::data::Batch;
use super::hazard::{HazardProbe, HazardProbeConfig, hazard_loss};
use super::loss::AuxiliaryLosses;
use super::occupancy::{batch_targets, occupancy_loss};
use crate::model::{ModelOutput, SsrModel};

/// The training-only probes a run trains, as one module for the optimiser (which keeps their
/// state by parameter id, beside the network's).
#[derive(Module, Debug)]
pub struct Probes {
    /// What the expert brakes for, from the scene tokens (`resume/hazard.bpk`).
    pub hazard: Option<HazardProbe>,
}

/// The hazard probe's and the occupancy head's outputs on a batch.
#[derive(Debug, Clone, Default)]
pub struct AuxiliaryOutputs {
    /// `[B, 5]` hazard logits.
    pub hazard: Option<Tensor<2>>,
    /// `[B, Q, 2]` occupancy logits of the network's head, their targets, and `[B]` 1 for the
    /// samples that record their actors.
    pub occupancy: Option<(Tensor<3>, Tensor<3>, Tensor<1>)>,
}

impl Probes {
    /// Fresh probes for the run's loss weights.
    pub fn new(config: &TrainConfig, device: &Device) -> Self {
        let (channels, hidden) = (config.model.channels, config.model.head.hidden_dim);
        Self {
            hazard: (config.loss.hazard > 0.0)
                .then(|| HazardProbeConfig { channels, hidden }.init(device)),
        }
    }

    /// Loads each probe's weights (with their parameter ids) from its file in `dir`.
    pub fn load(&mut self, dir: &Path) -> Result<(), String> {
        if let Some(probe) = &mut self.hazard {
            load_weights(probe, dir, "hazard.bpk")?;
        }
        Ok(())
    }

    /// Saves each probe's weights into its file in `dir`.
    pub fn save(&self, dir: &Path) -> Result<(), String> {
        if let Some(probe) = &self.hazard {
            save_weights(probe, dir, "hazard.bpk")?;
        }
        Ok(())
    }

    /// The probes' and `model`'s occupancy head's outputs on the network's `output` for
    /// `batch` (targets on `device`).
    pub fn run(
        &self,
        model: &SsrModel,
        output: &ModelOutput,
        batch: &Batch,
        config: &TrainConfig,
        device: &Device,
    ) -> AuxiliaryOutputs {
        AuxiliaryOutputs {
            hazard: self
                .hazard
                .as_ref()
                .map(|probe| probe.forward(output.scene.tokens.clone())),
            occupancy: model.occupancy.as_ref().map(|head| {
                let (targets, recorded) =
                    batch_targets(batch.actors(), &config.model.bev.grid, device);
                (head.forward(output.bev.clone()), targets, recorded)
            }),
        }
    }
}

impl AuxiliaryOutputs {
    /// The probes' losses against `batch`'s labels.
    pub fn losses(&self, batch: &Batch) -> AuxiliaryLosses {
        AuxiliaryLosses {
            hazard: self
                .hazard
                .clone()
                .map(|logits| hazard_loss(logits, &batch.hazards())),
            occupancy: self
                .occupancy
                .clone()
                .map(|(logits, targets, recorded)| occupancy_loss(logits, targets, recorded)),
        }
    }
}

/// Loads a module's weights, with their parameter ids, from `file` in the resume folder `dir`.
pub(crate) fn load_weights<M: Module>(
    module: &mut M,
    dir: &Path,
    file: &str,
) -> Result<(), String> {
    let mut store = BurnpackStore::from_file(dir.join(file))
        .validate(true)
        .allow_partial(false);
    module
        .load_from(&mut store)
        .map(|_| ())
        .map_err(|e| format!("{file}: {e}"))
}

/// Saves a module's weights, with their parameter ids, as `file` in the folder `dir`.
pub(crate) fn save_weights<M: Module>(module: &M, dir: &Path, file: &str) -> Result<(), String> {
    let mut store = BurnpackStore::from_file(dir.join(file)).overwrite(true);
    module.save_into(&mut store).map_err(|e| e.to_string())
}
