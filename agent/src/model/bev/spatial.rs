//! Spatial cross-attention: every BEV query lifts pillar points at several heights, projects
//! them into every camera through the episode's calibration (done on the CPU in
//! [`crate::model::grid::SampleGeometry`]) and samples the image features around each projection with
//! learned offsets and weights (deformable attention, BEVFormer's MSDeformableAttention3D). The
//! result is averaged over the cameras that see the cell.

use burn::module::Module;
use burn::tensor::{Device, Tensor};

use crate::model::cpu_kernels;
use crate::model::fused::FusedLinear;
use crate::model::init::{constant_linear, deformable_offsets, xavier_linear};
use crate::model::sampling::deformable_aggregate;

/// The sizes of a [`SpatialCrossAttention`].
#[derive(Debug, Clone)]
pub struct SpatialCrossAttentionConfig {
    /// Channels C of the BEV queries and the image features.
    pub channels: usize,
    /// Attention heads (C must be a multiple).
    pub heads: usize,
    /// Pillar heights lifted per BEV cell.
    pub anchors: usize,
    /// Sampling points per head, shared out among the anchors (a multiple of `anchors`).
    pub points: usize,
}

impl SpatialCrossAttentionConfig {
    /// A randomly initialised layer: offsets on BEVFormer's rays, uniform weights.
    pub fn init(&self, device: &Device) -> SpatialCrossAttention {
        let (c, heads, points) = (self.channels, self.heads, self.points);
        SpatialCrossAttention {
            offsets: deformable_offsets(c, 1, heads, points, device),
            weights: constant_linear(c, heads * points, vec![0.0; heads * points], device),
            value_proj: xavier_linear(c, c, device),
            output_proj: xavier_linear(c, c, device),
            heads,
            anchors: self.anchors,
            points_per_anchor: points / self.anchors,
        }
    }
}

/// Image features of a batch, ready for sampling.
pub struct ImageFeatures {
    /// `[B * cameras, h * w, C]`, camera embedding added.
    pub values: Tensor<3>,
    /// Height h of the feature map.
    pub height: usize,
    /// Width w of the feature map.
    pub width: usize,
    /// Cameras per sample.
    pub cameras: usize,
}

/// What every spatial layer of one tick samples from, computed once per tick.
pub struct SpatialContext<'a> {
    /// `[1, Q, C]` the BEV positional embedding (added to the queries for the offsets).
    pub pos: Tensor<3>,
    /// The image features.
    pub features: &'a ImageFeatures,
    /// `[B * cameras, Q, anchors, 2]` where each cell's pillar points fall in each camera,
    /// normalised image coordinates.
    pub camera_points: Tensor<4>,
    /// `[B, cameras, Q]` 1 where a camera sees the cell, else 0.
    pub camera_hits: Tensor<3>,
}

/// Deformable cross-attention from the BEV queries into the cameras (see the module doc).
#[derive(Module, Debug)]
pub struct SpatialCrossAttention {
    offsets: FusedLinear,
    weights: FusedLinear,
    value_proj: FusedLinear,
    output_proj: FusedLinear,
    heads: usize,
    anchors: usize,
    points_per_anchor: usize,
}

impl SpatialCrossAttention {
    /// The updated query, residual included.
    ///
    /// # Shapes
    ///
    /// - `query`: `[B, Q, C]`
    /// - output: `[B, Q, C]`
    pub fn forward(&self, query: Tensor<3>, context: &SpatialContext) -> Tensor<3> {
        let [b, q, c] = query.dims();
        let (heads, anchors, per_anchor) = (self.heads, self.anchors, self.points_per_anchor);
        let points = anchors * per_anchor;
        let features = context.features;
        let cams = features.cameras;
        let head_dim = c / heads;
        let device = query.device();
        let with_pos = query.clone() + context.pos.clone();

        // Offsets in feature cells, normalised by the feature map size.
        let scale = Tensor::<1>::from_floats(
            [1.0 / features.width as f32, 1.0 / features.height as f32],
            &device,
        )
        .reshape([1, 1, 1, 1, 1, 1, 2]);
        let offsets = self
            .offsets
            .forward(with_pos.clone())
            .reshape([b, q, heads, anchors, per_anchor, 2])
            .permute([0, 2, 1, 3, 4, 5])
            .unsqueeze_dim::<7>(1)
            * scale;
        let reference = context
            .camera_points
            .clone()
            .reshape([b, cams, 1, q, anchors, 1, 2]);
        let locations = (reference + offsets).reshape([b * cams * heads, q, points, 2]);

        let weights = cpu_kernels::softmax(
            self.weights
                .forward(with_pos)
                .reshape([b, q, heads, points]),
            3,
        )
        .permute([0, 2, 1, 3])
        .unsqueeze_dim::<5>(1)
        .expand([b, cams, heads, q, points])
        .reshape([b * cams * heads, q, points]);

        let hw = features.height * features.width;
        let values = self
            .value_proj
            .forward(features.values.clone())
            .reshape([b * cams, hw, heads, head_dim])
            .swap_dims(1, 2)
            .reshape([b * cams * heads, hw, head_dim]);
        let sampled =
            deformable_aggregate(values, features.height, features.width, locations, weights)
                .reshape([b, cams, heads, q, head_dim])
                .permute([0, 1, 3, 2, 4])
                .reshape([b, cams, q, c]);
        let hits = context.camera_hits.clone().unsqueeze_dim::<4>(3);
        let count = hits.clone().sum_dim(1).clamp_min(1.0).reshape([b, q, 1]);
        let mean = (sampled * hits).sum_dim(1).reshape([b, q, c]) / count;
        query + self.output_proj.forward(mean)
    }
}
