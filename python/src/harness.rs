//! The harness for Python agents (the engine of `a2perf_rs.TrainingRun`, `infer`, `generalize`,
//! `collect` and `report`): thin bindings over `a2perf_pipeline::external` and the pipelines'
//! `*_with` forms, with Python callables as [`PolicySource`](a2perf_pipeline::PolicySource)s.
//! Results come back as the JSON the pipelines write (the Python side decodes it).

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::{Mutex, MutexGuard};

use a2perf_core::Value;
use a2perf_pipeline::external::{ExternalOutcome, ExternalRun, ExternalRunSpec, external_plan};
use a2perf_pipeline::{
    ExperimentPlan, ExternalAgent, InferOptions, LoadedRun, ObservationSource, PipelineError,
    collect::{CollectOptions, CostRule},
    meters::system_meters,
    report::ReportOptions,
};
use pyo3::exceptions::{PyFileNotFoundError, PyRuntimeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::PyDict;

use crate::convert::{from_value, to_value};
use crate::env::registry;
use crate::errors::guard;
use crate::policy::{CallablePolicies, LoaderPolicies, pipeline_error};

fn plain(e: PipelineError) -> PyErr {
    pipeline_error(e, None)
}

fn to_json<T: serde::Serialize>(value: &T) -> PyResult<String> {
    serde_json::to_string(value).map_err(|e| PyRuntimeError::new_err(e.to_string()))
}

fn values(what: &str, d: Option<&Bound<'_, PyDict>>) -> PyResult<BTreeMap<String, Value>> {
    let mut out = BTreeMap::new();
    if let Some(d) = d {
        for (k, v) in d.iter() {
            let key: String = k.extract().map_err(|_| {
                pyo3::exceptions::PyTypeError::new_err(format!("{what}: keys must be strings"))
            })?;
            let value = to_value(&format!("{what}[{key:?}]"), &v)?;
            out.insert(key, value);
        }
    }
    Ok(out)
}

/// A run directory given to `infer`/`generalize`: `FileNotFoundError` when it does not exist,
/// `ValueError` when it is not a run directory or was not trained by an external agent.
fn external_run(dir: &Path, what: &str) -> PyResult<LoadedRun> {
    if !dir.exists() {
        return Err(PyFileNotFoundError::new_err(format!(
            "{}: no such run directory",
            dir.display()
        )));
    }
    let run = LoadedRun::open(dir).map_err(plain)?;
    run.require_external(what).map_err(plain)?;
    run.require_complete().map_err(plain)?;
    Ok(run)
}

enum Stage {
    Planned,
    Running(Box<ExternalRun>),
    Finished(String),
}

/// A Python agent's training run: `a2perf_rs._native.TrainingRun(out_dir, algorithm, …)`.
#[pyclass(module = "a2perf_rs._native", name = "TrainingRun")]
pub struct PyTrainingRun {
    plan: ExperimentPlan,
    seed: u64,
    stage: Mutex<Stage>,
}

impl PyTrainingRun {
    fn stage(&self) -> PyResult<MutexGuard<'_, Stage>> {
        self.stage.try_lock().map_err(|_| {
            PyRuntimeError::new_err(
                "the training run is busy (called from inside run.evaluate's policy, or from \
                 another thread)",
            )
        })
    }

    fn running<T>(&self, f: impl FnOnce(&mut ExternalRun) -> PyResult<T>) -> PyResult<T> {
        let mut stage = self.stage()?;
        match &mut *stage {
            Stage::Running(run) => f(run),
            Stage::Planned => Err(PyRuntimeError::new_err(
                "the training run has not started: use it as a context manager (`with \
                 a2perf_rs.TrainingRun(...) as run:`)",
            )),
            Stage::Finished(state) => Err(PyRuntimeError::new_err(format!(
                "the training run is over (marked {state}); start a new TrainingRun"
            ))),
        }
    }
}

#[pymethods]
impl PyTrainingRun {
    /// Plans the run (nothing is written until `begin`).
    #[new]
    #[pyo3(signature = (out_dir, algorithm, env_id=None, seed=0, hyperparameters=None, env_params=None, experiment=None, config=None, set=Vec::new()))]
    #[allow(clippy::too_many_arguments)]
    fn new(
        out_dir: PathBuf,
        algorithm: &str,
        env_id: Option<String>,
        seed: u64,
        hyperparameters: Option<&Bound<'_, PyDict>>,
        env_params: Option<&Bound<'_, PyDict>>,
        experiment: Option<String>,
        config: Option<PathBuf>,
        set: Vec<String>,
    ) -> PyResult<Self> {
        let spec = ExternalRunSpec {
            experiment,
            config,
            set,
            env_id,
            env_params: values("env_params", env_params)?,
            hyperparameters: values("hyperparameters", hyperparameters)?,
            ..ExternalRunSpec::new(out_dir, algorithm, seed)
        };
        let plan = guard("planning the run", || {
            external_plan(registry(), &spec).map_err(plain)
        })?;
        Ok(Self {
            plan,
            seed,
            stage: Mutex::new(Stage::Planned),
        })
    }

    /// Creates the run directory and starts the meters; returns warnings for the user.
    /// `harness`: what drives the run, as `run.json` records it (default: `TrainingRun`).
    #[pyo3(signature = (runtime, harness=None))]
    fn begin(&self, runtime: String, harness: Option<String>) -> PyResult<Vec<String>> {
        let mut stage = self.stage()?;
        if !matches!(*stage, Stage::Planned) {
            return Err(PyRuntimeError::new_err(
                "the training run was already started; start a new TrainingRun",
            ));
        }
        let agent = ExternalAgent {
            harness: harness
                .unwrap_or_else(|| format!("a2perf_rs {} TrainingRun", env!("CARGO_PKG_VERSION"))),
            runtime,
        };
        let run = guard("starting the run", || {
            ExternalRun::begin(
                registry(),
                self.plan.clone(),
                self.seed,
                agent,
                &system_meters(),
            )
            .map_err(plain)
        })?;
        let warnings = run.warnings().to_vec();
        *stage = Stage::Running(Box::new(run));
        Ok(warnings)
    }

    /// Closes the run: `outcome` is `completed`, `failed` or `interrupted` (with `note`).
    fn finish(&self, outcome: &str, note: &str) -> PyResult<String> {
        let mut stage = self.stage()?;
        let outcome = match outcome {
            "completed" => ExternalOutcome::Completed,
            "failed" => ExternalOutcome::Failed(note.into()),
            "interrupted" => ExternalOutcome::Interrupted(note.into()),
            other => {
                return Err(PyValueError::new_err(format!(
                    "outcome `{other}`: expected completed, failed or interrupted"
                )));
            }
        };
        let run = match std::mem::replace(&mut *stage, Stage::Finished("failed".into())) {
            Stage::Running(run) => run,
            other => {
                *stage = other;
                return Err(PyRuntimeError::new_err("the training run is not running"));
            }
        };
        let state = guard("finishing the run", || run.finish(outcome).map_err(plain))?;
        let name = format!("{state:?}").to_lowercase();
        *stage = Stage::Finished(name.clone());
        Ok(name)
    }

    /// Records an evaluation point (see `a2perf_pipeline::external::ExternalRun::log_evaluation`).
    fn log_evaluation(&self, env_steps: u64, mean_return: f64, std_return: f64) -> PyResult<()> {
        self.running(|run| {
            run.log_evaluation(env_steps, mean_return, std_return)
                .map_err(plain)
        })
    }

    /// Evaluates `policy` with the built-in protocol and records the point; `(mean, std)`.
    fn evaluate(
        &self,
        py: Python<'_>,
        env_steps: u64,
        policy: Py<PyAny>,
        with_info: bool,
    ) -> PyResult<(f64, f64)> {
        self.running(|run| {
            let source = CallablePolicies::new(py, policy, with_info);
            let env = run.make_env().map_err(plain)?;
            let spec = env.spec().clone();
            drop(env);
            let mut p = source.for_spec(py, &spec)?;
            run.evaluate(env_steps, &mut p)
                .map_err(|e| pipeline_error(e, Some(&source.errors)))
        })
    }

    /// Copies the agent's checkpoint file into `checkpoints/`; returns the stored path.
    fn save_checkpoint(&self, env_steps: u64, path: PathBuf) -> PyResult<PathBuf> {
        self.running(|run| run.save_checkpoint(env_steps, &path).map_err(plain))
    }

    /// The number of evaluation points logged so far.
    fn evaluations(&self) -> PyResult<usize> {
        self.running(|run| Ok(run.curve().points.len()))
    }

    /// Seconds since the run began.
    fn clock(&self) -> PyResult<f64> {
        self.running(|run| Ok(run.clock()))
    }

    /// The run directory (`out_dir/<experiment>/<task>__<algorithm>__seed<k>`).
    #[getter]
    fn run_dir(&self) -> PathBuf {
        self.plan.run_dir(self.seed)
    }

    /// The run's seed.
    #[getter]
    fn seed(&self) -> u64 {
        self.seed
    }

    /// The environment id.
    #[getter]
    fn env_id(&self) -> String {
        self.plan.task.env_id.clone()
    }

    /// The task's name (the report's table).
    #[getter]
    fn task(&self) -> String {
        self.plan.task.name.clone()
    }

    /// Every environment parameter in force.
    #[getter]
    fn env_params<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let d = PyDict::new(py);
        for (k, v) in &self.plan.task.env_params {
            d.set_item(k, from_value(py, v)?)?;
        }
        Ok(d)
    }

    /// The training settings (`total_env_steps`, `eval_interval`, `eval_episodes`,
    /// `checkpoint_interval`, `num_envs`).
    #[getter]
    fn training<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let t = &self.plan.training;
        let d = PyDict::new(py);
        d.set_item("total_env_steps", t.total_env_steps)?;
        d.set_item("eval_interval", t.eval_interval)?;
        d.set_item("eval_episodes", t.eval_episodes)?;
        d.set_item("checkpoint_interval", t.checkpoint_interval)?;
        d.set_item("num_envs", t.num_envs)?;
        Ok(d)
    }
}

/// At least one directory, each of them existing.
fn existing_dirs(dirs: &[PathBuf]) -> PyResult<()> {
    if dirs.is_empty() {
        return Err(PyValueError::new_err("no directories given"));
    }
    for d in dirs {
        if !d.exists() {
            return Err(PyFileNotFoundError::new_err(format!(
                "{}: no such directory",
                d.display()
            )));
        }
    }
    Ok(())
}

fn observation_source(s: Option<&str>) -> PyResult<Option<ObservationSource>> {
    match s {
        None => Ok(None),
        Some("rollouts") => Ok(Some(ObservationSource::Rollouts)),
        Some("random") => Ok(Some(ObservationSource::Random)),
        Some(other) => Err(PyValueError::new_err(format!(
            "observation_source `{other}`: expected `rollouts` or `random`"
        ))),
    }
}

/// `inference.json` of an external run, its final policy being `policy`.
#[pyfunction]
#[pyo3(signature = (run_dir, policy, with_info, episodes=None, observation_source=None, timing_samples=None))]
fn infer(
    py: Python<'_>,
    run_dir: PathBuf,
    policy: Py<PyAny>,
    with_info: bool,
    episodes: Option<usize>,
    observation_source: Option<&str>,
    timing_samples: Option<usize>,
) -> PyResult<String> {
    external_run(&run_dir, "infer")?;
    let opts = InferOptions {
        episodes,
        observation_source: self::observation_source(observation_source)?,
        timing_samples,
        meters: system_meters(),
        show_progress: false,
    };
    let mut source = CallablePolicies::new(py, policy, with_info);
    let results = guard("infer", || {
        a2perf_pipeline::infer_run_with(registry(), &run_dir, &mut source, &opts)
            .map_err(|e| pipeline_error(e, Some(&source.errors)))
    })?;
    to_json(&results)
}

/// `generalization.json` of an external run, its final policy being `policy`.
#[pyfunction]
#[pyo3(signature = (run_dir, policy, with_info, episodes=None))]
fn generalize(
    py: Python<'_>,
    run_dir: PathBuf,
    policy: Py<PyAny>,
    with_info: bool,
    episodes: Option<usize>,
) -> PyResult<String> {
    external_run(&run_dir, "generalize")?;
    let mut source = CallablePolicies::new(py, policy, with_info);
    let results = guard("generalize", || {
        a2perf_pipeline::generalize_run_with(registry(), &run_dir, &mut source, episodes, false)
            .map_err(|e| pipeline_error(e, Some(&source.errors)))
    })?;
    to_json(&results)
}

/// `a2perf collect` over `dirs`, external runs' checkpoints loaded by `loader`; the datasets go
/// to `out` (default: `datasets/` beside the first run, as the CLI's).
#[pyfunction]
#[pyo3(signature = (dirs, loader, out=None, eval_episodes=100, dataset_episodes=100, cost="measured", one_sigma=false))]
fn collect(
    dirs: Vec<PathBuf>,
    loader: Py<PyAny>,
    out: Option<PathBuf>,
    eval_episodes: usize,
    dataset_episodes: usize,
    cost: &str,
    one_sigma: bool,
) -> PyResult<String> {
    let cost = match cost {
        "measured" => CostRule::Measured,
        "pro_rata" | "pro-rata" => CostRule::ProRata,
        other => {
            return Err(PyValueError::new_err(format!(
                "cost `{other}`: expected `measured` or `pro_rata`"
            )));
        }
    };
    existing_dirs(&dirs)?;
    let runs = a2perf_pipeline::expand_runs(&dirs).map_err(plain)?;
    let out = out.unwrap_or_else(|| {
        runs[0]
            .parent()
            .map_or_else(|| PathBuf::from("datasets"), |p| p.join("datasets"))
    });
    let opts = CollectOptions {
        eval_episodes,
        dataset_episodes,
        cost,
        one_sigma,
        show_progress: false,
        cancel: Default::default(),
    };
    let mut source = LoaderPolicies::new(loader, registry());
    let summary = guard("collect", || {
        a2perf_pipeline::collect::collect_with(registry(), &runs, &out, &mut source, &opts)
            .map_err(|e| pipeline_error(e, Some(&source.errors)))
    })?;
    to_json(&serde_json::json!({
        "datasets": summary.datasets,
        "evaluations": summary.evaluations,
        "empty_levels": summary
            .empty_levels
            .iter()
            .map(|(task, level)| serde_json::json!({"task": task, "level": level}))
            .collect::<Vec<_>>(),
    }))
}

/// `a2perf report DIRS -o OUT [--paper TABLES]`; returns `report.json`.
#[pyfunction]
#[pyo3(signature = (dirs, out, bootstrap_reps=None, paper=None))]
fn report(
    dirs: Vec<PathBuf>,
    out: PathBuf,
    bootstrap_reps: Option<usize>,
    paper: Option<PathBuf>,
) -> PyResult<String> {
    existing_dirs(&dirs)?;
    let report = guard("report", || {
        // Read before anything is written, so a bad file leaves an earlier report untouched.
        let tables = paper
            .as_deref()
            .map(a2perf_pipeline::report::paper::PaperTables::load)
            .transpose()
            .map_err(plain)?;
        let opts = ReportOptions {
            bootstrap_reps: match bootstrap_reps {
                Some(r) => r,
                None => a2perf_pipeline::run::recorded_bootstrap_reps(&dirs).map_err(plain)?,
            },
            seed: 0,
        };
        a2perf_pipeline::report::write_report_with_paper(&dirs, &out, &opts, tables.as_ref())
            .map_err(plain)
    })?;
    to_json(&report)
}

/// The reset seed of episode `episode` of environment `index` in a run with `seed` (as the
/// built-in algorithms' training environments draw them).
#[pyfunction]
fn episode_seed(seed: u64, index: usize, episode: u64) -> u64 {
    a2perf_pipeline::external::episode_seed(seed, index, episode)
}

/// Adds the harness to the native module.
pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PyTrainingRun>()?;
    m.add_class::<crate::policy::SubmissionPolicy>()?;
    m.add_function(wrap_pyfunction!(infer, m)?)?;
    m.add_function(wrap_pyfunction!(generalize, m)?)?;
    m.add_function(wrap_pyfunction!(collect, m)?)?;
    m.add_function(wrap_pyfunction!(report, m)?)?;
    m.add_function(wrap_pyfunction!(episode_seed, m)?)?;
    Ok(())
}
