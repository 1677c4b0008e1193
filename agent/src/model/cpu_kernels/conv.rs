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

use gemm::Parallelism;
use rayon::prelude::*;

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
}

/// `input` `[batch, cin, h, w]`, `weight` `[cout, cin, kh, kw]`, optional `bias` `[cout]`, to
/// `[batch, cout, oh, ow]`, all row-major.
///
/// Panics if a slice's length does not match `geometry`, or the kernel (padded input) is larger
/// than the input (the caller checks the tensor shapes).
pub fn conv2d(input: &[f32], weight: &[f32], bias: Option<&[f32]>, geometry: Geometry) -> Vec<f32> {
    let Geometry {
        batch,
        channels_in,
        channels_out,
        input: [height, width],
        ..
    } = geometry;
    assert_eq!(
        input.len(),
        batch * channels_in * height * width,
        "input length"
    );
    assert_eq!(
        weight.len(),
        channels_out * geometry.patch_len(),
        "weight length"
    );
    let [out_h, out_w] = geometry.output();
    let pixels = out_h * out_w;
    let mut output = vec![0f32; batch * channels_out * pixels];
    let image_len = channels_in * height * width;
    let convolve = |(image, out): (&[f32], &mut [f32]), parallelism| {
        if geometry.is_pointwise() {
            multiply(weight, image, out, geometry, pixels, parallelism);
        } else {
            let patches = patch_matrix(image, geometry);
            multiply(weight, &patches, out, geometry, pixels, parallelism);
        }
        if let Some(bias) = bias {
            for (plane, &b) in out.chunks_exact_mut(pixels).zip(bias) {
                plane.iter_mut().for_each(|v| *v += b);
            }
        }
    };
    let images = input.chunks_exact(image_len);
    let outputs = output.chunks_exact_mut(channels_out * pixels);
    if batch == 1 {
        // One image: the matrix product itself runs on all threads.
        let threads = rayon::current_num_threads();
        images
            .zip(outputs)
            .for_each(|pair| convolve(pair, Parallelism::Rayon(threads)));
    } else {
        input
            .par_chunks_exact(image_len)
            .zip(output.par_chunks_exact_mut(channels_out * pixels))
            .for_each(|pair| convolve(pair, Parallelism::None));
    }
    output
}

/// `out` `[cout, pixels]` = `weight` `[cout, patch_len]` x `patches` `[patch_len, pixels]`.
fn multiply(
    weight: &[f32],
    patches: &[f32],
    out: &mut [f32],
    geometry: Geometry,
    pixels: usize,
    parallelism: Parallelism,
) {
    let k = geometry.patch_len();
    debug_assert_eq!(patches.len(), k * pixels);
    debug_assert_eq!(out.len(), geometry.channels_out * pixels);
    // SAFETY: the three matrices lie inside their slices: `out` holds cout x pixels with row
    // stride `pixels`, `weight` cout x k with row stride k, `patches` k x pixels with row stride
    // `pixels` (lengths checked above); `out` does not alias the inputs.
    unsafe {
        gemm::gemm(
            geometry.channels_out,
            pixels,
            k,
            out.as_mut_ptr(),
            1,
            pixels as isize,
            false,
            weight.as_ptr(),
            1,
            k as isize,
            patches.as_ptr(),
            1,
            pixels as isize,
            0.0,
            1.0,
            false,
            false,
            false,
            parallelism,
        );
    }
}

/// The image's patch matrix `[cin * kh * kw, out_h * out_w]`: row `(c, ky, kx)` holds input
/// channel `c` at `(oy * sy + ky - py, ox * sx + kx - px)` for every output pixel, zero in the
/// padding.
fn patch_matrix(image: &[f32], geometry: Geometry) -> Vec<f32> {
    let [height, width] = geometry.input;
    let [kh, kw] = geometry.kernel;
    let [sy, sx] = geometry.stride;
    let [py, px] = geometry.padding;
    let [out_h, out_w] = geometry.output();
    let mut patches = vec![0f32; geometry.patch_len() * out_h * out_w];
    for (row, patch_row) in patches.chunks_exact_mut(out_h * out_w).enumerate() {
        let (c, ky, kx) = (row / (kh * kw), row / kw % kh, row % kw);
        let plane = &image[c * height * width..][..height * width];
        // Output columns whose input column ox * sx + kx - px lies inside the image.
        let first = px.saturating_sub(kx).div_ceil(sx);
        let end = (width + px - kx).div_ceil(sx).min(out_w);
        if first >= end {
            continue;
        }
        for (oy, out_row) in patch_row.chunks_exact_mut(out_w).enumerate() {
            let Some(iy) = (oy * sy + ky).checked_sub(py).filter(|&iy| iy < height) else {
                continue;
            };
            let input_row = &plane[iy * width..][..width];
            let start = first * sx + kx - px;
            if sx == 1 {
                out_row[first..end].copy_from_slice(&input_row[start..start + end - first]);
            } else {
                for (out, &value) in out_row[first..end]
                    .iter_mut()
                    .zip(input_row[start..].iter().step_by(sx))
                {
                    *out = value;
                }
            }
        }
    }
    patches
}
