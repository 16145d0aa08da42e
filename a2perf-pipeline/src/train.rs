//! `a2perf train`: one resumable run per (task, algorithm, seed).
//!
//! A run that stops before completing (SIGTERM, Ctrl-C, `kill -9`, a failure) continues from its
//! newest valid resume point when the same command is run again, if its algorithm saves resume
//! points (every built-in one does; see [`a2perf_core::TrainingContext`]); otherwise, or when its
//! configuration changed, it is trained again from scratch. Each process that trains a run is a
//! *segment*, recorded in `train_segments.json` with its own system meters; `train_system.json`
//! combines them (see [`combine_segments`]).

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Instant;

use a2perf_core::{
    CancelToken, DirectoryCheckpoints, LearningCurve, Measurement, Meter, MeterReport, MeterSet,
    Provenance, Registry, ResumeDir, ResumePoint, ResumeWrite, RunDir, RunError, RunState,
    TrainingContext, write_atomic, write_json_atomic,
};
use serde::{Deserialize, Serialize};

use super::isolate::Isolation;
use super::plan::{ExperimentPlan, MetricSettings, RunJob};
use super::run_lock::{LockHolder, LockedRun, TRAIN_LOCK_FILE, TrainingLock};
use super::{
    CHECKPOINT_DIR, CURVE_CSV, CURVE_JSON, OPERATIVE_FILE, POLICY_FILE, PipelineError, RESUME_DIR,
    RUN_FILE, RUN_FORMAT_VERSION, Result, RunRecord, SYSTEM_INFO_FILE, SystemInfo,
    TRAIN_SEGMENTS_FILE, TRAIN_SYSTEM_FILE, io_err, progress,
};

/// The phase a meter measures.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Phase {
    /// The whole of training.
    Train,
    /// Inference rollouts.
    Inference,
}

/// Builds the system meters of a phase; the path is the run directory (for `emissions.csv`-style
/// outputs).
pub type MeterFactory =
    Arc<dyn Fn(Phase, &Path, &MetricSettings) -> Vec<Box<dyn Meter>> + Send + Sync>;

/// A factory that builds no meters (only wall-clock time is then recorded).
pub fn no_meters() -> MeterFactory {
    Arc::new(|_, _, _| Vec::new())
}

/// Options of [`train`].
#[derive(Clone)]
pub struct TrainOptions {
    /// Runs trained at the same time (0 = one per logical CPU).
    pub jobs: usize,
    /// Ctrl-C, SIGTERM: stops the runs in flight at their next safe point (writing a resume
    /// point when the algorithm supports it, and marking them `interrupted`) and starts no new
    /// ones.
    pub cancel: CancelToken,
    /// System meters.
    pub meters: MeterFactory,
    /// Show a progress bar.
    pub show_progress: bool,
    /// Where each run trains: in this process, or in a child process of its own (whose meters
    /// then measure that run alone).
    pub isolation: Isolation,
}

impl Default for TrainOptions {
    fn default() -> Self {
        Self {
            jobs: 1,
            cancel: CancelToken::new(),
            meters: no_meters(),
            show_progress: false,
            isolation: Isolation::InProcess,
        }
    }
}

/// System measurements of one phase (`train_system.json`, and the `system` part of
/// `inference.json`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PhaseSystem {
    /// Wall-clock time of the phase in seconds.
    pub wall_clock_s: f64,
    /// Most runs that shared this process while the phase ran. Meters measure the whole
    /// process, so with more than one the RAM and energy figures cover all of them.
    pub concurrent_runs: usize,
    /// The process that measured the phase (absent in records written before it was kept, and
    /// for segments of several processes combined).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub pid: Option<u32>,
    /// What the meters reported.
    pub meters: MeterReport,
    /// Meters that failed, and why (their values are then missing, never zero).
    pub meter_errors: Vec<String>,
    /// Training segments (processes) these figures combine: more than one when the run was
    /// interrupted and resumed (see [`combine_segments`]).
    #[serde(default = "one", skip_serializing_if = "is_one")]
    pub segments: usize,
    /// How the figures were combined, and what they miss.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub note: Option<String>,
}

fn one() -> usize {
    1
}

fn is_one(n: &usize) -> bool {
    *n == 1
}

/// What happened to one run.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum RunOutcome {
    /// Trained to completion now (possibly continuing an interrupted run).
    Completed,
    /// Already complete on disk; not redone.
    Skipped,
    /// Stopped by the cancel token (or never started because of it); the directory is marked
    /// `interrupted`, and a rerun continues it.
    Cancelled,
    /// Training failed; the directory is marked `failed` with the reason.
    Failed(String),
    /// Left alone: another trainer holds the run directory's training lock (see
    /// [`run_lock`](crate::run_lock)); the holder as it recorded itself.
    Locked(Option<LockHolder>),
}

/// Outcome of [`train`].
#[derive(Clone, Debug, Default)]
pub struct TrainSummary {
    /// Run directories with their outcome, in grid order.
    pub runs: Vec<(PathBuf, RunOutcome)>,
    /// Runs that continued from a resume point, and its environment steps.
    pub resumed: Vec<(PathBuf, u64)>,
    /// Things a user should know (fallbacks past corrupt resume points, runs restarted from
    /// scratch, environments that did not replay exactly), per run directory. The library never
    /// prints them; front ends do.
    pub warnings: Vec<(PathBuf, String)>,
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
}

/// `train_segments.json`: every segment of a run, oldest first.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct TrainSegments {
    /// The segments.
    pub segments: Vec<TrainSegment>,
}

/// Combines the system figures of a run's training segments: wall-clock time, energy,
/// emissions and other totals (units `kWh`, `kg`, `h`, `s`) are summed, `peak_*` values take the
/// maximum, and everything else (mean RAM, power) is the mean weighted by each segment's
/// wall-clock time. A value missing in any segment is missing in the result. `killed` segments
/// left no figures: the note says that their time and energy are not included.
///
/// ```
/// use a2perf_core::{Measurement, MeterReport};
/// use a2perf_pipeline::train::{PhaseSystem, combine_segments};
/// let seg = |secs: f64, kwh: f64, peak: f64, mean: f64| PhaseSystem {
///     wall_clock_s: secs,
///     concurrent_runs: 1,
///     pid: None,
///     meters: MeterReport { measurements: vec![
///         Measurement::measured("energy_kwh", kwh, "kWh"),
///         Measurement::measured("peak_ram_gb", peak, "GB"),
///         Measurement::measured("mean_ram_gb", mean, "GB"),
///     ] },
///     meter_errors: vec![],
///     segments: 1,
///     note: None,
/// };
/// let all = combine_segments(&[seg(10.0, 1.0, 2.0, 1.0), seg(30.0, 2.0, 1.5, 2.0)], 0);
/// assert_eq!(all.wall_clock_s, 40.0);
/// assert_eq!(all.segments, 2);
/// assert_eq!(all.meters.value("energy_kwh"), Some(3.0));
/// assert_eq!(all.meters.value("peak_ram_gb"), Some(2.0));
/// assert_eq!(all.meters.value("mean_ram_gb"), Some(1.75));
/// assert!(all.note.unwrap().contains("combined from 2 training segments"));
/// ```
pub fn combine_segments(parts: &[PhaseSystem], killed: usize) -> PhaseSystem {
    let n = parts.len() + killed;
    if let ([only], 0) = (parts, killed) {
        return only.clone();
    }
    let wall: f64 = parts.iter().map(|p| p.wall_clock_s).sum();
    let mut names: Vec<&str> = Vec::new();
    for p in parts {
        for m in &p.meters.measurements {
            if !names.contains(&m.name.as_str()) {
                names.push(&m.name);
            }
        }
    }
    let measurements = names
        .iter()
        .map(|name| {
            let found: Vec<(Option<&Measurement>, f64)> = parts
                .iter()
                .map(|p| (p.meters.get(name), p.wall_clock_s))
                .collect();
            let first = found
                .iter()
                .find_map(|(m, _)| *m)
                .cloned()
                .unwrap_or_else(|| Measurement::absent(name, "", "not reported"));
            let values: Option<Vec<(f64, f64)>> = found
                .iter()
                .map(|(m, w)| m.and_then(|m| m.value).map(|v| (v, *w)))
                .collect();
            let Some(values) = values else {
                let missing = found
                    .iter()
                    .filter(|(m, _)| m.and_then(|m| m.value).is_none())
                    .count();
                return match first.value {
                    None => first,
                    Some(_) => Measurement::absent(
                        name,
                        &first.unit,
                        &format!("missing in {missing} of {} training segments", parts.len()),
                    ),
                };
            };
            let total_like = ["kWh", "kg", "h", "s"].contains(&first.unit.as_str());
            let value = if total_like {
                values.iter().map(|(v, _)| v).sum()
            } else if name.starts_with("peak_") {
                values
                    .iter()
                    .map(|(v, _)| *v)
                    .fold(f64::NEG_INFINITY, f64::max)
            } else {
                let w: f64 = values.iter().map(|(_, w)| w).sum();
                if w > 0.0 {
                    values.iter().map(|(v, w)| v * w).sum::<f64>() / w
                } else {
                    values.iter().map(|(v, _)| v).sum::<f64>() / values.len() as f64
                }
            };
            let estimated = found
                .iter()
                .find_map(|(m, _)| match m.map(|m| &m.provenance) {
                    Some(Provenance::Estimated(how)) => Some(how.clone()),
                    _ => None,
                });
            Measurement {
                name: first.name.clone(),
                value: Some(value),
                unit: first.unit.clone(),
                provenance: match estimated {
                    Some(how) => Provenance::Estimated(format!(
                        "{how} (combined over {} segments)",
                        parts.len()
                    )),
                    None => Provenance::Measured,
                },
            }
        })
        .collect();
    let mut note = format!(
        "combined from {n} training segments (the run was interrupted and resumed): wall-clock \
         time, energy and emissions summed, peak RAM the maximum, mean RAM and power weighted by \
         each segment's wall-clock time"
    );
    if killed > 0 {
        note.push_str(&format!(
            "; {killed} segment(s) killed without a meter report (kill -9): their time and \
             energy are not included"
        ));
    }
    PhaseSystem {
        wall_clock_s: wall,
        concurrent_runs: parts.iter().map(|p| p.concurrent_runs).max().unwrap_or(1),
        pid: parts
            .first()
            .and_then(|p| p.pid)
            .filter(|pid| parts.iter().all(|p| p.pid == Some(*pid))),
        meters: MeterReport { measurements },
        meter_errors: parts
            .iter()
            .enumerate()
            .flat_map(|(i, p)| {
                p.meter_errors
                    .iter()
                    .map(move |e| format!("segment {}: {e}", i + 1))
            })
            .collect(),
        segments: n,
        note: Some(note),
    }
}

impl TrainSummary {
    /// Run directories with the given outcome.
    pub fn with(&self, outcome: &RunOutcome) -> Vec<&Path> {
        self.runs
            .iter()
            .filter(|(_, o)| o == outcome)
            .map(|(p, _)| p.as_path())
            .collect()
    }

    /// Runs left alone because another trainer holds them, with the holder.
    pub fn locked(&self) -> Vec<LockedRun> {
        self.runs
            .iter()
            .filter_map(|(p, o)| match o {
                RunOutcome::Locked(holder) => Some(LockedRun {
                    run: p.clone(),
                    holder: holder.clone(),
                }),
                _ => None,
            })
            .collect()
    }

    /// Failed runs and why.
    pub fn failures(&self) -> Vec<(&Path, &str)> {
        self.runs
            .iter()
            .filter_map(|(p, o)| match o {
                RunOutcome::Failed(why) => Some((p.as_path(), why.as_str())),
                _ => None,
            })
            .collect()
    }
}

static ACTIVE_RUNS: AtomicUsize = AtomicUsize::new(0);

/// Counts this run as active for as long as it lives.
pub(crate) struct ActiveRun {
    max_seen: usize,
}

impl ActiveRun {
    pub(crate) fn enter() -> Self {
        let now = ACTIVE_RUNS.fetch_add(1, Ordering::SeqCst) + 1;
        Self { max_seen: now }
    }
    pub(crate) fn observe(&mut self) -> usize {
        self.max_seen = self.max_seen.max(ACTIVE_RUNS.load(Ordering::SeqCst));
        self.max_seen
    }
}

impl Drop for ActiveRun {
    fn drop(&mut self) {
        ACTIVE_RUNS.fetch_sub(1, Ordering::SeqCst);
    }
}

/// System meters running over a phase that is not one closure call — a front end's block of
/// code, such as Python's `with a2perf_rs.TrainingRun(...)` — from [`start`](Self::start) to
/// [`finish`](Self::finish), with the phase's wall-clock time. Meter failures are recorded, not
/// fatal: a missing figure is reported as missing. The phase counts as an active run of this
/// process while it lasts (see [`PhaseSystem::concurrent_runs`]).
///
/// ```
/// use a2perf_pipeline::train::MeteredPhase;
/// let phase = MeteredPhase::start(Vec::new());
/// let system = phase.finish();
/// assert!(system.wall_clock_s >= 0.0 && system.meter_errors.is_empty());
/// assert!(system.concurrent_runs >= 1);
/// ```
pub struct MeteredPhase {
    set: MeterSet,
    errors: Vec<String>,
    active: ActiveRun,
    started_ok: bool,
    started: Instant,
}

impl MeteredPhase {
    /// Starts `meters` and the clock.
    pub fn start(meters: Vec<Box<dyn Meter>>) -> Self {
        let mut set = MeterSet::new(meters);
        let mut errors = Vec::new();
        let active = ActiveRun::enter();
        let started_ok = match set.start() {
            Ok(()) => true,
            Err(e) => {
                errors.push(e.to_string());
                false
            }
        };
        Self {
            set,
            errors,
            active,
            started_ok,
            started: Instant::now(),
        }
    }

    /// Seconds since [`start`](Self::start).
    pub fn elapsed_s(&self) -> f64 {
        self.started.elapsed().as_secs_f64()
    }

    /// Stops the clock and the meters and returns what they measured.
    pub fn finish(mut self) -> PhaseSystem {
        let wall = self.elapsed_s();
        let meters = if self.started_ok {
            self.set.finish().unwrap_or_else(|e| {
                self.errors.push(e.to_string());
                MeterReport::default()
            })
        } else {
            MeterReport::default()
        };
        PhaseSystem {
            wall_clock_s: wall,
            concurrent_runs: self.active.observe(),
            pid: Some(std::process::id()),
            meters,
            meter_errors: self.errors,
            segments: 1,
            note: None,
        }
    }
}

/// Runs `f` between the start and the finish of `meters` (see [`MeteredPhase`]).
pub(crate) fn measured<T>(meters: Vec<Box<dyn Meter>>, f: impl FnOnce() -> T) -> (T, PhaseSystem) {
    let phase = MeteredPhase::start(meters);
    let out = f();
    (out, phase.finish())
}

/// Checks that every experiment names a known environment and algorithm with valid parameters,
/// before any run starts.
pub fn preflight(registry: &Registry, jobs: &[RunJob]) -> Result<()> {
    let mut seen = std::collections::BTreeSet::new();
    for job in jobs {
        let key = (
            job.plan.name.clone(),
            job.plan.task.name.clone(),
            job.plan.algorithm.name.clone(),
        );
        if !seen.insert(key) {
            continue;
        }
        registry.env_params(&job.plan.task.env_id, &job.plan.task.env_params)?;
        registry.make_algorithm(&job.plan.algorithm.name, &job.plan.algorithm.params)?;
        if job.plan.training.total_env_steps == 0 {
            return Err(PipelineError::Invalid(format!(
                "experiment {}: training.total_env_steps must be positive",
                job.plan.name
            )));
        }
    }
    Ok(())
}

/// Trains every job, `opts.jobs` at a time. Complete runs are skipped; incomplete ones continue
/// from their newest valid resume point, or are trained from scratch when there is none (their
/// algorithm does not save resume points) or their configuration changed. Either way the result
/// is the same as an uninterrupted run's (training is deterministic, and resumption is exact).
///
/// Each run is trained under its directory's exclusive training lock
/// ([`run_lock`](crate::run_lock)); a run another trainer holds is left alone and reported as
/// [`RunOutcome::Locked`] with the holder's pid and host.
///
/// Returns an error only for problems that stop everything (unknown environment, unwritable
/// output); a run that fails is reported in the summary and leaves the others going.
pub fn train(registry: &Registry, jobs: &[RunJob], opts: &TrainOptions) -> Result<TrainSummary> {
    preflight(registry, jobs)?;
    let workers = match opts.jobs {
        0 => std::thread::available_parallelism().map_or(1, |n| n.get()),
        n => n,
    }
    .min(jobs.len())
    .max(1);
    let next = AtomicUsize::new(0);
    let results: Mutex<Vec<Option<Result<RunReport>>>> =
        Mutex::new((0..jobs.len()).map(|_| None).collect());
    let bar = progress::bar(jobs.len() as u64, "train", opts.show_progress);
    std::thread::scope(|scope| {
        for _ in 0..workers {
            scope.spawn(|| {
                loop {
                    if opts.cancel.is_cancelled() {
                        break;
                    }
                    let i = next.fetch_add(1, Ordering::SeqCst);
                    let Some(job) = jobs.get(i) else { break };
                    bar.set_message(
                        job.plan
                            .run_dir(job.seed)
                            .file_name()
                            .map(|n| n.to_string_lossy().into_owned())
                            .unwrap_or_default(),
                    );
                    let r = match &opts.isolation {
                        Isolation::InProcess => train_run(registry, job, opts),
                        Isolation::Children(command) => crate::isolate::train_in_child(
                            command,
                            &job.plan.run_dir(job.seed),
                            &opts.cancel,
                        ),
                    };
                    bar.inc(1);
                    if let Ok(mut slots) = results.lock() {
                        slots[i] = Some(r);
                    }
                }
            });
        }
    });
    bar.finish_and_clear();
    let slots = results
        .into_inner()
        .map_err(|_| PipelineError::Invalid("a training thread panicked".into()))?;
    let mut summary = TrainSummary::default();
    for (job, slot) in jobs.iter().zip(slots) {
        let dir = job.plan.run_dir(job.seed);
        match slot {
            Some(Ok(report)) => {
                if let Some(step) = report.resumed_from {
                    summary.resumed.push((dir.clone(), step));
                }
                summary
                    .warnings
                    .extend(report.warnings.into_iter().map(|w| (dir.clone(), w)));
                summary.runs.push((dir, report.outcome));
            }
            Some(Err(e)) => return Err(e),
            // Never started because of cancellation.
            None => summary.runs.push((dir, RunOutcome::Cancelled)),
        }
    }
    Ok(summary)
}

/// What [`train_run`] did to one run (a child process of [`Isolation::Children`] hands it to
/// its parent as JSON).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RunReport {
    /// How the run ended.
    pub outcome: RunOutcome,
    /// The resume point's environment steps, when the run continued from one.
    pub resumed_from: Option<u64>,
    /// Warnings for the user (see [`TrainSummary::warnings`]).
    pub warnings: Vec<String>,
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
fn remove_checkpoints_after(run: &RunDir, step: u64) -> Result<()> {
    for (s, path) in super::collect::checkpoints(run.path())? {
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

impl PlannedRun {
    /// The record of `job` trained by `algorithm` (hyperparameters resolved): the task's
    /// parameters resolved and the environment's provenance read from a probe instance.
    /// `external` marks a run trained outside the benchmark's algorithms.
    pub(crate) fn new(
        registry: &Registry,
        job: &RunJob,
        algorithm: super::AlgorithmSpec,
        external: Option<super::ExternalAgent>,
    ) -> Result<Self> {
        let plan = &job.plan;
        let env = registry.env(&plan.task.env_id)?.clone();
        let env_params = registry.env_params(&plan.task.env_id, &plan.task.env_params)?;
        let probe = (env.make)(&env_params).map_err(|source| a2perf_core::RegistryError::Env {
            id: plan.task.env_id.clone(),
            source,
        })?;
        let env_metadata = probe.spec().metadata.clone();
        drop(probe);
        let mut task = plan.task.clone();
        task.env_params = env_params.values().clone();
        let record = RunRecord {
            format_version: RUN_FORMAT_VERSION,
            experiment: plan.name.clone(),
            task,
            domain: env.domain.clone(),
            algorithm,
            seed: job.seed,
            training: plan.training.clone(),
            inference: plan.inference.clone(),
            generalization: plan.generalization.clone(),
            metrics: plan.metrics.clone(),
            env_metadata,
            dataset: plan.dataset.clone(),
            external,
        };
        // The exact bytes `write_json_atomic` writes, so that comparing them with the file on
        // disk is exact (no float parsing).
        let record_json =
            serde_json::to_vec_pretty(&record).map_err(|e| PipelineError::Corrupt {
                path: plan.run_dir(job.seed).join(RUN_FILE),
                reason: e.to_string(),
            })?;
        Ok(Self {
            record,
            record_json,
            env,
            env_params,
        })
    }
}

/// `run.json`, `system_info.json` and the operative config of a run that starts training.
pub(crate) fn write_run_files(
    run: &RunDir,
    record_json: &[u8],
    plan: &ExperimentPlan,
) -> Result<()> {
    write_atomic(&run.file(RUN_FILE), record_json).map_err(io_err(&run.file(RUN_FILE)))?;
    write_json_atomic(&run.file(SYSTEM_INFO_FILE), &SystemInfo::current())?;
    if let Some(write) = &plan.operative {
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

/// Trains one job (see [`train`]).
pub fn train_one(registry: &Registry, job: &RunJob, opts: &TrainOptions) -> Result<RunOutcome> {
    Ok(train_run(registry, job, opts)?.outcome)
}

/// Trains one job (see [`train`]), reporting whether it resumed and what went wrong on the way.
pub fn train_run(registry: &Registry, job: &RunJob, opts: &TrainOptions) -> Result<RunReport> {
    let plan = &job.plan;
    let dir = plan.run_dir(job.seed);
    let run = RunDir::new(&dir);
    let skipped = RunReport {
        outcome: RunOutcome::Skipped,
        resumed_from: None,
        warnings: Vec::new(),
    };
    if dir.exists() && run.status()?.is_some_and(|s| s.state.is_complete()) {
        return Ok(skipped);
    }
    // Held until this function returns; `prepare` reads the status again under the lock.
    let _lock = match TrainingLock::acquire(&dir) {
        Ok(lock) => lock,
        Err(PipelineError::Locked(mut runs)) => {
            return Ok(RunReport {
                outcome: RunOutcome::Locked(runs.pop().and_then(|r| r.holder)),
                resumed_from: None,
                warnings: Vec::new(),
            });
        }
        Err(e) => return Err(e),
    };
    let algo_entry = registry.algorithm(&plan.algorithm.name)?;
    let algo_params = a2perf_core::Params::resolve(&algo_entry.params, &plan.algorithm.params)
        .map_err(|source| a2perf_core::RegistryError::Param {
            context: format!("algorithm {}", plan.algorithm.name),
            source,
        })?;
    let algorithm = super::AlgorithmSpec {
        name: plan.algorithm.name.clone(),
        params: algo_params.values().clone(),
    };
    let PlannedRun {
        record_json,
        env,
        env_params,
        ..
    } = PlannedRun::new(registry, job, algorithm, None)?;
    let factory = move |_i: usize| (env.make)(&env_params);
    let mut warnings = Vec::new();
    let mut retried = false;
    loop {
        let (point, mut segments) = match prepare(&run, &record_json, &mut warnings)? {
            Start::Skip => return Ok(skipped),
            Start::Fresh => (None, TrainSegments::default()),
            Start::Resume(point, segments) => (Some(*point), segments),
        };
        write_run_files(&run, &record_json, plan)?;
        let point = match point {
            Some(mut p) => {
                remove_checkpoints_after(&run, p.progress.env_steps)?;
                // The curve's clock goes on from the time already spent on the run, so that it
                // stays comparable with the summed wall-clock time of `train_system.json`.
                let spent: f64 = segments
                    .segments
                    .iter()
                    .filter_map(|s| s.system.as_ref().map(|x| x.wall_clock_s))
                    .sum();
                p.progress.clock_s = p.progress.clock_s.max(spent);
                run.set_status(
                    RunState::Running,
                    &format!(
                        "resumed from step {} (segment {})",
                        p.progress.env_steps,
                        segments.segments.len() + 1
                    ),
                )?;
                Some(p)
            }
            None => None,
        };
        let started_at_step = point.as_ref().map_or(0, |p| p.progress.env_steps);
        segments.segments.push(TrainSegment {
            started_at_step,
            outcome: SegmentOutcome::Running,
            system: None,
            resume_points: Vec::new(),
            warnings: warnings.clone(),
        });
        write_json_atomic(&run.file(TRAIN_SEGMENTS_FILE), &segments)?;

        let mut algorithm =
            registry.make_algorithm(&plan.algorithm.name, &plan.algorithm.params)?;
        let mut sink = DirectoryCheckpoints::new(run.file(CHECKPOINT_DIR))
            .with_resume_dir(run.file(RESUME_DIR));
        let meters = (opts.meters)(Phase::Train, &dir, &plan.metrics);
        let offered = point.is_some();
        let ((result, curve, resumed_from, ctx_warnings, writes), system) =
            measured(meters, || {
                let mut ctx = TrainingContext::new(
                    &factory,
                    job.seed,
                    plan.training.clone(),
                    &mut sink,
                    opts.cancel.clone(),
                );
                if let Some(p) = point {
                    ctx = ctx.with_resume(p);
                }
                let r = algorithm.train(&mut ctx);
                let resumed_from = ctx.resumed_from();
                let warnings = ctx.warnings().to_vec();
                let writes = ctx.resume_writes().to_vec();
                (r, ctx.take_curve(), resumed_from, warnings, writes)
            });
        warnings.extend(ctx_warnings);
        if offered && resumed_from.is_none() {
            // The algorithm trained from scratch: earlier segments' work is not part of this run.
            let this = segments.segments.pop();
            segments.segments = this.into_iter().collect();
        }
        let outcome = match &result {
            Ok(_) => SegmentOutcome::Completed,
            Err(RunError::Cancelled) => SegmentOutcome::Interrupted,
            Err(_) => SegmentOutcome::Failed,
        };
        if let Some(seg) = segments.segments.last_mut() {
            seg.outcome = outcome;
            seg.system = Some(system);
            seg.resume_points = writes.clone();
            seg.warnings = warnings.clone();
        }
        write_json_atomic(&run.file(TRAIN_SEGMENTS_FILE), &segments)?;
        let report = |outcome| RunReport {
            outcome,
            resumed_from,
            warnings: warnings.clone(),
        };
        let policy = match result {
            Ok(p) => p,
            Err(RunError::Cancelled) => {
                let note = match writes.last().map(|w| w.env_steps).or(resumed_from) {
                    Some(step) => format!("interrupted; a rerun continues from step {step}"),
                    None => "interrupted before its first resume point; a rerun trains it \
                             from scratch"
                        .into(),
                };
                run.set_status(RunState::Interrupted, &note)?;
                return Ok(report(RunOutcome::Cancelled));
            }
            Err(RunError::Resume(why)) if resumed_from.is_some() && !retried => {
                // The algorithm cannot read its own state (another version wrote it): start
                // over rather than fail again on every rerun.
                warnings.push(format!(
                    "cannot resume from step {}: {why}; trained from scratch",
                    resumed_from.unwrap_or(0)
                ));
                wipe(&run)?;
                retried = true;
                continue;
            }
            Err(e) => {
                let why = e.to_string();
                run.set_status(RunState::Failed, &format!("failed: {why}"))?;
                return Ok(report(RunOutcome::Failed(why)));
            }
        };
        let ckpt = policy.checkpoint().map_err(|e| PipelineError::Run {
            run: dir.display().to_string(),
            source: e.into(),
        })?;
        write_atomic(&run.file(POLICY_FILE), &ckpt.to_bytes())
            .map_err(io_err(&run.file(POLICY_FILE)))?;
        write_curve(&run, &curve)?;
        write_train_system(&run, &segments)?;
        // Resume points are only good for an unfinished run, and off-policy ones hold the whole
        // replay buffer.
        ResumeDir::new(run.file(RESUME_DIR))
            .clear()
            .map_err(io_err(&run.file(RESUME_DIR)))?;
        let note = match segments.segments.len() {
            1 => "trained".to_string(),
            n => format!("trained in {n} segments (interrupted and resumed)"),
        };
        run.set_status(RunState::Complete, &note)?;
        return Ok(report(RunOutcome::Completed));
    }
}
