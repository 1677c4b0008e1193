//! Future Feature Predictor (training only): predicts the BEV of a future frame from the scene
//! tokens and the planned trajectory, so that the tokens must carry what the scene will become.
//!
//! - MLN (StreamPETR's motion-aware layer norm): gamma and beta from the predicted waypoints
//!   (not detached, so the BEV loss also shapes the planner) modulate the non-affine layer-norm
//!   of each token; it starts as the identity.
//! - A latent world model: self-attention layers without positional embedding.
//! - TokenFuser: the tokens, expanded linearly to a number of slots, are mixed back into every
//!   BEV cell with sigmoid weights computed from the current BEV.
//!
//! The loss side ([`crate::train::loss::bev_loss`]) compares the result with the detached BEV
//! of the future frame.

use burn::module::Module;
use burn::nn::{GroupNorm, GroupNormConfig};
use burn::tensor::activation::relu;
use burn::tensor::{Device, Tensor};

use super::config::SsrConfig;
use super::cpu_kernels::{self, Activation};
use super::fused::FusedLinear;
use super::init::{constant_linear, xavier_linear};
use super::norm::single_group_norm;
use super::transformer::{SelfAttentionLayer, run_layers};

/// Layer norm over the last dimension without learned scale or shift.
fn plain_layer_norm(x: Tensor<3>) -> Tensor<3> {
    let mean = x.clone().mean_dim(2);
    let centred = x - mean;
    let variance = centred.clone().powi_scalar(2).mean_dim(2);
    centred / variance.add_scalar(1e-5).sqrt()
}

/// Motion-aware layer norm conditioned on the flattened trajectory.
#[derive(Module, Debug)]
struct MotionLayerNorm {
    reduce: FusedLinear,
    gamma: FusedLinear,
    beta: FusedLinear,
}

impl MotionLayerNorm {
    fn new(condition: usize, channels: usize, device: &Device) -> Self {
        Self {
            reduce: xavier_linear(condition, channels, device),
            gamma: constant_linear(channels, channels, vec![1.0; channels], device),
            beta: constant_linear(channels, channels, vec![0.0; channels], device),
        }
    }

    /// `tokens` `[B, S, C]`, `condition` `[B, K]`.
    fn forward(&self, tokens: Tensor<3>, condition: Tensor<2>) -> Tensor<3> {
        let h = relu(self.reduce.forward(condition));
        let gamma = self.gamma.forward(h.clone()).unsqueeze_dim::<3>(1);
        let beta = self.beta.forward(h).unsqueeze_dim::<3>(1);
        plain_layer_norm(tokens) * gamma + beta
    }
}

/// TokenFuser: tokens back to a dense BEV.
#[derive(Module, Debug)]
struct TokenFuser {
    norm_tokens: GroupNorm,
    expand: FusedLinear,
    norm_slots: GroupNorm,
    norm_bev: GroupNorm,
    mix_in: FusedLinear,
    mix_out: FusedLinear,
}

impl TokenFuser {
    fn new(channels: usize, tokens: usize, slots: usize, device: &Device) -> Self {
        let group_norm = || {
            GroupNormConfig::new(1, channels)
                .with_epsilon(1e-6)
                .init(device)
        };
        Self {
            norm_tokens: group_norm(),
            expand: xavier_linear(tokens, slots, device),
            norm_slots: group_norm(),
            norm_bev: group_norm(),
            mix_in: xavier_linear(channels, slots, device),
            mix_out: xavier_linear(slots, slots, device),
        }
    }

    /// `tokens` `[B, S, C]`, `bev` `[B, Q, C]` to `[B, Q, C]`.
    fn forward(&self, tokens: Tensor<3>, bev: Tensor<3>) -> Tensor<3> {
        let tokens = single_group_norm(&self.norm_tokens, tokens);
        let slots = self
            .norm_slots
            .forward(self.expand.forward(tokens.swap_dims(1, 2)));
        let bev = single_group_norm(&self.norm_bev, bev);
        let hidden = cpu_kernels::activation(self.mix_in.forward(bev), Activation::Gelu);
        let mix = cpu_kernels::activation(self.mix_out.forward(hidden), Activation::Sigmoid);
        mix.matmul(slots.swap_dims(1, 2))
    }
}

/// The Future Feature Predictor: MLN on the planned waypoints, a latent world model of
/// self-attention layers, and TokenFuser back onto the BEV.
#[derive(Module, Debug)]
pub struct FutureFeaturePredictor {
    motion_norm: MotionLayerNorm,
    world_model: Vec<SelfAttentionLayer>,
    fuser: TokenFuser,
}

impl FutureFeaturePredictor {
    /// A randomly initialised predictor for `config` (the head's waypoints, `config.ffp` layers
    /// and fuser slots).
    pub fn new(config: &SsrConfig, device: &Device) -> Self {
        let c = config.channels;
        let t = &config.tokens;
        Self {
            motion_norm: MotionLayerNorm::new(2 * config.head.pred_len, c, device),
            world_model: (0..config.ffp.layers)
                .map(|_| SelfAttentionLayer::new(c, t.heads, t.ffn_dim, device))
                .collect(),
            fuser: TokenFuser::new(c, config.scene_tokens(), config.ffp.fuser_slots, device),
        }
    }

    /// `tokens` `[B, S, C]`, `waypoints` `[B, P, 2]`, `bev` `[B, Q, C]` (the current, un-gated
    /// BEV) to the predicted future BEV `[B, Q, C]`.
    pub fn forward(&self, tokens: Tensor<3>, waypoints: Tensor<3>, bev: Tensor<3>) -> Tensor<3> {
        let [b, p, _] = waypoints.dims();
        let dreamed = self
            .motion_norm
            .forward(tokens, waypoints.reshape([b, 2 * p]));
        let future_tokens = run_layers(&self.world_model, dreamed, None);
        self.fuser.forward(future_tokens, bev)
    }
}
