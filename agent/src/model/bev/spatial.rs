//! Spatial cross-attention: every BEV query lifts pillar points at several heights, projects
//! them into every camera through the episode's calibration (done on the CPU in
//! [`super::grid::SampleGeometry`]) and samples the image features around each projection with
//! learned offsets and weights (deformable attention, BEVFormer's MSDeformableAttention3D). The
//! result is averaged over the cameras that see the cell.

use burn::module::Module;
use burn::nn::Linear;
use burn::tensor::{Device, Tensor};

use crate::model::cpu_kernels;
use crate::model::init::{constant_linear, deformable_offsets, xavier_linear};
use crate::model::sampling::deformable_aggregate;

#[derive(Module, Debug)]
pub struct SpatialCrossAttention {
    offsets: Linear,
    weights: Linear,
    value_proj: Linear,
    output_proj: Linear,
    heads: usize,
    anchors: usize,
    points_per_anchor: usize,
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

impl SpatialCrossAttention {
    pub fn new(
        channels: usize,
        heads: usize,
        anchors: usize,
        points: usize,
        device: &Device,
    ) -> Self {
        let per_anchor = points / anchors;
        Self {
            offsets: deformable_offsets(channels, 1, heads, points, device),
            weights: constant_linear(channels, heads * points, vec![0.0; heads * points], device),
            value_proj: xavier_linear(channels, channels, device),
            output_proj: xavier_linear(channels, channels, device),
            heads,
            anchors,
            points_per_anchor: per_anchor,
        }
    }

    /// `query` `[B, Q, C]` (with `pos` `[1, Q, C]` added for the offsets), `camera_points`
    /// `[B * cameras, Q, anchors, 2]`, `camera_hits` `[B, cameras, Q]`. Returns the updated
    /// query (residual included).
    pub fn forward(
        &self,
        query: Tensor<3>,
        pos: Tensor<3>,
        features: &ImageFeatures,
        camera_points: Tensor<4>,
        camera_hits: Tensor<3>,
    ) -> Tensor<3> {
        let [b, q, c] = query.dims();
        let (heads, anchors, per_anchor) = (self.heads, self.anchors, self.points_per_anchor);
        let points = anchors * per_anchor;
        let cams = features.cameras;
        let head_dim = c / heads;
        let device = query.device();
        let with_pos = query.clone() + pos;

        // Offsets in feature cells, normalised by the feature map size.
        let scale = Tensor::<1>::from_floats(
            [1.0 / features.width as f32, 1.0 / features.height as f32],
            &device,
        )
        .reshape([1, 1, 1, 1, 1, 1, 2]);
        let offsets = cpu_kernels::linear(&self.offsets, with_pos.clone())
            .reshape([b, q, heads, anchors, per_anchor, 2])
            .permute([0, 2, 1, 3, 4, 5])
            .unsqueeze_dim::<7>(1)
            * scale;
        let reference = camera_points.reshape([b, cams, 1, q, anchors, 1, 2]);
        let locations = (reference + offsets).reshape([b * cams * heads, q, points, 2]);

        let weights = cpu_kernels::softmax(
            cpu_kernels::linear(&self.weights, with_pos).reshape([b, q, heads, points]),
            3,
        )
        .permute([0, 2, 1, 3])
        .unsqueeze_dim::<5>(1)
        .expand([b, cams, heads, q, points])
        .reshape([b * cams * heads, q, points]);

        let hw = features.height * features.width;
        let values = cpu_kernels::linear(&self.value_proj, features.values.clone())
            .reshape([b * cams, hw, heads, head_dim])
            .swap_dims(1, 2)
            .reshape([b * cams * heads, hw, head_dim]);
        let sampled =
            deformable_aggregate(values, features.height, features.width, locations, weights)
                .reshape([b, cams, heads, q, head_dim])
                .permute([0, 1, 3, 2, 4])
                .reshape([b, cams, q, c]);
        let hits = camera_hits.unsqueeze_dim::<4>(3);
        let count = hits.clone().sum_dim(1).clamp_min(1.0).reshape([b, q, 1]);
        let mean = (sampled * hits).sum_dim(1).reshape([b, q, c]) / count;
        query + cpu_kernels::linear(&self.output_proj, mean)
    }
}
