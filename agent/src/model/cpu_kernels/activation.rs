//! GELU, sigmoid and ReLU, element-wise, forward and backward: one parallel, vectorised pass
//! each.
//!
//! Flex applies an activation on one thread, GELU through libm's scalar `erf`, and autodiff
//! adds a second single-threaded pass for the derivative. Here `exp` and `erf` are branch-free
//! polynomials the compiler vectorises (AVX2 where the CPU has it), and chunks run in parallel.
//! Accuracy: `exp` within 2 ulp, `erf` within 3e-7 (Abramowitz and Stegun 7.1.26), so GELU
//! and sigmoid differ from Flex's by a few float32 roundings.

use super::parallel_output::filled_in_chunks;

/// Elements per parallel task.
const CHUNK: usize = 16 * 1024;

/// An element-wise activation with a fused kernel.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Activation {
    /// `x Φ(x)`, with `Φ` the standard normal CDF (exact, not the tanh approximation).
    Gelu,
    /// `1 / (1 + e^-x)`.
    Sigmoid,
    /// `max(x, 0)` (derivative 0 at 0).
    Relu,
}

/// `e^x`, clamped to the normal float32 range: `x = n ln 2 + r` with `|r| <= ln 2 / 2`,
/// `e^r` by Cephes' polynomial, `2^n` written into the exponent bits.
#[inline(always)]
pub(super) fn exp(x: f32) -> f32 {
    // Adding 1.5 * 2^23 rounds to an integer, which lands in the low mantissa bits.
    const SHIFT: f32 = 12_582_912.0;
    let x = x.clamp(-87.0, 88.0);
    let shifted = x * std::f32::consts::LOG2_E + SHIFT;
    let n = shifted - SHIFT;
    let r = x - n * 0.693_359_4 + n * 2.121_944_4e-4;
    let mut p = 1.987_569_1e-4;
    p = p * r + 1.398_199_9e-3;
    p = p * r + 8.333_452e-3;
    p = p * r + 4.166_579_6e-2;
    p = p * r + 0.166_666_65;
    p = p * r + 0.5;
    let e_r = p * r * r + r + 1.0;
    let exponent = (shifted.to_bits() as i32 - SHIFT.to_bits() as i32 + 127) << 23;
    e_r * f32::from_bits(exponent as u32)
}

/// `Φ(x)` and the normal density `φ(x)`, sharing one `exp(-x²/2)`.
#[inline(always)]
fn normal_cdf_pdf(x: f32) -> (f32, f32) {
    // erf(s) = 1 - t (a1 + t (a2 + ...)) e^(-s^2), t = 1 / (1 + p s), for s = |x| / sqrt(2).
    let s = x.abs() * std::f32::consts::FRAC_1_SQRT_2;
    let t = 1.0 / (1.0 + 0.327_591_1 * s);
    let mut poly = 1.061_405_4;
    poly = poly * t - 1.453_152;
    poly = poly * t + 1.421_413_8;
    poly = poly * t - 0.284_496_74;
    poly = poly * t + 0.254_829_6;
    let gaussian = exp(-0.5 * x * x);
    let erf_abs = 1.0 - poly * t * gaussian;
    let erf = if x < 0.0 { -erf_abs } else { erf_abs };
    // 1 / sqrt(2 pi)
    (0.5 + 0.5 * erf, 0.398_942_3 * gaussian)
}

#[inline(always)]
fn sigmoid(x: f32) -> f32 {
    1.0 / (1.0 + exp(-x))
}

impl Activation {
    #[inline(always)]
    fn value(self, x: f32) -> f32 {
        match self {
            Self::Gelu => x * normal_cdf_pdf(x).0,
            Self::Sigmoid => sigmoid(x),
            Self::Relu => x.max(0.0),
        }
    }

    /// The gradient with respect to `x`, given the output's gradient `grad`.
    #[inline(always)]
    fn gradient(self, x: f32, grad: f32) -> f32 {
        match self {
            Self::Gelu => {
                let (cdf, pdf) = normal_cdf_pdf(x);
                grad * (cdf + x * pdf)
            }
            Self::Sigmoid => {
                let s = sigmoid(x);
                grad * s * (1.0 - s)
            }
            Self::Relu => {
                if x > 0.0 {
                    grad
                } else {
                    0.0
                }
            }
        }
    }
}

/// `f(x[i], grad[i])` for every `i`, over chunks in parallel; AVX2 where the CPU has it (the
/// build targets baseline x86-64).
fn map(x: &[f32], grad: &[f32], f: impl Fn(f32, f32) -> f32 + Sync + Copy) -> Vec<f32> {
    filled_in_chunks(x.len(), CHUNK, |k, out| {
        let range = k * CHUNK..k * CHUNK + out.len();
        let (x, grad) = (&x[range.clone()], &grad[range]);
        #[cfg(target_arch = "x86_64")]
        if is_x86_feature_detected!("avx2") {
            // SAFETY: the CPU supports AVX2, the only feature the function is compiled for.
            return unsafe { map_chunk_avx2(out, x, grad, f) };
        }
        map_chunk(out, x, grad, f)
    })
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn map_chunk_avx2(out: &mut [f32], x: &[f32], grad: &[f32], f: impl Fn(f32, f32) -> f32) {
    map_chunk(out, x, grad, f)
}

#[inline(always)]
fn map_chunk(out: &mut [f32], x: &[f32], grad: &[f32], f: impl Fn(f32, f32) -> f32) {
    for ((out, &x), &grad) in out.iter_mut().zip(x).zip(grad) {
        *out = f(x, grad);
    }
}

/// `activation` applied to every element of `x`.
pub fn forward(activation: Activation, x: &[f32]) -> Vec<f32> {
    // The gradient slot is unused: zip it against `x` itself.
    match activation {
        Activation::Gelu => map(x, x, |x, _| Activation::Gelu.value(x)),
        Activation::Sigmoid => map(x, x, |x, _| Activation::Sigmoid.value(x)),
        Activation::Relu => map(x, x, |x, _| Activation::Relu.value(x)),
    }
}

/// The gradient with respect to `x` of [`forward`], given the output's gradient `grad`.
///
/// Panics if `grad` and `x` differ in length.
pub fn backward(activation: Activation, x: &[f32], grad: &[f32]) -> Vec<f32> {
    assert_eq!(grad.len(), x.len(), "gradient length");
    match activation {
        Activation::Gelu => map(x, grad, |x, g| Activation::Gelu.gradient(x, g)),
        Activation::Sigmoid => map(x, grad, |x, g| Activation::Sigmoid.gradient(x, g)),
        Activation::Relu => map(x, grad, |x, g| Activation::Relu.gradient(x, g)),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn exp_is_accurate_over_the_float_range() {
        for i in -870..=880 {
            let x = i as f32 * 0.1;
            let (fast, exact) = (exp(x), (x as f64).exp());
            assert!(
                ((fast as f64 - exact) / exact).abs() < 3e-7,
                "exp({x}) = {fast}, expected {exact}"
            );
        }
    }

    #[test]
    fn normal_cdf_matches_erf() {
        for i in -600..=600 {
            let x = i as f32 * 0.01;
            let exact = 0.5 * (1.0 + libm::erf(x as f64 / std::f64::consts::SQRT_2));
            let (cdf, _) = normal_cdf_pdf(x);
            assert!(
                (cdf as f64 - exact).abs() < 3e-7,
                "Φ({x}) = {cdf}, expected {exact}"
            );
        }
    }
}
