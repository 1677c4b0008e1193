//! Deformable aggregation as one pass over the data, for CPU inference.
//!
//! The tensor-op form in [`crate::model::sampling`] gathers all four corners of every point into a
//! `[N, Q, 4P, C]` tensor before weighting and summing them: at batch 8 that is 33 MB written
//! and read again per attention layer, half of the BEV encoder's time on the Flex backend. Here
//! each query accumulates its `4P` weighted corner rows straight into its output row, so memory
//! traffic is the inputs and the output only. This plays the role of BEVFormer's CUDA
//! `MultiScaleDeformableAttnFunction`: same result, no intermediate.

use rayon::prelude::*;

/// Shapes of one aggregation: `values` `[n, height * width, channels]`, `locations`
/// `[n, queries, points, 2]` (normalised (x, y)), `weights` `[n, queries, points]`.
#[derive(Debug, Clone, Copy)]
pub struct Shape {
    pub n: usize,
    pub height: usize,
    pub width: usize,
    pub channels: usize,
    pub queries: usize,
    pub points: usize,
}

impl Shape {
    /// Floats in one map of `values`.
    fn map_len(&self) -> usize {
        self.height * self.width * self.channels
    }

    /// Points over all queries of all maps.
    fn total_points(&self) -> usize {
        self.n * self.queries * self.points
    }
}

/// Queries per parallel task: enough corner rows (4 per point) to dwarf the scheduling.
const QUERIES_PER_TASK: usize = 64;

/// `[n, queries, channels]`: per query, the sum over its points of the weight times the
/// bilinear sample (zero outside the map). A point with a non-finite location samples zero.
///
/// Panics if a slice's length does not match `shape` (the caller checks the tensor shapes).
pub fn aggregate(values: &[f32], locations: &[f32], weights: &[f32], shape: Shape) -> Vec<f32> {
    assert_eq!(values.len(), shape.n * shape.map_len(), "values length");
    assert_eq!(
        locations.len(),
        2 * shape.total_points(),
        "locations length"
    );
    assert_eq!(weights.len(), shape.total_points(), "weights length");
    let channels = shape.channels;
    let inputs = Inputs {
        values,
        locations,
        weights,
        shape,
    };
    let mut output = vec![0f32; shape.n * shape.queries * channels];
    output
        .par_chunks_mut(channels * QUERIES_PER_TASK)
        .enumerate()
        .for_each(|(task, out)| accumulate(out, task * QUERIES_PER_TASK, &inputs));
    output
}

struct Inputs<'a> {
    values: &'a [f32],
    locations: &'a [f32],
    weights: &'a [f32],
    shape: Shape,
}

/// Fills the output rows of the queries from `first_query` on, with AVX2 where the CPU has it
/// (the build targets baseline x86-64, SSE2 only).
fn accumulate(out: &mut [f32], first_query: usize, inputs: &Inputs) {
    #[cfg(target_arch = "x86_64")]
    if is_x86_feature_detected!("avx2") {
        // SAFETY: the CPU supports AVX2, the only feature the function is compiled for.
        return unsafe { accumulate_avx2(out, first_query, inputs) };
    }
    accumulate_rows(out, first_query, inputs)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn accumulate_avx2(out: &mut [f32], first_query: usize, inputs: &Inputs) {
    accumulate_rows(out, first_query, inputs)
}

#[inline(always)]
fn accumulate_rows(out: &mut [f32], first_query: usize, inputs: &Inputs) {
    let shape = inputs.shape;
    let Shape {
        height,
        width,
        channels,
        queries,
        points,
        ..
    } = shape;
    let map_len = shape.map_len();
    for (query, out) in (first_query..).zip(out.chunks_exact_mut(channels)) {
        let map = &inputs.values[query / queries * map_len..][..map_len];
        for point in query * points..(query + 1) * points {
            let x = inputs.locations[2 * point] * width as f32 - 0.5;
            let y = inputs.locations[2 * point + 1] * height as f32 - 0.5;
            if !(x.is_finite() && y.is_finite()) {
                continue;
            }
            // Beyond -1 and the size every corner is outside; within, x + 2 >= 1 truncates to
            // floor(x) + 2 (baseline x86-64 has no rounding instruction for floor).
            let (x, y) = (x.clamp(-1.0, width as f32), y.clamp(-1.0, height as f32));
            let (x0, y0) = ((x + 2.0) as isize - 2, (y + 2.0) as isize - 2);
            let (fx, fy) = (x - x0 as f32, y - y0 as f32);
            for (row, wy) in [(y0, 1.0 - fy), (y0 + 1, fy)] {
                if row < 0 || row >= height as isize {
                    continue;
                }
                for (column, wx) in [(x0, 1.0 - fx), (x0 + 1, fx)] {
                    if column < 0 || column >= width as isize {
                        continue;
                    }
                    let weight = inputs.weights[point] * wy * wx;
                    let cell = row as usize * width + column as usize;
                    let features = &map[cell * channels..][..channels];
                    for (acc, value) in out.iter_mut().zip(features) {
                        *acc += weight * value;
                    }
                }
            }
        }
    }
}
