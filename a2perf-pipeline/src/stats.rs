//! Small descriptive statistics used throughout the pipelines.

use serde::{Deserialize, Serialize};

/// Summary of a sample: count, mean, population standard deviation (NumPy's default, as the
/// original harness), median, p90, p99, min and max. Empty samples give `count = 0` and NaNs.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Summary {
    /// Number of values.
    pub count: usize,
    /// Mean.
    pub mean: f64,
    /// Population standard deviation (ddof = 0).
    pub std: f64,
    /// Median (linear interpolation).
    pub median: f64,
    /// 90th percentile (linear interpolation).
    pub p90: f64,
    /// 99th percentile (linear interpolation).
    pub p99: f64,
    /// Minimum.
    pub min: f64,
    /// Maximum.
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
        let mut v: Vec<f64> = values.to_vec();
        v.sort_by(f64::total_cmp);
        let n = v.len();
        let mean = mean(&v);
        let var = if n == 0 {
            f64::NAN
        } else {
            v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / n as f64
        };
        Self {
            count: n,
            mean,
            std: var.sqrt(),
            median: percentile_sorted(&v, 50.0),
            p90: percentile_sorted(&v, 90.0),
            p99: percentile_sorted(&v, 99.0),
            min: v.first().copied().unwrap_or(f64::NAN),
            max: v.last().copied().unwrap_or(f64::NAN),
        }
    }
}

/// Mean (NaN when empty).
pub fn mean(v: &[f64]) -> f64 {
    if v.is_empty() {
        f64::NAN
    } else {
        v.iter().sum::<f64>() / v.len() as f64
    }
}

/// Sample standard deviation (ddof = 1; 0 for a single value, NaN when empty).
pub fn sample_std(v: &[f64]) -> f64 {
    match v.len() {
        0 => f64::NAN,
        1 => 0.0,
        n => {
            let m = mean(v);
            (v.iter().map(|x| (x - m).powi(2)).sum::<f64>() / (n - 1) as f64).sqrt()
        }
    }
}

/// Percentile `q` (0–100) of sorted values, NumPy's default linear interpolation.
pub fn percentile_sorted(sorted: &[f64], q: f64) -> f64 {
    match sorted.len() {
        0 => f64::NAN,
        1 => sorted[0],
        n => {
            let pos = (q / 100.0).clamp(0.0, 1.0) * (n - 1) as f64;
            let lo = pos.floor() as usize;
            let hi = pos.ceil() as usize;
            sorted[lo] + (sorted[hi] - sorted[lo]) * (pos - lo as f64)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn percentiles_match_numpy_linear() {
        let v = [1.0, 2.0, 3.0, 4.0, 10.0];
        assert!((percentile_sorted(&v, 90.0) - 7.6).abs() < 1e-12);
        assert_eq!(percentile_sorted(&v, 50.0), 3.0);
        assert!(Summary::of(&[]).mean.is_nan());
        assert_eq!(sample_std(&[1.0, 3.0]), 2f64.sqrt());
    }
}
