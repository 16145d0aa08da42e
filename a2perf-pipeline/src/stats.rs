//! The summary of a sample that run files record (`inference.json`); the arithmetic is
//! `a2perf_metrics::numeric`'s.

use a2perf_metrics::numeric;
use serde::{Deserialize, Serialize};

/// The mean of the run files (summed left to right), `a2perf_metrics`'s, under the name the
/// pipeline's modules call it by.
pub use a2perf_metrics::numeric::mean_sequential as mean;

/// Summary of a sample: count, mean, population standard deviation (NumPy's default, as the
/// original harness), median, p90, p99, min and max. Empty samples give `count = 0` and NaNs,
/// and so does a NaN among the values; files hold them as `null` and read them back as NaN.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Summary {
    /// Number of values.
    pub count: usize,
    /// Mean.
    #[serde(deserialize_with = "a2perf_core::results::f64_or_nan")]
    pub mean: f64,
    /// Population standard deviation (ddof = 0).
    #[serde(deserialize_with = "a2perf_core::results::f64_or_nan")]
    pub std: f64,
    /// Median (linear interpolation).
    #[serde(deserialize_with = "a2perf_core::results::f64_or_nan")]
    pub median: f64,
    /// 90th percentile (linear interpolation).
    #[serde(deserialize_with = "a2perf_core::results::f64_or_nan")]
    pub p90: f64,
    /// 99th percentile (linear interpolation).
    #[serde(deserialize_with = "a2perf_core::results::f64_or_nan")]
    pub p99: f64,
    /// Minimum.
    #[serde(deserialize_with = "a2perf_core::results::f64_or_nan")]
    pub min: f64,
    /// Maximum.
    #[serde(deserialize_with = "a2perf_core::results::f64_or_nan")]
    pub max: f64,
}

impl Summary {
    /// Summarises `values`.
    ///
    /// ```
    /// use a2perf_pipeline::stats::Summary;
    /// let s = Summary::of(&[1.0, 2.0, 3.0, 4.0]);
    /// assert_eq!((s.mean, s.median, s.min, s.max), (2.5, 2.5, 1.0, 4.0));
    /// assert!((s.std - 1.25f64.sqrt()).abs() < 1e-12);
    /// ```
    pub fn of(values: &[f64]) -> Self {
        let v = numeric::sorted(values);
        let n = v.len();
        // Summed in sorted order, as the recorded summaries were.
        Self {
            count: n,
            mean: numeric::mean_sequential(&v),
            std: numeric::std_sequential(&v, 0),
            median: numeric::percentile_sorted_lerp(&v, 50.0),
            p90: numeric::percentile_sorted_lerp(&v, 90.0),
            p99: numeric::percentile_sorted_lerp(&v, 99.0),
            min: v.first().copied().unwrap_or(f64::NAN),
            max: v.last().copied().unwrap_or(f64::NAN),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn summary_matches_numpy_linear_and_population_std() {
        let s = Summary::of(&[10.0, 1.0, 4.0, 2.0, 3.0]);
        assert!((s.p90 - 7.6).abs() < 1e-12);
        assert_eq!((s.median, s.min, s.max, s.count), (3.0, 1.0, 10.0, 5));
        assert_eq!(s.std, 10f64.sqrt());
        assert!(Summary::of(&[]).mean.is_nan());
        assert_eq!(Summary::of(&[2.0]).std, 0.0);
    }
}
