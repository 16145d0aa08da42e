//! `a2perf run`: train → infer → generalize → report in one call, resumable phase by phase.

use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use a2perf_core::{CancelToken, Registry};

use crate::error::io_err;
use crate::isolate::{ChildTask, Isolation};
use crate::phase::ActiveRun;
use crate::plan::DatasetSource;
use crate::pool::{self, Event, Slot};
use crate::progress;
use crate::report::{Report, ReportOptions};
use crate::run_dir::{CHECKPOINT_DIR, DATASET_REQUEST_FILE, POLICY_FILE};
use crate::train::{MeterFactory, RunOutcome, RunReport, TrainOptions, TrainSummary, no_meters};
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
    /// A phase starts (`train`, `infer`, `generalize`, `report`).
    Phase(&'static str),
    /// A task of the training pool started: training a run, or collecting the dataset of an
    /// experiment as soon as the runs it is collected from are trained.
    Started(&'a TrainTask),
    /// A task of the training pool ended (its outcome is in the next [`RunEvent::Trained`]).
    Finished(&'a TrainTask),
    /// Training of every run finished (or was skipped because complete).
    Trained(&'a TrainSummary),
    /// One run was inferred.
    Inferred(&'a Path, &'a InferenceResults),
    /// One run was generalized.
    Generalized(&'a Path, &'a GeneralizationResults),
    /// The report was written to the directory.
    Reported(&'a Path, &'a Report),
}

/// A task of the training pool of [`train_with_datasets`], as its [`RunEvent`]s name it.
///
/// ```
/// use a2perf_pipeline::run::TrainTask;
/// let task = TrainTask::Collect("bc_dog_pace".into());
/// assert_eq!(task.to_string(), "collect the dataset of `bc_dog_pace`");
/// ```
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum TrainTask {
    /// Training the run in this directory.
    Run(PathBuf),
    /// Collecting the dataset of the experiment with this name from its source runs.
    Collect(String),
}

impl std::fmt::Display for TrainTask {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            TrainTask::Run(dir) => write!(f, "train {}", dir.display()),
            TrainTask::Collect(name) => write!(f, "collect the dataset of `{name}`"),
        }
    }
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
    let listed = |what: &str, runs: Vec<(&Path, &str)>| {
        let list: Vec<String> = runs
            .iter()
            .map(|(dir, why)| format!("{}: {why}", dir.display()))
            .collect();
        format!("{} run(s) {what}: {}", runs.len(), list.join("; "))
    };
    let blocked = summary.blocked();
    let not_started = (!blocked.is_empty()).then(|| listed("not started", blocked));
    let failures = summary.failures();
    if !failures.is_empty() {
        let mut why = listed("failed", failures);
        if let Some(blocked) = not_started {
            why = format!("{why}; {blocked}");
        }
        return Err(PipelineError::Invalid(why));
    }
    let locked = summary.locked();
    if !locked.is_empty() {
        return Err(PipelineError::Locked(locked));
    }
    match not_started {
        Some(why) => Err(PipelineError::Invalid(why)),
        None => Ok(()),
    }
}

/// Collects the dataset of an experiment whose suite entry names one (`plan.dataset_from`), from
/// the (trained) runs of its source experiments, and records its provenance in the plan. Nothing
/// is collected when every run of the experiment is complete (the training phase skips them) and
/// the dataset exists; otherwise it is collected again — deterministically, so an interrupted
/// run resumes on the same data. Stops before its next episode once `cancel` fires
/// ([`PipelineError::Cancelled`]), leaving no partial dataset.
pub fn collect_dataset(
    registry: &Registry,
    plan: &mut ExperimentPlan,
    show_progress: bool,
    cancel: &CancelToken,
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
        opts.cancel = cancel.clone();
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

/// What a task of [`train_with_datasets`]' pool does.
#[derive(Clone, Copy)]
enum Work {
    /// Trains `jobs[job]`, a run of `plans[plan]`.
    Run { job: usize, plan: usize },
    /// Collects the dataset of `plans[plan]`.
    Collect { plan: usize },
}

/// The tasks of [`train_with_datasets`] in plan order (before the first run of an experiment
/// whose suite collects its dataset, that collection), with the tasks each waits for.
struct Schedule {
    jobs: Vec<crate::RunJob>,
    work: Vec<Work>,
    tasks: Vec<TrainTask>,
    deps: Vec<Vec<usize>>,
}

impl Schedule {
    fn of(plans: &[ExperimentPlan]) -> Self {
        let jobs = crate::grid(plans, None);
        let mut s = Schedule {
            jobs: Vec::with_capacity(jobs.len()),
            work: Vec::new(),
            tasks: Vec::new(),
            deps: Vec::new(),
        };
        let mut jobs = jobs.into_iter();
        let mut run_task = std::collections::BTreeMap::new();
        let mut collects = Vec::new();
        for (p, plan) in plans.iter().enumerate() {
            let collect = plan.dataset_from.as_ref().map(|source| {
                collects.push((s.work.len(), source));
                s.push(
                    Work::Collect { plan: p },
                    TrainTask::Collect(plan.name.clone()),
                    vec![],
                )
            });
            for job in jobs.by_ref().take(plan.seeds.len()) {
                let dir = job.plan.run_dir(job.seed);
                run_task.insert(dir.clone(), s.work.len());
                let work = Work::Run {
                    job: s.jobs.len(),
                    plan: p,
                };
                s.jobs.push(job);
                s.push(work, TrainTask::Run(dir), collect.into_iter().collect());
            }
        }
        // A source run outside `plans` is not waited for: collecting checks that it is complete.
        for (task, source) in collects {
            s.deps[task] = source
                .runs
                .iter()
                .filter_map(|r| run_task.get(r).copied())
                .collect();
        }
        s
    }

    fn push(&mut self, work: Work, task: TrainTask, deps: Vec<usize>) -> usize {
        self.work.push(work);
        self.tasks.push(task);
        self.deps.push(deps);
        self.work.len() - 1
    }

    /// Why a task that waited for task `by` (which did not succeed) did not start.
    fn blocked_by(&self, by: usize) -> String {
        match &self.tasks[by] {
            TrainTask::Run(dir) => format!(
                "not trained: the dataset it trains on is collected from {}, which did not \
                 complete",
                dir.display()
            ),
            TrainTask::Collect(name) => {
                format!("not trained: collecting the dataset of `{name}` failed")
            }
        }
    }
}

/// What a task of [`train_with_datasets`]' pool produced.
enum Done {
    Run(Result<RunReport>),
    Collect(Result<()>),
}

impl Done {
    /// Whether the tasks waiting for this one may start: a trained (or already complete) run, a
    /// collected dataset.
    fn succeeded(&self) -> bool {
        match self {
            Done::Run(Ok(r)) => matches!(r.outcome, RunOutcome::Completed | RunOutcome::Skipped),
            Done::Collect(r) => r.is_ok(),
            Done::Run(Err(_)) => false,
        }
    }
}

/// Trains every run of `plans` in one pool of `opts.jobs` workers, with the datasets of
/// experiments that train on one their suite collects ([`ExperimentPlan::dataset_from`]): each
/// such dataset is collected ([`collect_dataset`]) in the pool as soon as the runs it is
/// collected from are trained, while other runs go on training, and its experiment's runs train
/// right after. Reports each task as it starts and ends ([`RunEvent::Started`],
/// [`RunEvent::Finished`]) and then the whole training ([`RunEvent::Trained`]); stops with an
/// error when a run failed (naming it, and the runs that could not start without it), a dataset
/// could not be collected, or `opts.cancel` fired. Runs that do not depend on a failure are
/// trained all the same.
pub fn train_with_datasets(
    registry: &Registry,
    plans: &[ExperimentPlan],
    opts: &TrainOptions,
    on_event: &mut dyn FnMut(RunEvent<'_>),
) -> Result<()> {
    let s = Schedule::of(plans);
    crate::train::preflight(registry, &s.jobs)?;
    let collected: Vec<OnceLock<ExperimentPlan>> = plans.iter().map(|_| OnceLock::new()).collect();
    let work = |i: usize| match s.work[i] {
        Work::Run { job, plan } => {
            let with_dataset;
            let job = match collected[plan].get() {
                Some(attached) => {
                    with_dataset = crate::RunJob {
                        plan: attached.clone(),
                        ..s.jobs[job].clone()
                    };
                    &with_dataset
                }
                None => &s.jobs[job],
            };
            Done::Run(crate::train::train_job(registry, job, opts))
        }
        Work::Collect { plan: p } => {
            // Collection shares the process with the runs training beside it.
            let _active = ActiveRun::enter();
            let mut plan = plans[p].clone();
            // Its bars would fight the pool's; the pool's names the collection.
            let r = collect_dataset(registry, &mut plan, false, &opts.cancel);
            if r.is_ok() {
                let _ = collected[p].set(plan);
            }
            Done::Collect(r)
        }
    };
    let bar = progress::bar(s.tasks.len() as u64, "train", opts.show_progress);
    let slots = pool::run(
        &s.deps,
        pool::workers(opts.jobs),
        &opts.cancel,
        &work,
        &Done::succeeded,
        &mut |event| {
            let (Event::Started(i) | Event::Finished(i)) = event;
            let task = &s.tasks[i];
            match event {
                Event::Started(_) => {
                    bar.set_message(match task {
                        TrainTask::Run(dir) => crate::train::run_name(dir),
                        TrainTask::Collect(name) => format!("collect {name}"),
                    });
                    bar.suspend(|| on_event(RunEvent::Started(task)));
                }
                Event::Finished(_) => {
                    bar.inc(1);
                    bar.suspend(|| on_event(RunEvent::Finished(task)));
                }
            }
        },
    );
    bar.finish_and_clear();
    let mut summary = TrainSummary::default();
    let mut first_error = None;
    for ((slot, task), work) in slots.into_iter().zip(&s.tasks).zip(&s.work) {
        let run = match slot {
            Slot::Done(Done::Run(r)) => Slot::Done(r),
            Slot::Done(Done::Collect(r)) => {
                if let (Err(e), Work::Collect { plan }) = (r, work) {
                    // An interruption is what the pool returns then; the failure is not lost.
                    if opts.cancel.is_cancelled() && !matches!(e, PipelineError::Cancelled) {
                        let out = plans[*plan]
                            .dataset_from
                            .as_ref()
                            .map_or_else(PathBuf::new, |d| d.out.clone());
                        summary.warnings.push((out, format!("{task} failed: {e}")));
                    }
                    first_error.get_or_insert(e);
                }
                continue;
            }
            Slot::Blocked { by } => Slot::Blocked { by },
            Slot::NotRun => Slot::NotRun,
        };
        if let TrainTask::Run(dir) = task
            && let Err(e) = summary.add(dir.clone(), run, |by| s.blocked_by(by))
        {
            first_error.get_or_insert(e);
        }
    }
    on_event(RunEvent::Trained(&summary));
    if opts.cancel.is_cancelled() {
        return Err(PipelineError::Cancelled);
    }
    if let Some(e) = first_error {
        return Err(e);
    }
    check_trained(&summary, &opts.cancel)
}

/// Trains every run of `plans`, then infers and generalizes each (skipping runs whose
/// `inference.json` / `generalization.json` already exist: a retrained run starts from an empty
/// directory, so its old results cannot linger), then writes the report. Returns the report
/// directory.
///
/// Training is [`train_with_datasets`]: an experiment whose dataset comes from other experiments
/// of the suite is trained after them, in the same pool. Inference and generalization run one run
/// at a time in this process, whose meters measure the whole process, and `opts.jobs` runs at
/// once under [`Isolation::Children`], each in a child process of its own.
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
        Isolation::Children(_) => pool::workers(opts.jobs),
    };
    let todo: Vec<&PathBuf> = runs
        .iter()
        .filter(|d| !d.join(INFERENCE_FILE).is_file())
        .collect();
    let inferred = each_run(&todo, workers, cancel, |dir| match &opts.isolation {
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
    let generalized = each_run(&todo, workers, cancel, |dir| match &opts.isolation {
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

/// `phase` of every run of `dirs`, in the pool on up to `workers` threads, results in the
/// order of `dirs`. Every run is attempted (until a cancel); the first error in that order is
/// returned, so that one failing run does not lose the results of the others already written.
fn each_run<T: Send>(
    dirs: &[&PathBuf],
    workers: usize,
    cancel: &CancelToken,
    phase: impl Fn(&Path) -> Result<T> + Sync,
) -> Result<Vec<T>> {
    pool::run(
        &vec![Vec::new(); dirs.len()],
        workers,
        cancel,
        &|i| phase(dirs[i]),
        &|_| true,
        &mut |_| {},
    )
    .into_iter()
    .map(|slot| match slot {
        Slot::Done(r) => r,
        Slot::Blocked { .. } | Slot::NotRun => Err(PipelineError::Cancelled),
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
