//! The reliability metrics exactly as A2Perf computed its paper tables
//! (`a2perf/analysis/reliability.py`, Farama-Foundation/A2Perf @73791fd).
//!
//! These are *not* the rl-reliability-metrics library definitions (see [`crate::chan2019`]): A2Perf
//! re-implemented them with pandas, pooled over runs, with raw (not Δstep-normalised)
//! differences, centred windows and an upper-tail drawdown CVaR. Each function documents the
//! exact rule. Runs are the curves of one (domain, task, algorithm) group.

use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use thiserror::Error;

use crate::curve::Curve;
use crate::filter::{self, FilterError};
use crate::numeric::{self, Direction, Tail};

/// Lower-tail α of the CVaRs (`LEFT_TAIL_ALPHA`).
pub const LEFT_TAIL_ALPHA: f64 = 0.05;
/// Quantile of the long-term-risk threshold (`RIGHT_TAIL_ALPHA`).
pub const RIGHT_TAIL_ALPHA: f64 = 0.95;
/// Low-pass cutoff applied before the across-runs dispersion.
pub const LOWPASS_THRESH: f64 = 0.01;
/// Evaluation points per within-run window.
pub const EVAL_POINTS_PER_WINDOW: f64 = 5.0;
/// An across-run IQR needs *more than* this many runs at a step.
pub const MIN_NUM_DISPERSION_DATA_POINTS: usize = 2;

/// Errors of the A2Perf definitions.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum ReliabilityError {
    /// No runs (or no rollouts) were given.
    #[error("no {0} given")]
    Empty(&'static str),
    /// A run has too few points for the metric.
    #[error("run {run} has {points} point(s); {metric} needs at least {needed}")]
    TooShort {
        /// Index of the run.
        run: usize,
        /// Its number of points.
        points: usize,
        /// The metric.
        metric: &'static str,
        /// Points needed.
        needed: usize,
    },
    /// The median step gap truncates to zero, so no within-run eval points can be laid out.
    #[error(
        "run {run}: median step gap {median_gap} truncates to 0 (A2Perf lays out within-run eval points every int(median gap) steps)"
    )]
    StepSpacing {
        /// Index of the run.
        run: usize,
        /// The median gap between consecutive steps.
        median_gap: f64,
    },
    /// Filter design or application failed.
    #[error(transparent)]
    Filter(#[from] FilterError),
}

/// A value with a spread (mean and standard deviation over steps or windows).
///
/// `std` is NaN where the original gives NaN (e.g. pandas' std of a single value); JSON output
/// writes non-finite numbers as `null`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Spread {
    /// Mean.
    pub mean: f64,
    /// Standard deviation (see each metric for the ddof).
    pub std: f64,
}

/// The seven A2Perf reliability metrics.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum A2PerfMetric {
    /// IQR across runs of the low-passed curves.
    DispersionAcrossRuns,
    /// IQR of first differences in centred windows.
    DispersionWithinRuns,
    /// Negated lower CVaR of the pooled first differences.
    ShortTermRisk,
    /// Upper-tail mean of the pooled drawdowns.
    LongTermRisk,
    /// Lower CVaR of the final values.
    RiskAcrossRuns,
    /// IQR of the pooled rollout returns.
    DispersionAcrossRollouts,
    /// Lower CVaR of the pooled rollout returns.
    RiskAcrossRollouts,
}

impl A2PerfMetric {
    /// All seven, in the order of the paper's tables.
    pub const ALL: [A2PerfMetric; 7] = [
        A2PerfMetric::DispersionAcrossRuns,
        A2PerfMetric::DispersionWithinRuns,
        A2PerfMetric::ShortTermRisk,
        A2PerfMetric::LongTermRisk,
        A2PerfMetric::RiskAcrossRuns,
        A2PerfMetric::DispersionAcrossRollouts,
        A2PerfMetric::RiskAcrossRollouts,
    ];

    /// The snake_case name used in JSON output and in the original tables.
    pub fn name(self) -> &'static str {
        match self {
            A2PerfMetric::DispersionAcrossRuns => "dispersion_across_runs",
            A2PerfMetric::DispersionWithinRuns => "dispersion_within_runs",
            A2PerfMetric::ShortTermRisk => "short_term_risk",
            A2PerfMetric::LongTermRisk => "long_term_risk",
            A2PerfMetric::RiskAcrossRuns => "risk_across_runs",
            A2PerfMetric::DispersionAcrossRollouts => "dispersion_across_rollouts",
            A2PerfMetric::RiskAcrossRollouts => "risk_across_rollouts",
        }
    }

    /// Which direction is better (A2Perf's `OPTIMAL_METRIC_CRITERIA`).
    ///
    /// ```
    /// use a2perf_metrics::a2perf::A2PerfMetric;
    /// use a2perf_metrics::Direction;
    /// assert_eq!(A2PerfMetric::RiskAcrossRuns.direction(), Direction::HigherIsBetter);
    /// assert_eq!(A2PerfMetric::ShortTermRisk.direction(), Direction::LowerIsBetter);
    /// ```
    pub fn direction(self) -> Direction {
        match self {
            A2PerfMetric::RiskAcrossRuns | A2PerfMetric::RiskAcrossRollouts => {
                Direction::HigherIsBetter
            }
            _ => Direction::LowerIsBetter,
        }
    }
}

/// The five training-curve metrics of one (domain, task, algorithm) group.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct TrainingReliability {
    /// See [`dispersion_across_runs`] (lower is better).
    pub dispersion_across_runs: Spread,
    /// See [`dispersion_within_runs`] (lower is better).
    pub dispersion_within_runs: Spread,
    /// See [`short_term_risk`] (lower is better).
    pub short_term_risk: f64,
    /// See [`long_term_risk`] (lower is better).
    pub long_term_risk: f64,
    /// See [`risk_across_runs`] (higher is better).
    pub risk_across_runs: f64,
}

/// The two rollout metrics of one group.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct RolloutReliability {
    /// IQR of the pooled returns (lower is better).
    pub dispersion_across_rollouts: f64,
    /// Lower CVaR at α 0.05 of the pooled returns (higher is better).
    pub risk_across_rollouts: f64,
}

/// All five training metrics at once.
///
/// ```
/// use a2perf_metrics::{a2perf, Curve};
/// let runs: Vec<Curve> = (0..3)
///     .map(|j| Curve::from_values((0..40).map(|t| t as f64 * 0.1 + (t * (j + 1)) as f64 % 3.0).collect()).unwrap())
///     .collect();
/// let r = a2perf::training_reliability(&runs).unwrap();
/// assert!(r.dispersion_within_runs.mean >= 0.0);
/// ```
pub fn training_reliability(runs: &[Curve]) -> Result<TrainingReliability, ReliabilityError> {
    Ok(TrainingReliability {
        dispersion_across_runs: dispersion_across_runs(runs)?,
        dispersion_within_runs: dispersion_within_runs(runs)?,
        short_term_risk: short_term_risk(runs)?,
        long_term_risk: long_term_risk(runs)?,
        risk_across_runs: risk_across_runs(runs)?,
    })
}

/// Both rollout metrics at once.
///
/// ```
/// let r = a2perf_metrics::a2perf::rollout_reliability(&[1.0, 2.0, 3.0, 4.0, 5.0]).unwrap();
/// assert_eq!(r.dispersion_across_rollouts, 2.0);
/// assert_eq!(r.risk_across_rollouts, 1.0);
/// ```
pub fn rollout_reliability(returns: &[f64]) -> Result<RolloutReliability, ReliabilityError> {
    Ok(RolloutReliability {
        dispersion_across_rollouts: dispersion_across_rollouts(returns)?,
        risk_across_rollouts: risk_across_rollouts(returns)?,
    })
}

fn non_empty(runs: &[Curve]) -> Result<(), ReliabilityError> {
    if runs.is_empty() {
        return Err(ReliabilityError::Empty("runs"));
    }
    if let Some(run) = runs.iter().position(Curve::is_empty) {
        return Err(ReliabilityError::TooShort {
            run,
            points: 0,
            metric: "every metric",
            needed: 1,
        });
    }
    Ok(())
}

/// Dispersion across runs: low-pass each run (Butterworth order 8 at 0.01, `filtfilt`), then at
/// each step shared by **at least 3** runs take the IQR across them; IQRs of exactly 0 are
/// dropped (the original's `if result:`). Reports the mean and the pandas std (ddof 1) over
/// steps; both are NaN when no step qualifies.
///
/// The 0.01 filter is ill-conditioned (see [`crate::filter`]); the filter replicates the
/// reference's LAPACK operation order, so results match the original's golden values exactly.
pub fn dispersion_across_runs(runs: &[Curve]) -> Result<Spread, ReliabilityError> {
    non_empty(runs)?;
    let tf = filter::butter_lowpass(8, LOWPASS_THRESH)?;
    let smooth: Vec<Result<Vec<f64>, FilterError>> = runs
        .par_iter()
        .map(|r| filter::lowpass_with(&tf, r.values()))
        .collect();
    let smooth: Vec<Vec<f64>> = smooth.into_iter().collect::<Result<_, _>>()?;
    let mut iqrs = Vec::new();
    let mut group = Vec::with_capacity(runs.len());
    let push_group = |group: &mut Vec<f64>, iqrs: &mut Vec<f64>| {
        if group.len() > MIN_NUM_DISPERSION_DATA_POINTS {
            group.sort_unstable_by(f64::total_cmp);
            let v = numeric::iqr_sorted(group);
            if v != 0.0 {
                iqrs.push(v);
            }
        }
    };
    let first = runs[0].steps();
    if runs.iter().all(|r| r.steps() == first) {
        // Common case: every run was evaluated at the same steps.
        for i in 0..first.len() {
            group.clear();
            group.extend(smooth.iter().map(|s| s[i]));
            push_group(&mut group, &mut iqrs);
        }
    } else {
        let mut points: Vec<(f64, f64)> = runs
            .iter()
            .zip(&smooth)
            .flat_map(|(r, s)| r.steps().iter().copied().zip(s.iter().copied()))
            .collect();
        // Stable sort keeps run order within a step, like pandas' groupby.
        points.sort_by(|a, b| a.0.total_cmp(&b.0));
        let mut i = 0;
        while i < points.len() {
            let step = points[i].0;
            group.clear();
            while i < points.len() && points[i].0 == step {
                group.push(points[i].1);
                i += 1;
            }
            push_group(&mut group, &mut iqrs);
        }
    }
    Ok(Spread {
        mean: numeric::mean(&iqrs),
        std: numeric::std(&iqrs, 1),
    })
}

/// Dispersion within runs. Per run: `g = median(Δstep)`, window `w = int(5·g)`, eval points
/// `ceil(w/2), ceil(w/2)+int(g), … < max(step)`. Each window holds the raw first differences
/// (`Value.diff()`, not divided by Δstep) whose step lies in `[ceil(e − w/2), floor(e + w/2)]`;
/// windows with fewer than 2 differences are skipped. Reports mean and `np.std` (ddof 0) of the
/// window IQRs pooled over all runs.
pub fn dispersion_within_runs(runs: &[Curve]) -> Result<Spread, ReliabilityError> {
    non_empty(runs)?;
    // Runs are independent; collecting in order keeps the pooled order (and the sums) fixed.
    let per_run: Vec<Result<Vec<f64>, ReliabilityError>> = runs
        .par_iter()
        .enumerate()
        .map(|(r, run)| within_run_iqrs(r, run))
        .collect();
    // Sequential collection reports the first failing run, whatever the thread timing.
    let per_run: Vec<Vec<f64>> = per_run.into_iter().collect::<Result<_, _>>()?;
    let all: Vec<f64> = per_run.into_iter().flatten().collect();
    Ok(Spread {
        mean: numeric::mean(&all),
        std: numeric::std(&all, 0),
    })
}

fn within_run_iqrs(r: usize, run: &Curve) -> Result<Vec<f64>, ReliabilityError> {
    let mut all = Vec::new();
    let mut window_vals: Vec<f64> = Vec::with_capacity(16);
    if run.len() < 2 {
        return Err(ReliabilityError::TooShort {
            run: r,
            points: run.len(),
            metric: "dispersion_within_runs",
            needed: 2,
        });
    }
    let steps = run.steps();
    let mut gaps: Vec<f64> = steps.windows(2).map(|w| w[1] - w[0]).collect();
    let median_gap = numeric::median_select(&mut gaps);
    let window = (EVAL_POINTS_PER_WINDOW * median_gap).trunc();
    let stride = median_gap.trunc();
    if stride < 1.0 {
        return Err(ReliabilityError::StepSpacing { run: r, median_gap });
    }
    let diffs = run.raw_diffs();
    let diff_steps = &steps[1..];
    let max_step = steps[steps.len() - 1];
    let mut e = (window / 2.0).ceil();
    // Windows slide forward, so both bounds only ever advance.
    let (mut lo, mut hi) = (0usize, 0usize);
    while e < max_step {
        let low = (e - window / 2.0).ceil();
        let high = (e + window / 2.0).floor();
        while lo < diff_steps.len() && diff_steps[lo] < low {
            lo += 1;
        }
        hi = hi.max(lo);
        while hi < diff_steps.len() && diff_steps[hi] <= high {
            hi += 1;
        }
        if hi >= lo + 2 {
            window_vals.clear();
            window_vals.extend_from_slice(&diffs[lo..hi]);
            insertion_sort(&mut window_vals);
            all.push(numeric::iqr_sorted(&window_vals));
        }
        e += stride;
    }
    Ok(all)
}

/// Windows hold a handful of values; insertion sort beats the general sort there.
fn insertion_sort(v: &mut [f64]) {
    for i in 1..v.len() {
        let x = v[i];
        let mut j = i;
        while j > 0 && v[j - 1].total_cmp(&x).is_gt() {
            v[j] = v[j - 1];
            j -= 1;
        }
        v[j] = x;
    }
}

/// Short-term risk: the raw first differences of all runs pooled; `VaR = np.percentile(·, 5)`;
/// the result is `−mean(diffs ≤ VaR)`, so a larger positive number means bigger drops.
pub fn short_term_risk(runs: &[Curve]) -> Result<f64, ReliabilityError> {
    non_empty(runs)?;
    let diffs: Vec<f64> = runs.iter().flat_map(|r| r.raw_diffs()).collect();
    if diffs.is_empty() {
        return Err(ReliabilityError::TooShort {
            run: 0,
            points: 1,
            metric: "short_term_risk",
            needed: 2,
        });
    }
    Ok(-numeric::cvar_numpy(&diffs, Tail::Lower, LEFT_TAIL_ALPHA))
}

/// Long-term risk: the drawdowns (`cummax − value`) of all runs pooled; the mean of those at or
/// above their 95th percentile.
pub fn long_term_risk(runs: &[Curve]) -> Result<f64, ReliabilityError> {
    non_empty(runs)?;
    let dd: Vec<f64> = runs
        .iter()
        .flat_map(|r| numeric::drawdown(r.values()))
        .collect();
    Ok(numeric::cvar_numpy(&dd, Tail::Upper, RIGHT_TAIL_ALPHA))
}

/// Risk across runs: the lower CVaR at α 0.05 of the runs' final values (`np.percentile` linear,
/// inclusive). With fewer than 21 runs this is the smallest final value.
pub fn risk_across_runs(runs: &[Curve]) -> Result<f64, ReliabilityError> {
    non_empty(runs)?;
    let finals: Vec<f64> = runs.iter().filter_map(Curve::last_value).collect();
    Ok(numeric::cvar_numpy(&finals, Tail::Lower, LEFT_TAIL_ALPHA))
}

/// Dispersion across rollouts: `scipy.stats.iqr` of the pooled returns.
pub fn dispersion_across_rollouts(returns: &[f64]) -> Result<f64, ReliabilityError> {
    if returns.is_empty() {
        return Err(ReliabilityError::Empty("rollout returns"));
    }
    Ok(numeric::iqr(returns))
}

/// Risk across rollouts: lower CVaR at α 0.05 of the pooled returns.
pub fn risk_across_rollouts(returns: &[f64]) -> Result<f64, ReliabilityError> {
    if returns.is_empty() {
        return Err(ReliabilityError::Empty("rollout returns"));
    }
    Ok(numeric::cvar_numpy(returns, Tail::Lower, LEFT_TAIL_ALPHA))
}
