//! Reliability metrics and rliable statistics on numpy arrays (the engine of
//! `a2perf_rs.metrics`, which also accepts pandas DataFrames with the CLI's CSV columns).
//!
//! Tables arrive as records (`run, step, value` and `algorithm, task, run, score`) and are grouped
//! by `a2perf_metrics::csv`, so a DataFrame is read by the same rules as the CLI reads a CSV file.

use std::path::Path;

use a2perf_metrics::chan2019::{Metric, MetricValues};
use a2perf_metrics::csv::{self, NamedCurves};
use a2perf_metrics::rliable::{
    self, Aggregate, Aggregates, BootstrapConfig, IntervalEstimate, Profile, Scores,
};
use a2perf_metrics::{Curve, a2perf as a2};
use numpy::{PyArray1, PyArray2, PyReadonlyArray1, PyReadonlyArray2};
use pyo3::exceptions::{PyTypeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::PyList;

use crate::errors::guard;

fn value_error(e: impl std::fmt::Display) -> PyErr {
    PyValueError::new_err(e.to_string())
}

/// Curves from long-format records; `source` names the table in messages (rows are numbered
/// from 0).
fn curves(
    source: &str,
    runs: &[String],
    steps: &PyReadonlyArray1<'_, f64>,
    values: &PyReadonlyArray1<'_, f64>,
) -> PyResult<NamedCurves> {
    let (steps, values) = (steps.as_array(), values.as_array());
    if runs.len() != steps.len() || runs.len() != values.len() {
        return Err(PyValueError::new_err(format!(
            "{source}: {} run ids, {} steps and {} values",
            runs.len(),
            steps.len(),
            values.len()
        )));
    }
    let records = runs
        .iter()
        .zip(steps.iter().zip(values.iter()))
        .enumerate()
        .map(|(i, (r, (s, v)))| (i, r.as_str(), *s, *v));
    csv::curves_from_records(Path::new(source), records).map_err(value_error)
}

fn rollouts(source: &str, r: &PyReadonlyArray1<'_, f64>) -> PyResult<Vec<f64>> {
    let v: Vec<f64> = r.as_array().to_vec();
    if v.is_empty() {
        return Err(PyValueError::new_err(format!("{source}: no returns")));
    }
    if let Some(i) = v.iter().position(|x| !x.is_finite()) {
        return Err(PyValueError::new_err(format!(
            "{source}: return {i} is {}; returns must be finite",
            v[i]
        )));
    }
    Ok(v)
}

fn scores(source: &str, a: &PyReadonlyArray2<'_, f64>) -> PyResult<Scores> {
    let view = a.as_array();
    let rows: Vec<Vec<f64>> = view.rows().into_iter().map(|r| r.to_vec()).collect();
    if let Some((r, t)) = view
        .indexed_iter()
        .find(|(_, v)| !v.is_finite())
        .map(|(ix, _)| ix)
    {
        return Err(PyValueError::new_err(format!(
            "{source}: score of run {r}, task {t} is not finite"
        )));
    }
    Scores::from_rows(&rows).map_err(|e| PyValueError::new_err(format!("{source}: {e}")))
}

/// A2Perf's seven reliability metrics: a JSON object with the CLI's keys
/// (`a2perf metrics reliability --json`).
#[pyfunction]
#[pyo3(signature = (runs, steps, values, rollouts=None))]
fn a2perf_reliability(
    py: Python<'_>,
    runs: Vec<String>,
    steps: PyReadonlyArray1<'_, f64>,
    values: PyReadonlyArray1<'_, f64>,
    rollouts: Option<PyReadonlyArray1<'_, f64>>,
) -> PyResult<String> {
    let named = curves("curves", &runs, &steps, &values)?;
    let returns = rollouts
        .as_ref()
        .map(|r| self::rollouts("rollouts", r))
        .transpose()?;
    let list: Vec<Curve> = named.curves();
    py.detach(|| {
        guard("the reliability metrics", || {
            let t = a2::training_reliability(&list).map_err(|e| match &e {
                a2::ReliabilityError::TooShort { run, .. }
                | a2::ReliabilityError::StepSpacing { run, .. } => {
                    let id = named.runs.get(*run).map_or("?", |(id, _)| id.as_str());
                    PyValueError::new_err(format!("curves: run `{id}`: {e}"))
                }
                _ => value_error(format!("curves: {e}")),
            })?;
            let mut out = serde_json::to_value(t).map_err(value_error)?;
            if let (Some(r), Some(obj)) = (returns, out.as_object_mut()) {
                let r = a2::rollout_reliability(&r)
                    .map_err(|e| value_error(format!("rollouts: {e}")))?;
                let extra = serde_json::to_value(r).map_err(value_error)?;
                if let Some(e) = extra.as_object() {
                    obj.extend(e.clone());
                }
            }
            serde_json::to_string(&out).map_err(value_error)
        })
    })
}

/// One rl-reliability-metrics metric, given as the JSON of `chan2019::Metric`; returns
/// `(class name, values (flat), shape, bigger_is_better, dimensions)`.
#[pyfunction]
#[pyo3(signature = (metric_json, runs=None, steps=None, values=None, rollout_sets=None))]
#[allow(clippy::type_complexity)]
fn chan2019_evaluate<'py>(
    py: Python<'py>,
    metric_json: &str,
    runs: Option<Vec<String>>,
    steps: Option<PyReadonlyArray1<'_, f64>>,
    values: Option<PyReadonlyArray1<'_, f64>>,
    rollout_sets: Option<Vec<PyReadonlyArray1<'_, f64>>>,
) -> PyResult<(String, Bound<'py, PyArray1<f64>>, Vec<usize>, bool, String)> {
    let metric: Metric = serde_json::from_str(metric_json)
        .map_err(|e| PyValueError::new_err(format!("invalid metric specification: {e}")))?;
    let name = metric.class_name();
    let (flat, shape) = if metric.takes_rollouts() {
        let sets = rollout_sets
            .ok_or_else(|| PyTypeError::new_err(format!("{name} takes rollouts, not curves")))?;
        let sets: Vec<Vec<f64>> = sets
            .iter()
            .enumerate()
            .map(|(i, s)| rollouts(&format!("rollout set {i}"), s))
            .collect::<PyResult<_>>()?;
        let v = py.detach(|| {
            guard(&name, || {
                metric
                    .evaluate_rollouts(&sets)
                    .map_err(|e| value_error(format!("{name}: {e}")))
            })
        })?;
        let n = v.len();
        (v, vec![n])
    } else {
        let (Some(runs), Some(steps), Some(values)) = (runs, steps, values) else {
            return Err(PyTypeError::new_err(format!(
                "{name} takes curves, not rollouts"
            )));
        };
        let named = curves("curves", &runs, &steps, &values)?;
        let list = named.curves();
        let v = py.detach(|| {
            guard(&name, || {
                metric
                    .evaluate(&list)
                    .map_err(|e| value_error(format!("{name}: {e}")))
            })
        })?;
        match v {
            MetricValues::Flat(v) => {
                let n = v.len();
                (v, vec![n])
            }
            MetricValues::PerRunPerPoint(rows) => {
                let cols = rows.first().map_or(0, Vec::len);
                let shape = vec![rows.len(), cols];
                (rows.into_iter().flatten().collect(), shape)
            }
        }
    };
    let dims = serde_json::to_value(metric.dimensions())
        .ok()
        .and_then(|v| v.as_str().map(str::to_string))
        .unwrap_or_default();
    Ok((
        name,
        PyArray1::from_vec(py, flat),
        shape,
        metric.direction().bigger_is_better(),
        dims,
    ))
}

/// The curves' run ids, in order of first appearance, and their sorted steps and values, as the
/// CLI would group a `run,step,value` file (for checks and for pandas users).
#[pyfunction]
fn group_curves<'py>(
    py: Python<'py>,
    runs: Vec<String>,
    steps: PyReadonlyArray1<'_, f64>,
    values: PyReadonlyArray1<'_, f64>,
) -> PyResult<Bound<'py, PyList>> {
    let named = curves("curves", &runs, &steps, &values)?;
    let out = PyList::empty(py);
    for (id, c) in &named.runs {
        out.append((
            id,
            PyArray1::from_slice(py, c.steps()),
            PyArray1::from_slice(py, c.values()),
        ))?;
    }
    Ok(out)
}

/// Scores per algorithm from long-format records (`algorithm, task, run, score`), grouped as the
/// CLI groups `scores.csv`: `(tasks, [(algorithm, runs × tasks array), …])`.
#[pyfunction]
#[allow(clippy::type_complexity)]
fn group_scores<'py>(
    py: Python<'py>,
    algorithms: Vec<String>,
    tasks: Vec<String>,
    runs: Vec<String>,
    scores: PyReadonlyArray1<'_, f64>,
) -> PyResult<(Vec<String>, Vec<(String, Bound<'py, PyArray2<f64>>)>)> {
    let s = scores.as_array();
    let n = algorithms.len();
    if tasks.len() != n || runs.len() != n || s.len() != n {
        return Err(PyValueError::new_err(format!(
            "scores: {} algorithms, {} tasks, {} runs and {} scores",
            n,
            tasks.len(),
            runs.len(),
            s.len()
        )));
    }
    let records = (0..n).map(|i| {
        (
            i,
            algorithms[i].as_str(),
            tasks[i].as_str(),
            runs[i].as_str(),
            s[i],
        )
    });
    let named = csv::scores_from_records(Path::new("scores"), records).map_err(value_error)?;
    let mut out = Vec::with_capacity(named.algorithms.len());
    for (algo, sc) in named.algorithms {
        let rows: Vec<Vec<f64>> = (0..sc.runs())
            .map(|r| (0..sc.tasks()).map(|t| sc.get(r, t)).collect())
            .collect();
        let arr = PyArray2::from_vec2(py, &rows).map_err(value_error)?;
        out.push((algo, arr));
    }
    Ok((named.tasks, out))
}

fn config(reps: usize, seed: u64, confidence: f64, task_bootstrap: bool) -> BootstrapConfig {
    BootstrapConfig {
        reps,
        confidence,
        task_bootstrap,
        seed,
    }
}

type Interval<'py> = (
    Bound<'py, PyArray1<f64>>,
    Bound<'py, PyArray1<f64>>,
    Bound<'py, PyArray1<f64>>,
);

fn interval<'py>(py: Python<'py>, e: IntervalEstimate) -> Interval<'py> {
    (
        PyArray1::from_vec(py, e.point),
        PyArray1::from_vec(py, e.lower),
        PyArray1::from_vec(py, e.upper),
    )
}

fn aggregate(name: &str, gamma: f64) -> PyResult<Aggregate> {
    match name {
        "iqm" => Ok(Aggregate::Iqm),
        "mean" => Ok(Aggregate::Mean),
        "median" => Ok(Aggregate::Median),
        "optimality_gap" => Ok(Aggregate::OptimalityGap(gamma)),
        other => {
            let hint =
                a2perf_core::did_you_mean(other, ["iqm", "mean", "median", "optimality_gap"])
                    .map(|h| format!(" (did you mean `{h}`?)"))
                    .unwrap_or_default();
            Err(PyValueError::new_err(format!(
                "unknown aggregate `{other}`{hint}: use iqm, mean, median or optimality_gap"
            )))
        }
    }
}

/// Point values of aggregates (`iqm`, `mean`, `median`, `optimality_gap`) of a runs × tasks
/// array.
#[pyfunction]
#[pyo3(signature = (scores, aggregates, gamma=1.0))]
fn aggregates(
    scores: PyReadonlyArray2<'_, f64>,
    aggregates: Vec<String>,
    gamma: f64,
) -> PyResult<Vec<f64>> {
    let s = self::scores("scores", &scores)?;
    aggregates
        .iter()
        .map(|a| Ok(aggregate(a, gamma)?.compute(&s)))
        .collect()
}

/// Stratified-bootstrap intervals of aggregates: `(point, lower, upper)`.
#[pyfunction]
#[pyo3(signature = (scores, aggregates, gamma=1.0, reps=50_000, seed=0, confidence=0.95, task_bootstrap=false))]
#[allow(clippy::too_many_arguments)]
fn aggregate_ci<'py>(
    py: Python<'py>,
    scores: PyReadonlyArray2<'_, f64>,
    aggregates: Vec<String>,
    gamma: f64,
    reps: usize,
    seed: u64,
    confidence: f64,
    task_bootstrap: bool,
) -> PyResult<Interval<'py>> {
    let s = self::scores("scores", &scores)?;
    let stat = Aggregates(
        aggregates
            .iter()
            .map(|a| aggregate(a, gamma))
            .collect::<PyResult<_>>()?,
    );
    let cfg = config(reps, seed, confidence, task_bootstrap);
    let e = py.detach(|| {
        guard("bootstrap", || {
            rliable::bootstrap_ci(&s, &stat, &cfg).map_err(value_error)
        })
    })?;
    Ok(interval(py, e))
}

/// P(X > Y) averaged over tasks, with an independent stratified-bootstrap interval when
/// `reps > 0`: `(point, lower, upper)` (lower = upper = NaN without bootstrap).
#[pyfunction]
#[pyo3(signature = (x, y, reps=2000, seed=0, confidence=0.95))]
fn probability_of_improvement<'py>(
    py: Python<'py>,
    x: PyReadonlyArray2<'_, f64>,
    y: PyReadonlyArray2<'_, f64>,
    reps: usize,
    seed: u64,
    confidence: f64,
) -> PyResult<(f64, f64, f64)> {
    let (x, y) = (scores("x", &x)?, scores("y", &y)?);
    if reps == 0 {
        let p = rliable::probability_of_improvement(&x, &y).map_err(value_error)?;
        return Ok((p, f64::NAN, f64::NAN));
    }
    let cfg = config(reps, seed, confidence, false);
    let e = py.detach(|| {
        guard("bootstrap", || {
            rliable::probability_of_improvement_ci(&x, &y, &cfg).map_err(value_error)
        })
    })?;
    Ok((e.point[0], e.lower[0], e.upper[0]))
}

/// Performance profile at `taus` (fraction of run scores above τ, or of task means with
/// `over_runs=False`), with bootstrap intervals when `reps > 0`.
#[pyfunction]
#[pyo3(signature = (scores, taus, over_runs=true, reps=2000, seed=0, confidence=0.95))]
fn performance_profile<'py>(
    py: Python<'py>,
    scores: PyReadonlyArray2<'_, f64>,
    taus: Vec<f64>,
    over_runs: bool,
    reps: usize,
    seed: u64,
    confidence: f64,
) -> PyResult<Interval<'py>> {
    let s = self::scores("scores", &scores)?;
    if taus.iter().any(|t| t.is_nan()) {
        return Err(PyValueError::new_err("taus must not be NaN"));
    }
    let profile = Profile { taus, over_runs };
    if reps == 0 {
        let mut out = vec![0.0; profile.taus.len()];
        rliable::Statistic::eval(&profile, &s, &mut Vec::new(), &mut out);
        let nan = vec![f64::NAN; out.len()];
        return Ok(interval(
            py,
            IntervalEstimate {
                point: out,
                lower: nan.clone(),
                upper: nan,
            },
        ));
    }
    let cfg = config(reps, seed, confidence, false);
    let e = py.detach(|| {
        guard("bootstrap", || {
            rliable::bootstrap_ci(&s, &profile, &cfg).map_err(value_error)
        })
    })?;
    Ok(interval(py, e))
}

/// Adds the metric functions to the module.
pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    let py = m.py();
    let sub = PyModule::new(py, "metrics")?;
    sub.add_function(wrap_pyfunction!(a2perf_reliability, &sub)?)?;
    sub.add_function(wrap_pyfunction!(chan2019_evaluate, &sub)?)?;
    sub.add_function(wrap_pyfunction!(group_curves, &sub)?)?;
    sub.add_function(wrap_pyfunction!(group_scores, &sub)?)?;
    sub.add_function(wrap_pyfunction!(aggregates, &sub)?)?;
    sub.add_function(wrap_pyfunction!(aggregate_ci, &sub)?)?;
    sub.add_function(wrap_pyfunction!(probability_of_improvement, &sub)?)?;
    sub.add_function(wrap_pyfunction!(performance_profile, &sub)?)?;
    m.add_submodule(&sub)?;
    Ok(())
}
