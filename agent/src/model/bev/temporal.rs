//! Temporal self-attention: each BEV query attends, with deformable sampling, to two slots: the
//! episode's previous BEV aligned to the current ego frame, and the current queries themselves
//! (BEVFormer's TSA with a queue of two). On the first frame of an episode both slots are the
//! current queries.
//!
//! Alignment is exact in rotation and translation: the previous BEV is resampled at the
//! position each current cell centre had in the previous ego frame ([`align_previous_bev`]),
//! so a static object keeps its world position across ticks.

use burn::module::Module;
use burn::tensor::{Device, Tensor};

use crate::model::cpu_kernels;
use crate::model::fused::FusedLinear;
use crate::model::init::{constant_linear, deformable_offsets, xavier_linear};
use crate::model::sampling::{bilinear_sample, deformable_aggregate};

/// Queue slots: the aligned previous BEV and the current queries.
const SLOTS: usize = 2;

/// How old the history BEV is, seconds, in training and serving alike (one temporal contract):
/// SSR trains on 2 Hz keyframes with a queue of two. Training encodes the frame 0.5 s back with
/// the frame 1 s back as its own history (and nothing older), and serving computes exactly that
/// chain from the frames [`HISTORY_TICKS`] and twice [`HISTORY_TICKS`] steps earlier
/// (`crate::policy`), so the history BEV, its own history and the ego motion have the age and
/// the distribution they have in training.
pub const HISTORY_S: f64 = 0.5;
/// [`HISTORY_S`] in ticks ([`ssrdrive_proto::TICK_HZ`], the leaderboard's 20 Hz): 10.
pub const HISTORY_TICKS: usize = (HISTORY_S * ssrdrive_proto::TICK_HZ as f64) as usize;

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

/// The sizes of a [`TemporalSelfAttention`].
#[derive(Debug, Clone)]
pub struct TemporalSelfAttentionConfig {
    /// Channels C of the BEV queries.
    pub channels: usize,
    /// Attention heads (C must be a multiple).
    pub heads: usize,
    /// Sampling points per head and slot.
    pub points: usize,
    /// Rows of the BEV grid.
    pub rows: usize,
    /// Columns of the BEV grid.
    pub cols: usize,
}

impl TemporalSelfAttentionConfig {
    /// A randomly initialised layer: offsets on BEVFormer's rays, uniform weights.
    pub fn init(&self, device: &Device) -> TemporalSelfAttention {
        let (c, heads, points) = (self.channels, self.heads, self.points);
        TemporalSelfAttention {
            offsets: deformable_offsets(2 * c, SLOTS, heads, points, device),
            weights: constant_linear(
                2 * c,
                SLOTS * heads * points,
                vec![0.0; SLOTS * heads * points],
                device,
            ),
            value_proj: xavier_linear(c, c, device),
            output_proj: xavier_linear(c, c, device),
            heads,
            points,
            rows: self.rows,
            cols: self.cols,
        }
    }
}

/// What every temporal layer of one tick attends with, computed once per tick.
#[derive(Debug, Clone)]
pub struct TemporalContext {
    /// `[1, Q, C]` the BEV positional embedding.
    pub pos: Tensor<3>,
    /// `[B, Q, C]` the previous BEV in the current ego frame ([`align_previous_bev`]).
    pub aligned_previous: Tensor<3>,
    /// `[B, 1, 1]` 1 where the sample has a previous BEV, 0 on an episode's first frame.
    pub has_previous: Tensor<3>,
    /// `[1, Q, 2]` the normalised cell centres of the grid.
    pub reference: Tensor<3>,
}

/// BEVFormer's temporal self-attention over the two slots (see the module doc).
#[derive(Module, Debug)]
pub struct TemporalSelfAttention {
    offsets: FusedLinear,
    weights: FusedLinear,
    value_proj: FusedLinear,
    output_proj: FusedLinear,
    heads: usize,
    points: usize,
    rows: usize,
    cols: usize,
}

impl TemporalSelfAttention {
    /// The updated query, residual included.
    ///
    /// # Shapes
    ///
    /// - `query`: `[B, Q, C]`, Q = rows * cols
    /// - output: `[B, Q, C]`
    pub fn forward(&self, query: Tensor<3>, context: &TemporalContext) -> Tensor<3> {
        let [b, q, c] = query.dims();
        let (heads, points, rows, cols) = (self.heads, self.points, self.rows, self.cols);
        let head_dim = c / heads;
        let device = query.device();
        // First-frame path: a sample without a previous BEV attends to its own queries twice.
        let has_previous = context.has_previous.clone();
        let previous = context.aligned_previous.clone() * has_previous.clone()
            + query.clone() * has_previous.neg().add_scalar(1.0);
        let reference = context.reference.clone();
        let context = Tensor::cat(
            vec![previous.clone(), query.clone() + context.pos.clone()],
            2,
        );

        let scale = Tensor::<1>::from_floats([1.0 / cols as f32, 1.0 / rows as f32], &device)
            .reshape([1, 1, 1, 1, 1, 2]);
        let offsets = self
            .offsets
            .forward(context.clone())
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
            self.weights
                .forward(context)
                .reshape([b, q, SLOTS, heads, points]),
            4,
        )
        .permute([0, 2, 3, 1, 4])
        .reshape([b * SLOTS * heads, q, points]);

        let values = self
            .value_proj
            .forward(Tensor::stack::<4>(vec![previous, query.clone()], 1))
            .reshape([b * SLOTS, q, heads, head_dim])
            .swap_dims(1, 2)
            .reshape([b * SLOTS * heads, q, head_dim]);
        let sampled = deformable_aggregate(values, rows, cols, locations, weights)
            .reshape([b, SLOTS, heads, q, head_dim])
            .mean_dim(1)
            .reshape([b, heads, q, head_dim])
            .swap_dims(1, 2)
            .reshape([b, q, c]);
        query + self.output_proj.forward(sampled)
    }
}
