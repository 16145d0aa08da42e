//! # a2perf-python
//!
//! The native extension `a2perf_rs._native` of the `a2perf_rs` Python package (built by maturin,
//! see `pyproject.toml`): the benchmark's environments, vector stepping over Rust threads, the
//! reliability metrics and rliable statistics, and the circuit placement cost. The Python side
//! (`python/a2perf_rs/`) turns these into Gymnasium environments and numpy/pandas functions.
//!
//! One module per area: [`env`](mod@env) (one environment), [`vec_env`] (N environments stepped in Rust
//! threads with the GIL released), [`metrics`], [`circuit`], [`harness`] (Python agents
//! benchmarked by the pipelines: `TrainingRun`, `infer`, `generalize`, `collect`, `report`) with
//! [`policy`] (Python callables as policies); [`convert`] and [`errors`] hold the conversions and
//! the exception mapping they share.
//!
//! From Python (this crate cannot run Rust doc tests: it links against the interpreter that
//! loads it, which is why `pyproject.toml` builds it and `python/tests/` tests it):
//!
//! ```python
//! import gymnasium as gym
//! import a2perf_rs  # registers the `a2perf/` ids
//!
//! env = gym.make("a2perf/QuadrupedLocomotion-DogPace-v0", episode_steps=10)
//! obs, info = env.reset(seed=0)
//! obs, reward, terminated, truncated, info = env.step(env.action_space.sample())
//! assert gym.make(env.spec).reset(seed=0)[0].tolist() == env.reset(seed=0)[0].tolist()
//! ```
//!
//! It deliberately holds no benchmark logic of its own: environments come from
//! `a2perf_pipeline::registry`, metrics from `a2perf-metrics`, costs from `a2perf-circuit`, the
//! harness from `a2perf_pipeline::external` and the pipelines.

use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList, PyTuple};

pub mod circuit;
pub mod convert;
pub mod env;
pub mod errors;
pub mod harness;
pub mod metrics;
pub mod observation;
pub mod policy;
pub mod vec_env;

/// Every registered environment as `(id, domain, summary, [(name, kind, choices, default,
/// doc), …])`.
#[pyfunction]
fn env_entries(py: Python<'_>) -> PyResult<Bound<'_, PyList>> {
    let out = PyList::empty(py);
    for e in env::registry().envs() {
        let params = PyList::empty(py);
        for p in &e.params {
            params.append(convert::param_to_py(py, p)?)?;
        }
        out.append(PyTuple::new(
            py,
            [
                e.id.clone().into_pyobject(py)?.into_any(),
                e.domain.clone().into_pyobject(py)?.into_any(),
                e.summary.clone().into_pyobject(py)?.into_any(),
                params.into_any(),
            ],
        )?)?;
    }
    Ok(out)
}

/// `a2perf bench` in this process: the report as JSON (`a2perf_rs.bench` parses it), with the
/// loop's unit-by-unit timeline (`timeline_us`) when `timeline` is true.
#[pyfunction(name = "bench")]
#[pyo3(signature = (env_id, steps, seed, params=None, timeline=false))]
fn bench_env(
    py: Python<'_>,
    env_id: &str,
    steps: u64,
    seed: u64,
    params: Option<&Bound<'_, PyDict>>,
    timeline: bool,
) -> PyResult<String> {
    let reg = env::registry();
    let values = env::env_kwargs(params)?;
    let kind_of = |key: &str| env::param_kind(env_id, key);
    let report = py.detach(|| {
        errors::guard("bench", || {
            a2perf_pipeline::bench::bench_env(reg, env_id, &values, steps, seed).map_err(
                |e| match e {
                    a2perf_pipeline::bench::BenchError::Registry(e) => {
                        errors::registry_error(e, kind_of)
                    }
                    a2perf_pipeline::bench::BenchError::Env { source, .. } => {
                        errors::env_error(source)
                    }
                    other => pyo3::exceptions::PyValueError::new_err(other.to_string()),
                },
            )
        })
    })?;
    let mut json = serde_json::to_value(&report);
    if let (Ok(serde_json::Value::Object(fields)), true) = (&mut json, timeline) {
        fields.insert("timeline_us".into(), report.timeline_us.into());
    }
    json.and_then(|j| serde_json::to_string(&j))
        .map_err(|e| pyo3::exceptions::PyRuntimeError::new_err(e.to_string()))
}

/// `a2perf verify` in this process: the checks as JSON (`a2perf_rs.verify` parses it). A bundle
/// that cannot be read at all (truncated, tampered with, unsafe) raises `ValueError`. The GIL
/// is released meanwhile.
#[pyfunction(name = "verify")]
#[pyo3(signature = (path, retrain=false))]
fn verify_bundle(py: Python<'_>, path: std::path::PathBuf, retrain: bool) -> PyResult<String> {
    use a2perf_pipeline::bundle::{Outcome, VerifyOptions, verify};
    let v = py.detach(|| {
        errors::guard("verify", || {
            verify(env::registry(), &path, &VerifyOptions { retrain })
                .map_err(|e| pyo3::exceptions::PyValueError::new_err(e.to_string()))
        })
    })?;
    let checks: Vec<serde_json::Value> = v
        .checks
        .iter()
        .map(|c| {
            let (outcome, detail) = match &c.outcome {
                Outcome::Holds(d) => ("holds", d),
                Outcome::Fails(d) => ("fails", d),
                Outcome::Skipped(d) => ("skipped", d),
            };
            serde_json::json!({"run": c.run, "what": c.what, "outcome": outcome, "detail": detail})
        })
        .collect();
    serde_json::to_string(&serde_json::json!({"holds": v.holds(), "checks": checks}))
        .map_err(|e| pyo3::exceptions::PyRuntimeError::new_err(e.to_string()))
}

/// `None` when Chromium and chromedriver are installed, else the reason they cannot be used.
#[pyfunction]
fn chromium_unavailable_reason() -> Option<String> {
    a2perf_web::chromium::chromium_available()
        .err()
        .map(|e| e.to_string())
}

#[pymodule]
fn _native(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    m.add("BackendError", m.py().get_type::<errors::BackendError>())?;
    m.add(
        "RunLockedError",
        m.py().get_type::<errors::RunLockedError>(),
    )?;
    m.add_function(wrap_pyfunction!(env_entries, m)?)?;
    m.add_function(wrap_pyfunction!(chromium_unavailable_reason, m)?)?;
    m.add_function(wrap_pyfunction!(bench_env, m)?)?;
    m.add_function(wrap_pyfunction!(verify_bundle, m)?)?;
    m.add_class::<env::PyEnv>()?;
    m.add_class::<vec_env::PyVecEnv>()?;
    metrics::register(m)?;
    circuit::register(m)?;
    harness::register(m)?;
    Ok(())
}
