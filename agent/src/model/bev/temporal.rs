//! Temporal self-attention: each BEV query attends, with deformable sampling, to two slots: the
//! episode's previous BEV aligned to the current ego frame, and the current queries themselves
//! (BEVFormer's TSA with a queue of two). On the first frame of an episode both slots are the
//! current queries.
//!
//! Alignment is exact in rotation and translation: the previous BEV is resampled at the
//! position each current cell centre had in the previous ego frame ([`align_previous_bev`]),
//! so a static object keeps its world position across ticks.

use burn::module::Module;
use burn::nn::Linear;
use burn::tensor::{Device, Tensor};

use crate::model::cpu_kernels;
use crate::model::init::{constant_linear, deformable_offsets, xavier_linear};
use crate::model::sampling::{bilinear_sample, deformable_aggregate};

/// Queue slots: the aligned previous BEV and the current queries.
const SLOTS: usize = 2;

/// How old the history BEV is, seconds, in training and serving alike (one temporal contract):
/// SSR trains on 2 Hz keyframes with a queue of two. Serving attends to the BEV it computed
/// [`HISTORY_TICKS`] steps earlier, itself computed with the one before it (ten interleaved
/// recursive chains at 0.5 s); training encodes the frame 0.5 s back with the frame 1 s back as
/// its own history, so both the BEV and the ego motion fed to the can-bus have the age and the
/// distribution they have when serving.
pub const HISTORY_S: f64 = 0.5;
/// [`HISTORY_S`] in steps of the leaderboard's 20 Hz.
pub const HISTORY_TICKS: usize = 10;

/// Resamples the previous BEV (`[B, Q, C]`) into the current ego frame: cell i takes the
/// previous BEV at `previous_points[:, i]` (normalised coordinates in the previous grid,
/// `[B, Q, 2]`); cells that were outside the previous grid become zero.
pub fn align_previous_bev(
    previous: Tensor<3>,
    rows: usize,
    cols: usize,
    previous_points: Tensor<3>,
) -> Tensor<3> {
    bilinear_sample(previous, rows, cols, previous_points)
}

#[derive(Module, Debug)]
pub struct TemporalSelfAttention {
    offsets: Linear,
    weights: Linear,
    value_proj: Linear,
    output_proj: Linear,
    heads: usize,
    points: usize,
}

impl TemporalSelfAttention {
    pub fn new(channels: usize, heads: usize, points: usize, device: &Device) -> Self {
        Self {
            offsets: deformable_offsets(2 * channels, SLOTS, heads, points, device),
            weights: constant_linear(
                2 * channels,
                SLOTS * heads * points,
                vec![0.0; SLOTS * heads * points],
                device,
            ),
            value_proj: xavier_linear(channels, channels, device),
            output_proj: xavier_linear(channels, channels, device),
            heads,
            points,
        }
    }

    /// `query` `[B, Q, C]`, `pos` `[1, Q, C]`, `aligned_previous` `[B, Q, C]`, `has_previous`
    /// `[B, 1, 1]`, `reference` `[1, Q, 2]` the normalised cell centres of the `rows x cols`
    /// grid. Returns the updated query (residual included).
    #[allow(clippy::too_many_arguments)]
    pub fn forward(
        &self,
        query: Tensor<3>,
        pos: Tensor<3>,
        aligned_previous: Tensor<3>,
        has_previous: Tensor<3>,
        reference: Tensor<3>,
        rows: usize,
        cols: usize,
    ) -> Tensor<3> {
        let [b, q, c] = query.dims();
        let (heads, points) = (self.heads, self.points);
        let head_dim = c / heads;
        let device = query.device();
        // First-frame path: a sample without a previous BEV attends to its own queries twice.
        let previous = aligned_previous * has_previous.clone()
            + query.clone() * has_previous.neg().add_scalar(1.0);
        let context = Tensor::cat(vec![previous.clone(), query.clone() + pos], 2);

        let scale = Tensor::<1>::from_floats([1.0 / cols as f32, 1.0 / rows as f32], &device)
            .reshape([1, 1, 1, 1, 1, 2]);
        let offsets = cpu_kernels::linear(&self.offsets, context.clone())
            .reshape([b, q, SLOTS, heads, points, 2])
            .permute([0, 2, 3, 1, 4, 5])
            * scale;
        let locations = (offsets + reference.reshape([1, 1, 1, q, 1, 2])).reshape([
            b * SLOTS * heads,
            q,
            points,
            2,
        ]);
        let weights = cpu_kernels::softmax(
            cpu_kernels::linear(&self.weights, context).reshape([b, q, SLOTS, heads, points]),
            4,
        )
        .permute([0, 2, 3, 1, 4])
        .reshape([b * SLOTS * heads, q, points]);

        let values = cpu_kernels::linear(
            &self.value_proj,
            Tensor::stack::<4>(vec![previous, query.clone()], 1),
        )
        .reshape([b * SLOTS, q, heads, head_dim])
        .swap_dims(1, 2)
        .reshape([b * SLOTS * heads, q, head_dim]);
        let sampled = deformable_aggregate(values, rows, cols, locations, weights)
            .reshape([b, SLOTS, heads, q, head_dim])
            .mean_dim(1)
            .reshape([b, heads, q, head_dim])
            .swap_dims(1, 2)
            .reshape([b, q, c]);
        query + cpu_kernels::linear(&self.output_proj, sampled)
    }
}
