//! Differentiable bilinear sampling of feature maps at continuous locations, the primitive of
//! both deformable attentions and of the temporal BEV alignment.
//!
//! Semantics are those of `grid_sample` with bilinear interpolation, zero padding and
//! `align_corners = false`: a location is (x, y) normalised by the map size, so (0, 0) is the
//! top-left corner of the map, (1, 1) the bottom-right corner, and the centre of cell (i, j)
//! is ((i + 0.5) / W, (j + 0.5) / H). Outside the map the features are zero.
//!
//! Two implementations, one result, both differentiable:
//! - Tensor ops (any backend): all four corners of all points are fetched with one row gather
//!   (`select`), whose backward pass is a cheap scatter-add, rather than with `grid_sample_2d`,
//!   which has no autodiff kernel in Burn and falls back to a slow decomposition in training.
//! - On the CPU backend, a fused loop ([`cpu_kernels::deformable_aggregate`]) that never
//!   materialises the gathered corners, with a fused backward pass.
//!
//! Tests check both against `grid_sample_2d` and against each other.

use burn::tensor::ops::PadMode;
use burn::tensor::{Int, Tensor};

use super::cpu_kernels;

/// Deformable aggregation: samples `values` (`[N, H*W, C]`, rows in row-major (y, x) order) at
/// `locations` (`[N, Q, P, 2]`, normalised (x, y)) and sums the P samples of each query with
/// `weights` (`[N, Q, P]`). Returns `[N, Q, C]`.
pub fn deformable_aggregate(
    values: Tensor<3>,
    height: usize,
    width: usize,
    locations: Tensor<4>,
    weights: Tensor<3>,
) -> Tensor<3> {
    let [_, hw, _] = values.dims();
    assert_eq!(
        hw,
        height * width,
        "values hold {hw} rows for a {height}x{width} map"
    );
    if cpu_kernels::is_flex(&values.device()) {
        cpu_kernels::deformable_aggregate(values, height, width, locations, weights)
    } else {
        deformable_aggregate_by_tensor_ops(values, height, width, locations, weights)
    }
}

/// [`deformable_aggregate`] composed of Burn tensor ops, on any backend.
pub fn deformable_aggregate_by_tensor_ops(
    values: Tensor<3>,
    height: usize,
    width: usize,
    locations: Tensor<4>,
    weights: Tensor<3>,
) -> Tensor<3> {
    let [n, _, c] = values.dims();
    let [_, q, p, _] = locations.dims();
    let device = values.device();
    let l = q * p;
    // A zero border (1 before, 2 after) lets every corner of a clamped point be gathered
    // without masks: points are clamped to [-1, size], whose corners fall in [-1, size + 1].
    let (padded_h, padded_w) = (height + 3, width + 3);
    let rows = values
        .reshape([n, height, width, c])
        .pad([(1, 2), (1, 2), (0, 0)], PadMode::Constant(0.0))
        .reshape([n * padded_h * padded_w, c]);

    let locations = locations.reshape([n, l, 2]);
    let axis = |index: usize, size: usize| {
        let pixel = locations
            .clone()
            .narrow(2, index, 1)
            .mul_scalar(size as f32)
            .sub_scalar(0.5)
            .clamp(-1.0, size as f32);
        // floor(x) for x >= -1, through truncation of x + 2 (Flex's floor is slow).
        let low = pixel.clone().add_scalar(2.0).int().float().sub_scalar(2.0);
        // Weights of the two neighbours low and low + 1: 1 - |pixel - neighbour|.
        let neighbours =
            low.clone() + Tensor::<1>::from_floats([0.0, 1.0], &device).reshape([1, 1, 2]);
        (low, (pixel - neighbours).abs().neg().add_scalar(1.0))
    };
    let (x0, wx) = axis(0, width);
    let (y0, wy) = axis(1, height);
    // Corner order: (x0, y0), (x1, y0), (x0, y1), (x1, y1).
    let weight = (wy.unsqueeze_dim::<4>(3) * wx.unsqueeze_dim::<4>(2)).reshape([n, l, 4])
        * weights.reshape([n, l, 1]);

    let top_left = (y0.add_scalar(1.0).mul_scalar(padded_w as f32) + x0.add_scalar(1.0)).int();
    let corner_offsets =
        Tensor::<1, Int>::from_ints([0, 1, padded_w as i32, padded_w as i32 + 1], &device)
            .reshape([1, 1, 4]);
    let base = Tensor::<1, Int>::arange(0..n as i64, &device)
        .mul_scalar((padded_h * padded_w) as i64)
        .reshape([n, 1, 1]);
    let index = (top_left + base + corner_offsets).reshape([n * l * 4]);
    let corners = rows.select(0, index).reshape([n, q, p * 4, c]);
    (corners * weight.reshape([n, q, p * 4, 1]))
        .sum_dim(2)
        .reshape([n, q, c])
}

/// Samples `values` (`[N, H*W, C]`) at `locations` (`[N, L, 2]`, normalised (x, y)).
/// Returns `[N, L, C]`.
pub fn bilinear_sample(
    values: Tensor<3>,
    height: usize,
    width: usize,
    locations: Tensor<3>,
) -> Tensor<3> {
    let [n, l, _] = locations.dims();
    let ones = Tensor::ones([n, l, 1], &locations.device());
    deformable_aggregate(values, height, width, locations.reshape([n, l, 1, 2]), ones)
}
