//! Percentiles of measured samples (latencies, step times), the one rule every benchmark and
//! load test quotes: nearest rank, the sample at `round(fraction * (n - 1))` of the sorted set.

/// The `fraction` (0 to 1) percentile of `sorted` samples, nearest rank; NaN when there are
/// none.
pub fn percentile(sorted: &[f64], fraction: f64) -> f64 {
    match sorted.len() {
        0 => f64::NAN,
        n => sorted[((fraction * (n - 1) as f64).round() as usize).min(n - 1)],
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_nearest_rank_of_the_sorted_samples() {
        let samples = [1.0, 2.0, 3.0, 4.0, 5.0];
        assert_eq!(percentile(&samples, 0.5), 3.0);
        assert_eq!(percentile(&samples, 0.9), 5.0);
        assert_eq!(percentile(&samples, 0.0), 1.0);
        assert_eq!(percentile(&samples, 1.0), 5.0);
        assert!(percentile(&[], 0.5).is_nan());
    }
}
