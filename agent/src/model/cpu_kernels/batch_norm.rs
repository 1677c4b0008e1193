//! Batch normalisation in training (statistics of the batch itself), forward and backward.
//!
//! Flex computes the statistics through a transposed copy of the whole activation and then
//! normalises, scales and shifts in separate single-threaded passes; its backward pass takes as
//! many again. Here each direction is two parallel passes: per channel, the sums (reading the
//! channel's planes of every sample); per plane, the output.

use rayon::prelude::*;

use super::parallel_output::filled_in_chunks;

/// An activation `[batch, channels, plane]` (the plane: every axis after the channels).
#[derive(Debug, Clone, Copy)]
pub struct Shape {
    pub batch: usize,
    pub channels: usize,
    pub plane: usize,
}

impl Shape {
    fn len(&self) -> usize {
        self.batch * self.channels * self.plane
    }

    /// Values per channel.
    fn count(&self) -> f64 {
        (self.batch * self.plane) as f64
    }

    /// The planes of `channel`, one per sample.
    fn planes<'a>(&self, data: &'a [f32], channel: usize) -> impl Iterator<Item = &'a [f32]> {
        (0..self.batch)
            .map(move |n| &data[(n * self.channels + channel) * self.plane..][..self.plane])
    }

    /// Panics unless `data` holds exactly this shape and `per_channel` one value per channel.
    fn check(&self, data: &[f32], per_channel: &[&[f32]]) {
        assert_eq!(data.len(), self.len(), "input length");
        for values in per_channel {
            assert_eq!(values.len(), self.channels, "per-channel length");
        }
    }
}

/// Per-channel mean and biased variance of `x`: two passes per channel (the mean, then the
/// squared deviations), each plane summed in float32 and the planes in float64.
fn statistics(x: &[f32], shape: Shape) -> (Vec<f32>, Vec<f32>) {
    (0..shape.channels)
        .into_par_iter()
        .map(|channel| {
            let sum: f64 = shape
                .planes(x, channel)
                .map(|plane| plane.iter().sum::<f32>() as f64)
                .sum();
            let mean = (sum / shape.count()) as f32;
            let squares: f64 = shape
                .planes(x, channel)
                .map(|plane| plane.iter().map(|v| (v - mean) * (v - mean)).sum::<f32>() as f64)
                .sum();
            (mean, (squares / shape.count()) as f32)
        })
        .unzip()
}

/// A new vector of `x`'s length, written plane by plane by `f(channel, plane_out, plane_x,
/// plane_grad)`, planes in parallel.
fn map_planes(
    x: &[f32],
    grad: &[f32],
    shape: Shape,
    f: impl Fn(usize, &mut [f32], &[f32], &[f32]) + Sync,
) -> Vec<f32> {
    let plane = shape.plane;
    filled_in_chunks(x.len(), plane, |index, out| {
        let range = index * plane..(index + 1) * plane;
        f(index % shape.channels, out, &x[range.clone()], &grad[range])
    })
}

/// The output of [`forward`].
pub struct Forward {
    pub output: Vec<f32>,
    /// Per channel.
    pub mean: Vec<f32>,
    /// Per channel, biased (divided by the count), without epsilon.
    pub variance: Vec<f32>,
}

/// `x` normalised per channel by its batch statistics (`epsilon` added to the variance), times
/// `gamma`, plus `beta` (one value per channel each).
///
/// Panics if a slice's length does not match `shape`.
pub fn forward(x: &[f32], shape: Shape, gamma: &[f32], beta: &[f32], epsilon: f32) -> Forward {
    shape.check(x, &[gamma, beta]);
    let (mean, variance) = statistics(x, shape);
    let (scale, shift): (Vec<f32>, Vec<f32>) = (0..shape.channels)
        .map(|c| {
            let scale = gamma[c] / (variance[c] + epsilon).sqrt();
            (scale, beta[c] - mean[c] * scale)
        })
        .unzip();
    // The gradient slot is unused: zip it against `x` itself.
    let output = map_planes(x, x, shape, |c, out, x, _| {
        for (o, v) in out.iter_mut().zip(x) {
            *o = v * scale[c] + shift[c];
        }
    });
    Forward {
        output,
        mean,
        variance,
    }
}

/// Gradients of [`forward`] with respect to its three inputs.
pub struct Gradients {
    pub input: Vec<f32>,
    pub gamma: Vec<f32>,
    pub beta: Vec<f32>,
}

/// The gradients of [`forward`]'s output with respect to `x`, `gamma` and `beta`, given the
/// output's gradient `grad`. Per channel, with `x̂` the normalised input, `rstd` the
/// reciprocal standard deviation and `M` the count: `dbeta = Σ grad`, `dgamma = Σ grad * x̂`,
/// `dx = gamma * rstd * (grad - dbeta / M - x̂ * dgamma / M)`. The statistics are recomputed
/// from `x`.
///
/// Panics if a slice's length does not match `shape`.
pub fn backward(x: &[f32], shape: Shape, gamma: &[f32], grad: &[f32], epsilon: f32) -> Gradients {
    shape.check(x, &[gamma]);
    shape.check(grad, &[]);
    let (mean, variance) = statistics(x, shape);
    let rstd: Vec<f32> = variance
        .iter()
        .map(|v| 1.0 / (v + epsilon).sqrt())
        .collect();
    let (d_gamma, d_beta): (Vec<f32>, Vec<f32>) = (0..shape.channels)
        .into_par_iter()
        .map(|c| {
            let (mut sum, mut sum_normalised) = (0f64, 0f64);
            for (x, grad) in shape.planes(x, c).zip(shape.planes(grad, c)) {
                sum += grad.iter().sum::<f32>() as f64;
                sum_normalised += x
                    .iter()
                    .zip(grad)
                    .map(|(v, g)| g * (v - mean[c]) * rstd[c])
                    .sum::<f32>() as f64;
            }
            (sum_normalised as f32, sum as f32)
        })
        .unzip();
    let count = shape.count() as f32;
    let d_input = map_planes(x, grad, shape, |c, d_x, x, grad| {
        let (mean_grad, mean_grad_normalised) = (d_beta[c] / count, d_gamma[c] / count);
        let scale = gamma[c] * rstd[c];
        for ((d, v), g) in d_x.iter_mut().zip(x).zip(grad) {
            let normalised = (v - mean[c]) * rstd[c];
            *d = scale * (g - mean_grad - normalised * mean_grad_normalised);
        }
    });
    Gradients {
        input: d_input,
        gamma: d_gamma,
        beta: d_beta,
    }
}
