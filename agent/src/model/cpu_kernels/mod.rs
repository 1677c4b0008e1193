//! Fused CPU kernels, where Burn's CPU backend (Flex) is slowest.
//!
//! Each kernel computes what the tensor-op form it replaces computes, to float32 rounding (the
//! vectorised `exp` and `erf` of [`activation`] are within 2 ulp and 3e-7), as one pass over
//! the data in plain Rust, parallel through rayon on the same global pool as Flex. Deformable
//! aggregation, convolution, linear layers, layer and batch norm, softmax and the activations
//! also train: [`extension`] gives them hand-written backward passes, and they run on Flex
//! with or without autodiff ([`is_flex`]). Max pool runs in inference only
//! ([`is_flex_inference`]); its training form keeps Burn's op and the argmax indices the
//! backward pass needs. A GPU keeps its data on the device and Burn's tensor ops. The model's
//! layers reach the kernels through [`super::fused`], which picks them by device. Tests check
//! every kernel, forward and backward, against its tensor-op form.

mod activation;
mod batch_norm;
mod conv;
mod deformable;
mod extension;
mod layer_norm;
mod linear;
mod matrix;
mod max_pool;
mod parallel_output;
mod softmax;

use burn::backend::Dispatch;
use burn::tensor::{Device, Tensor, TensorData};

pub use activation::Activation;
use extension::KernelOps;

/// Whether the device is Flex in inference (no autodiff): where the inference-only kernels
/// (max pool, the deformable sampler's loop) serve.
pub fn is_flex_inference(device: &Device) -> bool {
    !device.is_autodiff() && *device == Device::flex()
}

/// Whether the device is Flex, with or without autodiff: where the differentiable kernels of
/// [`extension`] serve.
pub fn is_flex(device: &Device) -> bool {
    device.clone().without_autodiff() == Device::flex()
}

fn floats<const D: usize>(tensor: Tensor<D>) -> Vec<f32> {
    tensor
        .into_data()
        .try_into_vec::<f32>()
        .expect("the model's tensors are float32")
}

/// [`crate::model::sampling::deformable_aggregate`]: `values` `[N, H*W, C]`, `locations`
/// `[N, Q, P, 2]`, `weights` `[N, Q, P]`, to `[N, Q, C]`. Differentiable: with autodiff the
/// backward pass is the fused one of [`extension`].
pub fn deformable_aggregate(
    values: Tensor<3>,
    height: usize,
    width: usize,
    locations: Tensor<4>,
    weights: Tensor<3>,
) -> Tensor<3> {
    Tensor::from_dispatch(<Dispatch as KernelOps>::deformable_aggregate(
        values.into_dispatch(),
        locations.into_dispatch(),
        weights.into_dispatch(),
        height,
        width,
    ))
}

/// Layer norm over the last axis of `x`: normalised with `epsilon`, times `gamma`, plus `beta`,
/// as Burn's `LayerNorm` when the two have the last axis's length `[d]`. Shorter ones repeat
/// along the axis (its length must be a multiple of theirs). On Flex only (see
/// [`is_flex`]); differentiable: with autodiff the backward pass is the fused one
/// of [`extension`].
pub fn layer_norm<const D: usize>(
    x: Tensor<D>,
    gamma: Tensor<1>,
    beta: Tensor<1>,
    epsilon: f64,
) -> Tensor<D> {
    Tensor::from_dispatch(<Dispatch as KernelOps>::layer_norm(
        x.into_dispatch(),
        gamma.into_dispatch(),
        beta.into_dispatch(),
        epsilon,
    ))
}

/// `x` `[..., d_in]` times the transpose of `weight` `[d_out, d_in]` plus `bias` `[d_out]`, as
/// Burn's `Linear`. On Flex only (see [`is_flex`]); differentiable: with autodiff the backward
/// pass is the fused one of [`extension`].
pub fn linear<const D: usize>(x: Tensor<D>, weight: Tensor<2>, bias: Tensor<1>) -> Tensor<D> {
    Tensor::from_dispatch(<Dispatch as KernelOps>::linear(
        x.into_dispatch(),
        weight.into_dispatch(),
        bias.into_dispatch(),
    ))
}

/// `activation` applied to every element of `x`: the fused kernel where it applies (Flex, in
/// inference and training; differentiable), else Burn's op.
pub fn activation<const D: usize>(x: Tensor<D>, activation: Activation) -> Tensor<D> {
    if !is_flex(&x.device()) {
        return match activation {
            Activation::Gelu => burn::tensor::activation::gelu(x),
            Activation::Sigmoid => burn::tensor::activation::sigmoid(x),
            Activation::Relu => burn::tensor::activation::relu(x),
        };
    }
    Tensor::from_dispatch(<Dispatch as KernelOps>::activation(
        x.into_dispatch(),
        activation,
    ))
}

/// Softmax of `x` along `dim`: the fused kernel where it applies (Flex, in inference and
/// training; differentiable) and `dim` is the last axis, else Burn's op.
pub fn softmax<const D: usize>(x: Tensor<D>, dim: usize) -> Tensor<D> {
    if dim + 1 != D || !is_flex(&x.device()) {
        return burn::tensor::activation::softmax(x, dim);
    }
    Tensor::from_dispatch(<Dispatch as KernelOps>::softmax(x.into_dispatch()))
}

/// Batch norm of `x` `[N, C, ...]` by its own statistics per channel (`epsilon` added to the
/// variance), times `gamma` `[C]`, plus `beta` `[C]`: the output, the batch mean and the biased
/// variance (neither tracked). As Burn's `batch_norm_train`, on Flex only (see
/// [`is_flex`]); differentiable: with autodiff the backward pass is the fused one
/// of [`extension`].
pub fn batch_norm_train<const D: usize>(
    x: Tensor<D>,
    gamma: Tensor<1>,
    beta: Tensor<1>,
    epsilon: f64,
) -> (Tensor<D>, Tensor<1>, Tensor<1>) {
    let (output, mean, variance) = <Dispatch as KernelOps>::batch_norm_train(
        x.into_dispatch(),
        gamma.into_dispatch(),
        beta.into_dispatch(),
        epsilon,
    );
    (
        Tensor::from_dispatch(output),
        Tensor::from_dispatch(mean),
        Tensor::from_dispatch(variance),
    )
}

/// Max pooling of `[N, C, H, W]` with a square window, a stride and symmetric padding (padded
/// cells never win: they count as -inf), as Burn's `max_pool2d` in floor mode.
pub fn max_pool2d(x: Tensor<4>, kernel: usize, stride: usize, padding: usize) -> Tensor<4> {
    let [n, c, height, width] = x.dims();
    let device = x.device();
    let window = max_pool::Window {
        kernel,
        stride,
        padding,
    };
    let (out_h, out_w) = (window.output_len(height), window.output_len(width));
    let output = max_pool::max_pool2d(&floats(x), n * c, height, width, window);
    Tensor::from_data(TensorData::new(output, [n, c, out_h, out_w]), &device)
}

/// Convolution of `x` `[N, Cin, H, W]` by `weight` `[Cout, Cin, kh, kw]` plus `bias` `[Cout]`,
/// one group, no dilation, symmetric zero `padding` (`[rows, columns]`), as Burn's `conv2d`.
/// Differentiable: with autodiff the backward pass is the fused one of [`extension`].
pub fn conv2d(
    x: Tensor<4>,
    weight: Tensor<4>,
    bias: Option<Tensor<1>>,
    stride: [usize; 2],
    padding: [usize; 2],
) -> Tensor<4> {
    let output = Tensor::from_dispatch(<Dispatch as KernelOps>::conv2d(
        x.into_dispatch(),
        weight.into_dispatch(),
        stride,
        padding,
    ));
    match bias {
        Some(bias) => {
            let [channels] = bias.dims();
            output + bias.reshape([1, channels, 1, 1])
        }
        None => output,
    }
}
