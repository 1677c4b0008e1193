//! The occupancy head: from the BEV, which cells a road user covers, per cell and class
//! (TransFuser's and InterFuser's BEV auxiliary task).
//!
//! It trains the BEV to hold the road users: imitation gives the BEV only the gradient of six
//! waypoints and a control per frame, and a car stopped ahead explains only part of a brake
//! label (the learner drove into stopped cars it had seen for two seconds). It is in the
//! network, and in its checkpoints, when [`super::config::SsrConfig::occupancy_head`] says so,
//! so that what the network believes occupied can be read at serving too. The labels and the
//! loss are the trainer's ([`crate::train::occupancy`]).
//!
//! The motion head ([`super::config::SsrConfig::motion_head`]) is a second head of the same
//! shape trained on where the road users will be [`MOTION_HORIZON_S`] later, in the current
//! ego frame: the current BEV and the history it attends to show how they move, and the
//! safety stop reads it to brake for a car crossing towards the path before it is on it.

use burn::module::Module;
use burn::tensor::activation::relu;
use burn::tensor::{Device, Tensor};

use super::fused::FusedLinear;
use super::init::xavier_linear;

/// The head's channels, in logit order: what the car must not hit on the road (vehicles,
/// cyclists, obstacles) and walkers.
pub const OCCUPANCY_CHANNELS: [&str; 2] = ["vehicle", "walker"];

/// How far ahead the motion head looks, seconds (the training sample's future frame, SSR's
/// 1.5 s horizon).
pub const MOTION_HORIZON_S: f64 = 1.5;

/// Size of an [`OccupancyHead`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct OccupancyHeadConfig {
    /// Channels of the BEV (the network's `channels`).
    pub channels: usize,
    /// Width of the hidden layer.
    pub hidden: usize,
}

impl OccupancyHeadConfig {
    /// A randomly initialised head.
    pub fn init(&self, device: &Device) -> OccupancyHead {
        OccupancyHead {
            hidden: xavier_linear(self.channels, self.hidden, device),
            out: xavier_linear(self.hidden, OCCUPANCY_CHANNELS.len(), device),
        }
    }
}

/// One hidden layer per BEV cell, a logit per channel of [`OCCUPANCY_CHANNELS`].
#[derive(Module, Debug)]
pub struct OccupancyHead {
    hidden: FusedLinear,
    out: FusedLinear,
}

impl OccupancyHead {
    /// Occupancy logits of each BEV cell.
    ///
    /// # Shapes
    /// - bev: `[B, Q, C]`
    /// - output: `[B, Q, 2]` (in [`OCCUPANCY_CHANNELS`] order)
    pub fn forward(&self, bev: Tensor<3>) -> Tensor<3> {
        self.out.forward(relu(self.hidden.forward(bev)))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::float_tensor;

    #[test]
    fn the_head_maps_each_cell_to_a_logit_per_channel() {
        let device = Device::flex();
        let head = OccupancyHeadConfig {
            channels: 8,
            hidden: 16,
        }
        .init(&device);
        let bev = float_tensor(
            (0..2 * 5 * 8).map(|v| v as f32 * 0.01).collect(),
            [2, 5, 8],
            &device,
        );
        assert_eq!(head.forward(bev).dims(), [2, 5, 2]);
    }
}
