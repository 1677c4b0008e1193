//! Scenes TokenLearner (STL): the BEV is gated channel-wise by the navigation information (the
//! RoadOption command and the target point, concatenated as the paper does; the command alone
//! in an ablation), concatenated with
//! the BEV positional embedding, and summarised by TokenLearner into a few scene tokens that
//! self-attention layers then relate. The token attention maps come back for visualisation.
//!
//! Unlike SSR's released code, the TokenLearner logits are transposed (not reinterpreted
//! row-major), so token s attends with weights computed from every cell; we load no SSR weights,
//! and the reinterpretation is a quirk, not part of the method.

use burn::module::Module;
use burn::nn::{GroupNorm, GroupNormConfig};
use burn::tensor::activation::{relu, sigmoid};
use burn::tensor::{Device, Tensor};
use ssrdrive_proto::command::COMMANDS;

use super::config::SsrConfig;
use super::cpu_kernels::{self, Activation};
use super::fused::FusedLinear;
use super::init::xavier_linear;
use super::norm::single_group_norm;
use super::transformer::{SelfAttentionLayer, run_layers};

/// Target points enter the gate divided by this many metres.
pub const TARGET_SCALE: f32 = 25.0;

/// Channel gate from the navigation information (an SE-style MLP ending in a sigmoid): the
/// command and the target point, or the command alone (an ablation).
#[derive(Module, Debug)]
pub struct NavigationGate {
    fc_in: FusedLinear,
    fc_out: FusedLinear,
    reads_target_point: bool,
}

impl NavigationGate {
    /// A randomly initialised gate over `channels` BEV channels, reading the target point
    /// beside the command when `reads_target_point`.
    pub fn new(channels: usize, reads_target_point: bool, device: &Device) -> Self {
        let inputs = COMMANDS + if reads_target_point { 2 } else { 0 };
        Self {
            fc_in: xavier_linear(inputs, channels, device),
            fc_out: xavier_linear(channels, channels, device),
            reads_target_point,
        }
    }

    /// The gate in (0, 1) for each channel.
    ///
    /// # Shapes
    /// - command: `[B, 6]` (one-hot)
    /// - target_point: `[B, 2]` (ego frame, m; unused by a command-only gate)
    /// - output: `[B, C]`
    pub fn forward(&self, command: Tensor<2>, target_point: Tensor<2>) -> Tensor<2> {
        let navigation = if self.reads_target_point {
            Tensor::cat(vec![command, target_point.div_scalar(TARGET_SCALE)], 1)
        } else {
            command
        };
        sigmoid(self.fc_out.forward(relu(self.fc_in.forward(navigation))))
    }
}

/// TokenLearner: spatial attention maps from a small MLP over group-normalised features.
#[derive(Module, Debug)]
pub struct TokenLearner {
    norm: GroupNorm,
    fc_in: FusedLinear,
    fc_out: FusedLinear,
}

impl TokenLearner {
    /// A randomly initialised learner of `tokens` tokens over `channels`-wide features, through an
    /// MLP with a `bottleneck`-wide hidden layer.
    pub fn new(channels: usize, bottleneck: usize, tokens: usize, device: &Device) -> Self {
        Self {
            norm: GroupNormConfig::new(1, channels)
                .with_epsilon(1e-6)
                .init(device),
            fc_in: xavier_linear(channels, bottleneck, device),
            fc_out: xavier_linear(bottleneck, tokens, device),
        }
    }

    /// `x` `[B, Q, D]` to tokens `[B, S, D]` and attention `[B, S, Q]` (each row sums to 1).
    pub fn forward(&self, x: Tensor<3>) -> (Tensor<3>, Tensor<3>) {
        let normalised = single_group_norm(&self.norm, x.clone());
        let hidden = cpu_kernels::activation(self.fc_in.forward(normalised), Activation::Gelu);
        let logits = self.fc_out.forward(hidden);
        let attention = cpu_kernels::softmax(logits.swap_dims(1, 2), 2);
        (attention.clone().matmul(x), attention)
    }
}

/// What STL hands to the head.
#[derive(Debug, Clone)]
pub struct SceneTokens {
    /// `[B, S, C]` after self-attention (`[B, Q, C]`: the BEV plus its positions, without STL).
    pub tokens: Tensor<3>,
    /// `[B, S, Q]` TokenLearner attention over BEV cells (none without STL).
    pub attention: Option<Tensor<3>>,
    /// `[B, C]` navigation gate (none without STL).
    pub gate: Option<Tensor<2>>,
}

/// The navigation gate, TokenLearner and token self-attention; absent in the "no STL"
/// ablation ([`super::config::TokenConfig::dense_bev`]).
#[derive(Module, Debug)]
struct LearnerParts {
    gate: NavigationGate,
    learner: TokenLearner,
    layers: Vec<SelfAttentionLayer>,
}

/// Scenes TokenLearner: navigation gate, TokenLearner and token self-attention over the BEV
/// (or, in the "no STL" ablation, the BEV cells passed through with their positions).
#[derive(Module, Debug)]
pub struct SceneTokenLearner {
    parts: Option<LearnerParts>,
}

impl SceneTokenLearner {
    /// A randomly initialised STL for `config.tokens` (no parameters in the "no STL" ablation).
    pub fn new(config: &SsrConfig, device: &Device) -> Self {
        let c = config.channels;
        let t = &config.tokens;
        let parts = (!t.dense_bev).then(|| LearnerParts {
            gate: NavigationGate::new(c, t.gate_target_point, device),
            learner: TokenLearner::new(2 * c, t.bottleneck, t.num_tokens, device),
            layers: (0..t.layers)
                .map(|_| SelfAttentionLayer::new(c, t.heads, t.ffn_dim, device))
                .collect(),
        });
        Self { parts }
    }

    /// `bev` `[B, Q, C]`, `pos` `[1, Q, C]`, `command` `[B, 6]`, `target_point` `[B, 2]`.
    pub fn forward(
        &self,
        bev: Tensor<3>,
        pos: Tensor<3>,
        command: Tensor<2>,
        target_point: Tensor<2>,
    ) -> SceneTokens {
        let [b, q, c] = bev.dims();
        let pos = pos.expand([b, q, c]);
        let Some(parts) = &self.parts else {
            return SceneTokens {
                tokens: bev + pos,
                attention: None,
                gate: None,
            };
        };
        let gate = parts.gate.forward(command, target_point);
        let gated = bev * gate.clone().unsqueeze_dim::<3>(1);
        let (tokens, attention) = parts.learner.forward(Tensor::cat(vec![gated, pos], 2));
        let s = tokens.dims()[1];
        let content = tokens.clone().narrow(2, 0, c);
        let token_pos = tokens.narrow(2, c, c);
        let tokens = run_layers(&parts.layers, content, Some(token_pos));
        debug_assert_eq!(tokens.dims(), [b, s, c]);
        SceneTokens {
            tokens,
            attention: Some(attention),
            gate: Some(gate),
        }
    }
}
