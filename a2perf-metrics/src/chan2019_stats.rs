//! Statistics on library metric results (`rl_reliability_metrics/analysis/stats.py`).
//!
//! Results are ranked per task over all (algorithm, run) entries, rank 1 = best, ties averaged.
//! Algorithms are compared by the difference of their mean ranks with a two-sided permutation
//! test, mean ranks get bootstrap confidence intervals, and p-value thresholds are corrected for
//! the `C(n, 2)` pairwise comparisons (Benjamini–Yekutieli or Bonferroni).
//!
//! Randomness comes from [`RngStream`] instead of NumPy's global legacy generator, so p-values and
//! intervals agree with the original statistically, not digit for digit.
//!
//! Data layout: `results[algorithm][task][run]` (the library's `ATR`); per-eval-point results
//! (`ATRP`) are first collapsed to their median over a timeframe with [`collapse_timeframe`].
//! Across-run metrics (`ATP`) need the metric re-evaluated on permuted or resampled *curves*
//! ([`permutation_test_across_runs`], [`bootstrap_mean_rank_ci_across_runs`]); the original
//! precomputes those evaluations to disk, we evaluate them in place.

use std::ops::Range;

use a2perf_core::RngStream;
use thiserror::Error;

use crate::chan2019::{LibraryError, Metric};
use crate::curve::Curve;
use crate::numeric::{self, Direction};

/// Errors of the statistics.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum StatsError {
    /// Shapes do not line up.
    #[error("shape mismatch: {0}")]
    Shape(String),
    /// A parameter is outside its domain.
    #[error("invalid parameter: {0}")]
    Param(String),
    /// Evaluating the metric failed.
    #[error(transparent)]
    Metric(#[from] LibraryError),
}

/// `[algorithm][task][run]` metric values or ranks.
pub type Atr = Vec<Vec<Vec<f64>>>;

fn check_shape(results: &Atr) -> Result<(usize, usize), StatsError> {
    let n_tasks = results.first().map_or(0, Vec::len);
    if results.is_empty() || n_tasks == 0 {
        return Err(StatsError::Shape("no algorithms or no tasks".into()));
    }
    for (a, algo) in results.iter().enumerate() {
        if algo.len() != n_tasks {
            return Err(StatsError::Shape(format!(
                "algorithm {a} has {} tasks, expected {n_tasks}",
                algo.len()
            )));
        }
    }
    Ok((results.len(), n_tasks))
}

/// `StatsRunner.rank_per_task`: per task, `rankdata` over every (algorithm, run) entry; flipped
/// (`n + 1 − rank`) when bigger is better, so 1 is always best.
///
/// ```
/// use a2perf_metrics::{chan2019_stats::rank_per_task, Direction};
/// let r = rank_per_task(&vec![vec![vec![1.0, 3.0]], vec![vec![2.0, 2.0]]], Direction::HigherIsBetter).unwrap();
/// assert_eq!(r, vec![vec![vec![4.0, 1.0]], vec![vec![2.5, 2.5]]]);
/// ```
pub fn rank_per_task(results: &Atr, direction: Direction) -> Result<Atr, StatsError> {
    let (_, n_tasks) = check_shape(results)?;
    let mut ranks: Atr = results
        .iter()
        .map(|a| a.iter().map(|t| vec![0.0; t.len()]).collect())
        .collect();
    for task in 0..n_tasks {
        let flat: Vec<f64> = results
            .iter()
            .flat_map(|a| a[task].iter().copied())
            .collect();
        let n = flat.len() as f64;
        let mut r = numeric::rankdata(&flat).into_iter();
        for algo in ranks.iter_mut() {
            for slot in algo[task].iter_mut() {
                let v = r.next().unwrap_or(f64::NAN);
                *slot = if direction.bigger_is_better() {
                    n + 1.0 - v
                } else {
                    v
                };
            }
        }
    }
    Ok(ranks)
}

fn mean_rank(task_runs: &[Vec<f64>]) -> f64 {
    let flat: Vec<f64> = task_runs.iter().flatten().copied().collect();
    numeric::mean(&flat)
}

/// Result of a permutation test between two algorithms.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PermutationTest {
    /// Mean rank of the second algorithm minus that of the first.
    pub observed_diff: f64,
    /// Two-sided p-value `mean(|null| ≥ |observed|)`.
    pub p_value: f64,
}

/// `StatsRunner.compare_algorithms` for ATR results: rank everything, then build the null
/// distribution by permuting the pooled ranks of the two algorithms within each task.
///
/// ```
/// use a2perf_core::RngStream;
/// use a2perf_metrics::{chan2019_stats::permutation_test, Direction};
/// let results = vec![vec![vec![1.0, 2.0, 3.0]], vec![vec![4.0, 5.0, 6.0]]];
/// let t = permutation_test(&results, 0, 1, Direction::HigherIsBetter, 500, &mut RngStream::new(0, "doc")).unwrap();
/// assert_eq!(t.observed_diff, -3.0);
/// assert!(t.p_value > 0.0 && t.p_value < 0.3);
/// ```
pub fn permutation_test(
    results: &Atr,
    algo1: usize,
    algo2: usize,
    direction: Direction,
    n_permutations: usize,
    rng: &mut RngStream,
) -> Result<PermutationTest, StatsError> {
    let ranks = rank_per_task(results, direction)?;
    let (r1, r2) = match (ranks.get(algo1), ranks.get(algo2)) {
        (Some(a), Some(b)) => (a, b),
        _ => return Err(StatsError::Param("algorithm index out of range".into())),
    };
    if n_permutations == 0 {
        return Err(StatsError::Param("n_permutations must be positive".into()));
    }
    let observed = mean_rank(r2) - mean_rank(r1);
    let mut pooled: Vec<Vec<f64>> = r1
        .iter()
        .zip(r2)
        .map(|(a, b)| a.iter().chain(b).copied().collect())
        .collect();
    let mut extreme = 0usize;
    for _ in 0..n_permutations {
        let (mut s1, mut n1, mut s2, mut n2) = (0.0, 0usize, 0.0, 0usize);
        for (task, pool) in pooled.iter_mut().enumerate() {
            rng.shuffle(pool);
            let k = r1[task].len();
            s1 += pool[..k].iter().sum::<f64>();
            n1 += k;
            s2 += pool[k..].iter().sum::<f64>();
            n2 += pool.len() - k;
        }
        let diff = s2 / n2 as f64 - s1 / n1 as f64;
        // Tolerance for the summation order of equal mean ranks (observed vs permuted).
        if diff.abs() >= observed.abs() - 1e-12 {
            extreme += 1;
        }
    }
    Ok(PermutationTest {
        observed_diff: observed,
        p_value: extreme as f64 / n_permutations as f64,
    })
}

/// `StatsRunner.bootstrap_confidence_interval` for ATR results: resample the runs of `algo`
/// with replacement within each task (others fixed), re-rank, take its mean rank; the interval is
/// the `[α/2, 1 − α/2]` linear percentiles of that distribution.
pub fn bootstrap_mean_rank_ci(
    results: &Atr,
    algo: usize,
    direction: Direction,
    n_bootstrap: usize,
    alpha: f64,
    rng: &mut RngStream,
) -> Result<(f64, f64), StatsError> {
    check_shape(results)?;
    if algo >= results.len() {
        return Err(StatsError::Param("algorithm index out of range".into()));
    }
    if n_bootstrap == 0 || !(alpha > 0.0 && alpha < 1.0) {
        return Err(StatsError::Param(
            "n_bootstrap must be positive and alpha in (0, 1)".into(),
        ));
    }
    let mut resampled = results.clone();
    let mut dist = Vec::with_capacity(n_bootstrap);
    for _ in 0..n_bootstrap {
        for (task, runs) in results[algo].iter().enumerate() {
            for slot in resampled[algo][task].iter_mut() {
                *slot = runs[rng.index(runs.len())];
            }
        }
        let ranks = rank_per_task(&resampled, direction)?;
        dist.push(mean_rank(&ranks[algo]));
    }
    let s = numeric::sorted(&dist);
    Ok((
        numeric::percentile_sorted(&s, 100.0 * alpha / 2.0),
        numeric::percentile_sorted(&s, 100.0 * (1.0 - alpha / 2.0)),
    ))
}

/// How to correct for multiple comparisons.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Correction {
    /// Benjamini–Yekutieli: one threshold per comparison rank.
    BenjaminiYekutieli,
    /// Bonferroni: one threshold `α / m`.
    Bonferroni,
}

/// `multiple_comparisons_correction`: with `m = C(n_algorithms, 2)`, Benjamini–Yekutieli gives
/// `[α/m] + [i·α/(m·c_i) for i = 2..m]` with `c_i = Σ_{k≤i} 1/k` (the i-th threshold applies to
/// the pair with the i-th largest p-value, as the original documents); Bonferroni gives `[α/m]`.
///
/// ```
/// use a2perf_metrics::chan2019_stats::{multiple_comparisons_correction, Correction};
/// let t = multiple_comparisons_correction(4, 0.05, Correction::Bonferroni);
/// assert_eq!(t, vec![0.05 / 6.0]);
/// ```
pub fn multiple_comparisons_correction(
    n_algorithms: usize,
    alpha: f64,
    method: Correction,
) -> Vec<f64> {
    let m = n_algorithms * n_algorithms.saturating_sub(1) / 2;
    if m == 0 {
        return Vec::new();
    }
    let mf = m as f64;
    match method {
        Correction::Bonferroni => vec![alpha / mf],
        Correction::BenjaminiYekutieli => {
            let mut c = 1.0;
            let mut out = vec![1.0 / mf * alpha];
            for i in 2..=m {
                c += 1.0 / i as f64;
                out.push(i as f64 / (mf * c) * alpha);
            }
            out
        }
    }
}

/// `get_timeframe_points`: indices of the eval points in `timeframe` of `n_timeframes` equal
/// spans. As in the original, span starts are `k·len` **not offset by the first eval point**;
/// the last timeframe runs to the end.
///
/// ```
/// use a2perf_metrics::chan2019_stats::timeframe_points;
/// let eps: Vec<f64> = (0..10).map(f64::from).collect();
/// assert_eq!(timeframe_points(&eps, 3, 0).unwrap(), 0..3);
/// assert_eq!(timeframe_points(&eps, 3, 2).unwrap(), 6..10);
/// ```
pub fn timeframe_points(
    eval_points: &[f64],
    n_timeframes: usize,
    timeframe: usize,
) -> Result<Range<usize>, StatsError> {
    let (Some(first), Some(last)) = (eval_points.first(), eval_points.last()) else {
        return Err(StatsError::Param("no eval points".into()));
    };
    if timeframe >= n_timeframes {
        return Err(StatsError::Param(format!(
            "timeframe {timeframe} out of {n_timeframes}"
        )));
    }
    let len = (last - first) / n_timeframes as f64;
    let start = if timeframe == 0 {
        0
    } else {
        let t = timeframe as f64 * len;
        eval_points
            .iter()
            .position(|e| *e >= t)
            .ok_or_else(|| StatsError::Param("empty timeframe".into()))?
    };
    let end = if timeframe == n_timeframes - 1 {
        eval_points.len()
    } else {
        let t = (timeframe + 1) as f64 * len;
        eval_points
            .iter()
            .rposition(|e| *e < t)
            .ok_or_else(|| StatsError::Param("empty timeframe".into()))?
            + 1
    };
    Ok(start..end)
}

/// Collapses `[run][eval]` results to one value per run: the median over the eval points in
/// `points` (the original's `collapse_on_timepoints`).
pub fn collapse_timeframe(per_run_per_point: &[Vec<f64>], points: Range<usize>) -> Vec<f64> {
    per_run_per_point
        .iter()
        .map(|row| numeric::median(row.get(points.clone()).unwrap_or(&[])))
        .collect()
}

/// `[algorithm][task][run]` curves.
pub type CurvesAtr = Vec<Vec<Vec<Curve>>>;

/// An across-run (ATP) metric collapsed to one value: the median over the eval points in
/// `points` (all of them when `None`).
fn atp_value(
    metric: &Metric,
    curves: &[Curve],
    points: &Option<Range<usize>>,
) -> Result<f64, StatsError> {
    let v = metric.evaluate(curves)?.flatten();
    let sel = match points {
        Some(r) => v.get(r.clone()).unwrap_or(&[]).to_vec(),
        None => v,
    };
    Ok(numeric::median(&sel))
}

fn atp_values(
    metric: &Metric,
    curves: &CurvesAtr,
    points: &Option<Range<usize>>,
) -> Result<Atr, StatsError> {
    curves
        .iter()
        .map(|algo| {
            algo.iter()
                .map(|task| Ok(vec![atp_value(metric, task, points)?]))
                .collect()
        })
        .collect()
}

fn check_curves(curves: &CurvesAtr, algos: &[usize]) -> Result<(), StatsError> {
    let n_tasks = curves.first().map_or(0, Vec::len);
    if curves.is_empty() || n_tasks == 0 || curves.iter().any(|a| a.len() != n_tasks) {
        return Err(StatsError::Shape(
            "curves must be [algorithm][task][run] with the same tasks for every algorithm".into(),
        ));
    }
    if algos.iter().any(|a| *a >= curves.len()) {
        return Err(StatsError::Param("algorithm index out of range".into()));
    }
    Ok(())
}

/// Permutation test for an across-run metric: within each task the runs of the two algorithms
/// are pooled, shuffled and split again, the metric is re-evaluated on both halves (median over
/// `points` of its eval points), everything is re-ranked and the mean-rank difference recorded.
///
/// ```
/// use a2perf_core::RngStream;
/// use a2perf_metrics::{chan2019::Metric, chan2019_stats::permutation_test_across_runs, Curve};
/// let algo = |shift: f64| vec![(0..4).map(|r| Curve::from_values(vec![0.0, shift + r as f64]).unwrap()).collect::<Vec<_>>()];
/// let curves = vec![algo(0.0), algo(10.0)];
/// let m = Metric::lower_cvar_on_across(Some(vec![1.0]));
/// let t = permutation_test_across_runs(&curves, &m, 0, 1, None, 50, &mut RngStream::new(0, "doc")).unwrap();
/// assert_eq!(t.observed_diff, -1.0);
/// ```
pub fn permutation_test_across_runs(
    curves: &CurvesAtr,
    metric: &Metric,
    algo1: usize,
    algo2: usize,
    points: Option<Range<usize>>,
    n_permutations: usize,
    rng: &mut RngStream,
) -> Result<PermutationTest, StatsError> {
    check_curves(curves, &[algo1, algo2])?;
    if n_permutations == 0 {
        return Err(StatsError::Param("n_permutations must be positive".into()));
    }
    let direction = metric.direction();
    let mut values = atp_values(metric, curves, &points)?;
    let ranks = rank_per_task(&values, direction)?;
    let observed = mean_rank(&ranks[algo2]) - mean_rank(&ranks[algo1]);
    let mut extreme = 0usize;
    for _ in 0..n_permutations {
        for task in 0..curves[algo1].len() {
            let mut pool: Vec<Curve> = curves[algo1][task]
                .iter()
                .chain(&curves[algo2][task])
                .cloned()
                .collect();
            rng.shuffle(&mut pool);
            let k = curves[algo1][task].len();
            values[algo1][task] = vec![atp_value(metric, &pool[..k], &points)?];
            values[algo2][task] = vec![atp_value(metric, &pool[k..], &points)?];
        }
        let r = rank_per_task(&values, direction)?;
        let diff = mean_rank(&r[algo2]) - mean_rank(&r[algo1]);
        if diff.abs() >= observed.abs() - 1e-12 {
            extreme += 1;
        }
    }
    Ok(PermutationTest {
        observed_diff: observed,
        p_value: extreme as f64 / n_permutations as f64,
    })
}

/// Bootstrap interval on the mean rank of `algo` for an across-run metric: its runs are
/// resampled with replacement within each task and the metric re-evaluated; other algorithms
/// stay fixed.
pub fn bootstrap_mean_rank_ci_across_runs(
    curves: &CurvesAtr,
    metric: &Metric,
    algo: usize,
    points: Option<Range<usize>>,
    n_bootstrap: usize,
    alpha: f64,
    rng: &mut RngStream,
) -> Result<(f64, f64), StatsError> {
    check_curves(curves, &[algo])?;
    if n_bootstrap == 0 || !(alpha > 0.0 && alpha < 1.0) {
        return Err(StatsError::Param(
            "n_bootstrap must be positive and alpha in (0, 1)".into(),
        ));
    }
    let direction = metric.direction();
    let mut values = atp_values(metric, curves, &points)?;
    let mut dist = Vec::with_capacity(n_bootstrap);
    for _ in 0..n_bootstrap {
        for (task, runs) in curves[algo].iter().enumerate() {
            let sample: Vec<Curve> = (0..runs.len())
                .map(|_| runs[rng.index(runs.len())].clone())
                .collect();
            values[algo][task] = vec![atp_value(metric, &sample, &points)?];
        }
        let r = rank_per_task(&values, direction)?;
        dist.push(mean_rank(&r[algo]));
    }
    let s = numeric::sorted(&dist);
    Ok((
        numeric::percentile_sorted(&s, 100.0 * alpha / 2.0),
        numeric::percentile_sorted(&s, 100.0 * (1.0 - alpha / 2.0)),
    ))
}
