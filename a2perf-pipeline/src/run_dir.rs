//! The run directory: its file names, its record (`run.json`), the readers and writers of its
//! files, and where the policies rolled out of it come from. Every phase reads and writes run
//! directories through this module; none spells a file name itself.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use a2perf_core::replay::EpisodeLog;
use a2perf_core::{
    Checkpoint, Env, EnvSpec, LearningCurve, Policy, Registry, ResumeDir, ResumePoint, ResumeWrite,
    RunDir, TimeSplit, TrainingSettings, Value, write_atomic, write_json_atomic,
};
use serde::{Deserialize, Serialize};

use crate::dataset::DatasetProvenance;
use crate::error::{PipelineError, Result, io_err};
use crate::phase::{MetricSettings, PhaseSystem, combine_segments};
use crate::spec::{
    AlgorithmSpec, GeneralizationSettings, InferenceSettings, ObservationSource, OperativeWriter,
    SuiteSource, TaskSpec,
};
use crate::stats::Summary;
use crate::sysinfo::SystemInfo;

// Run directories are named from their task, algorithm and seed, in characters safe in a path
// on every platform.

/// `s` with characters that are awkward in paths replaced by `_`.
pub fn path_safe(s: &str) -> String {
    s.chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || matches!(c, '-' | '_' | '.') {
                c
            } else {
                '_'
            }
        })
        .collect()
}

/// `<task>__<algorithm>__seed<k>`, made [`path_safe`].
pub fn run_dir_name(task: &str, algorithm: &str, seed: u64) -> String {
    format!("{}__{}__seed{seed}", path_safe(task), path_safe(algorithm))
}

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
/// The CodeCarbon-style row of each training segment, in the run directory.
pub const TRAIN_EMISSIONS_FILE: &str = "train_emissions.csv";
/// The CodeCarbon-style row of each `infer`, in the run directory.
pub const INFERENCE_EMISSIONS_FILE: &str = "inference_emissions.csv";

/// `submission/code/`: a submission's participant folder as `a2perf submit` ran it (copied when
/// its training starts, without its `.venv`, hidden files and caches).
pub const SUBMISSION_CODE_DIR: &str = "submission/code";
/// `submission/files/`: a submission's own files, what its `train()` saves for its
/// `load_policy` (`a2perf_rs.submission.task().files_dir`).
pub const SUBMISSION_FILES_DIR: &str = "submission/files";

/// `episodes/`: the logged actions and seeds of every inference and generalization episode.
pub const EPISODES_DIR: &str = "episodes";
/// `episodes/inference.json`: the logs of `infer`'s rollouts, in episode order.
pub const INFERENCE_EPISODES_FILE: &str = "episodes/inference.json";
/// `episodes/generalization/`: one log file per generalization task.
pub const GENERALIZATION_EPISODES_DIR: &str = "episodes/generalization";

/// `episodes/generalization/<task>.json`, relative to the run directory: the logs of one
/// generalization task's rollouts (the task's name made path-safe).
///
/// ```
/// use a2perf_pipeline::run_dir::generalization_episodes_file;
/// assert_eq!(
///     generalization_episodes_file("a/b c"),
///     "episodes/generalization/a_b_c.json"
/// );
/// ```
pub fn generalization_episodes_file(task: &str) -> String {
    format!("{GENERALIZATION_EPISODES_DIR}/{}.json", path_safe(task))
}

/// Writes episode logs to `dir/name` as compact JSON (they are the bulk of a bundle).
pub(crate) fn write_episode_logs(dir: &Path, name: &str, logs: &[EpisodeLog]) -> Result<()> {
    let path = dir.join(name);
    if let Some(parent) = path.parent() {
        std::fs::create_dir_all(parent).map_err(io_err(parent))?;
    }
    Ok(a2perf_core::write_json_compact_atomic(&path, &logs)?)
}

/// Every run directory at or below each of `dirs`; a directory without any is an error naming it.
pub fn expand_runs(dirs: &[PathBuf]) -> Result<Vec<PathBuf>> {
    let mut out = Vec::new();
    for d in dirs {
        let found = find_runs(d)?;
        if found.is_empty() {
            return Err(PipelineError::Invalid(format!(
                "{}: no run directories (no run.json) found",
                d.display()
            )));
        }
        out.extend(found);
    }
    Ok(out)
}

/// `status.json` (written by [`a2perf_core::RunDir`]).
pub const STATUS_FILE: &str = "status.json";
/// `env_identity.json`: the content hashes of every environment a run used (a bundle member
/// that `a2perf bundle` adds; see [`bundle`](crate::bundle)).
pub const IDENTITY_FILE: &str = "env_identity.json";
/// `submission/`: what `a2perf submit` keeps of a submission in its run directory (its folder
/// under [`SUBMISSION_CODE_DIR`], its own files under [`SUBMISSION_FILES_DIR`]); a bundle
/// carries it.
pub const PARTICIPANT_DIR: &str = "submission";

/// The files of a complete run that a bundle carries when present (besides the episode logs,
/// the checkpoint and a submission's folder): its record, configuration, curves, results and
/// system figures.
pub const BUNDLED_FILES: &[&str] = &[
    RUN_FILE,
    STATUS_FILE,
    OPERATIVE_FILE,
    CURVE_CSV,
    CURVE_JSON,
    TRAIN_SYSTEM_FILE,
    TRAIN_SEGMENTS_FILE,
    SYSTEM_INFO_FILE,
    TRAIN_EMISSIONS_FILE,
    INFERENCE_FILE,
    INFERENCE_EMISSIONS_FILE,
    GENERALIZATION_FILE,
];

/// Decodes an episode-log file's bytes (`origin` names it in errors).
pub fn parse_episode_logs(bytes: &[u8], origin: &Path) -> Result<Vec<EpisodeLog>> {
    serde_json::from_slice(bytes).map_err(|e| PipelineError::Corrupt {
        path: origin.to_path_buf(),
        reason: e.to_string(),
    })
}

/// `collect/`: the run's checkpoint evaluations (`collect` writes them).
pub const COLLECT_DIR: &str = "collect";
/// `collect/evaluation.json`: every checkpoint's evaluation.
pub const EVALUATION_FILE: &str = "evaluation.json";
/// `<experiment>/datasets/request.json`: what a suite's dataset step collected from (its step and
/// the sha256 of every source checkpoint), so that a rerun with the same request reuses it.
pub const DATASET_REQUEST_FILE: &str = "request.json";
/// `train.lock`: the training lock (see [`run_lock`](crate::run_lock)).
pub use crate::error::TRAIN_LOCK_FILE;
/// `operative_config.ron`.
pub const OPERATIVE_FILE: &str = a2perf_core::config::OPERATIVE_CONFIG_FILE;

/// `inference.json`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct InferenceResults {
    /// Greedy rollouts run.
    pub episodes: usize,
    /// Return of every rollout (undiscounted sum of rewards).
    #[serde(deserialize_with = "a2perf_core::results::vec_f64_or_nan")]
    pub rollout_returns: Vec<f64>,
    /// Summary of `rollout_returns`.
    pub returns: Summary,
    /// Length of every rollout.
    pub episode_lengths: Vec<usize>,
    /// Per-call inference time in milliseconds on the configured observations (the figure the
    /// report uses).
    pub inference_time_ms: Summary,
    /// Which observations `inference_time_ms` was measured on.
    pub observation_source: ObservationSource,
    /// Time of every `Policy::act` call made during the rollouts, in milliseconds.
    pub rollout_call_time_ms: Summary,
    /// Time of each call on random observation-space samples (the original harness's method),
    /// in milliseconds, when requested.
    pub random_observation_time_ms: Option<Summary>,
    /// Random samples on which the policy returned an error (e.g. no legal action).
    pub random_observation_failures: usize,
    /// RAM, power and energy over the rollouts.
    pub system: PhaseSystem,
}

/// Result on one task of the suite.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TaskResult {
    /// Task name.
    pub name: String,
    /// Environment id.
    pub env_id: String,
    /// Parameters that differ from the id's defaults.
    pub params: BTreeMap<String, Value>,
    /// Return of every rollout.
    #[serde(deserialize_with = "a2perf_core::results::vec_f64_or_nan")]
    pub returns: Vec<f64>,
    /// Mean return (`None` when the task could not be run or the mean is not finite; see
    /// `error`).
    pub mean_return: Option<f64>,
    /// Why the policy could not be run on this task (e.g. its observation does not fit), or
    /// why it has no mean return.
    pub error: Option<String>,
}

/// `generalization.json`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct GeneralizationResults {
    /// Domain of the suite.
    pub domain: String,
    /// Where the suite came from (absent in files written before suites were configurable,
    /// which always used the registry's).
    #[serde(default)]
    pub source: Option<SuiteSource>,
    /// Rollouts per task.
    pub episodes: usize,
    /// Per-task results, in suite order.
    pub tasks: Vec<TaskResult>,
    /// Sum of the per-task mean returns (the paper's generalization score); `None` if any task
    /// could not be run.
    pub sum_of_mean_returns: Option<f64>,
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
    /// `a2perf_rs.TrainingRun`, see [`external`](crate::external)): who trained it. Absent for built-in runs.
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
/// agent (the Python package's callables). [`infer::infer_run_with`](crate::infer::infer_run_with),
/// [`generalize::generalize_run_with`](crate::generalize::generalize_run_with) and [`collect::collect_with`](crate::collect::collect_with) take one.
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
    policy_from_checkpoint_bytes(registry, &bytes, path, spec)
}

/// Rebuilds the policy saved in checkpoint `bytes` (read from `path`, which errors name) with
/// the registered loader of its algorithm. Only the benchmark's own loaders run: a checkpoint
/// is data.
pub fn policy_from_checkpoint_bytes(
    registry: &Registry,
    bytes: &[u8],
    path: &Path,
    spec: &EnvSpec,
) -> Result<Box<dyn Policy>> {
    let ckpt = Checkpoint::from_bytes(bytes).map_err(|e| PipelineError::Corrupt {
        path: path.to_path_buf(),
        reason: e.to_string(),
    })?;
    let entry = registry.algorithm(&ckpt.algorithm)?;
    (entry.load_policy)(&ckpt, spec).map_err(|e| PipelineError::Corrupt {
        path: path.to_path_buf(),
        reason: e.to_string(),
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

/// Checkpoint files of a run, sorted by step.
pub fn checkpoints(run: &Path) -> Result<Vec<(u64, PathBuf)>> {
    let dir = run.join(CHECKPOINT_DIR);
    let mut out = Vec::new();
    if !dir.is_dir() {
        return Ok(out);
    }
    for e in std::fs::read_dir(&dir).map_err(io_err(&dir))? {
        let p = e.map_err(io_err(&dir))?.path();
        let name = p
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default();
        if let Some(step) = name
            .strip_prefix("step_")
            .and_then(|s| s.strip_suffix(".ckpt"))
            .and_then(|s| s.parse::<u64>().ok())
        {
            out.push((step, p));
        }
    }
    out.sort();
    Ok(out)
}

/// How one training segment (one process working on a run) ended.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SegmentOutcome {
    /// Still running (or killed before it could say otherwise; the next segment finds out).
    Running,
    /// Killed without finishing (`kill -9`, power loss): no meter report.
    Killed,
    /// Stopped at a safe point on request (SIGTERM, Ctrl-C).
    Interrupted,
    /// Failed; the run's status says why.
    Failed,
    /// Training finished.
    Completed,
}

/// One training segment of a run (`train_segments.json`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TrainSegment {
    /// Environment steps the segment started from (0, or its resume point's).
    pub started_at_step: u64,
    /// How it ended.
    pub outcome: SegmentOutcome,
    /// System meters over the segment; `None` when it was killed.
    pub system: Option<PhaseSystem>,
    /// The resume points it wrote: step, size and the time each took.
    #[serde(default)]
    pub resume_points: Vec<ResumeWrite>,
    /// Warnings of the segment.
    #[serde(default)]
    pub warnings: Vec<String>,
    /// Where the segment's wall time went (environment steps, acting, learning, evaluation,
    /// checkpoint I/O); `None` when it was killed, or written before it was recorded.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub time_split: Option<TimeSplit>,
}

/// `train_segments.json`: every segment of a run, oldest first.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct TrainSegments {
    /// The segments.
    pub segments: Vec<TrainSegment>,
}

/// How a run directory is to be trained.
pub(crate) enum Start {
    /// Already complete.
    Skip,
    /// From nothing (the directory is new or was emptied).
    Fresh,
    /// From a resume point, after these earlier segments.
    Resume(Box<ResumePoint>, TrainSegments),
}

/// Empties the run directory, keeping its training lock file: the lock lives on that file, and
/// a rival that opened it must still find it locked.
pub(crate) fn wipe(run: &RunDir) -> Result<()> {
    let path = run.path();
    for entry in std::fs::read_dir(path).map_err(io_err(path))? {
        let entry = entry.map_err(io_err(path))?;
        if entry.file_name() == TRAIN_LOCK_FILE {
            continue;
        }
        let p = entry.path();
        let removed = if entry.file_type().map_err(io_err(&p))?.is_dir() {
            std::fs::remove_dir_all(&p)
        } else {
            std::fs::remove_file(&p)
        };
        removed.map_err(io_err(&p))?;
    }
    Ok(())
}

/// Decides how to train `run`, given the record it would get: skip it (complete), continue it
/// from its newest valid resume point, or start it from an empty directory (new, never
/// resumable, or made with another configuration; stale checkpoints must not mix in).
pub(crate) fn prepare(
    run: &RunDir,
    record_json: &[u8],
    warnings: &mut Vec<String>,
) -> Result<Start> {
    let path = run.path();
    if path.exists() {
        match run.status()? {
            Some(s) if s.state.is_complete() => return Ok(Start::Skip),
            Some(_) => {
                let recorded = std::fs::read(run.file(RUN_FILE)).ok();
                if recorded.as_deref() != Some(record_json) {
                    // No run.json: killed before writing it, so nothing of it can be resumed.
                    if recorded.is_some() {
                        warnings.push(
                            "its configuration changed since it was interrupted: trained from \
                             scratch"
                                .into(),
                        );
                    }
                    wipe(run)?;
                } else {
                    let resume_dir = ResumeDir::new(run.file(RESUME_DIR));
                    let newest = resume_dir
                        .newest_valid()
                        .map_err(io_err(resume_dir.path()))?;
                    warnings.extend(newest.warnings);
                    match newest.point {
                        Some((_, point)) => {
                            let segments = read_segments(run, warnings);
                            return Ok(Start::Resume(Box::new(point), segments));
                        }
                        None => wipe(run)?,
                    }
                }
            }
            None => {
                let mut entries = std::fs::read_dir(path).map_err(io_err(path))?;
                // The training lock file is this trainer's own.
                let foreign = entries.any(|e| !e.is_ok_and(|e| e.file_name() == TRAIN_LOCK_FILE));
                if foreign {
                    return Err(PipelineError::Invalid(format!(
                        "{}: exists, is not empty and has no status.json; refusing to overwrite \
                         it (move it away or choose another output directory)",
                        path.display()
                    )));
                }
            }
        }
    }
    run.begin()?;
    Ok(Start::Fresh)
}

/// The recorded segments, with those still marked running (their process was killed) marked
/// killed. An unreadable file is replaced, with a warning: the figures of earlier segments are
/// then missing from `train_system.json`.
fn read_segments(run: &RunDir, warnings: &mut Vec<String>) -> TrainSegments {
    let p = run.file(TRAIN_SEGMENTS_FILE);
    let mut segments: TrainSegments = if p.is_file() {
        a2perf_core::results::read_json(&p).unwrap_or_else(|e| {
            warnings.push(format!("{e}; the earlier segments' figures are lost"));
            TrainSegments::default()
        })
    } else {
        TrainSegments::default()
    };
    for s in &mut segments.segments {
        if s.outcome == SegmentOutcome::Running {
            s.outcome = SegmentOutcome::Killed;
        }
    }
    segments
}

/// Policy checkpoints written after `step` by a segment that did not get to save a resume point
/// past them; the resumed run writes them again.
pub(crate) fn remove_checkpoints_after(run: &RunDir, step: u64) -> Result<()> {
    for (s, path) in checkpoints(run.path())? {
        if s > step {
            std::fs::remove_file(&path).map_err(io_err(&path))?;
        }
    }
    Ok(())
}

/// What a run is — its `run.json` record, with the exact bytes written — and the environment
/// its training uses.
pub(crate) struct PlannedRun {
    /// The record.
    pub(crate) record: RunRecord,
    /// `record` as `run.json` holds it.
    pub(crate) record_json: Vec<u8>,
    /// The task's environment.
    pub(crate) env: a2perf_core::EnvEntry,
    /// Its parameters, resolved.
    pub(crate) env_params: a2perf_core::Params,
}

/// `run.json`, `system_info.json` and the operative config of a run that starts training.
pub(crate) fn write_run_files(
    run: &RunDir,
    record_json: &[u8],
    operative: Option<&OperativeWriter>,
) -> Result<()> {
    write_atomic(&run.file(RUN_FILE), record_json).map_err(io_err(&run.file(RUN_FILE)))?;
    write_json_atomic(&run.file(SYSTEM_INFO_FILE), &SystemInfo::current())?;
    if let Some(write) = operative {
        write(run.path()).map_err(|reason| PipelineError::Corrupt {
            path: run.file(OPERATIVE_FILE),
            reason,
        })?;
    }
    Ok(())
}

/// `curve.csv` and `curve.json`.
pub(crate) fn write_curve(run: &RunDir, curve: &LearningCurve) -> Result<()> {
    let mut csv = String::from("env_steps,mean_return,std_return,wall_seconds\n");
    for p in &curve.points {
        csv.push_str(&format!(
            "{},{},{},{}\n",
            p.env_steps, p.mean_return, p.std_return, p.wall_seconds
        ));
    }
    write_atomic(&run.file(CURVE_CSV), csv.as_bytes()).map_err(io_err(&run.file(CURVE_CSV)))?;
    write_json_atomic(&run.file(CURVE_JSON), curve)?;
    Ok(())
}

/// `train_system.json`: the system figures of every segment that reported some, combined.
pub(crate) fn write_train_system(run: &RunDir, segments: &TrainSegments) -> Result<()> {
    let reported: Vec<PhaseSystem> = segments
        .segments
        .iter()
        .filter_map(|s| s.system.clone())
        .collect();
    let killed = segments.segments.len() - reported.len();
    write_json_atomic(
        &run.file(TRAIN_SYSTEM_FILE),
        &combine_segments(&reported, killed),
    )?;
    Ok(())
}
