//! Fully connected layers, `x W + b` over the last axis, forward and backward: each a product
//! over the rows of the whole batch.
//!
//! Flex's backward pass copies the transposed input before multiplying it, zero-fills its
//! outputs first and sums the bias gradient on one thread, and most of the model's layers are
//! too small for its matrix products to use more than one. Here the transposes are strided views
//! read by `gemm`, large products run on all threads, and the weight and bias gradients are
//! summed per thread over a share of the rows.

use gemm::Parallelism;
use rayon::prelude::*;

use super::matrix::{Matrix, add_into, matmul};
use super::parallel_output::{filled_in_chunks, zeros};

/// Products of at least this many multiply-adds run on all threads.
const PARALLEL_WORK: usize = 1 << 20;

/// Output values per parallel task when the bias is copied into every row (whole rows).
const BIAS_VALUES_PER_TASK: usize = 16 * 1024;

/// A layer's sizes: `rows` inputs of `inputs` values to `outputs` values.
#[derive(Debug, Clone, Copy)]
struct Sizes {
    rows: usize,
    inputs: usize,
    outputs: usize,
}

impl Sizes {
    /// Reads the sizes from the slices, panicking unless they fit together.
    fn new(x: &[f32], weight: &[f32], outputs: usize) -> Self {
        assert!(
            outputs > 0 && weight.len().is_multiple_of(outputs),
            "weight length"
        );
        let inputs = weight.len() / outputs;
        assert!(inputs > 0 && x.len().is_multiple_of(inputs), "input length");
        Self {
            rows: x.len() / inputs,
            inputs,
            outputs,
        }
    }

    fn parallelism(&self, rows: usize) -> Parallelism {
        if rows * self.inputs * self.outputs >= PARALLEL_WORK {
            Parallelism::Rayon(rayon::current_num_threads())
        } else {
            Parallelism::None
        }
    }
}

/// `x` `[rows, inputs]` times `weight` `[inputs, outputs]` plus `bias` `[outputs]`, all
/// row-major.
///
/// Panics if the lengths do not fit those shapes.
pub fn forward(x: &[f32], weight: &[f32], bias: &[f32]) -> Vec<f32> {
    let sizes = Sizes::new(x, weight, bias.len());
    let outputs = sizes.outputs;
    let task = outputs * (BIAS_VALUES_PER_TASK / outputs).max(1);
    let mut output = filled_in_chunks(sizes.rows * outputs, task, |_, out| {
        out.chunks_exact_mut(outputs)
            .for_each(|row| row.copy_from_slice(bias))
    });
    matmul(
        &mut output,
        Matrix::new(x, sizes.rows, sizes.inputs),
        Matrix::new(weight, sizes.inputs, sizes.outputs),
        true,
        sizes.parallelism(sizes.rows),
    );
    output
}

/// Gradients of [`forward`] with respect to its three inputs.
pub struct Gradients {
    /// `None` unless asked for.
    pub input: Option<Vec<f32>>,
    pub weight: Vec<f32>,
    pub bias: Vec<f32>,
}

/// The gradients of [`forward`]'s output with respect to `x`, `weight` and `bias`, given the
/// output's gradient `grad` (`[rows, outputs]`): `dx = grad W^T` (only when `input_grad`),
/// `dW = x^T grad`, `db` the column sums of `grad`.
///
/// The weight and bias gradients are summed over one share of the rows per thread, then the
/// shares in order: the result does not depend on scheduling.
///
/// Panics if the lengths do not fit the shapes.
pub fn backward(
    x: &[f32],
    weight: &[f32],
    grad: &[f32],
    outputs: usize,
    input_grad: bool,
) -> Gradients {
    let sizes = Sizes::new(x, weight, outputs);
    let Sizes {
        rows,
        inputs,
        outputs,
    } = sizes;
    assert_eq!(grad.len(), rows * outputs, "gradient length");
    let grad_matrix = Matrix::new(grad, rows, outputs);
    let input = input_grad.then(|| {
        let mut d_x = zeros(x.len());
        matmul(
            &mut d_x,
            grad_matrix,
            Matrix::new(weight, inputs, outputs).transposed(),
            false,
            sizes.parallelism(rows),
        );
        d_x
    });
    let shares = match sizes.parallelism(rows) {
        Parallelism::None => 1,
        _ => rayon::current_num_threads(),
    };
    let rows_per_share = rows.div_ceil(shares).max(1);
    let partial_sums: Vec<(Vec<f32>, Vec<f32>)> = x
        .par_chunks(rows_per_share * inputs)
        .zip(grad.par_chunks(rows_per_share * outputs))
        .map(|(x, grad)| {
            let share_rows = x.len() / inputs;
            let mut d_weight = vec![0f32; weight.len()];
            matmul(
                &mut d_weight,
                Matrix::new(x, share_rows, inputs).transposed(),
                Matrix::new(grad, share_rows, outputs),
                false,
                Parallelism::None,
            );
            let mut d_bias = vec![0f32; outputs];
            for row in grad.chunks_exact(outputs) {
                add_into(&mut d_bias, row);
            }
            (d_weight, d_bias)
        })
        .collect();
    let mut shares = partial_sums.into_iter();
    let (mut d_weight, mut d_bias) = shares
        .next()
        .unwrap_or_else(|| (vec![0f32; weight.len()], vec![0f32; outputs]));
    for (weight_part, bias_part) in shares {
        add_into(&mut d_weight, &weight_part);
        add_into(&mut d_bias, &bias_part);
    }
    Gradients {
        input,
        weight: d_weight,
        bias: d_bias,
    }
}
