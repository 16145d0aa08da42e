//! `a2perf train`: one resumable run per (task, algorithm, seed).

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Instant;

use a2perf_core::{
    CancelToken, DirectoryCheckpoints, Meter, MeterReport, MeterSet, Registry, RunDir, RunError,
    RunState, TrainingContext, write_atomic, write_json_atomic,
};
use serde::{Deserialize, Serialize};

use super::plan::{MetricSettings, RunJob};
use super::{
    CHECKPOINT_DIR, CURVE_CSV, CURVE_JSON, OPERATIVE_FILE, POLICY_FILE, PipelineError, RUN_FILE,
    RUN_FORMAT_VERSION, Result, RunRecord, SYSTEM_INFO_FILE, SystemInfo, TRAIN_SYSTEM_FILE, io_err,
    progress,
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
    /// Ctrl-C: stops the runs in flight (left resumable) and starts no new ones.
    pub cancel: CancelToken,
    /// System meters.
    pub meters: MeterFactory,
    /// Show a progress bar.
    pub show_progress: bool,
}

impl Default for TrainOptions {
    fn default() -> Self {
        Self {
            jobs: 1,
            cancel: CancelToken::new(),
            meters: no_meters(),
            show_progress: false,
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
    /// What the meters reported.
    pub meters: MeterReport,
    /// Meters that failed, and why (their values are then missing, never zero).
    pub meter_errors: Vec<String>,
}

/// What happened to one run.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum RunOutcome {
    /// Trained to completion now.
    Completed,
    /// Already complete on disk; not redone.
    Skipped,
    /// Stopped by the cancel token; the directory is marked incomplete and will be redone.
    Cancelled,
    /// Training failed; the directory is marked incomplete with the reason.
    Failed(String),
}

/// Outcome of [`train`].
#[derive(Clone, Debug, Default)]
pub struct TrainSummary {
    /// Run directories with their outcome, in grid order.
    pub runs: Vec<(PathBuf, RunOutcome)>,
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

/// Runs `f` between the start and the finish of `meters`, recording wall-clock time. Meter
/// failures are recorded, not fatal: a missing figure is reported as missing.
pub(crate) fn measured<T>(meters: Vec<Box<dyn Meter>>, f: impl FnOnce() -> T) -> (T, PhaseSystem) {
    let mut set = MeterSet::new(meters);
    let mut errors = Vec::new();
    let mut active = ActiveRun::enter();
    let started_ok = match set.start() {
        Ok(()) => true,
        Err(e) => {
            errors.push(e.to_string());
            false
        }
    };
    let t = Instant::now();
    let out = f();
    let wall = t.elapsed().as_secs_f64();
    let meters = if started_ok {
        set.finish().unwrap_or_else(|e| {
            errors.push(e.to_string());
            MeterReport::default()
        })
    } else {
        MeterReport::default()
    };
    let concurrent_runs = active.observe();
    (
        out,
        PhaseSystem {
            wall_clock_s: wall,
            concurrent_runs,
            meters,
            meter_errors: errors,
        },
    )
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

/// Trains every job, `opts.jobs` at a time. Complete runs are skipped; incomplete ones are redone
/// from scratch (training is deterministic, so the result is the same as an uninterrupted run).
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
    let results: Mutex<Vec<Option<Result<RunOutcome>>>> =
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
                    let r = train_one(registry, job, opts);
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
            Some(Ok(outcome)) => summary.runs.push((dir, outcome)),
            Some(Err(e)) => return Err(e),
            // Never started because of cancellation.
            None => summary.runs.push((dir, RunOutcome::Cancelled)),
        }
    }
    Ok(summary)
}

/// Prepares the run directory: `Ok(false)` when the run is already complete.
fn prepare(run: &RunDir) -> Result<bool> {
    let path = run.path();
    if path.exists() {
        match run.status()? {
            Some(s) if s.state == RunState::Complete => return Ok(false),
            Some(_) => {
                // Incomplete: start again from nothing, so stale checkpoints cannot mix in.
                std::fs::remove_dir_all(path).map_err(io_err(path))?;
            }
            None => {
                let mut entries = std::fs::read_dir(path).map_err(io_err(path))?;
                if entries.next().is_some() {
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
    Ok(true)
}

/// Trains one job (see [`train`]).
pub fn train_one(registry: &Registry, job: &RunJob, opts: &TrainOptions) -> Result<RunOutcome> {
    let plan = &job.plan;
    let dir = plan.run_dir(job.seed);
    let run = RunDir::new(&dir);
    if !prepare(&run)? {
        return Ok(RunOutcome::Skipped);
    }
    let entry = registry.env(&plan.task.env_id)?.clone();
    let env_params = registry.env_params(&plan.task.env_id, &plan.task.env_params)?;
    let algo_entry = registry.algorithm(&plan.algorithm.name)?;
    let algo_params = a2perf_core::Params::resolve(&algo_entry.params, &plan.algorithm.params)
        .map_err(|source| a2perf_core::RegistryError::Param {
            context: format!("algorithm {}", plan.algorithm.name),
            source,
        })?;
    let probe = (entry.make)(&env_params).map_err(|source| a2perf_core::RegistryError::Env {
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
        domain: entry.domain.clone(),
        algorithm: super::AlgorithmSpec {
            name: plan.algorithm.name.clone(),
            params: algo_params.values().clone(),
        },
        seed: job.seed,
        training: plan.training.clone(),
        inference: plan.inference.clone(),
        generalization: plan.generalization.clone(),
        metrics: plan.metrics.clone(),
        env_metadata,
        dataset: plan.dataset.clone(),
    };
    write_json_atomic(&run.file(RUN_FILE), &record)?;
    write_json_atomic(&run.file(SYSTEM_INFO_FILE), &SystemInfo::current())?;
    if let Some(write) = &plan.operative {
        write(run.path()).map_err(|reason| PipelineError::Corrupt {
            path: run.file(OPERATIVE_FILE),
            reason,
        })?;
    }

    let mut algorithm = registry.make_algorithm(&plan.algorithm.name, &plan.algorithm.params)?;
    let factory = move |_i: usize| (entry.make)(&env_params);
    let mut sink = DirectoryCheckpoints::new(run.file(CHECKPOINT_DIR));
    let meters = (opts.meters)(Phase::Train, &dir, &plan.metrics);
    let ((result, curve), system) = measured(meters, || {
        let mut ctx = TrainingContext::new(
            &factory,
            job.seed,
            plan.training.clone(),
            &mut sink,
            opts.cancel.clone(),
        );
        let r = algorithm.train(&mut ctx);
        (r, ctx.take_curve())
    });
    let policy = match result {
        Ok(p) => p,
        Err(RunError::Cancelled) => {
            run.set_status(RunState::Running, "cancelled; will be redone")?;
            return Ok(RunOutcome::Cancelled);
        }
        Err(e) => {
            let why = e.to_string();
            run.set_status(RunState::Running, &format!("failed: {why}"))?;
            return Ok(RunOutcome::Failed(why));
        }
    };
    let ckpt = policy.checkpoint().map_err(|e| PipelineError::Run {
        run: dir.display().to_string(),
        source: e.into(),
    })?;
    write_atomic(&run.file(POLICY_FILE), &ckpt.to_bytes())
        .map_err(io_err(&run.file(POLICY_FILE)))?;
    let mut csv = String::from("env_steps,mean_return,std_return,wall_seconds\n");
    for p in &curve.points {
        csv.push_str(&format!(
            "{},{},{},{}\n",
            p.env_steps, p.mean_return, p.std_return, p.wall_seconds
        ));
    }
    write_atomic(&run.file(CURVE_CSV), csv.as_bytes()).map_err(io_err(&run.file(CURVE_CSV)))?;
    write_json_atomic(&run.file(CURVE_JSON), &curve)?;
    write_json_atomic(&run.file(TRAIN_SYSTEM_FILE), &system)?;
    run.set_status(RunState::Complete, "trained")?;
    Ok(RunOutcome::Completed)
}
