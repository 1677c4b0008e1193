//! Comfort, the way Bench2Drive scores "driving smoothness": the ego's motion sampled at 10 Hz,
//! cut into windows of 20 samples (2 s), and a window is comfortable when six smoothed signals
//! stay inside nuPlan's bounds all through it. A run's comfort is the share of its full windows
//! that are comfortable; a run of at most one window is judged whole (1 or 0).
//!
//! The signals (nuPlan's `ego_*_metric`s): longitudinal acceleration (2.40 up, 4.05 down, m/s²),
//! lateral acceleration (4.89 m/s²), jerk of the acceleration's magnitude (8.37 m/s³),
//! longitudinal jerk (4.13 m/s³), yaw rate (0.95 rad/s) and yaw acceleration (1.93 rad/s²).
//! Accelerations and yaw rate are smoothed with a Savitzky-Golay filter (window 7, order 2,
//! scipy's `interp` ends) and the jerks and the yaw acceleration are that filter's first
//! derivative of the smoothed signals, all within one window.
//!
//! Where we differ from Bench2Drive's `tools/efficiency_smoothness_benchmark.py`: it reads
//! CARLA's `get_angular_velocity()`, which is in degrees per second, against the rad/s bounds,
//! and it checks the smoothed yaw rate where nuPlan checks the yaw acceleration; we use radians
//! and the derivative, as nuPlan defines the metrics. Our accelerations are the velocity's
//! differences over the 0.1 s sample interval (CARLA reports its physics step's).

use glam::DVec2;

/// Seconds between two samples (Bench2Drive records at 10 Hz).
pub const SAMPLE_S: f64 = 0.1;
/// Simulation ticks between two samples.
pub const TICKS_PER_SAMPLE: u64 = ssrdrive_proto::TICK_HZ as u64 / 10;
/// Samples in one judged window (2 s).
pub const WINDOW_SAMPLES: usize = 20;
/// Savitzky-Golay window length, samples.
const FILTER_WINDOW: usize = 7;
/// Savitzky-Golay polynomial order.
const FILTER_ORDER: usize = 2;

/// nuPlan's comfort bounds, SI units.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ComfortBounds {
    /// Longitudinal acceleration, upper bound (m/s²).
    pub max_lon_accel: f64,
    /// Longitudinal acceleration, lower bound (m/s², negative).
    pub min_lon_accel: f64,
    /// |lateral acceleration| (m/s²).
    pub max_abs_lat_accel: f64,
    /// |jerk of the acceleration's magnitude| (m/s³).
    pub max_abs_mag_jerk: f64,
    /// |longitudinal jerk| (m/s³).
    pub max_abs_lon_jerk: f64,
    /// |yaw rate| (rad/s).
    pub max_abs_yaw_rate: f64,
    /// |yaw acceleration| (rad/s²).
    pub max_abs_yaw_accel: f64,
}

impl Default for ComfortBounds {
    fn default() -> Self {
        Self {
            max_lon_accel: 2.40,
            min_lon_accel: -4.05,
            max_abs_lat_accel: 4.89,
            max_abs_mag_jerk: 8.37,
            max_abs_lon_jerk: 4.13,
            max_abs_yaw_rate: 0.95,
            max_abs_yaw_accel: 1.93,
        }
    }
}

/// The ego's motion at one sample.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MotionSample {
    /// Velocity, map frame, m/s.
    pub velocity: DVec2,
    /// Heading, rad counter-clockwise from +x.
    pub yaw: f64,
}

/// Collects a run's motion at 10 Hz and judges its comfort.
#[derive(Debug, Clone, Default)]
pub struct ComfortTrace {
    samples: Vec<MotionSample>,
}

impl ComfortTrace {
    /// Adds the sample of the next 0.1 s.
    pub fn push(&mut self, sample: MotionSample) {
        self.samples.push(sample);
    }

    /// The share of comfortable windows (0 to 1); `None` for fewer than three samples (too few
    /// to fit the filter's parabola).
    pub fn comfort(&self, bounds: &ComfortBounds) -> Option<f64> {
        if self.samples.len() <= FILTER_ORDER {
            return None;
        }
        let signals = Signals::of(&self.samples);
        if self.samples.len() <= WINDOW_SAMPLES {
            return Some(if signals.comfortable(0..self.samples.len(), bounds) {
                1.0
            } else {
                0.0
            });
        }
        let windows = self.samples.len() / WINDOW_SAMPLES;
        let good = (0..windows)
            .filter(|w| signals.comfortable(w * WINDOW_SAMPLES..(w + 1) * WINDOW_SAMPLES, bounds))
            .count();
        Some(good as f64 / windows as f64)
    }
}

/// The raw per-sample signals of a run.
struct Signals {
    lon: Vec<f64>,
    lat: Vec<f64>,
    magnitude: Vec<f64>,
    yaw_rate: Vec<f64>,
}

impl Signals {
    /// Accelerations are the velocity's backward differences, the yaw rate the heading's
    /// (wrapped); the first sample repeats the second's. Needs at least two samples.
    fn of(samples: &[MotionSample]) -> Self {
        let mut out = Signals {
            lon: Vec::with_capacity(samples.len()),
            lat: Vec::with_capacity(samples.len()),
            magnitude: Vec::with_capacity(samples.len()),
            yaw_rate: Vec::with_capacity(samples.len()),
        };
        for pair in samples.windows(2) {
            let (previous, now) = (pair[0], pair[1]);
            let accel = (now.velocity - previous.velocity) / SAMPLE_S;
            let forward = DVec2::from_angle(now.yaw);
            let right = DVec2::new(forward.y, -forward.x);
            out.lon.push(accel.dot(forward));
            out.lat.push(accel.dot(right));
            out.magnitude.push(accel.length());
            out.yaw_rate
                .push(crate::map::angle_diff(now.yaw, previous.yaw) / SAMPLE_S);
        }
        for signal in [
            &mut out.lon,
            &mut out.lat,
            &mut out.magnitude,
            &mut out.yaw_rate,
        ] {
            signal.insert(0, signal[0]);
        }
        out
    }

    /// Whether every bound holds on every sample of `range`, the filter working within it.
    fn comfortable(&self, range: std::ops::Range<usize>, bounds: &ComfortBounds) -> bool {
        let lon = smooth(&self.lon[range.clone()], 0);
        let lat = smooth(&self.lat[range.clone()], 0);
        let magnitude = smooth(&self.magnitude[range.clone()], 0);
        let yaw_rate = smooth(&self.yaw_rate[range], 0);
        let within =
            |values: &[f64], low: f64, high: f64| values.iter().all(|v| *v > low && *v < high);
        within(&lon, bounds.min_lon_accel, bounds.max_lon_accel)
            && within(&lat, -bounds.max_abs_lat_accel, bounds.max_abs_lat_accel)
            && within(
                &smooth(&magnitude, 1),
                -bounds.max_abs_mag_jerk,
                bounds.max_abs_mag_jerk,
            )
            && within(
                &smooth(&lon, 1),
                -bounds.max_abs_lon_jerk,
                bounds.max_abs_lon_jerk,
            )
            && within(&yaw_rate, -bounds.max_abs_yaw_rate, bounds.max_abs_yaw_rate)
            && within(
                &smooth(&yaw_rate, 1),
                -bounds.max_abs_yaw_accel,
                bounds.max_abs_yaw_accel,
            )
    }
}

/// Savitzky-Golay filtering of `y` sampled every [`SAMPLE_S`]: the value (`derivative` 0) or
/// the first derivative (1, per second) at each sample of the parabola fitted by least squares
/// to the window of [`FILTER_WINDOW`] samples around it, shifted inward at the ends (scipy's
/// `savgol_filter(mode="interp")`); the window shrinks to the signal when it is shorter.
pub fn smooth(y: &[f64], derivative: usize) -> Vec<f64> {
    let n = y.len();
    let window = FILTER_WINDOW.min(n);
    (0..n)
        .map(|i| {
            let start = i.saturating_sub(window / 2).min(n - window);
            let c = fit_parabola(&y[start..start + window], i - start);
            match derivative {
                0 => c[0],
                _ => c[1] / SAMPLE_S,
            }
        })
        .collect()
}

/// Least-squares `c0 + c1 x + c2 x²` through `y[j]` at `x = j - at` (fewer than three points fit
/// a lower order); returns the coefficients.
fn fit_parabola(y: &[f64], at: usize) -> [f64; 3] {
    let order = FILTER_ORDER.min(y.len().saturating_sub(1));
    let mut normal = [[0.0f64; 4]; 3];
    for (j, &value) in y.iter().enumerate() {
        let x = j as f64 - at as f64;
        let powers = [1.0, x, x * x];
        for r in 0..=order {
            for c in 0..=order {
                normal[r][c] += powers[r] * powers[c];
            }
            normal[r][3] += powers[r] * value;
        }
    }
    solve(&mut normal, order + 1)
}

/// Gauss-Jordan elimination with partial pivoting of the first `size` rows of an augmented
/// matrix; unknowns beyond `size` are 0.
fn solve(m: &mut [[f64; 4]; 3], size: usize) -> [f64; 3] {
    for col in 0..size {
        let pivot = (col..size)
            .max_by(|a, b| m[*a][col].abs().total_cmp(&m[*b][col].abs()))
            .unwrap_or(col);
        m.swap(col, pivot);
        let p = m[col][col];
        if p.abs() < 1e-12 {
            continue;
        }
        let pivot_row = m[col].map(|v| v / p);
        m[col] = pivot_row;
        for (r, row) in m.iter_mut().enumerate().take(size) {
            if r != col {
                let f = row[col];
                for (value, pivot_value) in row.iter_mut().zip(pivot_row) {
                    *value -= f * pivot_value;
                }
            }
        }
    }
    let mut out = [0.0; 3];
    for (r, value) in out.iter_mut().enumerate().take(size) {
        *value = m[r][3];
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn straight(speeds: impl IntoIterator<Item = f64>) -> ComfortTrace {
        let mut trace = ComfortTrace::default();
        for v in speeds {
            trace.push(MotionSample {
                velocity: DVec2::new(v, 0.0),
                yaw: 0.0,
            });
        }
        trace
    }

    #[test]
    fn the_filter_keeps_a_parabola_and_differentiates_it() {
        let y: Vec<f64> = (0..12)
            .map(|k| 1.0 + 2.0 * k as f64 + 0.5 * (k * k) as f64)
            .collect();
        let values = smooth(&y, 0);
        let slopes = smooth(&y, 1);
        for k in 0..12 {
            assert!((values[k] - y[k]).abs() < 1e-9, "value at {k}");
            // dy/dk = 2 + k per sample, per second divided by 0.1 s.
            assert!(
                (slopes[k] - (2.0 + k as f64) / SAMPLE_S).abs() < 1e-8,
                "slope at {k}"
            );
        }
    }

    #[test]
    fn cruising_is_comfortable_and_a_hard_stop_is_not() {
        let bounds = ComfortBounds::default();
        assert_eq!(
            straight(std::iter::repeat_n(8.0, 60)).comfort(&bounds),
            Some(1.0)
        );
        // 2 s cruise, then braking at 8 m/s² (past the 4.05 bound) to a stop, then standing.
        let braking = (0..60).map(|k| match k {
            0..20 => 8.0,
            20..30 => 8.0 - 0.8 * (k - 19) as f64,
            _ => 0.0,
        });
        let comfort = straight(braking).comfort(&bounds).unwrap();
        assert!(comfort < 1.0 && comfort > 0.0, "{comfort}");
    }

    #[test]
    fn a_gentle_speed_change_passes_where_a_sharp_turn_fails_on_yaw_rate() {
        let bounds = ComfortBounds::default();
        let gentle = straight((0..40).map(|k| 5.0 + 0.1 * k as f64)); // 1 m/s²
        assert_eq!(gentle.comfort(&bounds), Some(1.0));
        // A 90° turn in 1 s at 5 m/s: yaw rate ~1.57 rad/s, lateral ~7.9 m/s².
        let mut turning = ComfortTrace::default();
        for k in 0..40 {
            let yaw = (k.clamp(10, 20) - 10) as f64 * std::f64::consts::FRAC_PI_2 / 10.0;
            turning.push(MotionSample {
                velocity: DVec2::from_angle(yaw) * 5.0,
                yaw,
            });
        }
        assert_eq!(turning.comfort(&bounds), Some(0.0));
    }

    #[test]
    fn short_runs_are_judged_whole_and_tiny_ones_not_at_all() {
        let bounds = ComfortBounds::default();
        assert_eq!(straight([3.0, 3.0]).comfort(&bounds), None);
        assert_eq!(
            straight(std::iter::repeat_n(3.0, 15)).comfort(&bounds),
            Some(1.0)
        );
        // 41 samples: two full windows judged, the last sample left out.
        assert_eq!(
            straight(std::iter::repeat_n(3.0, 41)).comfort(&bounds),
            Some(1.0)
        );
    }
}
