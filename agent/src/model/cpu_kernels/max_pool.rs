//! Max pooling over NCHW planes.
//!
//! Flex pools through a general scalar loop that also records the index of every maximum
//! (5.7 ms for the stem's `[8, 16, 48, 160]` output). Here each output row first takes the
//! element-wise maximum of its window's input rows (contiguous, vectorised), then the
//! maximum of each window across that row.

use rayon::prelude::*;

/// A square pooling window.
#[derive(Debug, Clone, Copy)]
pub struct Window {
    pub kernel: usize,
    pub stride: usize,
    pub padding: usize,
}

impl Window {
    /// Output length along an axis of `len` inputs (floor mode).
    pub fn output_len(&self, len: usize) -> usize {
        (len + 2 * self.padding - self.kernel) / self.stride + 1
    }

    /// The input range the window of output `index` covers, clipped to `0..len`.
    fn inputs(&self, index: usize, len: usize) -> std::ops::Range<usize> {
        let start = (index * self.stride).saturating_sub(self.padding);
        let end = (index * self.stride + self.kernel - self.padding).min(len);
        start..end
    }
}

/// `planes` planes of `height x width`, row-major, to their pooled planes. NaN wins, as in
/// Burn's and PyTorch's pooling.
pub fn max_pool2d(
    input: &[f32],
    planes: usize,
    height: usize,
    width: usize,
    window: Window,
) -> Vec<f32> {
    assert_eq!(input.len(), planes * height * width, "input length");
    assert!(
        window.kernel > window.padding,
        "padding must be smaller than the window"
    );
    let (out_h, out_w) = (window.output_len(height), window.output_len(width));
    let mut output = vec![0f32; planes * out_h * out_w];
    output
        .par_chunks_mut(out_h * out_w)
        .zip(input.par_chunks(height * width))
        .for_each(|(out_plane, plane)| {
            let mut row_max = vec![f32::NEG_INFINITY; width];
            for (oy, out_row) in out_plane.chunks_mut(out_w).enumerate() {
                row_max.fill(f32::NEG_INFINITY);
                for y in window.inputs(oy, height) {
                    for (m, &v) in row_max.iter_mut().zip(&plane[y * width..][..width]) {
                        *m = nan_max(*m, v);
                    }
                }
                out_row.fill(f32::NEG_INFINITY);
                for tap in 0..window.kernel {
                    // Outputs whose window's tap `tap` falls inside the row.
                    let first = window.padding.saturating_sub(tap).div_ceil(window.stride);
                    let last = (width + window.padding - tap)
                        .div_ceil(window.stride)
                        .min(out_w);
                    for ox in first..last {
                        let m = &mut out_row[ox];
                        *m = nan_max(*m, row_max[ox * window.stride + tap - window.padding]);
                    }
                }
            }
        });
    output
}

/// The larger of two values, NaN if either is NaN. Branch-free (`|`, not `||`), so the row
/// loop vectorises.
fn nan_max(a: f32, b: f32) -> f32 {
    if (a > b) | a.is_nan() { a } else { b }
}
