//! The reliability metrics of Chan et al. (ICLR 2020) as defined by the
//! `rl-reliability-metrics` library (google-research, @50da84b).
//!
//! Conventions of the library, kept here:
//! - window sizes and eval points are in **timepoint units** (e.g. steps), not sample counts;
//!   windows are trailing and inclusive: `e − w + 1 ≤ t ≤ e`;
//! - within-run metrics detrend by `Δy/Δt` ([`Curve::slope_curve`]);
//! - across-run metrics read the curves at the eval points (exactly, or at the nearest timepoint
//!   within half a window) after an optional Butterworth low-pass over the whole curve;
//! - CVaR uses `scipy.stats.scoreatpercentile` and inclusive comparisons ([`numeric::cvar`]).
//!
//! Every metric is a [`Metric`] value: its parameters, its [`Metric::direction`] and its
//! [`Metric::dimensions`]. Curve metrics return [`MetricValues`]; rollout metrics take rollout
//! sets (one slice of returns per set) and return one value per set.

use serde::{Deserialize, Serialize};
use thiserror::Error;

use crate::curve::Curve;
use crate::filter::{self, FilterError};
use crate::numeric::{self, Direction, Tail};

/// Errors of the library metrics.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum LibraryError {
    /// No curves or rollout sets were given.
    #[error("no {0} given")]
    Empty(&'static str),
    /// A window contains no timepoint.
    #[error(
        "no timepoints in window of size {window} at eval point {eval_point} for curve {curve}"
    )]
    EmptyWindow {
        /// Curve index.
        curve: usize,
        /// Eval point.
        eval_point: f64,
        /// Window size.
        window: f64,
    },
    /// No timepoint within half a window of an eval point.
    #[error(
        "curve {curve} has no timepoint within a window of size {window} around eval point {eval_point}"
    )]
    NoNearby {
        /// Curve index.
        curve: usize,
        /// Eval point.
        eval_point: f64,
        /// Window size.
        window: f64,
    },
    /// The curves share no timepoint.
    #[error("the curves share no timepoint")]
    NoCommonTimepoints,
    /// A parameter is outside its domain.
    #[error("invalid parameter: {0}")]
    Param(String),
    /// This metric takes rollout sets, not curves (or the reverse).
    #[error("metric {0} does not apply to this kind of input")]
    WrongInput(&'static str),
    /// Filter design or application failed.
    #[error(transparent)]
    Filter(#[from] FilterError),
}

/// How values are normalised before (or after) a metric.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum Baseline {
    /// No normalisation.
    #[default]
    None,
    /// Divide by the curve range `p95(y) − y[0]` (per run; across runs by its median).
    CurveRange,
    /// Rollout metrics: divide by each set's median return.
    MedianPerf,
    /// Divide by a constant (median-performance metrics: `y / value`).
    Value(f64),
    /// Band normalisation `(y − low)/(high − low)` (median-performance metrics only).
    Band {
        /// Lower baseline.
        low: f64,
        /// Upper baseline.
        high: f64,
    },
}

/// A dispersion measure.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Dispersion {
    /// Interquartile range (`scipy.stats.iqr`).
    Iqr,
    /// Median absolute deviation (no 1.4826 factor).
    Mad,
    /// Standard deviation with ddof 1.
    Std,
}

impl Dispersion {
    /// Applies the measure to a sample.
    pub fn apply(self, x: &[f64]) -> f64 {
        match self {
            Dispersion::Iqr => numeric::iqr(x),
            Dispersion::Mad => numeric::mad(x),
            Dispersion::Std => numeric::std(x, 1),
        }
    }

    fn name(self) -> &'static str {
        match self {
            Dispersion::Iqr => "Iqr",
            Dispersion::Mad => "Mad",
            Dispersion::Std => "Stddev",
        }
    }
}

/// Where across-run metrics read the curves.
#[derive(Clone, Debug, PartialEq, Default, Serialize, Deserialize)]
pub struct AcrossRuns {
    /// Butterworth cutoff (order 8, Nyquist = 1) applied to each whole curve first.
    pub lowpass_thresh: Option<f64>,
    /// Eval points (timepoints); `None` = every timepoint common to all curves.
    pub eval_points: Option<Vec<f64>>,
    /// If set, read each curve at its timepoint nearest to the eval point, which must be closer
    /// than `window_size / 2`; otherwise read exactly at the eval point.
    pub window_size: Option<f64>,
}

/// What a CVaR is taken over.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum CvarTarget {
    /// Per run, the `Δy/Δt` differences (short-term risk).
    Diffs,
    /// Per run, the raw values over time.
    Raw,
    /// Per run, the drawdowns (long-term risk).
    Drawdown,
    /// Across runs at each eval point (risk across runs).
    Across(AcrossRuns),
}

/// One library metric with its parameters.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Metric {
    /// `IqrWithinRuns` / `MadWithinRuns` / `StddevWithinRuns`.
    DispersionWithinRuns {
        /// The measure.
        dispersion: Dispersion,
        /// Window in timepoints; `None` = the whole run.
        window_size: Option<f64>,
        /// Eval points; `None` = every valid timepoint of the differenced curve.
        eval_points: Option<Vec<f64>>,
        /// `None`, `CurveRange` or `Value`.
        baseline: Baseline,
    },
    /// `IqrAcrossRuns` / `MadAcrossRuns` / `StddevAcrossRuns`.
    DispersionAcrossRuns {
        /// The measure.
        dispersion: Dispersion,
        /// Where to read the curves.
        across: AcrossRuns,
        /// `None`, `CurveRange` (median over runs) or `Value`.
        baseline: Baseline,
    },
    /// `LowerCVaROn*` / `UpperCVaROn*`.
    Cvar {
        /// What the CVaR is over.
        target: CvarTarget,
        /// Which tail.
        tail: Tail,
        /// Tail probability (default 0.05).
        alpha: f64,
        /// `None`, `CurveRange` (per run, applied first) or `Value`.
        baseline: Baseline,
    },
    /// `MaxDrawdown`.
    MaxDrawdown {
        /// Subtracted from the values first.
        baseline: Option<f64>,
        /// Divide each curve by `|mean|` (after the baseline).
        mean_normalize: bool,
    },
    /// `HighFreqEnergyWithinRuns`: spectral energy above `thresh` over energy at positive
    /// frequencies.
    HighFreqEnergyWithinRuns {
        /// Frequency threshold (cycles per timepoint unit).
        thresh: f64,
    },
    /// `MedianPerfDuringTraining`.
    MedianPerfDuringTraining {
        /// Window in timepoints; `None` = the whole run.
        window_size: Option<f64>,
        /// Eval points; `None` = every valid common timepoint.
        eval_points: Option<Vec<f64>>,
        /// `None`, `Value(high)` (`y/high`) or `Band`.
        baseline: Baseline,
    },
    /// `IqrAcrossRollouts` / `MadAcrossRollouts` / `StddevAcrossRollouts`.
    DispersionAcrossRollouts {
        /// The measure.
        dispersion: Dispersion,
        /// `None`, `MedianPerf` or `Value`.
        baseline: Baseline,
    },
    /// `LowerCVaRAcrossRollouts` / `UpperCVaRAcrossRollouts`.
    CvarAcrossRollouts {
        /// Which tail.
        tail: Tail,
        /// Tail probability.
        alpha: f64,
        /// `None`, `MedianPerf` or `Value`.
        baseline: Baseline,
    },
    /// `MedianPerfAcrossRollouts`.
    MedianPerfAcrossRollouts {
        /// `None`, `Value(high)` or `Band`.
        baseline: Baseline,
    },
}

/// The shape of a metric's result (the library's `result_dimensions`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum Dimensions {
    /// One value per run (or rollout set).
    #[serde(rename = "ATR")]
    Atr,
    /// One value per run and eval point.
    #[serde(rename = "ATRP")]
    Atrp,
    /// One value per eval point.
    #[serde(rename = "ATP")]
    Atp,
}

/// A metric's values.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(untagged)]
pub enum MetricValues {
    /// `[run]` (ATR) or `[eval point]` (ATP).
    Flat(Vec<f64>),
    /// `[run][eval point]` (ATRP).
    PerRunPerPoint(Vec<Vec<f64>>),
}

impl MetricValues {
    /// The values as one flat vector (row-major for ATRP).
    pub fn flatten(&self) -> Vec<f64> {
        match self {
            MetricValues::Flat(v) => v.clone(),
            MetricValues::PerRunPerPoint(v) => v.iter().flatten().copied().collect(),
        }
    }
}

impl Metric {
    /// The library's default `IqrWithinRuns`.
    pub fn iqr_within_runs() -> Self {
        Metric::DispersionWithinRuns {
            dispersion: Dispersion::Iqr,
            window_size: None,
            eval_points: None,
            baseline: Baseline::None,
        }
    }

    /// The library's default `IqrAcrossRuns`.
    pub fn iqr_across_runs() -> Self {
        Metric::DispersionAcrossRuns {
            dispersion: Dispersion::Iqr,
            across: AcrossRuns::default(),
            baseline: Baseline::None,
        }
    }

    /// `LowerCVaROnDiffs(alpha=0.05)`.
    pub fn lower_cvar_on_diffs() -> Self {
        Metric::Cvar {
            target: CvarTarget::Diffs,
            tail: Tail::Lower,
            alpha: 0.05,
            baseline: Baseline::None,
        }
    }

    /// `UpperCVaROnDrawdown(alpha=0.05)`: the mean of the worst drawdowns.
    pub fn upper_cvar_on_drawdown() -> Self {
        Metric::Cvar {
            target: CvarTarget::Drawdown,
            tail: Tail::Upper,
            alpha: 0.05,
            baseline: Baseline::None,
        }
    }

    /// `LowerCVaROnAcross(alpha=0.05)` at the given eval points (e.g. the final step).
    pub fn lower_cvar_on_across(eval_points: Option<Vec<f64>>) -> Self {
        Metric::Cvar {
            target: CvarTarget::Across(AcrossRuns {
                eval_points,
                ..AcrossRuns::default()
            }),
            tail: Tail::Lower,
            alpha: 0.05,
            baseline: Baseline::None,
        }
    }

    /// The library's class name (`IqrWithinRuns`, `LowerCVaROnDiffs`, …).
    ///
    /// ```
    /// use a2perf_metrics::chan2019::Metric;
    /// assert_eq!(Metric::lower_cvar_on_diffs().class_name(), "LowerCVaROnDiffs");
    /// ```
    pub fn class_name(&self) -> String {
        let tail = |t: &Tail| match t {
            Tail::Lower => "Lower",
            Tail::Upper => "Upper",
        };
        match self {
            Metric::DispersionWithinRuns { dispersion, .. } => {
                format!("{}WithinRuns", dispersion.name())
            }
            Metric::DispersionAcrossRuns { dispersion, .. } => {
                format!("{}AcrossRuns", dispersion.name())
            }
            Metric::Cvar {
                target, tail: t, ..
            } => {
                let on = match target {
                    CvarTarget::Diffs => "Diffs",
                    CvarTarget::Raw => "Raw",
                    CvarTarget::Drawdown => "Drawdown",
                    CvarTarget::Across(_) => "Across",
                };
                format!("{}CVaROn{on}", tail(t))
            }
            Metric::MaxDrawdown { .. } => "MaxDrawdown".into(),
            Metric::HighFreqEnergyWithinRuns { .. } => "HighFreqEnergyWithinRuns".into(),
            Metric::MedianPerfDuringTraining { .. } => "MedianPerfDuringTraining".into(),
            Metric::DispersionAcrossRollouts { dispersion, .. } => {
                format!("{}AcrossRollouts", dispersion.name())
            }
            Metric::CvarAcrossRollouts { tail: t, .. } => format!("{}CVaRAcrossRollouts", tail(t)),
            Metric::MedianPerfAcrossRollouts { .. } => "MedianPerfAcrossRollouts".into(),
        }
    }

    /// Which direction is better (the library's `bigger_is_better`).
    ///
    /// Note the library's choices: every CVaR on diffs/raw/across is "bigger is better", both
    /// drawdown CVaRs are "smaller is better".
    pub fn direction(&self) -> Direction {
        let bigger = match self {
            Metric::DispersionWithinRuns { .. }
            | Metric::DispersionAcrossRuns { .. }
            | Metric::MaxDrawdown { .. }
            | Metric::HighFreqEnergyWithinRuns { .. }
            | Metric::DispersionAcrossRollouts { .. } => false,
            Metric::Cvar { target, .. } => !matches!(target, CvarTarget::Drawdown),
            Metric::MedianPerfDuringTraining { .. }
            | Metric::CvarAcrossRollouts { .. }
            | Metric::MedianPerfAcrossRollouts { .. } => true,
        };
        if bigger {
            Direction::HigherIsBetter
        } else {
            Direction::LowerIsBetter
        }
    }

    /// The result's dimensions.
    pub fn dimensions(&self) -> Dimensions {
        match self {
            Metric::DispersionWithinRuns { .. } | Metric::MedianPerfDuringTraining { .. } => {
                Dimensions::Atrp
            }
            Metric::DispersionAcrossRuns { .. } => Dimensions::Atp,
            Metric::Cvar {
                target: CvarTarget::Across(_),
                ..
            } => Dimensions::Atp,
            _ => Dimensions::Atr,
        }
    }

    /// `true` for the metrics that take rollout sets instead of curves.
    pub fn takes_rollouts(&self) -> bool {
        matches!(
            self,
            Metric::DispersionAcrossRollouts { .. }
                | Metric::CvarAcrossRollouts { .. }
                | Metric::MedianPerfAcrossRollouts { .. }
        )
    }

    /// Evaluates a curve metric on one (algorithm, task) group of runs.
    ///
    /// ```
    /// use a2perf_metrics::{chan2019::{Metric, MetricValues}, Curve};
    /// let runs = vec![
    ///     Curve::from_values(vec![0.0, 1.0, 0.5, 2.0]).unwrap(),
    ///     Curve::from_values(vec![0.0, 2.0, 1.0, 1.0]).unwrap(),
    /// ];
    /// let v = Metric::lower_cvar_on_diffs().evaluate(&runs).unwrap();
    /// assert_eq!(v, MetricValues::Flat(vec![-0.5, -1.0]));
    /// ```
    pub fn evaluate(&self, curves: &[Curve]) -> Result<MetricValues, LibraryError> {
        if curves.is_empty() {
            return Err(LibraryError::Empty("curves"));
        }
        match self {
            Metric::DispersionWithinRuns {
                dispersion,
                window_size,
                eval_points,
                baseline,
            } => dispersion_within_runs(
                curves,
                *dispersion,
                *window_size,
                eval_points.as_deref(),
                baseline,
            )
            .map(MetricValues::PerRunPerPoint),
            Metric::DispersionAcrossRuns {
                dispersion,
                across,
                baseline,
            } => dispersion_across_runs(curves, *dispersion, across, baseline)
                .map(MetricValues::Flat),
            Metric::Cvar {
                target,
                tail,
                alpha,
                baseline,
            } => cvar_metric(curves, target, *tail, *alpha, baseline).map(MetricValues::Flat),
            Metric::MaxDrawdown {
                baseline,
                mean_normalize,
            } => Ok(MetricValues::Flat(max_drawdown(
                curves,
                *baseline,
                *mean_normalize,
            ))),
            Metric::HighFreqEnergyWithinRuns { thresh } => Ok(MetricValues::Flat(
                curves
                    .iter()
                    .map(|c| high_freq_energy(c, *thresh))
                    .collect(),
            )),
            Metric::MedianPerfDuringTraining {
                window_size,
                eval_points,
                baseline,
            } => {
                median_perf_during_training(curves, *window_size, eval_points.as_deref(), baseline)
                    .map(MetricValues::PerRunPerPoint)
            }
            _ => Err(LibraryError::WrongInput("rollout metric given curves")),
        }
    }

    /// Evaluates a rollout metric on rollout sets (one slice of returns per set, e.g. per
    /// checkpoint); one value per set.
    ///
    /// ```
    /// use a2perf_metrics::chan2019::{Baseline, Dispersion, Metric};
    /// let m = Metric::DispersionAcrossRollouts { dispersion: Dispersion::Iqr, baseline: Baseline::None };
    /// assert_eq!(m.evaluate_rollouts(&[vec![1.0, 2.0, 3.0, 4.0, 5.0]]).unwrap(), vec![2.0]);
    /// ```
    pub fn evaluate_rollouts(&self, sets: &[Vec<f64>]) -> Result<Vec<f64>, LibraryError> {
        if sets.is_empty() {
            return Err(LibraryError::Empty("rollout sets"));
        }
        let medians: Vec<f64> = sets.iter().map(|s| numeric::median(s)).collect();
        match self {
            Metric::DispersionAcrossRollouts {
                dispersion,
                baseline,
            } => {
                let mut out: Vec<f64> = sets.iter().map(|s| dispersion.apply(s)).collect();
                match baseline {
                    Baseline::MedianPerf => {
                        for (o, m) in out.iter_mut().zip(&medians) {
                            *o /= m;
                        }
                    }
                    Baseline::Value(v) if *v != 0.0 => out.iter_mut().for_each(|o| *o /= v),
                    _ => {}
                }
                Ok(out)
            }
            Metric::CvarAcrossRollouts {
                tail,
                alpha,
                baseline,
            } => {
                check_alpha(*alpha)?;
                Ok(sets
                    .iter()
                    .zip(&medians)
                    .map(|(s, m)| {
                        let div = match baseline {
                            Baseline::MedianPerf => *m,
                            Baseline::Value(v) => *v,
                            _ => 1.0,
                        };
                        let scaled: Vec<f64> = s.iter().map(|v| v / div).collect();
                        numeric::cvar(&scaled, *tail, *alpha)
                    })
                    .collect())
            }
            Metric::MedianPerfAcrossRollouts { baseline } => {
                let (low, high) = band(baseline);
                Ok(sets
                    .iter()
                    .map(|s| {
                        let normed: Vec<f64> = s.iter().map(|v| (v - low) / (high - low)).collect();
                        numeric::median(&normed)
                    })
                    .collect())
            }
            _ => Err(LibraryError::WrongInput("curve metric given rollout sets")),
        }
    }
}

fn band(baseline: &Baseline) -> (f64, f64) {
    match baseline {
        Baseline::Value(high) => (0.0, *high),
        Baseline::Band { low, high } => (*low, *high),
        _ => (0.0, 1.0),
    }
}

fn check_alpha(alpha: f64) -> Result<(), LibraryError> {
    if (0.0..=1.0).contains(&alpha) {
        Ok(())
    } else {
        Err(LibraryError::Param(format!(
            "alpha {alpha} must be in [0, 1]"
        )))
    }
}

/// The library's `curve_range`: `np.percentile(y, 95) − y[0]` per curve.
///
/// ```
/// use a2perf_metrics::{chan2019::curve_range, Curve};
/// let c = Curve::from_values((0..=100).map(f64::from).collect()).unwrap();
/// assert_eq!(curve_range(&c), 95.0);
/// ```
pub fn curve_range(curve: &Curve) -> f64 {
    let y = curve.values();
    match y.first() {
        Some(first) => numeric::percentile(y, 95.0) - first,
        None => f64::NAN,
    }
}

/// `get_all_valid_eval_points`: timepoints common to all curves that are `≥ min + w − 1`.
pub fn valid_eval_points(curves: &[Curve], window_size: f64) -> Result<Vec<f64>, LibraryError> {
    let mut common: Vec<f64> = match curves.first() {
        Some(c) => c.steps().to_vec(),
        None => return Err(LibraryError::Empty("curves")),
    };
    for c in &curves[1..] {
        let s = c.steps();
        common.retain(|t| s.binary_search_by(|x| x.total_cmp(t)).is_ok());
    }
    let Some(min) = common.first().copied() else {
        return Err(LibraryError::NoCommonTimepoints);
    };
    let lo = min + window_size - 1.0;
    Ok(common.into_iter().filter(|t| *t >= lo).collect())
}

/// `apply_window_fn` on one curve: `f` of the values with `e − w + 1 ≤ t ≤ e` at each eval point.
fn apply_window(
    curve: &Curve,
    index: usize,
    eval_points: &[f64],
    window: f64,
    f: impl Fn(&[f64]) -> f64,
) -> Result<Vec<f64>, LibraryError> {
    let t = curve.steps();
    let y = curve.values();
    eval_points
        .iter()
        .map(|&e| {
            let lo = t.partition_point(|x| *x < e - window + 1.0);
            let hi = t.partition_point(|x| *x <= e);
            if hi <= lo {
                Err(LibraryError::EmptyWindow {
                    curve: index,
                    eval_point: e,
                    window,
                })
            } else {
                Ok(f(&y[lo..hi]))
            }
        })
        .collect()
}

fn whole_run_window(curves: &[Curve]) -> Result<f64, LibraryError> {
    let valid = valid_eval_points(curves, 1.0)?;
    match (valid.first(), valid.last()) {
        (Some(a), Some(b)) => Ok(b - a + 1.0),
        _ => Err(LibraryError::NoCommonTimepoints),
    }
}

/// `_DispersionWithinRuns`: per run, the dispersion of `Δy/Δt` in trailing windows; `[run][eval]`.
pub fn dispersion_within_runs(
    curves: &[Curve],
    dispersion: Dispersion,
    window_size: Option<f64>,
    eval_points: Option<&[f64]>,
    baseline: &Baseline,
) -> Result<Vec<Vec<f64>>, LibraryError> {
    curves
        .iter()
        .enumerate()
        .map(|(i, curve)| {
            let diff = curve.slope_curve();
            let one = std::slice::from_ref(&diff);
            let w = match window_size {
                Some(w) => w,
                None => whole_run_window(one)?,
            };
            let owned;
            let eps = match eval_points {
                Some(e) => e,
                None => {
                    owned = valid_eval_points(one, w)?;
                    &owned
                }
            };
            let mut out = apply_window(&diff, i, eps, w, |x| dispersion.apply(x))?;
            match baseline {
                Baseline::CurveRange => {
                    let r = curve_range(curve);
                    out.iter_mut().for_each(|v| *v /= r);
                }
                Baseline::Value(b) if *b != 0.0 => out.iter_mut().for_each(|v| *v /= b),
                _ => {}
            }
            Ok(out)
        })
        .collect()
}

/// `across_runs_preprocess`: the curves' values at the eval points, `[run][eval]`.
pub fn across_runs_values(
    curves: &[Curve],
    across: &AcrossRuns,
) -> Result<Vec<Vec<f64>>, LibraryError> {
    let owned;
    let eval_points = match &across.eval_points {
        Some(e) => e.as_slice(),
        None => {
            owned = valid_eval_points(curves, 1.0)?;
            &owned
        }
    };
    let filtered: Vec<Curve>;
    let curves = match across.lowpass_thresh {
        Some(th) if th != 0.0 => {
            let tf = filter::butter_lowpass(8, th)?;
            filtered = curves
                .iter()
                .map(|c| Ok(c.with_values(filter::lowpass_with(&tf, c.values())?)))
                .collect::<Result<_, FilterError>>()?;
            &filtered
        }
        _ => curves,
    };
    curves
        .iter()
        .enumerate()
        .map(|(i, c)| {
            let t = c.steps();
            let points: Vec<f64> = match across.window_size {
                Some(w) if w != 0.0 => eval_points
                    .iter()
                    .map(|&e| {
                        // find_nearest: first index of minimal distance.
                        let mut best = 0;
                        let mut best_d = f64::INFINITY;
                        for (k, x) in t.iter().enumerate() {
                            let d = (x - e).abs();
                            if d < best_d {
                                best_d = d;
                                best = k;
                            }
                        }
                        if t.is_empty() || best_d >= w / 2.0 {
                            Err(LibraryError::NoNearby {
                                curve: i,
                                eval_point: e,
                                window: w,
                            })
                        } else {
                            Ok(t[best])
                        }
                    })
                    .collect::<Result<_, _>>()?,
                _ => eval_points.to_vec(),
            };
            apply_window(c, i, &points, 1.0, |x| x[0])
        })
        .collect()
}

fn column(values: &[Vec<f64>], j: usize) -> Vec<f64> {
    values.iter().map(|row| row[j]).collect()
}

/// `_DispersionAcrossRuns`: the dispersion across runs at each eval point.
pub fn dispersion_across_runs(
    curves: &[Curve],
    dispersion: Dispersion,
    across: &AcrossRuns,
    baseline: &Baseline,
) -> Result<Vec<f64>, LibraryError> {
    let vals = across_runs_values(curves, across)?;
    let n_eval = vals.first().map_or(0, Vec::len);
    let mut out: Vec<f64> = (0..n_eval)
        .map(|j| dispersion.apply(&column(&vals, j)))
        .collect();
    match baseline {
        Baseline::CurveRange => {
            let ranges: Vec<f64> = curves.iter().map(curve_range).collect();
            let m = numeric::median(&ranges);
            out.iter_mut().for_each(|v| *v /= m);
        }
        Baseline::Value(b) if *b != 0.0 => out.iter_mut().for_each(|v| *v /= b),
        _ => {}
    }
    Ok(out)
}

/// `_CVaR`: per run (diffs, raw, drawdown) or per eval point (across).
pub fn cvar_metric(
    curves: &[Curve],
    target: &CvarTarget,
    tail: Tail,
    alpha: f64,
    baseline: &Baseline,
) -> Result<Vec<f64>, LibraryError> {
    check_alpha(alpha)?;
    let scaled: Vec<Curve>;
    let curves = match baseline {
        Baseline::CurveRange => {
            scaled = curves
                .iter()
                .map(|c| {
                    let r = curve_range(c);
                    c.with_values(c.values().iter().map(|v| v / r).collect())
                })
                .collect();
            &scaled
        }
        Baseline::Value(b) if *b != 0.0 => {
            scaled = curves
                .iter()
                .map(|c| c.with_values(c.values().iter().map(|v| v / b).collect()))
                .collect();
            &scaled
        }
        _ => curves,
    };
    match target {
        CvarTarget::Across(across) => {
            let vals = across_runs_values(curves, across)?;
            let n_eval = vals.first().map_or(0, Vec::len);
            Ok((0..n_eval)
                .map(|j| numeric::cvar(&column(&vals, j), tail, alpha))
                .collect())
        }
        CvarTarget::Raw => Ok(curves
            .iter()
            .map(|c| numeric::cvar(c.values(), tail, alpha))
            .collect()),
        CvarTarget::Diffs => Ok(curves
            .iter()
            .map(|c| numeric::cvar(c.slope_curve().values(), tail, alpha))
            .collect()),
        CvarTarget::Drawdown => Ok(curves
            .iter()
            .map(|c| numeric::cvar(&numeric::drawdown(c.values()), tail, alpha))
            .collect()),
    }
}

/// `MaxDrawdown`: the largest peak-to-valley drop of each curve.
pub fn max_drawdown(curves: &[Curve], baseline: Option<f64>, mean_normalize: bool) -> Vec<f64> {
    curves
        .iter()
        .map(|c| {
            let mut y: Vec<f64> = c
                .values()
                .iter()
                .map(|v| v - baseline.unwrap_or(0.0))
                .collect();
            if mean_normalize {
                let m = numeric::mean(&y).abs();
                y.iter_mut().for_each(|v| *v /= m);
            }
            numeric::drawdown(&y)
                .into_iter()
                .fold(f64::NEG_INFINITY, f64::max)
        })
        .collect()
}

/// `HighFreqEnergyWithinRuns` for one curve: `Σ|X_k|²` over frequencies `> thresh` divided by
/// `Σ|X_k|²` over positive frequencies, with `np.fft.fftfreq(n, t[1] − t[0])`.
///
/// Computed with a direct DFT (O(n²)); twiddle angles are reduced modulo `n` for accuracy.
pub fn high_freq_energy(curve: &Curve, thresh: f64) -> f64 {
    let y = curve.values();
    let n = y.len();
    if n < 2 {
        return f64::NAN;
    }
    let dt = curve.steps()[1] - curve.steps()[0];
    let (mut above, mut positive) = (0.0, 0.0);
    // fftfreq: k = 0..=(n-1)/2 are the non-negative frequencies k/(n·dt).
    for k in 1..=(n - 1) / 2 {
        let freq = k as f64 / (n as f64 * dt);
        let (mut re, mut im) = (0.0, 0.0);
        for (j, v) in y.iter().enumerate() {
            let phase = ((j * k) % n) as f64 / n as f64;
            let ang = -2.0 * std::f64::consts::PI * phase;
            re += v * ang.cos();
            im += v * ang.sin();
        }
        let p = re * re + im * im;
        positive += p;
        if freq > thresh {
            above += p;
        }
    }
    above / positive
}

/// `MedianPerfDuringTraining`: the median value in trailing windows; `[run][eval]`.
pub fn median_perf_during_training(
    curves: &[Curve],
    window_size: Option<f64>,
    eval_points: Option<&[f64]>,
    baseline: &Baseline,
) -> Result<Vec<Vec<f64>>, LibraryError> {
    let w = match window_size {
        Some(w) => w,
        None => whole_run_window(curves)?,
    };
    let owned;
    let eps = match eval_points {
        Some(e) => e,
        None => {
            owned = valid_eval_points(curves, w)?;
            &owned
        }
    };
    let (low, high) = band(baseline);
    curves
        .iter()
        .enumerate()
        .map(|(i, c)| {
            let normed = c.with_values(
                c.values()
                    .iter()
                    .map(|v| (v - low) / (high - low))
                    .collect(),
            );
            apply_window(&normed, i, eps, w, numeric::median)
        })
        .collect()
}
