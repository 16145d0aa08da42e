//! Percentile bootstrap from one sequential random stream: the intervals of `a2perf report`.
//!
//! [`crate::rliable::bootstrap_ci`] draws its replicates in fixed chunks from derived streams,
//! so that they can be computed in parallel; the report draws every replicate in turn from one
//! [`RngStream`] (one index per resampled value) and takes the 2.5th and 97.5th percentiles of
//! the sorted replicates with [`numeric::percentile_sorted_lerp`]. Both are deterministic for a
//! given stream; they give different intervals, and recorded reports use this one.

use a2perf_core::RngStream;

use crate::numeric;

/// Fills `into` with `src.len()` values of `src` drawn with replacement, one
/// `rng.index(src.len())` per value, in order.
///
/// ```
/// use a2perf_core::RngStream;
/// let mut rng = RngStream::new(0, "doc");
/// let mut out = Vec::new();
/// a2perf_metrics::bootstrap::resample(&[1.0, 2.0, 3.0], &mut out, &mut rng);
/// assert_eq!(out.len(), 3);
/// assert!(out.iter().all(|v| [1.0, 2.0, 3.0].contains(v)));
/// ```
pub fn resample(src: &[f64], into: &mut Vec<f64>, rng: &mut RngStream) {
    into.clear();
    into.extend((0..src.len()).map(|_| src[rng.index(src.len())]));
}

/// The 95% percentile interval of bootstrap replicates: their 2.5th and 97.5th percentiles
/// ([`numeric::percentile_sorted_lerp`]), `[NaN, NaN]` when there are none.
///
/// ```
/// let reps: Vec<f64> = (0..=1000).map(f64::from).rev().collect();
/// assert_eq!(a2perf_metrics::bootstrap::interval95(reps), [25.0, 975.0]);
/// ```
pub fn interval95(mut replicates: Vec<f64>) -> [f64; 2] {
    replicates.sort_by(f64::total_cmp);
    [
        numeric::percentile_sorted_lerp(&replicates, 2.5),
        numeric::percentile_sorted_lerp(&replicates, 97.5),
    ]
}

/// The 95% interval of `statistic` over `reps` replicates, each computed by `replicate` (which
/// draws its resample from the caller's stream).
///
/// ```
/// use a2perf_core::RngStream;
/// let data = [1.0, 2.0, 3.0, 4.0];
/// let mut rng = RngStream::new(7, "doc");
/// let mut buf = Vec::new();
/// let [lo, hi] = a2perf_metrics::bootstrap::interval95_of(200, || {
///     a2perf_metrics::bootstrap::resample(&data, &mut buf, &mut rng);
///     a2perf_metrics::numeric::mean_sequential(&buf)
/// });
/// assert!(1.0 <= lo && lo <= hi && hi <= 4.0);
/// ```
pub fn interval95_of(reps: usize, mut replicate: impl FnMut() -> f64) -> [f64; 2] {
    interval95((0..reps).map(|_| replicate()).collect())
}

/// Percentile-bootstrap 95% interval of the mean of `values`: `reps` resamples drawn from
/// `rng`, each summed left to right from +0.0. `None` when there are no values or repetitions,
/// or a value is not finite.
///
/// ```
/// use a2perf_core::RngStream;
/// let mut rng = RngStream::new(0, "doc");
/// let [lo, hi] = a2perf_metrics::bootstrap::mean_ci(&[1.0, 2.0, 3.0], 1000, &mut rng).unwrap();
/// assert!(1.0 <= lo && lo < 2.0 && 2.0 < hi && hi <= 3.0);
/// assert!(a2perf_metrics::bootstrap::mean_ci(&[f64::NAN], 10, &mut rng).is_none());
/// ```
pub fn mean_ci(values: &[f64], reps: usize, rng: &mut RngStream) -> Option<[f64; 2]> {
    if values.is_empty() || reps == 0 || values.iter().any(|v| !v.is_finite()) {
        return None;
    }
    let n = values.len();
    Some(interval95_of(reps, || {
        // Summed as drawn from +0.0 (not `Iterator::sum`'s −0.0): the recorded intervals did.
        let mut s = 0.0;
        for _ in 0..n {
            s += values[rng.index(n)];
        }
        s / n as f64
    }))
}
