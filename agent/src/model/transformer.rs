//! Post-norm transformer layers (mmcv's BaseTransformerLayer order: self-attention -> LN ->
//! FFN -> LN) over a short sequence of tokens, with an optional positional embedding added to
//! queries and keys but not to values. Used over the scene tokens and in the FFP world model.

use burn::module::Module;
use burn::nn::attention::{MhaInput, MultiHeadAttention, MultiHeadAttentionConfig};
use burn::nn::{Initializer, LayerNorm, Linear};
use burn::tensor::activation::relu;
use burn::tensor::{Device, Tensor};

use super::cpu_kernels;
use super::init::xavier_linear;
use super::norm::{layer_norm, layer_norm_config};

#[derive(Module, Debug)]
pub struct SelfAttentionLayer {
    attention: MultiHeadAttention,
    norm_attention: LayerNorm,
    ffn_in: Linear,
    ffn_out: Linear,
    norm_ffn: LayerNorm,
}

impl SelfAttentionLayer {
    pub fn new(channels: usize, heads: usize, ffn_dim: usize, device: &Device) -> Self {
        Self {
            attention: MultiHeadAttentionConfig::new(channels, heads)
                .with_dropout(0.0)
                .with_initializer(Initializer::XavierUniform { gain: 1.0 })
                .init(device),
            norm_attention: layer_norm_config(channels).init(device),
            ffn_in: xavier_linear(channels, ffn_dim, device),
            ffn_out: xavier_linear(ffn_dim, channels, device),
            norm_ffn: layer_norm_config(channels).init(device),
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
        let x = layer_norm(&self.norm_attention, x + attended);
        let ffn = cpu_kernels::linear(
            &self.ffn_out,
            relu(cpu_kernels::linear(&self.ffn_in, x.clone())),
        );
        layer_norm(&self.norm_ffn, x + ffn)
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
