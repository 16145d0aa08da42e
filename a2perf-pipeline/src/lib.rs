//! # a2perf-pipeline
//!
//! The benchmark pipelines as a library: plan, train, infer, generalize, collect and report,
//! plus the registry of every built-in environment and algorithm. The `a2perf` command
//! (`a2perf-cli`) and the Python package (`python/`) are two front ends over it; a participant's
//! own binary or test can call it with its own [`Registry`]:
//!
//! - [`train()`]: one run per (task, algorithm, seed), resumable, shardable;
//! - [`infer_run`]: rollouts and per-call inference time of a trained policy;
//! - [`generalize_run`]: returns on every task of the domain's generalization suite;
//! - [`collect`]: checkpoint evaluation, expertise levels and offline datasets;
//! - [`report`]: the paper's four-category tables, plots and a leaderboard entry;
//! - [`run_experiments`]: all of the above in order, skipping what is already on disk;
//! - [`external`]: runs trained outside the benchmark's algorithms (a Python agent), recorded
//!   like built-in ones and rolled out through a [`PolicySource`].
//!
//! ```
//! use a2perf_pipeline::Shard;
//! let shard: Shard = "1/4".parse().unwrap();
//! assert!(shard.contains(5) && !shard.contains(4));
//! ```
//!
//! It deliberately does not schedule work across machines: a shard (`--shard i/N`) lets an
//! existing batch system (Slurm job arrays, Kubernetes indexed jobs) spread a sweep, and
//! [`report`] merges the result directories. It prints nothing but progress bars (when asked):
//! messages are the front ends' business.
//!
//! Every pipeline works on plain directories. An experiment directory
//! `OUTPUT/EXPERIMENT_NAME/` holds one run directory per (task, algorithm, seed), named
//! `<task>__<algorithm>__seed<k>`, with these files (all written atomically):
//!
//! | file | written by | contents |
//! |---|---|---|
//! | `status.json` | train | `running`, `interrupted`, `failed` or `complete` (reruns skip complete runs and continue the others) |
//! | `run.json` | train | [`RunRecord`]: task, resolved parameters, seed, settings |
//! | `operative_config.ron` | train | every config value in force (when a config file was used) |
//! | `system_info.json` | train | [`SystemInfo`] of the machine |
//! | `curve.csv`, `curve.json` | train | evaluation return against environment steps |
//! | `train_system.json` | train | system meters over the whole training (all segments) |
//! | `train_segments.json` | train | each training segment (process): start step, outcome, meters, resume points written |
//! | `checkpoints/step_*.ckpt` | train | checkpoints at the configured interval |
//! | `resume/step_*.resume` | train | the newest two resume points, while the run is unfinished |
//! | `policy.ckpt` | train | the final policy |
//! | `inference.json` | infer | rollout returns, per-call inference time, meters |
//! | `generalization.json` | generalize | per-task mean returns and their sum |
//! | `collect/` | collect | checkpoint evaluations, expertise levels, datasets |
//! | `train.lock` | train | the training lock ([`run_lock`]): the pid and host of the process training the run, empty when none does |

#![warn(missing_docs)]

// The README's Rust example runs as a doc test of this crate (the one that depends on every
// domain), so the front page cannot drift from the API.
#[cfg(doctest)]
#[doc = include_str!("../../README.md")]
struct ReadmeExamples;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

pub use a2perf_core::CancelToken;
use a2perf_core::{
    Checkpoint, Env, EnvSpec, Policy, Registry, RegistryError, RunError, TrainingSettings,
    results::ResultsError,
};
use serde::{Deserialize, Serialize};

pub mod arrow;
pub mod bench;
pub mod bundle;
pub mod collect;
pub mod external;
pub mod generalize;
pub mod infer;
pub mod isolate;
pub mod meters;
pub mod minari;
pub mod plan;
pub mod progress;
pub mod registry;
pub mod report;
pub mod run;
pub mod run_lock;
pub mod stats;
pub mod sysinfo;
pub mod train;

pub use generalize::{GeneralizationResults, generalize_run, generalize_run_with};
pub use infer::{InferOptions, InferenceResults, infer_run, infer_run_with};
pub use plan::{
    AlgorithmSpec, ExperimentPlan, GeneralizationSettings, GeneralizationSuite, GeneralizationTask,
    InferenceSettings, LoadedPlans, MetricSettings, ObservationSource, ProfileRecord,
    ProfileSwitch, RunJob, Shard, Suite, SuiteSource, TaskSpec, check_dir_name, from_experiment,
    grid, load_plans, parse_seeds,
};
pub use run::{RunEvent, RunOptions, expand_runs, run_experiments};
pub use sysinfo::SystemInfo;
pub use train::{
    MeterFactory, RunOutcome, RunReport, TrainOptions, TrainSummary, train, train_one, train_run,
};

/// `run.json`.
pub const RUN_FILE: &str = "run.json";
/// `curve.csv`.
pub const CURVE_CSV: &str = "curve.csv";
/// `curve.json`.
pub const CURVE_JSON: &str = "curve.json";
/// `train_system.json`.
pub const TRAIN_SYSTEM_FILE: &str = "train_system.json";
/// `system_info.json`.
pub const SYSTEM_INFO_FILE: &str = "system_info.json";
/// `policy.ckpt`.
pub const POLICY_FILE: &str = "policy.ckpt";
/// `checkpoints/`.
pub const CHECKPOINT_DIR: &str = "checkpoints";
/// `resume/`: resume points of an unfinished run (see [`a2perf_core::ResumeDir`]).
pub const RESUME_DIR: &str = "resume";
/// `train_segments.json`: one entry per process that trained the run.
pub const TRAIN_SEGMENTS_FILE: &str = "train_segments.json";
/// `inference.json`.
pub const INFERENCE_FILE: &str = "inference.json";
/// `generalization.json`.
pub const GENERALIZATION_FILE: &str = "generalization.json";
/// `operative_config.ron`.
pub const OPERATIVE_FILE: &str = a2perf_core::config::OPERATIVE_CONFIG_FILE;

/// Everything that can go wrong in a pipeline. Each variant names the file or run concerned.
#[derive(Debug, thiserror::Error)]
pub enum PipelineError {
    /// Reading or writing a file failed.
    #[error("{}: {source}", path.display())]
    Io {
        /// The file or directory.
        path: PathBuf,
        /// The error.
        source: std::io::Error,
    },
    /// A results file or checkpoint exists but cannot be used.
    #[error("{}: {reason}", path.display())]
    Corrupt {
        /// The file.
        path: PathBuf,
        /// Why.
        reason: String,
    },
    /// An environment or algorithm is unknown or badly parameterised.
    #[error(transparent)]
    Registry(#[from] RegistryError),
    /// Training or a rollout failed.
    #[error("{run}: {source}")]
    Run {
        /// The run directory.
        run: String,
        /// The error.
        source: RunError,
    },
    /// A rollout failed: the policy or the environment returned an error in this episode at
    /// this step (both counted from 0).
    #[error("{run}: episode {episode}, step {step} (counted from 0): {source}")]
    Rollout {
        /// The run directory (and the task, for generalization).
        run: String,
        /// Episode index.
        episode: usize,
        /// Step index within the episode (the policy call that failed, or the step after it).
        step: usize,
        /// The error.
        source: RunError,
    },
    /// A request that cannot be carried out (bad shard, no seeds, …).
    #[error("{0}")]
    Invalid(String),
    /// Cancelled (Ctrl-C); the state on disk is resumable.
    #[error("cancelled; rerun the same command to resume")]
    Cancelled,
    /// Run directories that another trainer holds (see [`run_lock`]): left alone, neither
    /// trained nor treated as complete.
    #[error("{}", .0.iter().map(ToString::to_string).collect::<Vec<_>>().join("; "))]
    Locked(Vec<run_lock::LockedRun>),
}

impl From<ResultsError> for PipelineError {
    fn from(e: ResultsError) -> Self {
        match e {
            ResultsError::Io { path, source } => PipelineError::Io { path, source },
            ResultsError::Corrupt { path, reason } => PipelineError::Corrupt { path, reason },
        }
    }
}

/// Shorthand.
pub type Result<T, E = PipelineError> = std::result::Result<T, E>;

pub(crate) fn io_err(path: &Path) -> impl FnOnce(std::io::Error) -> PipelineError + '_ {
    move |source| PipelineError::Io {
        path: path.to_path_buf(),
        source,
    }
}

/// Where an offline algorithm's training data came from, and what producing it cost.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct DatasetProvenance {
    /// Dataset directory.
    pub path: String,
    /// Dataset id.
    pub dataset_id: String,
    /// Training sample cost: energy (kWh) spent training the policies that generated the data.
    pub training_sample_cost_kwh: Option<f64>,
    /// How the cost was obtained (`measured` or `pro_rata`).
    pub cost_method: String,
}

impl DatasetProvenance {
    /// The provenance of a dataset written by `collect`, used from `path`.
    pub fn from_info(info: &collect::DatasetInfo, path: &str) -> Self {
        Self {
            path: path.into(),
            dataset_id: info.dataset_id.clone(),
            training_sample_cost_kwh: info.training_sample_cost_kwh,
            cost_method: match info.cost_rule {
                collect::CostRule::Measured => "measured".into(),
                collect::CostRule::ProRata => "pro_rata".into(),
            },
        }
    }
}

/// `run.json`: what a run is, with every parameter resolved.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RunRecord {
    /// Layout version of this file.
    pub format_version: u32,
    /// Experiment name.
    pub experiment: String,
    /// The task.
    pub task: TaskSpec,
    /// The environment's domain (`circuit_training`, `web_navigation`, …).
    pub domain: String,
    /// The algorithm, hyperparameters resolved (defaults included).
    pub algorithm: AlgorithmSpec,
    /// The seed.
    pub seed: u64,
    /// Budgets and schedules.
    pub training: TrainingSettings,
    /// Inference settings used by `infer`.
    pub inference: InferenceSettings,
    /// Generalization settings used by `generalize`.
    pub generalization: GeneralizationSettings,
    /// Meter and statistics settings.
    #[serde(default)]
    pub metrics: MetricSettings,
    /// Provenance recorded by the environment (netlist, clip, website hashes, …).
    pub env_metadata: BTreeMap<String, String>,
    /// For offline algorithms: the dataset and its sample cost.
    #[serde(default)]
    pub dataset: Option<DatasetProvenance>,
    /// For runs trained outside the benchmark's algorithms (a Python agent through
    /// `a2perf_rs.TrainingRun`, see [`external`]): who trained it. Absent for built-in runs.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub external: Option<ExternalAgent>,
}

/// An agent trained outside the benchmark's algorithms, as recorded in `run.json`: its policy
/// lives in the agent's own code and checkpoint format, so the pipelines roll it out through a
/// [`PolicySource`] its front end gives them (e.g. a Python callable), never through the
/// registry's checkpoint loaders.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ExternalAgent {
    /// The harness that recorded the run (`a2perf_rs.TrainingRun`).
    pub harness: String,
    /// The agent's language and runtime (`CPython 3.11.7`), as the front end describes it.
    pub runtime: String,
}

/// Current layout version of [`RunRecord`].
pub const RUN_FORMAT_VERSION: u32 = 1;

/// A run directory with its decoded `run.json`.
#[derive(Clone, Debug)]
pub struct LoadedRun {
    /// The directory.
    pub dir: PathBuf,
    /// Its record.
    pub record: RunRecord,
}

impl LoadedRun {
    /// Reads `dir/run.json`, with errors naming the file.
    pub fn open(dir: &Path) -> Result<Self> {
        if !dir.is_dir() {
            return Err(PipelineError::Invalid(format!(
                "{}: not a run directory (it does not exist or is not a directory)",
                dir.display()
            )));
        }
        let path = dir.join(RUN_FILE);
        if !path.is_file() {
            return Err(PipelineError::Invalid(format!(
                "{}: not a run directory (no {RUN_FILE}; run `a2perf train` first)",
                dir.display()
            )));
        }
        let record: RunRecord = a2perf_core::results::read_json(&path)?;
        if record.format_version != RUN_FORMAT_VERSION {
            return Err(PipelineError::Corrupt {
                path,
                reason: format!(
                    "layout version {} is not supported (expected {RUN_FORMAT_VERSION})",
                    record.format_version
                ),
            });
        }
        Ok(Self {
            dir: dir.to_path_buf(),
            record,
        })
    }

    /// Whether training finished.
    pub fn is_complete(&self) -> Result<bool> {
        Ok(a2perf_core::RunDir::new(&self.dir).is_complete()?)
    }

    /// Fails unless training finished.
    pub fn require_complete(&self) -> Result<()> {
        if self.is_complete()? {
            Ok(())
        } else {
            Err(PipelineError::Invalid(format!(
                "{}: training did not complete; rerun `a2perf train` to finish it",
                self.dir.display()
            )))
        }
    }

    /// Builds the run's environment.
    pub fn make_env(&self, registry: &Registry) -> Result<Box<dyn Env>> {
        Ok(registry.make_env(&self.record.task.env_id, &self.record.task.env_params)?)
    }

    /// Loads the final policy for an environment with `spec`.
    pub fn load_policy(&self, registry: &Registry, spec: &EnvSpec) -> Result<Box<dyn Policy>> {
        RegistryPolicies(registry).policy(self, &self.dir.join(POLICY_FILE), spec)
    }

    /// Fails for a run trained by an external agent, whose checkpoints only its own code reads.
    pub fn require_builtin(&self, what: &str) -> Result<()> {
        match &self.record.external {
            None => Ok(()),
            Some(agent) => Err(PipelineError::Invalid(format!(
                "{}: trained by an external agent ({}, {}); its checkpoints are in the agent's \
                 own format, so {what} needs the agent's policy: from Python, \
                 a2perf_rs.infer / generalize / collect with a policy callable or loader",
                self.dir.display(),
                agent.harness,
                agent.runtime
            ))),
        }
    }

    /// Fails for a run trained by a built-in algorithm (its results belong to that algorithm's
    /// policy, not to one given by a front end).
    pub fn require_external(&self, what: &str) -> Result<()> {
        if self.record.external.is_some() {
            return Ok(());
        }
        Err(PipelineError::Invalid(format!(
            "{}: trained by the built-in algorithm `{}`, not by an external agent; {what} it \
             with the `a2perf` command (or the pipeline with the registry's policies)",
            self.dir.display(),
            self.record.algorithm.name
        )))
    }

    /// Short name of the run (its directory name).
    pub fn name(&self) -> String {
        self.dir.file_name().map_or_else(
            || self.dir.display().to_string(),
            |n| n.to_string_lossy().into(),
        )
    }
}

/// Where a pipeline gets the policies it rolls out: the registry's checkpoint loaders for the
/// benchmark's own algorithms ([`RegistryPolicies`]), or a front end's policies for an external
/// agent (the Python package's callables). [`infer::infer_run_with`],
/// [`generalize::generalize_run_with`] and [`collect::collect_with`] take one.
pub trait PolicySource {
    /// The policy of `run` saved in `checkpoint` (its `policy.ckpt` or one of
    /// `checkpoints/step_*.ckpt`), for an environment with `spec`.
    fn policy(
        &mut self,
        run: &LoadedRun,
        checkpoint: &Path,
        spec: &EnvSpec,
    ) -> Result<Box<dyn Policy>>;

    /// Whether an error of one of its policies stops the phase with that error (an exception in
    /// a user's code) rather than being recorded as that generalization task's failure (the
    /// benchmark's networks on an observation they do not fit).
    fn errors_are_fatal(&self) -> bool {
        false
    }
}

/// The benchmark's checkpoints, rebuilt by the registry's loaders.
///
/// ```
/// use a2perf_pipeline::{PolicySource, RegistryPolicies};
/// let reg = a2perf_pipeline::registry::full_registry();
/// assert!(!RegistryPolicies(&reg).errors_are_fatal());
/// ```
pub struct RegistryPolicies<'a>(pub &'a Registry);

impl PolicySource for RegistryPolicies<'_> {
    fn policy(
        &mut self,
        run: &LoadedRun,
        checkpoint: &Path,
        spec: &EnvSpec,
    ) -> Result<Box<dyn Policy>> {
        run.require_builtin("rolling it out")?;
        load_checkpoint_policy(self.0, checkpoint, spec)
    }
}

/// Reads a checkpoint file and rebuilds its policy with the registered loader.
pub fn load_checkpoint_policy(
    registry: &Registry,
    path: &Path,
    spec: &EnvSpec,
) -> Result<Box<dyn Policy>> {
    let bytes = std::fs::read(path).map_err(io_err(path))?;
    let ckpt = Checkpoint::from_bytes(&bytes).map_err(|e| PipelineError::Corrupt {
        path: path.to_path_buf(),
        reason: e.to_string(),
    })?;
    let entry = registry.algorithm(&ckpt.algorithm)?;
    (entry.load_policy)(&ckpt, spec).map_err(|e| PipelineError::Corrupt {
        path: path.to_path_buf(),
        reason: e.to_string(),
    })
}

/// A policy that counts its calls, so that a failed rollout can say at which step it failed.
struct CountedPolicy<'a> {
    inner: &'a mut dyn Policy,
    calls: usize,
}

impl Policy for CountedPolicy<'_> {
    fn act(
        &mut self,
        obs: &a2perf_core::Observation,
        mode: a2perf_core::ActMode,
    ) -> std::result::Result<a2perf_core::Action, a2perf_core::PolicyError> {
        self.calls += 1;
        self.inner.act(obs, mode)
    }
    fn checkpoint(&self) -> std::result::Result<Checkpoint, a2perf_core::PolicyError> {
        self.inner.checkpoint()
    }
}

/// [`a2perf_core::rollout`] whose error names the run (`run()`), the episode and the step.
pub(crate) fn located_rollout(
    env: &mut dyn Env,
    policy: &mut dyn Policy,
    seed: u64,
    mode: a2perf_core::ActMode,
    record: bool,
    episode: usize,
    run: impl FnOnce() -> String,
) -> Result<a2perf_core::Episode> {
    let mut counted = CountedPolicy {
        inner: policy,
        calls: 0,
    };
    a2perf_core::rollout(env, &mut counted, seed, mode, record).map_err(|source| {
        PipelineError::Rollout {
            run: run(),
            episode,
            step: counted.calls.saturating_sub(1),
            source,
        }
    })
}

/// Finds run directories (those holding `run.json`) at or below `root`, up to three levels deep,
/// sorted by path.
pub fn find_runs(root: &Path) -> Result<Vec<PathBuf>> {
    fn walk(dir: &Path, depth: usize, out: &mut Vec<PathBuf>) -> Result<()> {
        if dir.join(RUN_FILE).is_file() {
            out.push(dir.to_path_buf());
            return Ok(());
        }
        if depth == 0 {
            return Ok(());
        }
        let entries = std::fs::read_dir(dir).map_err(io_err(dir))?;
        for e in entries {
            let e = e.map_err(io_err(dir))?;
            let p = e.path();
            if p.is_dir() && !e.file_name().to_string_lossy().starts_with('.') {
                walk(&p, depth - 1, out)?;
            }
        }
        Ok(())
    }
    if !root.is_dir() {
        return Err(PipelineError::Invalid(format!(
            "{}: no such directory",
            root.display()
        )));
    }
    let mut out = Vec::new();
    walk(root, 3, &mut out)?;
    out.sort();
    Ok(out)
}
