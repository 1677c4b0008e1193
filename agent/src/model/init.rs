//! Initialisers shared by several modules: Xavier linears, zeroed layers, and BEVFormer's
//! circular initial sampling offsets for deformable attention.

use burn::module::Param;
use burn::nn::{Initializer, LinearConfig};
use burn::tensor::{Device, Tensor};

use super::fused::FusedLinear;

/// A linear layer with Xavier-uniform weights and zero bias.
pub fn xavier_linear(d_in: usize, d_out: usize, device: &Device) -> FusedLinear {
    let mut linear = LinearConfig::new(d_in, d_out)
        .with_initializer(Initializer::XavierUniform { gain: 1.0 })
        .init(device);
    linear.bias = Some(Param::from_tensor(Tensor::zeros([d_out], device)));
    linear.into()
}

/// A linear layer with zero weights and the given bias.
pub fn constant_linear(d_in: usize, d_out: usize, bias: Vec<f32>, device: &Device) -> FusedLinear {
    assert_eq!(bias.len(), d_out);
    let mut linear = LinearConfig::new(d_in, d_out)
        .with_initializer(Initializer::Zeros)
        .init(device);
    linear.bias = Some(Param::from_tensor(super::float_tensor(
        bias,
        [d_out],
        device,
    )));
    linear.into()
}

/// Offset layer of a deformable attention: zero weights, and a bias that places head h's points
/// on a ray at angle 2 pi h / heads, point k at distance k + 1 (BEVFormer's initialisation).
/// Layout of the output: `[groups, heads, points, 2]`, groups outermost.
pub fn deformable_offsets(
    d_in: usize,
    groups: usize,
    heads: usize,
    points: usize,
    device: &Device,
) -> FusedLinear {
    let mut bias = Vec::with_capacity(groups * heads * points * 2);
    for _ in 0..groups {
        for head in 0..heads {
            let angle = std::f32::consts::TAU * head as f32 / heads as f32;
            let (s, c) = angle.sin_cos();
            let scale = c.abs().max(s.abs());
            for point in 0..points {
                let k = (point + 1) as f32;
                bias.extend([c / scale * k, s / scale * k]);
            }
        }
    }
    constant_linear(d_in, groups * heads * points * 2, bias, device)
}
