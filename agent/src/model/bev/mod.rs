//! BEV encoder: learned BEV queries with a learned positional embedding and the ego's motion
//! and speed injected as BEVFormer's can-bus, refined by layers of temporal self-attention,
//! spatial cross-attention into the camera features, and a feed-forward network (each followed
//! by layer norm, BEVFormer's post-norm order).

mod spatial;
mod temporal;

pub use super::grid::{BevGrid, CAN_BUS_DIM, GeometryTensors, SampleGeometry};
use burn::module::{Module, Param};
use burn::tensor::activation::relu;
use burn::tensor::{Device, Distribution, Tensor};
pub use spatial::ImageFeatures;
use spatial::{SpatialContext, SpatialCrossAttention, SpatialCrossAttentionConfig};
use ssrdrive_proto::camera::MAX_CAMERAS;
pub use temporal::{HISTORY_S, HISTORY_TICKS, align_previous_bev};
use temporal::{TemporalContext, TemporalSelfAttention, TemporalSelfAttentionConfig};

use crate::model::config::SsrConfig;
use crate::model::cpu_kernels::{self, Activation};
use crate::model::float_tensor;
use crate::model::fused::{FusedLayerNorm, FusedLinear};
use crate::model::init::xavier_linear;

/// TSA -> LN -> SCA -> LN -> FFN -> LN.
#[derive(Module, Debug)]
struct EncoderLayer {
    temporal: TemporalSelfAttention,
    norm_temporal: FusedLayerNorm,
    spatial: SpatialCrossAttention,
    norm_spatial: FusedLayerNorm,
    ffn_in: FusedLinear,
    ffn_out: FusedLinear,
    norm_ffn: FusedLayerNorm,
}

impl EncoderLayer {
    /// A randomly initialised layer for `config`.
    fn new(config: &SsrConfig, device: &Device) -> Self {
        let c = config.channels;
        let bev = &config.bev;
        Self {
            temporal: TemporalSelfAttentionConfig {
                channels: c,
                heads: bev.heads,
                points: bev.temporal_points,
                rows: bev.grid.rows,
                cols: bev.grid.cols,
            }
            .init(device),
            norm_temporal: FusedLayerNorm::new(c, device),
            spatial: SpatialCrossAttentionConfig {
                channels: c,
                heads: bev.heads,
                anchors: bev.pillar_heights.len(),
                points: bev.spatial_points,
            }
            .init(device),
            norm_spatial: FusedLayerNorm::new(c, device),
            ffn_in: xavier_linear(c, bev.ffn_dim, device),
            ffn_out: xavier_linear(bev.ffn_dim, c, device),
            norm_ffn: FusedLayerNorm::new(c, device),
        }
    }

    /// # Shapes
    ///
    /// - `query`: `[B, Q, C]`
    /// - output: `[B, Q, C]`
    fn forward(
        &self,
        query: Tensor<3>,
        temporal: &TemporalContext,
        spatial: &SpatialContext,
    ) -> Tensor<3> {
        let query = self
            .norm_temporal
            .forward(self.temporal.forward(query, temporal));
        let query = self
            .norm_spatial
            .forward(self.spatial.forward(query, spatial));
        let hidden = cpu_kernels::activation(self.ffn_in.forward(query.clone()), Activation::Relu);
        self.norm_ffn.forward(query + self.ffn_out.forward(hidden))
    }
}

/// The BEV encoder: learned queries, positional and camera embeddings, can-bus injection and
/// the encoder layers (TSA -> LN -> SCA -> LN -> FFN -> LN).
#[derive(Module, Debug)]
pub struct BevEncoder {
    queries: Param<Tensor<2>>,
    row_embed: Param<Tensor<2>>,
    col_embed: Param<Tensor<2>>,
    camera_embed: Param<Tensor<2>>,
    can_bus_in: FusedLinear,
    can_bus_out: FusedLinear,
    can_bus_norm: FusedLayerNorm,
    layers: Vec<EncoderLayer>,
    rows: usize,
    cols: usize,
}

fn uniform(shape: [usize; 2], device: &Device) -> Param<Tensor<2>> {
    Param::from_tensor(Tensor::random(
        shape,
        Distribution::Uniform(0.0, 1.0),
        device,
    ))
}

impl BevEncoder {
    /// A randomly initialised encoder for `config` (grid, channels, heads, sampling points,
    /// layers).
    pub fn new(config: &SsrConfig, device: &Device) -> Self {
        let c = config.channels;
        let bev = &config.bev;
        let layers = (0..bev.layers)
            .map(|_| EncoderLayer::new(config, device))
            .collect();
        Self {
            queries: Param::from_tensor(Tensor::random(
                [bev.grid.cells(), c],
                Distribution::Normal(0.0, 1.0),
                device,
            )),
            row_embed: uniform([bev.grid.rows, c / 2], device),
            col_embed: uniform([bev.grid.cols, c / 2], device),
            camera_embed: Param::from_tensor(Tensor::random(
                [MAX_CAMERAS, c],
                Distribution::Normal(0.0, 1.0),
                device,
            )),
            can_bus_in: xavier_linear(CAN_BUS_DIM, c / 2, device),
            can_bus_out: xavier_linear(c / 2, c, device),
            can_bus_norm: FusedLayerNorm::new(c, device),
            layers,
            rows: bev.grid.rows,
            cols: bev.grid.cols,
        }
    }

    /// The BEV positional embedding `[1, Q, C]`: [column embedding, row embedding] per cell.
    pub fn positions(&self) -> Tensor<3> {
        let (rows, cols) = (self.rows, self.cols);
        let half = self.col_embed.dims()[1];
        let col = self
            .col_embed
            .val()
            .unsqueeze_dim::<3>(0)
            .expand([rows, cols, half]);
        let row = self
            .row_embed
            .val()
            .unsqueeze_dim::<3>(1)
            .expand([rows, cols, half]);
        Tensor::cat(vec![col, row], 2).reshape([1, rows * cols, 2 * half])
    }

    /// Camera features `[B * cameras, C, h, w]` to sampling values with the camera embedding.
    pub fn image_features(&self, features: Tensor<4>, cameras: usize) -> ImageFeatures {
        let [bn, c, h, w] = features.dims();
        let embed = self
            .camera_embed
            .val()
            .narrow(0, 0, cameras)
            .reshape([1, cameras, 1, c]);
        let values = features
            .reshape([bn / cameras, cameras, c, h * w])
            .swap_dims(2, 3)
            + embed;
        ImageFeatures {
            values: values.reshape([bn, h * w, c]),
            height: h,
            width: w,
            cameras,
        }
    }

    /// Encodes one tick: the BEV from the camera features, the tick's geometry and the
    /// previous BEV (any values where `geometry.has_previous` is 0).
    ///
    /// # Shapes
    ///
    /// - `previous_bev`: `[B, Q, C]`
    /// - output: `[B, Q, C]`
    pub fn forward(
        &self,
        features: &ImageFeatures,
        geometry: &GeometryTensors,
        previous_bev: Tensor<3>,
    ) -> Tensor<3> {
        let device = previous_bev.device();
        let b = previous_bev.dims()[0];
        let pos = self.positions();
        let temporal = TemporalContext {
            pos: pos.clone(),
            aligned_previous: align_previous_bev(
                previous_bev,
                self.rows,
                self.cols,
                geometry.previous_points.clone(),
            ),
            has_previous: geometry.has_previous.clone(),
            reference: reference_points(self.rows, self.cols, &device),
        };
        let spatial = SpatialContext {
            pos,
            features,
            camera_points: geometry.camera_points.clone(),
            camera_hits: geometry.camera_hits.clone(),
        };
        let can_bus = self
            .can_bus_norm
            .forward(relu(self.can_bus_out.forward(relu(
                self.can_bus_in.forward(geometry.can_bus.clone()),
            ))));
        let mut query = self.queries.val().unsqueeze_dim::<3>(0).repeat_dim(0, b)
            + can_bus.unsqueeze_dim::<3>(1);
        for layer in &self.layers {
            query = layer.forward(query, &temporal, &spatial);
        }
        query
    }
}

/// Normalised centres of a `rows x cols` grid's cells, `[1, Q, 2]`.
fn reference_points(rows: usize, cols: usize, device: &Device) -> Tensor<3> {
    let values: Vec<f32> = (0..rows * cols)
        .flat_map(|i| {
            [
                ((i % cols) as f32 + 0.5) / cols as f32,
                ((i / cols) as f32 + 0.5) / rows as f32,
            ]
        })
        .collect();
    float_tensor(values, [1, rows * cols, 2], device)
}
