//! Softmax over the last axis, forward and backward, one pass per row.
//!
//! Burn composes softmax from a maximum, a subtraction, an exponential, a sum and a division,
//! each a single-threaded pass over the tensor on Flex and each recorded for the backward pass.
//! Here rows run in parallel, with the vectorised `exp` of [`super::activation`].

use super::activation::exp;
use super::parallel_output::filled_in_chunks;

/// Values per parallel task (whole rows, at least one).
const VALUES_PER_TASK: usize = 16 * 1024;

/// Writes the softmax of `row` into `out`.
#[inline(always)]
fn softmax_row(out: &mut [f32], row: &[f32]) {
    let max = row.iter().fold(f32::NEG_INFINITY, |m, &v| m.max(v));
    let mut sum = 0.0;
    for (o, &v) in out.iter_mut().zip(row) {
        *o = exp(v - max);
        sum += *o;
    }
    let scale = 1.0 / sum;
    out.iter_mut().for_each(|o| *o *= scale);
}

/// A new vector of `x`'s length, written row by row (rows of length `d`) by
/// `f(out_row, x_row, grad_row)`, in parallel.
fn map_rows(
    x: &[f32],
    grad: &[f32],
    d: usize,
    f: impl Fn(&mut [f32], &[f32], &[f32]) + Sync,
) -> Vec<f32> {
    assert!(
        d > 0 && x.len().is_multiple_of(d),
        "input length {} in rows of {d}",
        x.len()
    );
    assert_eq!(grad.len(), x.len(), "gradient length");
    let task = d * (VALUES_PER_TASK / d).max(1);
    filled_in_chunks(x.len(), task, |k, out| {
        let range = k * task..k * task + out.len();
        for ((out, x), grad) in out
            .chunks_exact_mut(d)
            .zip(x[range.clone()].chunks_exact(d))
            .zip(grad[range].chunks_exact(d))
        {
            f(out, x, grad);
        }
    })
}

/// The softmax of every row of `d` values of `x`.
///
/// Panics unless `x` is whole rows.
pub fn forward(x: &[f32], d: usize) -> Vec<f32> {
    // The gradient slot is unused: zip it against `x` itself.
    map_rows(x, x, d, |out, row, _| softmax_row(out, row))
}

/// The gradient with respect to `x` of [`forward`], given the output's gradient `grad`: per
/// row, with `y` the softmax (recomputed), `dx = y * (grad - Σ grad * y)`.
///
/// Panics unless `x` is whole rows and `grad` matches it.
pub fn backward(x: &[f32], grad: &[f32], d: usize) -> Vec<f32> {
    map_rows(x, grad, d, |d_x, row, grad| {
        softmax_row(d_x, row);
        let dot: f32 = d_x.iter().zip(grad).map(|(y, g)| y * g).sum();
        for (d, g) in d_x.iter_mut().zip(grad) {
            *d *= g - dot;
        }
    })
}
