//! NumPy/SciPy-compatible numeric primitives.
//!
//! The reference implementations (rl-reliability-metrics, A2Perf's `reliability.py`, rliable) are
//! written against NumPy 1.26 and SciPy 1.11. To reproduce their numbers to ~1e-12 these helpers
//! follow the same arithmetic, not just the same mathematics:
//!
//! - sums use NumPy's pairwise summation (`pairwise_sum_DOUBLE`, blocks of 8, split above 128);
//! - `np.percentile(method="linear")` interpolates with NumPy's `_lerp`, which switches formula at
//!   `t >= 0.5`;
//! - `scipy.stats.scoreatpercentile` (used by the library's CVaR) is a *different* weighted
//!   average, `(a·(j−idx) + b·(idx−i)) / ((j−idx)+(idx−i))`, so it gets its own function.
//!
//! Values are expected to be finite; NaN sorts last (IEEE total order) and propagates.

use serde::{Deserialize, Serialize};

/// Which direction of a metric is better.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Direction {
    /// Larger values are better (e.g. risk across runs, returns).
    HigherIsBetter,
    /// Smaller values are better (e.g. dispersions, energy).
    LowerIsBetter,
}

impl Direction {
    /// `true` for [`Direction::HigherIsBetter`] (the library's `bigger_is_better`).
    pub fn bigger_is_better(self) -> bool {
        matches!(self, Direction::HigherIsBetter)
    }
}

/// Which tail a CVaR is taken over.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Tail {
    /// Mean of the values at or below the α-quantile.
    Lower,
    /// Mean of the values at or above the (1−α)-quantile.
    Upper,
}

/// NumPy's pairwise summation of a contiguous `float64` array.
///
/// ```
/// assert_eq!(a2perf_metrics::numeric::pairwise_sum(&[1.0, 2.0, 3.0]), 6.0);
/// ```
pub fn pairwise_sum(x: &[f64]) -> f64 {
    let n = x.len();
    if n < 8 {
        let mut res = 0.0;
        for v in x {
            res += v;
        }
        res
    } else if n <= 128 {
        let mut r = [0.0f64; 8];
        r.copy_from_slice(&x[..8]);
        let full = n - n % 8;
        let mut i = 8;
        while i < full {
            for j in 0..8 {
                r[j] += x[i + j];
            }
            i += 8;
        }
        let mut res = ((r[0] + r[1]) + (r[2] + r[3])) + ((r[4] + r[5]) + (r[6] + r[7]));
        while i < n {
            res += x[i];
            i += 1;
        }
        res
    } else {
        let mut n2 = n / 2;
        n2 -= n2 % 8;
        pairwise_sum(&x[..n2]) + pairwise_sum(&x[n2..])
    }
}

/// Left-to-right sum, exactly as `Iterator::sum` (which starts from −0.0, so a sum of negative
/// zeros stays −0.0).
///
/// NumPy sums pairwise ([`pairwise_sum`]); the two agree for fewer than 8 values, up to the
/// sign of a zero sum. `a2perf report` and the run summaries have always summed this way, so
/// their files keep their bytes by using it.
///
/// ```
/// use a2perf_metrics::numeric::sequential_sum;
/// assert_eq!(sequential_sum(&[1.0, 2.0, 3.0]), 6.0);
/// assert!(sequential_sum(&[-0.0]).is_sign_negative());
/// ```
pub fn sequential_sum(x: &[f64]) -> f64 {
    x.iter().sum()
}

/// Mean by [`sequential_sum`] (NaN for an empty slice): [`mean`] with the summation order of
/// `a2perf report` and the run summaries instead of NumPy's.
///
/// ```
/// assert_eq!(a2perf_metrics::numeric::mean_sequential(&[1.0, 2.0, 6.0]), 3.0);
/// assert!(a2perf_metrics::numeric::mean_sequential(&[]).is_nan());
/// ```
pub fn mean_sequential(x: &[f64]) -> f64 {
    if x.is_empty() {
        return f64::NAN;
    }
    sequential_sum(x) / x.len() as f64
}

/// Variance (`np.var(x, ddof=ddof)`) summed by [`sequential_sum`] (NaN when `len <= ddof`),
/// the summation order of `a2perf report` and the run summaries.
///
/// ```
/// assert_eq!(a2perf_metrics::numeric::var_sequential(&[1.0, 3.0], 1), 2.0);
/// assert!(a2perf_metrics::numeric::var_sequential(&[1.0], 1).is_nan());
/// ```
pub fn var_sequential(x: &[f64], ddof: usize) -> f64 {
    if x.len() <= ddof {
        return f64::NAN;
    }
    let m = mean_sequential(x);
    x.iter().map(|v| (v - m).powi(2)).sum::<f64>() / (x.len() - ddof) as f64
}

/// [`std()`] summed by [`sequential_sum`]: the square root of [`var_sequential`].
///
/// ```
/// let s = a2perf_metrics::numeric::std_sequential(&[1.0, 3.0], 1);
/// assert_eq!(s, 2f64.sqrt());
/// assert_eq!(a2perf_metrics::numeric::std_sequential(&[5.0], 0), 0.0);
/// ```
pub fn std_sequential(x: &[f64], ddof: usize) -> f64 {
    var_sequential(x, ddof).sqrt()
}

/// The two-sided 95% Student-t quantile (`t.ppf(0.975, df)`) to three decimals, for the
/// t-interval of a mean over `df + 1` values; the normal 1.96 beyond 30 degrees of freedom,
/// NaN for none.
///
/// ```
/// use a2perf_metrics::numeric::student_t975;
/// assert_eq!(student_t975(2), 4.303);
/// assert_eq!(student_t975(100), 1.96);
/// assert!(student_t975(0).is_nan());
/// ```
pub fn student_t975(df: usize) -> f64 {
    const T: [f64; 30] = [
        12.706, 4.303, 3.182, 2.776, 2.571, 2.447, 2.365, 2.306, 2.262, 2.228, 2.201, 2.179, 2.160,
        2.145, 2.131, 2.120, 2.110, 2.101, 2.093, 2.086, 2.080, 2.074, 2.069, 2.064, 2.060, 2.056,
        2.052, 2.048, 2.045, 2.042,
    ];
    if df == 0 {
        f64::NAN
    } else {
        T.get(df - 1).copied().unwrap_or(1.96)
    }
}

/// `np.mean` of a 1-D array (NaN for an empty slice).
///
/// ```
/// assert_eq!(a2perf_metrics::numeric::mean(&[1.0, 2.0, 6.0]), 3.0);
/// ```
pub fn mean(x: &[f64]) -> f64 {
    if x.is_empty() {
        return f64::NAN;
    }
    pairwise_sum(x) / x.len() as f64
}

/// `np.std(x, ddof=ddof)` (NaN when `len <= ddof`).
///
/// ```
/// let s = a2perf_metrics::numeric::std(&[1.0, 2.0, 3.0, 4.0], 1);
/// assert!((s - 1.2909944487358056).abs() < 1e-15);
/// ```
pub fn std(x: &[f64], ddof: usize) -> f64 {
    if x.len() <= ddof {
        return f64::NAN;
    }
    let m = mean(x);
    let sq: Vec<f64> = x
        .iter()
        .map(|v| {
            let d = v - m;
            d * d
        })
        .collect();
    (pairwise_sum(&sq) / (x.len() - ddof) as f64).sqrt()
}

/// A sorted copy (IEEE total order, so NaN sorts last).
pub fn sorted(x: &[f64]) -> Vec<f64> {
    let mut v = x.to_vec();
    v.sort_unstable_by(f64::total_cmp);
    v
}

/// NumPy's `_lerp(a, b, t)`: the formula flips at `t >= 0.5` for symmetry.
fn np_lerp(a: f64, b: f64, t: f64) -> f64 {
    let diff = b - a;
    if t >= 0.5 {
        b - diff * (1.0 - t)
    } else {
        a + diff * t
    }
}

/// `np.quantile(x, q, method="linear")` of already **sorted** data, `q` in `[0, 1]`.
pub fn quantile_sorted(sorted: &[f64], q: f64) -> f64 {
    let n = sorted.len();
    if n == 0 {
        return f64::NAN;
    }
    let virtual_index = (n - 1) as f64 * q;
    if virtual_index >= (n - 1) as f64 {
        return sorted[n - 1];
    }
    if virtual_index <= 0.0 {
        return sorted[0];
    }
    let prev = virtual_index.floor();
    let i = prev as usize;
    np_lerp(sorted[i], sorted[i + 1], virtual_index - prev)
}

/// `np.percentile(x, p, method="linear")` of already **sorted** data, `p` in `[0, 100]`.
pub fn percentile_sorted(sorted: &[f64], p: f64) -> f64 {
    quantile_sorted(sorted, p / 100.0)
}

/// Linear percentile `p` (0–100, clamped) of already **sorted** data with the one-sided
/// interpolation `a + (b − a)·t` at every position.
///
/// [`percentile_sorted`] follows NumPy's `_lerp`, which switches to `b − (b − a)·(1 − t)` for
/// `t ≥ 0.5`; the two pick the same neighbours and weights and differ at most in the last bit.
/// `a2perf report` (bootstrap intervals, box plots) and the run summaries (median, p90, p99 of
/// `inference.json`) have always used this form, so their files keep their bytes by using it.
///
/// ```
/// use a2perf_metrics::numeric::percentile_sorted_lerp;
/// let v = [1.0, 2.0, 3.0, 4.0, 10.0];
/// assert!((percentile_sorted_lerp(&v, 90.0) - 7.6).abs() < 1e-12);
/// assert_eq!(percentile_sorted_lerp(&v, 50.0), 3.0);
/// assert_eq!(percentile_sorted_lerp(&[7.0], 25.0), 7.0);
/// assert!(percentile_sorted_lerp(&[], 50.0).is_nan());
/// ```
pub fn percentile_sorted_lerp(sorted: &[f64], p: f64) -> f64 {
    match sorted.len() {
        0 => f64::NAN,
        1 => sorted[0],
        n => {
            let pos = (p / 100.0).clamp(0.0, 1.0) * (n - 1) as f64;
            let lo = pos.floor() as usize;
            let hi = pos.ceil() as usize;
            sorted[lo] + (sorted[hi] - sorted[lo]) * (pos - lo as f64)
        }
    }
}

/// `np.percentile(x, p, method="linear")`.
///
/// ```
/// let p = a2perf_metrics::numeric::percentile(&[4.0, 1.0, 3.0, 2.0], 50.0);
/// assert_eq!(p, 2.5);
/// ```
pub fn percentile(x: &[f64], p: f64) -> f64 {
    percentile_sorted(&sorted(x), p)
}

/// `scipy.stats.scoreatpercentile(x, per)` (interpolation `fraction`) of **sorted** data.
pub fn score_at_percentile_sorted(sorted: &[f64], per: f64) -> f64 {
    let n = sorted.len();
    if n == 0 {
        return f64::NAN;
    }
    let idx = per / 100.0 * (n - 1) as f64;
    let i = idx.trunc();
    if i == idx {
        return sorted[(i as usize).min(n - 1)];
    }
    let iu = i as usize;
    let j = i + 1.0;
    let (w0, w1) = (j - idx, idx - i);
    (sorted[iu] * w0 + sorted[(iu + 1).min(n - 1)] * w1) / (w0 + w1)
}

/// `np.quantile(x, q, method="linear")` reordering `x` in place (O(n) selection, no full sort).
pub fn quantile_select(x: &mut [f64], q: f64) -> f64 {
    let n = x.len();
    if n == 0 {
        return f64::NAN;
    }
    let virtual_index = (n - 1) as f64 * q;
    if virtual_index >= (n - 1) as f64 {
        return x.iter().copied().fold(f64::NEG_INFINITY, |a, b| {
            if b.total_cmp(&a).is_gt() { b } else { a }
        });
    }
    if virtual_index <= 0.0 {
        return x.iter().copied().fold(
            f64::INFINITY,
            |a, b| {
                if b.total_cmp(&a).is_lt() { b } else { a }
            },
        );
    }
    let prev = virtual_index.floor();
    let i = prev as usize;
    let (_, lo, rest) = x.select_nth_unstable_by(i, f64::total_cmp);
    let lo = *lo;
    let hi = rest.iter().copied().fold(
        f64::INFINITY,
        |a, b| if b.total_cmp(&a).is_lt() { b } else { a },
    );
    np_lerp(lo, hi, virtual_index - prev)
}

/// `np.median` (NaN for an empty slice).
///
/// ```
/// assert_eq!(a2perf_metrics::numeric::median(&[3.0, 1.0, 2.0, 10.0]), 2.5);
/// ```
pub fn median(x: &[f64]) -> f64 {
    median_sorted(&sorted(x))
}

/// `np.median` reordering `x` in place (O(n) selection).
pub fn median_select(x: &mut [f64]) -> f64 {
    let n = x.len();
    if n == 0 {
        return f64::NAN;
    }
    let (lower, mid, _) = x.select_nth_unstable_by(n / 2, f64::total_cmp);
    let mid = *mid;
    if n % 2 == 1 {
        mid
    } else {
        let below = lower.iter().copied().fold(f64::NEG_INFINITY, |a, b| {
            if b.total_cmp(&a).is_gt() { b } else { a }
        });
        (below + mid) / 2.0
    }
}

/// `np.median` of already **sorted** data.
pub fn median_sorted(s: &[f64]) -> f64 {
    let n = s.len();
    if n == 0 {
        f64::NAN
    } else if n % 2 == 1 {
        s[n / 2]
    } else {
        (s[n / 2 - 1] + s[n / 2]) / 2.0
    }
}

/// `scipy.stats.iqr(x)`: 75th minus 25th linear percentile.
///
/// ```
/// assert_eq!(a2perf_metrics::numeric::iqr(&[1.0, 2.0, 3.0, 4.0, 5.0]), 2.0);
/// ```
pub fn iqr(x: &[f64]) -> f64 {
    let s = sorted(x);
    iqr_sorted(&s)
}

/// [`iqr`] of already **sorted** data.
pub fn iqr_sorted(s: &[f64]) -> f64 {
    percentile_sorted(s, 75.0) - percentile_sorted(s, 25.0)
}

/// Median absolute deviation `median(|x − median(x)|)`, without the 1.4826 factor (as the
/// library's `median_absolute_deviations`).
///
/// ```
/// assert_eq!(a2perf_metrics::numeric::mad(&[1.0, 2.0, 3.0, 4.0, 100.0]), 1.0);
/// ```
pub fn mad(x: &[f64]) -> f64 {
    let m = median(x);
    let dev: Vec<f64> = x.iter().map(|v| (v - m).abs()).collect();
    median(&dev)
}

/// Drawdown `cummax(y) − y` (non-negative: how far below its best so far a curve is).
///
/// ```
/// assert_eq!(a2perf_metrics::numeric::drawdown(&[1.0, 3.0, 2.0, 4.0]), vec![0.0, 0.0, 1.0, 0.0]);
/// ```
pub fn drawdown(y: &[f64]) -> Vec<f64> {
    let mut peak = f64::NEG_INFINITY;
    y.iter()
        .map(|&v| {
            if v > peak || peak.is_nan() {
                peak = v;
            }
            peak - v
        })
        .collect()
}

/// Mean of the entries selected by `keep` (NaN when none is selected).
fn masked_mean(x: &[f64], keep: impl Fn(f64) -> bool) -> f64 {
    let sel: Vec<f64> = x.iter().copied().filter(|v| keep(*v)).collect();
    mean(&sel)
}

/// The library's `compute_cvar`: VaR by `scipy.stats.scoreatpercentile`, inclusive comparison.
///
/// With `alpha = 0.05` and fewer than 21 distinct values the lower CVaR is the minimum.
///
/// ```
/// use a2perf_metrics::numeric::{cvar, Tail};
/// assert_eq!(cvar(&[3.0, 1.0, 2.0], Tail::Lower, 0.05), 1.0);
/// assert_eq!(cvar(&[3.0, 1.0, 2.0], Tail::Upper, 0.05), 3.0);
/// ```
pub fn cvar(x: &[f64], tail: Tail, alpha: f64) -> f64 {
    let s = sorted(x);
    match tail {
        Tail::Lower => {
            let var = score_at_percentile_sorted(&s, 100.0 * alpha);
            masked_mean(x, |v| v <= var)
        }
        Tail::Upper => {
            let var = score_at_percentile_sorted(&s, 100.0 * (1.0 - alpha));
            masked_mean(x, |v| v >= var)
        }
    }
}

/// A2Perf's CVaR: VaR by `np.percentile(·, 100·q, method="linear")`, inclusive comparison.
/// `q` is the quantile of the threshold (A2Perf passes 0.05 for the lower and 0.95 for the
/// upper tail).
pub fn cvar_numpy(x: &[f64], tail: Tail, q: f64) -> f64 {
    let mut scratch = x.to_vec();
    let var = quantile_select(&mut scratch, (q * 100.0) / 100.0);
    match tail {
        Tail::Lower => masked_mean(x, |v| v <= var),
        Tail::Upper => masked_mean(x, |v| v >= var),
    }
}

/// `scipy.stats.rankdata(x)` with the default `average` method for ties (ranks start at 1).
///
/// ```
/// assert_eq!(a2perf_metrics::numeric::rankdata(&[10.0, 20.0, 10.0]), vec![1.5, 3.0, 1.5]);
/// ```
pub fn rankdata(x: &[f64]) -> Vec<f64> {
    let mut idx: Vec<usize> = (0..x.len()).collect();
    idx.sort_by(|&a, &b| x[a].total_cmp(&x[b]));
    let mut ranks = vec![0.0; x.len()];
    let mut i = 0;
    while i < idx.len() {
        let mut j = i;
        while j + 1 < idx.len() && x[idx[j + 1]] == x[idx[i]] {
            j += 1;
        }
        // Ranks i+1..=j+1 share their average.
        let avg = (i + 1 + j + 1) as f64 / 2.0;
        for &k in &idx[i..=j] {
            ranks[k] = avg;
        }
        i = j + 1;
    }
    ranks
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pairwise_sum_matches_plain_sum_on_integers() {
        let x: Vec<f64> = (0..1000).map(f64::from).collect();
        assert_eq!(pairwise_sum(&x), 499_500.0);
        let y: Vec<f64> = (0..37).map(f64::from).collect();
        assert_eq!(pairwise_sum(&y), 666.0);
    }

    #[test]
    fn percentile_endpoints_and_interpolation() {
        let s = [1.0, 2.0, 4.0, 8.0];
        assert_eq!(percentile_sorted(&s, 0.0), 1.0);
        assert_eq!(percentile_sorted(&s, 100.0), 8.0);
        // (n-1)*0.5 = 1.5 → between 2 and 4.
        assert_eq!(percentile_sorted(&s, 50.0), 3.0);
        assert_eq!(score_at_percentile_sorted(&s, 50.0), 3.0);
        assert_eq!(score_at_percentile_sorted(&s, 100.0), 8.0);
    }

    #[test]
    fn selection_matches_sorting() {
        let x: Vec<f64> = (0..101)
            .map(|i| ((i * 37) % 101) as f64 * 0.5 - 7.0)
            .collect();
        let s = sorted(&x);
        for q in [0.0, 0.05, 0.25, 0.5, 0.75, 0.95, 1.0] {
            assert_eq!(quantile_select(&mut x.clone(), q), quantile_sorted(&s, q));
        }
        assert_eq!(median_select(&mut x.clone()), median_sorted(&s));
        assert_eq!(median_select(&mut x[..100].to_vec()), median(&x[..100]));
    }

    #[test]
    fn rankdata_handles_ties_and_order() {
        assert_eq!(
            rankdata(&[3.0, 1.0, 4.0, 1.0, 5.0]),
            vec![3.0, 1.5, 4.0, 1.5, 5.0]
        );
        assert_eq!(rankdata(&[2.0, 2.0, 2.0]), vec![2.0, 2.0, 2.0]);
    }

    #[test]
    fn empty_inputs_give_nan_not_panic() {
        assert!(mean(&[]).is_nan());
        assert!(median(&[]).is_nan());
        assert!(percentile(&[], 5.0).is_nan());
        assert!(cvar(&[], Tail::Lower, 0.05).is_nan());
        assert!(std(&[1.0], 1).is_nan());
    }
}
