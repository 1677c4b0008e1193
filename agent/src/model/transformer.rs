//! Post-norm transformer layers (mmcv's BaseTransformerLayer order: self-attention -> LN ->
//! FFN -> LN) over a short sequence of tokens, with an optional positional embedding added to
//! queries and keys but not to values. Used over the scene tokens and in the FFP world model.

use burn::module::Module;
use burn::nn::Initializer;
use burn::nn::attention::{MhaInput, MultiHeadAttention, MultiHeadAttentionConfig};
use burn::tensor::activation::relu;
use burn::tensor::{Device, Tensor};

use super::fused::{FusedLayerNorm, FusedLinear};
use super::init::xavier_linear;

#[derive(Module, Debug)]
pub struct SelfAttentionLayer {
    attention: MultiHeadAttention,
    norm_attention: FusedLayerNorm,
    ffn_in: FusedLinear,
    ffn_out: FusedLinear,
    norm_ffn: FusedLayerNorm,
}

impl SelfAttentionLayer {
    pub fn new(channels: usize, heads: usize, ffn_dim: usize, device: &Device) -> Self {
        Self {
            attention: MultiHeadAttentionConfig::new(channels, heads)
                .with_dropout(0.0)
                .with_initializer(Initializer::XavierUniform { gain: 1.0 })
                .init(device),
            norm_attention: FusedLayerNorm::new(channels, device),
            ffn_in: xavier_linear(channels, ffn_dim, device),
            ffn_out: xavier_linear(ffn_dim, channels, device),
            norm_ffn: FusedLayerNorm::new(channels, device),
        }
    }

    /// `x` `[B, L, C]`, `pos` `[B, L, C]` or none.
    pub fn forward(&self, x: Tensor<3>, pos: Option<Tensor<3>>) -> Tensor<3> {
        let query_key = match pos {
            Some(pos) => x.clone() + pos,
            None => x.clone(),
        };
        let attended = self
            .attention
            .forward(MhaInput::new(query_key.clone(), query_key, x.clone()))
            .context;
        let x = self.norm_attention.forward(x + attended);
        let ffn = self.ffn_out.forward(relu(self.ffn_in.forward(x.clone())));
        self.norm_ffn.forward(x + ffn)
    }
}

/// A stack of [`SelfAttentionLayer`]s sharing one positional embedding.
pub fn run_layers(
    layers: &[SelfAttentionLayer],
    mut x: Tensor<3>,
    pos: Option<Tensor<3>>,
) -> Tensor<3> {
    for layer in layers {
        x = layer.forward(x, pos.clone());
    }
    x
}
