//! 2-D convolution as im2col plus one matrix product per image, written straight into the
//! NCHW output.
//!
//! Flex convolves tiles of 512 output pixels: per tile it builds a pixel-major patch matrix,
//! multiplies it into a fresh buffer and scatters that buffer into the output one element at a
//! time, after a single-threaded NCHW-to-NHWC copy of the input. For the backbone's narrow
//! layers that bookkeeping costs more than the arithmetic (a third of a batch-8 forward pass).
//! Here the patch matrix of an image is channel-major (`[cin * kh * kw, pixels]`, each row a
//! shifted copy of one input row segment), and `gemm` writes `weight x patches` directly into
//! the image's output planes. A 1x1 stride-1 convolution multiplies the input itself.

use std::borrow::Cow;

use gemm::Parallelism;
use rayon::prelude::*;

use super::matrix::{Matrix, add_into, matmul};
use super::parallel_output::{filled_in_chunks, zeros};

/// A convolution's geometry: one group, no dilation, symmetric zero padding.
#[derive(Debug, Clone, Copy)]
pub struct Geometry {
    pub batch: usize,
    pub channels_in: usize,
    pub channels_out: usize,
    /// Input `[height, width]`.
    pub input: [usize; 2],
    pub kernel: [usize; 2],
    pub stride: [usize; 2],
    pub padding: [usize; 2],
}

impl Geometry {
    /// Output `[height, width]`.
    pub fn output(&self) -> [usize; 2] {
        std::array::from_fn(|axis| {
            (self.input[axis] + 2 * self.padding[axis] - self.kernel[axis]) / self.stride[axis] + 1
        })
    }

    fn patch_len(&self) -> usize {
        self.channels_in * self.kernel[0] * self.kernel[1]
    }

    fn is_pointwise(&self) -> bool {
        self.kernel == [1, 1] && self.stride == [1, 1] && self.padding == [0, 0]
    }

    /// Floats in one input image.
    fn image_len(&self) -> usize {
        self.channels_in * self.input[0] * self.input[1]
    }

    /// Output pixels per channel.
    fn pixels(&self) -> usize {
        let [out_h, out_w] = self.output();
        out_h * out_w
    }

    /// Panics unless the input and weight lengths match the geometry.
    fn check(&self, input: &[f32], weight: &[f32]) {
        assert_eq!(input.len(), self.batch * self.image_len(), "input length");
        assert_eq!(
            weight.len(),
            self.channels_out * self.patch_len(),
            "weight length"
        );
    }
}

/// `input` `[batch, cin, h, w]` convolved by `weight` `[cout, cin, kh, kw]`, to
/// `[batch, cout, oh, ow]`, all row-major.
///
/// Panics if a slice's length does not match `geometry`, or the kernel (padded input) is larger
/// than the input (the caller checks the tensor shapes).
pub fn conv2d(input: &[f32], weight: &[f32], geometry: Geometry) -> Vec<f32> {
    geometry.check(input, weight);
    let (batch, channels_out) = (geometry.batch, geometry.channels_out);
    let (pixels, image_len) = (geometry.pixels(), geometry.image_len());
    let weight = Matrix::new(weight, channels_out, geometry.patch_len());
    let convolve = |image: &[f32], out: &mut [f32], parallelism| {
        let patches = patches(image, geometry);
        let patches = Matrix::new(&patches, geometry.patch_len(), pixels);
        matmul(out, weight, patches, false, parallelism);
    };
    let output_len = channels_out * pixels;
    if batch == 1 {
        // One image: the matrix product itself runs on all threads.
        let mut output = zeros(output_len);
        convolve(
            input,
            &mut output,
            Parallelism::Rayon(rayon::current_num_threads()),
        );
        output
    } else {
        filled_in_chunks(batch * output_len, output_len, |k, out| {
            convolve(&input[k * image_len..][..image_len], out, Parallelism::None)
        })
    }
}

/// The image's patch matrix: the image itself for a pointwise convolution, else
/// [`patch_matrix`].
fn patches(image: &[f32], geometry: Geometry) -> Cow<'_, [f32]> {
    if geometry.is_pointwise() {
        Cow::Borrowed(image)
    } else {
        Cow::Owned(patch_matrix(image, geometry))
    }
}

/// Calls `f(patch_offset, input_offset, len)` for every run of `len` patch-matrix entries that
/// come from one input row: entry `patch_offset + i` of the patch matrix is input element
/// `input_offset + i * stride_x` of the image. Entries in no run are zero padding.
fn for_each_run(geometry: Geometry, mut f: impl FnMut(usize, usize, usize)) {
    let [height, width] = geometry.input;
    let [kh, kw] = geometry.kernel;
    let [sy, sx] = geometry.stride;
    let [py, px] = geometry.padding;
    let [out_h, out_w] = geometry.output();
    for row in 0..geometry.patch_len() {
        let (c, ky, kx) = (row / (kh * kw), row / kw % kh, row % kw);
        // Output columns whose input column ox * sx + kx - px lies inside the image.
        let first = px.saturating_sub(kx).div_ceil(sx);
        let end = (width + px - kx).div_ceil(sx).min(out_w);
        if first >= end {
            continue;
        }
        for oy in 0..out_h {
            let Some(iy) = (oy * sy + ky).checked_sub(py).filter(|&iy| iy < height) else {
                continue;
            };
            f(
                (row * out_h + oy) * out_w + first,
                (c * height + iy) * width + first * sx + kx - px,
                end - first,
            );
        }
    }
}

/// The image's patch matrix `[cin * kh * kw, out_h * out_w]`: row `(c, ky, kx)` holds input
/// channel `c` at `(oy * sy + ky - py, ox * sx + kx - px)` for every output pixel, zero in the
/// padding.
fn patch_matrix(image: &[f32], geometry: Geometry) -> Vec<f32> {
    let [out_h, out_w] = geometry.output();
    let sx = geometry.stride[1];
    let mut patches = vec![0f32; geometry.patch_len() * out_h * out_w];
    for_each_run(geometry, |patch, input, len| {
        let out = &mut patches[patch..patch + len];
        if sx == 1 {
            out.copy_from_slice(&image[input..input + len]);
        } else {
            for (out, &value) in out.iter_mut().zip(image[input..].iter().step_by(sx)) {
                *out = value;
            }
        }
    });
    patches
}

/// The transpose of [`patch_matrix`]: adds every patch-matrix entry into the input element it
/// was copied from.
fn add_patch_matrix(patches: &[f32], image: &mut [f32], geometry: Geometry) {
    let sx = geometry.stride[1];
    for_each_run(geometry, |patch, input, len| {
        for (target, &value) in image[input..]
            .iter_mut()
            .step_by(sx)
            .zip(&patches[patch..patch + len])
        {
            *target += value;
        }
    });
}

/// Gradients of [`conv2d`] with respect to its input and weight.
pub struct Gradients {
    /// `None` unless asked for.
    pub input: Option<Vec<f32>>,
    pub weight: Vec<f32>,
}

/// The gradients of [`conv2d`]'s output with respect to `input` and `weight`, given the
/// output's gradient `grad` (`[batch, cout, oh, ow]`). The input gradient is computed only when `input_grad` holds (an
/// image fed to the first layer needs none).
///
/// Per image, with `P` its patch matrix and `G` its output gradient (`[cout, pixels]`):
/// the weight gradient adds `G x P^T`, and the input gradient is `W^T x G` folded back onto the
/// image (the transpose of im2col). Images run in parallel, each thread summing its own weight
/// gradient; a single image runs the products on all threads instead.
pub fn conv2d_backward(
    input: &[f32],
    weight: &[f32],
    grad: &[f32],
    geometry: Geometry,
    input_grad: bool,
) -> Gradients {
    geometry.check(input, weight);
    let (batch, channels_out) = (geometry.batch, geometry.channels_out);
    let (pixels, image_len) = (geometry.pixels(), geometry.image_len());
    assert_eq!(grad.len(), batch * channels_out * pixels, "gradient length");
    let mut d_input = input_grad.then(|| zeros(input.len()));
    let mut d_images: Vec<Option<&mut [f32]>> = match &mut d_input {
        Some(d_input) => d_input.chunks_exact_mut(image_len).map(Some).collect(),
        None => (0..batch).map(|_| None).collect(),
    };
    let weight_matrix = Matrix::new(weight, channels_out, geometry.patch_len());
    let image_grads = |image: &[f32],
                       grad: &[f32],
                       d_image: &mut Option<&mut [f32]>,
                       d_weight: &mut [f32],
                       parallelism| {
        let patches = patches(image, geometry);
        let patches = Matrix::new(&patches, geometry.patch_len(), pixels);
        let grad = Matrix::new(grad, channels_out, pixels);
        matmul(d_weight, grad, patches.transposed(), true, parallelism);
        let Some(d_image) = d_image else {
            return;
        };
        if geometry.is_pointwise() {
            matmul(
                d_image,
                weight_matrix.transposed(),
                grad,
                false,
                parallelism,
            );
        } else {
            let mut d_patches = vec![0f32; patches.data.len()];
            matmul(
                &mut d_patches,
                weight_matrix.transposed(),
                grad,
                false,
                parallelism,
            );
            add_patch_matrix(&d_patches, d_image, geometry);
        }
    };
    // One task per thread, each summing its images' weight gradients in order: the result
    // does not depend on scheduling.
    let threads = rayon::current_num_threads();
    let per_task = batch.div_ceil(threads);
    let parallelism = if batch == 1 {
        Parallelism::Rayon(threads)
    } else {
        Parallelism::None
    };
    let partial_sums: Vec<Vec<f32>> = input
        .par_chunks(per_task * image_len)
        .zip(grad.par_chunks(per_task * channels_out * pixels))
        .zip(d_images.par_chunks_mut(per_task))
        .map(|((images, grads), d_images)| {
            let mut d_weight = vec![0f32; weight.len()];
            for ((image, grad), d_image) in images
                .chunks_exact(image_len)
                .zip(grads.chunks_exact(channels_out * pixels))
                .zip(d_images)
            {
                image_grads(image, grad, d_image, &mut d_weight, parallelism);
            }
            d_weight
        })
        .collect();
    let mut partial_sums = partial_sums.into_iter();
    let mut d_weight = partial_sums
        .next()
        .unwrap_or_else(|| vec![0f32; weight.len()]);
    for part in partial_sums {
        add_into(&mut d_weight, &part);
    }
    Gradients {
        input: d_input,
        weight: d_weight,
    }
}
