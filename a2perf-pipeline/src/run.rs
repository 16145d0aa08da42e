//! `a2perf run`: train → infer → generalize → report in one call, resumable phase by phase.

use std::path::{Path, PathBuf};

use a2perf_core::{CancelToken, Registry};

use crate::error::io_err;
use crate::isolate::{ChildTask, Isolation};
use crate::plan::DatasetSource;
use crate::report::{Report, ReportOptions};
use crate::run_dir::{CHECKPOINT_DIR, DATASET_REQUEST_FILE, POLICY_FILE};
use crate::train::{MeterFactory, RunReport, TrainOptions, TrainSummary, no_meters};
use crate::{
    ExperimentPlan, GENERALIZATION_FILE, GeneralizationResults, INFERENCE_FILE, InferOptions,
    InferenceResults, LoadedRun, MetricSettings, PipelineError, Result,
};

pub use crate::run_dir::expand_runs;

/// Options of [`run_experiments`].
#[derive(Clone)]
pub struct RunOptions {
    /// Runs trained at the same time (0 = one per logical CPU).
    pub jobs: usize,
    /// Stops the chain at the next run boundary (training runs stop at their next progress call).
    pub cancel: CancelToken,
    /// System meters for training and inference.
    pub meters: MeterFactory,
    /// Show progress bars.
    pub show_progress: bool,
    /// Report directory (default: `report/` in the first experiment directory).
    pub report_dir: Option<PathBuf>,
    /// Where each run trains, infers and generalizes: in this process, or in child processes of
    /// its own ([`Isolation::Children`]: its system figures are then its alone).
    pub isolation: Isolation,
}

impl Default for RunOptions {
    fn default() -> Self {
        Self {
            jobs: 1,
            cancel: CancelToken::new(),
            meters: no_meters(),
            show_progress: false,
            report_dir: None,
            isolation: Isolation::InProcess,
        }
    }
}

/// What [`run_experiments`] has just done, for a front end to print.
#[derive(Debug)]
pub enum RunEvent<'a> {
    /// A phase starts (`train`, `collect`, `infer`, `generalize`, `report`).
    Phase(&'static str),
    /// Training of every run finished (or was skipped because complete).
    Trained(&'a TrainSummary),
    /// One run was inferred.
    Inferred(&'a Path, &'a InferenceResults),
    /// One run was generalized.
    Generalized(&'a Path, &'a GeneralizationResults),
    /// The report was written to the directory.
    Reported(&'a Path, &'a Report),
}

/// The bootstrap repetitions recorded by the first run below `dirs` (the config's
/// `metrics.bootstrap_reps`), else the default.
pub fn recorded_bootstrap_reps(dirs: &[PathBuf]) -> Result<usize> {
    for d in dirs {
        if let Some(run) = crate::find_runs(d)?.first() {
            return Ok(LoadedRun::open(run)?.record.metrics.bootstrap_reps);
        }
    }
    Ok(MetricSettings::default().bootstrap_reps)
}

/// Turns a training summary into an error when runs were cancelled, failed, or left alone because
/// another trainer holds them ([`PipelineError::Locked`]: they are not complete, so nothing may
/// infer or report them as if they were).
pub fn check_trained(summary: &TrainSummary, cancel: &CancelToken) -> Result<()> {
    if cancel.is_cancelled() {
        return Err(PipelineError::Cancelled);
    }
    let failures = summary.failures();
    if !failures.is_empty() {
        let list: Vec<String> = failures
            .iter()
            .map(|(dir, why)| format!("{}: {why}", dir.display()))
            .collect();
        return Err(PipelineError::Invalid(format!(
            "{} run(s) failed: {}",
            failures.len(),
            list.join("; ")
        )));
    }
    let locked = summary.locked();
    if !locked.is_empty() {
        return Err(PipelineError::Locked(locked));
    }
    Ok(())
}

/// Collects the dataset of an experiment whose suite entry names one (`plan.dataset_from`), from
/// the (trained) runs of its source experiments, and records its provenance in the plan. Nothing
/// is collected when every run of the experiment is complete (the training phase skips them) and
/// the dataset exists; otherwise it is collected again — deterministically, so an interrupted
/// run resumes on the same data.
pub fn collect_dataset(
    registry: &Registry,
    plan: &mut ExperimentPlan,
    show_progress: bool,
) -> Result<()> {
    let Some(source) = plan.dataset_from.clone() else {
        return Ok(());
    };
    let complete = plan.seeds.iter().all(|s| {
        a2perf_core::RunDir::new(plan.run_dir(*s))
            .is_complete()
            .unwrap_or(false)
    });
    // A dataset whose recorded request matches (same step, same source checkpoints) is reused:
    // collection is seeded, so collecting it again would write the same samples. The sources'
    // checkpoints are hashed only when the trained runs do not already settle it.
    if !(complete && source.samples.is_file()) {
        let request = dataset_request(&source)?;
        let request_file = source.out.join(DATASET_REQUEST_FILE);
        let recorded = std::fs::read(&request_file).ok();
        if source.samples.is_file() && recorded.as_deref() == Some(request.as_slice()) {
            return attach_dataset(plan);
        }
        let level = source.step.level()?;
        let mut opts = source.step.collect_options()?;
        opts.show_progress = show_progress;
        let summary = crate::collect::collect_levels(
            registry,
            &source.runs,
            &source.out,
            &mut crate::RegistryPolicies(registry),
            &opts,
            &[level],
        )?;
        if !summary.datasets.iter().any(|d| d.level == level) {
            return Err(PipelineError::Invalid(format!(
                "experiment `{}`: no checkpoint of {} reached the `{}` level, so there is no \
                 dataset to train on (give its suite entry another `level`, or `one_sigma: true`)",
                plan.name,
                source.step.from.join(", "),
                level.name()
            )));
        }
        a2perf_core::write_atomic(&request_file, &request).map_err(io_err(&request_file))?;
    }
    attach_dataset(plan)
}

/// The request a dataset step collects for, as bytes: the step's settings and, per source run,
/// the sha256 of its final policy and of every checkpoint it kept.
fn dataset_request(source: &DatasetSource) -> Result<Vec<u8>> {
    let mut runs = Vec::with_capacity(source.runs.len());
    for run in &source.runs {
        let mut files = vec![run.join(POLICY_FILE)];
        if let Ok(entries) = std::fs::read_dir(run.join(CHECKPOINT_DIR)) {
            let mut kept: Vec<PathBuf> = entries.filter_map(|e| e.ok().map(|e| e.path())).collect();
            kept.sort();
            files.extend(kept);
        }
        let mut hashes = serde_json::Map::new();
        for f in files.iter().filter(|f| f.is_file()) {
            let bytes = std::fs::read(f).map_err(io_err(f))?;
            let name = f
                .strip_prefix(run)
                .unwrap_or(f)
                .to_string_lossy()
                .into_owned();
            hashes.insert(name, crate::bundle::sha256_hex(&bytes).into());
        }
        runs.push(serde_json::json!({ "run": run, "sha256": hashes }));
    }
    let request = serde_json::json!({ "step": source.step, "runs": runs });
    serde_json::to_vec_pretty(&request).map_err(|e| PipelineError::Invalid(e.to_string()))
}

/// Records in `plan` the provenance of the dataset its suite collected for it (nothing for a
/// plan without a suite dataset step).
fn attach_dataset(plan: &mut ExperimentPlan) -> Result<()> {
    if let Some(source) = &plan.dataset_from {
        let samples = source.samples.to_string_lossy().into_owned();
        plan.dataset = crate::collect::dataset_info_for(&source.samples)?
            .map(|info| crate::DatasetProvenance::from_info(&info, &samples));
    }
    Ok(())
}

/// Trains the one run of `plans` whose directory is `run`, in this process: the child side of
/// [`Isolation::Children`]. The child builds `plans` from the same configs as its parent, so the
/// run is the one the parent would have trained; a run whose suite collects its dataset gets
/// that dataset's provenance, as [`collect_dataset`] gives it in the parent.
pub fn train_run_at(
    registry: &Registry,
    plans: &[ExperimentPlan],
    run: &Path,
    opts: &TrainOptions,
) -> Result<RunReport> {
    let (plan, seed) = plans
        .iter()
        .find_map(|p| {
            p.seeds
                .iter()
                .find(|s| p.run_dir(**s) == run)
                .map(|s| (p, *s))
        })
        .ok_or_else(|| {
            PipelineError::Invalid(format!(
                "{}: no run of these configs has this directory",
                run.display()
            ))
        })?;
    let mut plan = plan.clone();
    attach_dataset(&mut plan)?;
    crate::train::preflight(registry, &crate::grid(std::slice::from_ref(&plan), None))?;
    let job = crate::RunJob {
        index: 0,
        plan,
        seed,
    };
    crate::train::train_run(registry, &job, opts)
}

/// Trains every run of `plans`, an experiment whose dataset the suite collects from other
/// experiments ([`ExperimentPlan::dataset_from`]) in a second stage: first every other run is
/// trained, then the datasets are collected ([`collect_dataset`]), then those experiments are
/// trained. Reports each stage through `on_event` (`Trained`, and `Phase("collect")` /
/// `Phase("train")` between the stages); stops with an error when a run failed or `opts.cancel`
/// fired.
pub fn train_with_datasets(
    registry: &Registry,
    plans: &[ExperimentPlan],
    opts: &TrainOptions,
    on_event: &mut dyn FnMut(RunEvent<'_>),
) -> Result<()> {
    let (direct, dependent): (Vec<ExperimentPlan>, Vec<ExperimentPlan>) = plans
        .iter()
        .cloned()
        .partition(|p| p.dataset_from.is_none());
    let summary = crate::train(registry, &crate::grid(&direct, None), opts)?;
    on_event(RunEvent::Trained(&summary));
    check_trained(&summary, &opts.cancel)?;
    if dependent.is_empty() {
        return Ok(());
    }
    on_event(RunEvent::Phase("collect"));
    let mut ready = Vec::with_capacity(dependent.len());
    for mut plan in dependent {
        if opts.cancel.is_cancelled() {
            return Err(PipelineError::Cancelled);
        }
        collect_dataset(registry, &mut plan, opts.show_progress)?;
        ready.push(plan);
    }
    on_event(RunEvent::Phase("train"));
    let summary = crate::train(registry, &crate::grid(&ready, None), opts)?;
    on_event(RunEvent::Trained(&summary));
    check_trained(&summary, &opts.cancel)
}

/// Trains every run of `plans`, then infers and generalizes each (skipping runs whose
/// `inference.json` / `generalization.json` already exist: a retrained run starts from an empty
/// directory, so its old results cannot linger), then writes the report. Returns the report
/// directory.
///
/// Training is [`train_with_datasets`]: an experiment whose dataset comes from other experiments
/// of the suite is trained after them.
pub fn run_experiments(
    registry: &Registry,
    plans: &[ExperimentPlan],
    opts: &RunOptions,
    on_event: &mut dyn FnMut(RunEvent<'_>),
) -> Result<PathBuf> {
    if plans.is_empty() {
        return Err(PipelineError::Invalid("no experiments to run".into()));
    }
    let cancel = &opts.cancel;
    on_event(RunEvent::Phase("train"));
    let train_opts = TrainOptions {
        jobs: opts.jobs,
        cancel: cancel.clone(),
        meters: opts.meters.clone(),
        show_progress: opts.show_progress,
        isolation: opts.isolation.clone(),
    };
    train_with_datasets(registry, plans, &train_opts, on_event)?;

    let mut experiments: Vec<PathBuf> = plans.iter().map(ExperimentPlan::experiment_dir).collect();
    experiments.dedup();
    let runs: Vec<PathBuf> = plans
        .iter()
        .flat_map(|p| p.seeds.iter().map(|s| p.run_dir(*s)))
        .collect();

    on_event(RunEvent::Phase("infer"));
    let infer_opts = InferOptions {
        meters: opts.meters.clone(),
        show_progress: opts.show_progress,
        ..Default::default()
    };
    // In this process the meters measure the whole process, so runs infer one at a time;
    // under `--isolate` each run infers in a child of its own, so `--jobs` children run at once
    // and every run's figures stay its own.
    let workers = match &opts.isolation {
        Isolation::InProcess => 1,
        Isolation::Children(_) => resolve_jobs(opts.jobs),
    };
    let todo: Vec<&PathBuf> = runs
        .iter()
        .filter(|d| !d.join(INFERENCE_FILE).is_file())
        .collect();
    let inferred = pooled(&todo, workers, cancel, |dir| match &opts.isolation {
        Isolation::InProcess => crate::infer_run(registry, dir, &infer_opts),
        Isolation::Children(command) => {
            crate::isolate::phase_in_child(command, ChildTask::Infer { run: dir }, cancel)?;
            read_result::<InferenceResults>(&dir.join(INFERENCE_FILE))
        }
    })?;
    for (dir, r) in todo.iter().zip(&inferred) {
        on_event(RunEvent::Inferred(dir, r));
    }

    on_event(RunEvent::Phase("generalize"));
    let todo: Vec<&PathBuf> = runs
        .iter()
        .filter(|d| !d.join(GENERALIZATION_FILE).is_file())
        .collect();
    let generalized = pooled(&todo, workers, cancel, |dir| match &opts.isolation {
        Isolation::InProcess => crate::generalize_run(registry, dir, None, opts.show_progress),
        Isolation::Children(command) => {
            crate::isolate::phase_in_child(command, ChildTask::Generalize { run: dir }, cancel)?;
            read_result::<GeneralizationResults>(&dir.join(GENERALIZATION_FILE))
        }
    })?;
    for (dir, r) in todo.iter().zip(&generalized) {
        on_event(RunEvent::Generalized(dir, r));
    }

    on_event(RunEvent::Phase("report"));
    let out = opts
        .report_dir
        .clone()
        .unwrap_or_else(|| experiments[0].join("report"));
    let report_opts = ReportOptions {
        bootstrap_reps: recorded_bootstrap_reps(&experiments)?,
        seed: 0,
    };
    let report = crate::report::write_report(&experiments, &out, &report_opts)?;
    on_event(RunEvent::Reported(&out, &report));
    Ok(out)
}

/// Worker threads for `jobs` (0 = one per logical CPU).
fn resolve_jobs(jobs: usize) -> usize {
    match jobs {
        0 => std::thread::available_parallelism().map_or(1, |n| n.get()),
        n => n,
    }
}

/// `phase` of every run of `dirs`, on up to `workers` threads, results in the order of `dirs`.
/// Every run is attempted (until a cancel); the first error in that order is returned, so that
/// one failing run does not lose the results of the others already written.
fn pooled<T: Send>(
    dirs: &[&PathBuf],
    workers: usize,
    cancel: &CancelToken,
    phase: impl Fn(&Path) -> Result<T> + Sync,
) -> Result<Vec<T>> {
    let next = std::sync::atomic::AtomicUsize::new(0);
    let slots: Vec<std::sync::Mutex<Option<Result<T>>>> =
        dirs.iter().map(|_| std::sync::Mutex::new(None)).collect();
    std::thread::scope(|scope| {
        for _ in 0..workers.clamp(1, dirs.len().max(1)) {
            scope.spawn(|| {
                loop {
                    let i = next.fetch_add(1, std::sync::atomic::Ordering::SeqCst);
                    let Some(dir) = dirs.get(i) else { break };
                    let r = if cancel.is_cancelled() {
                        Err(PipelineError::Cancelled)
                    } else {
                        phase(dir)
                    };
                    if let Ok(mut slot) = slots[i].lock() {
                        *slot = Some(r);
                    }
                }
            });
        }
    });
    slots
        .into_iter()
        .map(|s| {
            s.into_inner()
                .ok()
                .flatten()
                .unwrap_or_else(|| Err(PipelineError::Invalid("a worker thread panicked".into())))
        })
        .collect()
}

/// A results file a child process wrote.
fn read_result<T: serde::de::DeserializeOwned>(path: &Path) -> Result<T> {
    let bytes = std::fs::read(path).map_err(|e| {
        PipelineError::Invalid(format!(
            "{}: not written by its process: {e}",
            path.display()
        ))
    })?;
    serde_json::from_slice(&bytes)
        .map_err(|e| PipelineError::Invalid(format!("{}: {e}", path.display())))
}
