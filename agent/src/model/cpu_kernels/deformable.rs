//! Deformable aggregation as one pass over the data, for CPU inference.
//!
//! The tensor-op form in [`crate::model::sampling`] gathers all four corners of every point into a
//! `[N, Q, 4P, C]` tensor before weighting and summing them: at batch 8 that is 33 MB written
//! and read again per attention layer, half of the BEV encoder's time on the Flex backend. Here
//! each query accumulates its `4P` weighted corner rows straight into its output row, so memory
//! traffic is the inputs and the output only. This plays the role of BEVFormer's CUDA
//! `MultiScaleDeformableAttnFunction`: same result, no intermediate.

use rayon::prelude::*;

use super::parallel_output::{filled_in_chunks, zeros};

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

    /// Panics unless the three inputs' lengths match the shape.
    fn check(&self, values: &[f32], locations: &[f32], weights: &[f32]) {
        assert_eq!(values.len(), self.n * self.map_len(), "values length");
        assert_eq!(locations.len(), 2 * self.total_points(), "locations length");
        assert_eq!(weights.len(), self.total_points(), "weights length");
    }
}

/// Queries per parallel task: enough corner rows (4 per point) to dwarf the scheduling.
const QUERIES_PER_TASK: usize = 64;

/// `[n, queries, channels]`: per query, the sum over its points of the weight times the
/// bilinear sample (zero outside the map). A point with a non-finite location samples zero.
///
/// Panics if a slice's length does not match `shape` (the caller checks the tensor shapes).
pub fn aggregate(values: &[f32], locations: &[f32], weights: &[f32], shape: Shape) -> Vec<f32> {
    shape.check(values, locations, weights);
    let channels = shape.channels;
    let inputs = Inputs {
        values,
        locations,
        weights,
        shape,
    };
    filled_in_chunks(
        shape.n * shape.queries * channels,
        channels * QUERIES_PER_TASK,
        |task, out| accumulate(out, task * QUERIES_PER_TASK, &inputs),
    )
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
    let (channels, queries, points) = (shape.channels, shape.queries, shape.points);
    let map_len = shape.map_len();
    for (query, out) in (first_query..).zip(out.chunks_exact_mut(channels)) {
        let map = &inputs.values[query / queries * map_len..][..map_len];
        for point in query * points..(query + 1) * points {
            let Some(footprint) = Footprint::new(&inputs.locations[2 * point..], &shape) else {
                continue;
            };
            for corner in footprint.corners(&shape).into_iter().flatten() {
                let weight = inputs.weights[point] * corner.wx * corner.wy;
                let features = &map[corner.cell * channels..][..channels];
                for (acc, value) in out.iter_mut().zip(features) {
                    *acc += weight * value;
                }
            }
        }
    }
}

/// Where one point samples its map: the top-left corner cell of its bilinear footprint and its
/// fractional offset from it, in pixels.
struct Footprint {
    x0: isize,
    y0: isize,
    fx: f32,
    fy: f32,
    /// Whether x (y) lies inside the clamp range, where the sample depends on it.
    moves_x: bool,
    moves_y: bool,
}

impl Footprint {
    /// `location` starts with the point's normalised (x, y); `None` when either is not finite
    /// (the point samples zero).
    #[inline(always)]
    fn new(location: &[f32], shape: &Shape) -> Option<Self> {
        let (width, height) = (shape.width as f32, shape.height as f32);
        let x = location[0] * width - 0.5;
        let y = location[1] * height - 0.5;
        if !(x.is_finite() && y.is_finite()) {
            return None;
        }
        // Beyond -1 and the size every corner is outside; within, x + 2 >= 1 truncates to
        // floor(x) + 2 (baseline x86-64 has no rounding instruction for floor).
        let (cx, cy) = (x.clamp(-1.0, width), y.clamp(-1.0, height));
        let (x0, y0) = ((cx + 2.0) as isize - 2, (cy + 2.0) as isize - 2);
        Some(Self {
            x0,
            y0,
            fx: cx - x0 as f32,
            fy: cy - y0 as f32,
            moves_x: (-1.0..=width).contains(&x),
            moves_y: (-1.0..=height).contains(&y),
        })
    }

    /// The corners inside the map. A method rather than a callback, so that it inlines into
    /// the AVX2 loops (a closure would be compiled for baseline x86-64).
    #[inline(always)]
    fn corners(&self, shape: &Shape) -> [Option<Corner>; 4] {
        let corner = |row: isize, column: isize, wy: f32, wx: f32, dwy: f32, dwx: f32| {
            let inside = (0..shape.height as isize).contains(&row)
                && (0..shape.width as isize).contains(&column);
            inside.then(|| Corner {
                cell: row as usize * shape.width + column as usize,
                wx,
                wy,
                d_wx: dwx,
                d_wy: dwy,
            })
        };
        let (x0, y0, fx, fy) = (self.x0, self.y0, self.fx, self.fy);
        [
            corner(y0, x0, 1.0 - fy, 1.0 - fx, -1.0, -1.0),
            corner(y0, x0 + 1, 1.0 - fy, fx, -1.0, 1.0),
            corner(y0 + 1, x0, fy, 1.0 - fx, 1.0, -1.0),
            corner(y0 + 1, x0 + 1, fy, fx, 1.0, 1.0),
        ]
    }
}

/// One corner of a bilinear footprint: its cell, its weight `wx * wy`, and the derivatives of
/// `wx` and `wy` with respect to the pixel coordinates.
struct Corner {
    cell: usize,
    wx: f32,
    wy: f32,
    d_wx: f32,
    d_wy: f32,
}

/// The dot product of two rows, in eight independent lanes so that it vectorises.
#[inline(always)]
fn dot(a: &[f32], b: &[f32]) -> f32 {
    let mut lanes = [0f32; 8];
    let (a_chunks, b_chunks) = (a.chunks_exact(8), b.chunks_exact(8));
    let tail: f32 = a_chunks
        .remainder()
        .iter()
        .zip(b_chunks.remainder())
        .map(|(x, y)| x * y)
        .sum();
    for (a, b) in a_chunks.zip(b_chunks) {
        for lane in 0..8 {
            lanes[lane] += a[lane] * b[lane];
        }
    }
    lanes.iter().sum::<f32>() + tail
}

/// Gradients of [`aggregate`] with respect to its three inputs.
pub struct Gradients {
    pub values: Vec<f32>,
    pub locations: Vec<f32>,
    pub weights: Vec<f32>,
}

/// The gradients of [`aggregate`]'s output with respect to `values`, `locations` and `weights`,
/// given the output's gradient `grad` (`[n, queries, channels]`). A location gets no gradient
/// along an axis where it lies outside the clamp range or is not finite, as in the tensor-op
/// form.
///
/// Maps run in parallel: every query reads and scatters into its own map only.
pub fn aggregate_backward(
    values: &[f32],
    locations: &[f32],
    weights: &[f32],
    grad: &[f32],
    shape: Shape,
) -> Gradients {
    shape.check(values, locations, weights);
    assert_eq!(
        grad.len(),
        shape.n * shape.queries * shape.channels,
        "gradient length"
    );
    let mut gradients = Gradients {
        values: zeros(values.len()),
        locations: zeros(locations.len()),
        weights: zeros(weights.len()),
    };
    let map_points = shape.queries * shape.points;
    gradients
        .values
        .par_chunks_mut(shape.map_len())
        .zip(gradients.locations.par_chunks_mut(2 * map_points))
        .zip(gradients.weights.par_chunks_mut(map_points))
        .enumerate()
        .for_each(|(map, ((d_values, d_locations), d_weights))| {
            let map_inputs = MapInputs {
                values: &values[map * shape.map_len()..][..shape.map_len()],
                locations: &locations[2 * map * map_points..][..2 * map_points],
                weights: &weights[map * map_points..][..map_points],
                grad: &grad[map * shape.queries * shape.channels..]
                    [..shape.queries * shape.channels],
                shape,
            };
            backward_map(&map_inputs, d_values, d_locations, d_weights);
        });
    gradients
}

/// One map's slices of the backward inputs.
struct MapInputs<'a> {
    values: &'a [f32],
    locations: &'a [f32],
    weights: &'a [f32],
    grad: &'a [f32],
    shape: Shape,
}

/// [`backward_map_rows`] with AVX2 where the CPU has it.
fn backward_map(inputs: &MapInputs, d_values: &mut [f32], d_loc: &mut [f32], d_w: &mut [f32]) {
    #[cfg(target_arch = "x86_64")]
    if is_x86_feature_detected!("avx2") {
        // SAFETY: the CPU supports AVX2, the only feature the function is compiled for.
        return unsafe { backward_map_avx2(inputs, d_values, d_loc, d_w) };
    }
    backward_map_rows(inputs, d_values, d_loc, d_w)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn backward_map_avx2(inputs: &MapInputs, d_values: &mut [f32], d_loc: &mut [f32], d_w: &mut [f32]) {
    backward_map_rows(inputs, d_values, d_loc, d_w)
}

#[inline(always)]
fn backward_map_rows(
    inputs: &MapInputs,
    d_values: &mut [f32],
    d_locations: &mut [f32],
    d_weights: &mut [f32],
) {
    let shape = inputs.shape;
    let (channels, points) = (shape.channels, shape.points);
    let scale = [shape.width as f32, shape.height as f32];
    for (query, grad) in inputs.grad.chunks_exact(channels).enumerate() {
        for point in query * points..(query + 1) * points {
            let Some(footprint) = Footprint::new(&inputs.locations[2 * point..], &shape) else {
                continue;
            };
            let weight = inputs.weights[point];
            // d output / d (point weight) and d output / d (pixel x, pixel y), dotted with grad.
            let (mut d_weight, mut d_pixel) = (0.0, [0.0f32; 2]);
            for Corner {
                cell,
                wx,
                wy,
                d_wx,
                d_wy,
            } in footprint.corners(&shape).into_iter().flatten()
            {
                let features = &inputs.values[cell * channels..][..channels];
                let dot = dot(features, grad);
                d_weight += wx * wy * dot;
                d_pixel[0] += d_wx * wy * dot;
                d_pixel[1] += wx * d_wy * dot;
                let share = weight * wx * wy;
                for (d, g) in d_values[cell * channels..][..channels].iter_mut().zip(grad) {
                    *d += share * g;
                }
            }
            d_weights[point] = d_weight;
            for (axis, moves) in [footprint.moves_x, footprint.moves_y]
                .into_iter()
                .enumerate()
            {
                if moves {
                    d_locations[2 * point + axis] = weight * d_pixel[axis] * scale[axis];
                }
            }
        }
    }
}
