//! The auxiliary outputs a run trains beside the imitation losses: the network's hazard head on
//! the scene tokens ([`crate::model::hazard`]; loss in [`super::hazard`]), its light head on
//! them ([`crate::model::light`]; labels and loss in [`super::light`]), its occupancy head
//! on the BEV and the motion head, its twin for the future frame ([`crate::model::occupancy`];
//! labels and loss in [`super::occupancy`]); their outputs and losses on a batch.

use burn::tensor::{Device, Tensor};

use super::config::TrainConfig;
use super::data::Batch;
use super::hazard::hazard_loss;
use super::light::{light_labels, light_loss};
use super::loss::AuxiliaryLosses;
use super::occupancy::{batch_targets, occupancy_loss};
use crate::model::{ModelOutput, SsrModel};

/// The hazard head's and the occupancy head's outputs on a batch, each `None` where the
/// network has no such head.
#[derive(Debug, Clone, Default)]
pub struct AuxiliaryOutputs {
    /// `[B, 5]` hazard logits.
    pub hazard: Option<Tensor<2>>,
    /// `[B, Q, 2]` occupancy logits of the network's head, their targets, and `[B]` 1 for the
    /// samples that record their actors.
    pub occupancy: Option<(Tensor<3>, Tensor<3>, Tensor<1>)>,
    /// The same for the motion head, against the future frame's actors.
    pub motion: Option<(Tensor<3>, Tensor<3>, Tensor<1>)>,
    /// `[B, 4]` light logits.
    pub light: Option<Tensor<2>>,
}

impl AuxiliaryOutputs {
    /// `model`'s auxiliary heads on the network's `output` for `batch` (targets on `device`).
    pub fn of(
        model: &SsrModel,
        output: &ModelOutput,
        batch: &Batch,
        config: &TrainConfig,
        device: &Device,
    ) -> Self {
        Self {
            hazard: model
                .hazard
                .as_ref()
                .map(|head| head.forward(output.scene.tokens.clone())),
            occupancy: model.occupancy.as_ref().map(|head| {
                let (targets, recorded) =
                    batch_targets(batch.actors(), &config.model.bev.grid, device);
                (head.forward(output.bev.clone()), targets, recorded)
            }),
            motion: model.motion.as_ref().map(|head| {
                let (targets, recorded) =
                    batch_targets(batch.future_actors(), &config.model.bev.grid, device);
                (head.forward(output.bev.clone()), targets, recorded)
            }),
            light: model
                .light
                .as_ref()
                .map(|head| head.forward(output.scene.tokens.clone())),
        }
    }

    /// The heads' losses against `batch`'s labels.
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
            motion: self
                .motion
                .clone()
                .map(|(logits, targets, recorded)| occupancy_loss(logits, targets, recorded)),
            light: self
                .light
                .clone()
                .map(|logits| light_loss(logits, &light_labels(batch.lights()))),
        }
    }
}
