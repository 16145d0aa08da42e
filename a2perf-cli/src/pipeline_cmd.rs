//! `a2perf train | infer | generalize | report | run | collect`: the clap front end of the
//! pipelines in `a2perf_pipeline`. Parsing arguments and printing results is all it does.

use std::path::{Path, PathBuf};
use std::time::Duration;

use a2perf_core::Registry;
use a2perf_pipeline::{
    self as pipeline, CancelToken, ExperimentPlan, InferOptions, ObservationSource, TrainOptions,
    collect::{CollectOptions, CostRule},
    report::ReportOptions,
};
use anyhow::{Context, Result};
use clap::{Args, ValueEnum};

/// Arguments of `a2perf train`.
#[derive(Args, Debug)]
pub struct TrainArgs {
    /// Experiment configs (or suite files such as configs/quickstart.ron).
    #[arg(required = true)]
    pub configs: Vec<PathBuf>,
    /// Config override `dotted.path=value`, applied to every experiment (repeatable).
    #[arg(long = "set", value_name = "KEY=VALUE")]
    pub set: Vec<String>,
    /// Seeds, replacing the configs': `0..10`, `0..=9`, `1,3,5`.
    #[arg(long)]
    pub seeds: Option<String>,
    /// Run only shard `i` of `N` of the seed × task grid (0-based, e.g. `$SLURM_ARRAY_TASK_ID/N`).
    #[arg(long, value_name = "i/N")]
    pub shard: Option<String>,
    /// Runs trained at the same time (0 = one per CPU). Meters measure the whole process, so
    /// with more than one the system metrics cover all concurrent runs (the report says so).
    #[arg(long, default_value_t = 1)]
    pub jobs: usize,
    /// After SIGTERM or Ctrl-C, seconds to wait for the runs in flight to write a resume point
    /// at their next safe point; past that the process exits anyway (the runs then continue from
    /// their last interval checkpoint). Exit code 75 either way.
    #[arg(long, value_name = "SECONDS", default_value_t = 30.0)]
    pub preempt_grace: f64,
    /// Train each run in a process of its own (a child of this one), so that its RAM, energy
    /// and time are its alone: not shared with the runs beside it (`--jobs`) nor inflated by
    /// what earlier runs left in the process. Training is the same either way.
    #[arg(long)]
    pub isolate: bool,
    /// Hide progress bars.
    #[arg(long)]
    pub quiet: bool,
    /// The child side of `--isolate`: train only the run in this directory (one of the
    /// configs' runs) ...
    #[arg(long, hide = true, value_name = "DIR", requires = "report_to")]
    pub run_dir: Option<PathBuf>,
    /// ... and write what happened to it (JSON) to this file.
    #[arg(long, hide = true, value_name = "FILE", requires = "run_dir")]
    pub report_to: Option<PathBuf>,
}

/// Arguments of `a2perf infer`.
#[derive(Args, Debug)]
pub struct InferArgs {
    /// Run directories (or experiment directories holding them).
    #[arg(required = true)]
    pub dirs: Vec<PathBuf>,
    /// Greedy rollouts (default: the run's config, 100 unless changed).
    #[arg(long)]
    pub episodes: Option<usize>,
    /// Observations the reported inference time is measured on.
    #[arg(long, value_enum)]
    pub observations: Option<ObsArg>,
    /// Calls timed on random observations (with `--observations random`).
    #[arg(long)]
    pub timing_samples: Option<usize>,
    /// Hide progress bars.
    #[arg(long)]
    pub quiet: bool,
}

/// Which observations `infer` times.
#[derive(Clone, Copy, Debug, ValueEnum)]
pub enum ObsArg {
    /// Every call made during the rollouts.
    Rollouts,
    /// Uniform samples of the observation space (the original harness's method).
    Random,
}

/// Arguments of `a2perf generalize`.
#[derive(Args, Debug)]
pub struct GeneralizeArgs {
    /// Run directories (or experiment directories holding them).
    #[arg(required = true)]
    pub dirs: Vec<PathBuf>,
    /// Rollouts per task (default: the run's config, 100 unless changed).
    #[arg(long)]
    pub episodes: Option<usize>,
    /// Hide progress bars.
    #[arg(long)]
    pub quiet: bool,
}

/// Arguments of `a2perf report`.
#[derive(Args, Debug)]
pub struct ReportArgs {
    /// Experiment directories, run directories or bundle files (`a2perf bundle`); their runs
    /// are merged. Bundles are verified first (one that fails stops the report), and a group
    /// whose runs all come from verified bundles is marked verified.
    #[arg(required = true)]
    pub dirs: Vec<PathBuf>,
    /// Output directory (default: `report/` inside the first directory).
    #[arg(short = 'o', long)]
    pub output: Option<PathBuf>,
    /// Bootstrap resamples for confidence intervals (default: the runs' config, 50,000).
    #[arg(long)]
    pub bootstrap_reps: Option<usize>,
    /// The paper's tables (e.g. docs/paper/tables.json): adds the paper's column beside ours
    /// under every table whose task matches, with a verdict on returns and generalization and
    /// the ratio ours / paper for energy, RAM and wall-clock time; checks the paper's findings
    /// on the runs; writes comparison.json.
    #[arg(long, value_name = "TABLES_JSON")]
    pub paper: Option<PathBuf>,
    /// DIRS are report directories (each with `report.json` and `curves.csv`, e.g.
    /// `docs/results/*/`), not runs: merge them into one page, OUT/index.html, beside the
    /// merged OUT/report.json its numbers refer to (IQMs and probabilities of improvement are
    /// computed again over the merged groups). Needs `-o`, which must not be one of DIRS.
    #[arg(long, requires = "output", conflicts_with_all = ["paper", "bootstrap_reps"])]
    pub from_reports: bool,
    /// Only the verified groups in leaderboard.json (those whose runs all come from bundles
    /// given as inputs, which verified).
    #[arg(long, conflicts_with = "from_reports")]
    pub verified_only: bool,
}

/// Arguments of `a2perf run`.
#[derive(Args, Debug)]
pub struct RunArgs {
    /// Experiment configs or suite files (e.g. configs/quickstart.ron).
    #[arg(required = true)]
    pub configs: Vec<PathBuf>,
    /// Config override `dotted.path=value`, applied to every experiment (repeatable).
    #[arg(long = "set", value_name = "KEY=VALUE")]
    pub set: Vec<String>,
    /// Seeds, replacing the configs'.
    #[arg(long)]
    pub seeds: Option<String>,
    /// Runs trained at the same time (0 = one per CPU).
    #[arg(long, default_value_t = 1)]
    pub jobs: usize,
    /// After SIGTERM or Ctrl-C, seconds to wait for a safe point before exiting anyway (see
    /// `a2perf train --help`).
    #[arg(long, value_name = "SECONDS", default_value_t = 30.0)]
    pub preempt_grace: f64,
    /// Report directory (default: the suite's `report_dir`, else `report/` in the first
    /// experiment directory).
    #[arg(short = 'o', long)]
    pub output: Option<PathBuf>,
    /// Train, infer and generalize each run in processes of its own (children of this one), so
    /// that its RAM, energy and time are its alone: not shared with the runs beside it
    /// (`--jobs`) nor inflated by what earlier runs left in the process. Results are the same
    /// either way.
    #[arg(long)]
    pub isolate: bool,
    /// Hide progress bars.
    #[arg(long)]
    pub quiet: bool,
}

/// Arguments of `a2perf collect`.
#[derive(Args, Debug)]
pub struct CollectArgs {
    /// Run directories (or experiment directories holding them) whose checkpoints to use.
    #[arg(required = true)]
    pub dirs: Vec<PathBuf>,
    /// Episodes per checkpoint evaluation.
    #[arg(long, default_value_t = 100)]
    pub eval_episodes: usize,
    /// Episodes per dataset (per expertise level).
    #[arg(long, default_value_t = 100)]
    pub dataset_episodes: usize,
    /// Training sample cost: energy measured up to each checkpoint, or the original's pro-rata
    /// rule (total energy × checkpoint / last checkpoint).
    #[arg(long, value_enum, default_value_t = CostArg::Measured)]
    pub cost: CostArg,
    /// Assign levels with the paper's one-σ wording instead of the original code's rule.
    #[arg(long)]
    pub one_sigma: bool,
    /// Output directory for the datasets (default: `datasets/` next to the experiment).
    #[arg(short = 'o', long)]
    pub output: Option<PathBuf>,
    /// Hide progress bars.
    #[arg(long)]
    pub quiet: bool,
    /// After SIGTERM or Ctrl-C, seconds to wait for the collection to stop at its next episode
    /// (dropping the dataset it was writing) before exiting anyway. Exit code 75 either way;
    /// datasets already complete stay until a rerun collects them all anew.
    #[arg(long, value_name = "SECONDS", default_value_t = 30.0)]
    pub preempt_grace: f64,
}

/// How the training sample cost is assigned.
#[derive(Clone, Copy, Debug, ValueEnum)]
pub enum CostArg {
    /// Energy measured up to the checkpoint (interpolated over the recorded curve's wall time).
    Measured,
    /// The original's rule: total energy × checkpoint number / last checkpoint number.
    ProRata,
}

/// Exit code of `train` and `run` when they stopped on SIGTERM or Ctrl-C (`EX_TEMPFAIL`): the
/// runs in flight are resumable, so a wrapper (a Slurm requeue, a Kubernetes restart) should run
/// the same command again.
pub const EXIT_INTERRUPTED: i32 = 75;

/// Exit code of `train` and `run` when they left runs alone because another trainer holds them
/// (`EX_CANTCREAT`, "cannot create an output file": the run directory is being written by that
/// process). Distinct from [`EXIT_INTERRUPTED`] because rerunning at once would only meet the
/// same lock: wait for the holder (its pid and host are printed), then rerun.
pub const EXIT_LOCKED: i32 = 73;

/// A cancel token set by the first SIGTERM or SIGINT: runs then write a resume point at their
/// next safe point and stop, and the process exits with [`EXIT_INTERRUPTED`] — at the latest
/// `grace` after the signal. A second SIGINT exits at once with 130, a second SIGTERM with 143.
fn cancel_on_signals(grace: f64) -> Result<CancelToken> {
    cancel_on_signals_with(grace, true)
}

/// [`cancel_on_signals`]; with `repeat_exits` false a second SIGTERM does not exit at once. The
/// child process of `--isolate` runs so: its parent forwards the first SIGTERM it receives, and
/// `pkill a2perf` reaches the child directly as well.
fn cancel_on_signals_with(grace: f64, repeat_exits: bool) -> Result<CancelToken> {
    if !(grace.is_finite() && grace >= 0.0) {
        anyhow::bail!("--preempt-grace must be a non-negative number of seconds, got {grace}");
    }
    let token = CancelToken::new();
    // Elsewhere the default handlers stay: a signal kills the process, and runs continue from
    // their last interval checkpoint.
    #[cfg(unix)]
    {
        use signal_hook::consts::{SIGINT, SIGTERM};
        let mut signals = signal_hook::iterator::Signals::new([SIGINT, SIGTERM])
            .context("installing the SIGINT/SIGTERM handler")?;
        let t = token.clone();
        let grace = Duration::from_secs_f64(grace);
        std::thread::spawn(move || {
            for signal in signals.forever() {
                let name = if signal == SIGTERM {
                    "SIGTERM"
                } else {
                    "SIGINT"
                };
                if t.is_cancelled() {
                    if !repeat_exits && signal == SIGTERM {
                        continue;
                    }
                    eprintln!("\n{name} again: exiting now");
                    std::process::exit(128 + signal);
                }
                eprintln!(
                    "\n{name}: runs write a resume point at their next safe point and stop, a \
                     collection drops the dataset it is writing (exiting within {} s, code \
                     {EXIT_INTERRUPTED}); {name} again to exit now",
                    grace.as_secs_f64()
                );
                t.cancel();
                std::thread::spawn(move || {
                    std::thread::sleep(grace);
                    eprintln!(
                        "no safe point within {} s: exiting; the runs continue from their newest \
                         resume point",
                        grace.as_secs_f64()
                    );
                    std::process::exit(EXIT_INTERRUPTED);
                });
            }
        });
    }
    Ok(token)
}

/// How runs execute: in this process, or (`--isolate`) each in child processes that run this
/// program again: `train` with the same configs, overrides and seeds for one run directory,
/// `infer` and `generalize` on it.
fn isolation(
    isolate: bool,
    configs: &[PathBuf],
    set: &[String],
    seeds: Option<&str>,
    grace: f64,
) -> Result<pipeline::isolate::Isolation> {
    use pipeline::isolate::{ChildTask, Isolation};
    if !isolate {
        return Ok(Isolation::InProcess);
    }
    let exe = std::env::current_exe().context("--isolate: finding this program to run it again")?;
    let (configs, set, seeds) = (configs.to_vec(), set.to_vec(), seeds.map(String::from));
    Ok(Isolation::Children(std::sync::Arc::new(move |task| {
        let mut c = std::process::Command::new(&exe);
        match task {
            ChildTask::Train { run, report } => {
                c.arg("train").args(&configs);
                for s in &set {
                    c.arg("--set").arg(s);
                }
                if let Some(s) = &seeds {
                    c.arg("--seeds").arg(s);
                }
                c.arg("--quiet")
                    .arg("--preempt-grace")
                    .arg(grace.to_string())
                    .arg("--run-dir")
                    .arg(run)
                    .arg("--report-to")
                    .arg(report);
            }
            ChildTask::Infer { run } => {
                c.arg("infer").arg(run).arg("--quiet");
            }
            ChildTask::Generalize { run } => {
                c.arg("generalize").arg(run).arg("--quiet");
            }
        }
        c
    })))
}

fn expand_runs(dirs: &[PathBuf]) -> Result<Vec<PathBuf>> {
    Ok(pipeline::expand_runs(dirs)?)
}

fn load(
    registry: &Registry,
    configs: &[PathBuf],
    set: &[String],
    seeds: Option<&str>,
) -> Result<pipeline::LoadedPlans> {
    let seeds = seeds.map(pipeline::parse_seeds).transpose()?;
    Ok(pipeline::load_plans(
        configs,
        set,
        seeds.as_deref(),
        registry,
    )?)
}

fn train_plans(
    registry: &Registry,
    plans: &[ExperimentPlan],
    shard: Option<pipeline::Shard>,
    jobs: usize,
    quiet: bool,
    cancel: &CancelToken,
    isolation: pipeline::isolate::Isolation,
) -> Result<()> {
    let grid = pipeline::grid(plans, shard);
    let opts = TrainOptions {
        jobs,
        cancel: cancel.clone(),
        meters: pipeline::meters::system_meters(),
        show_progress: !quiet,
        isolation,
    };
    let summary = pipeline::train(registry, &grid, &opts)?;
    print_train_summary(&summary);
    Ok(pipeline::run::check_trained(&summary, cancel)?)
}

fn print_train_summary(summary: &pipeline::TrainSummary) {
    for (dir, warning) in &summary.warnings {
        eprintln!("warning: {}: {warning}", dir.display());
    }
    for (dir, step) in &summary.resumed {
        eprintln!("{}: resumed from step {step}", dir.display());
    }
    let done = summary.with(&pipeline::RunOutcome::Completed).len();
    let skipped = summary.with(&pipeline::RunOutcome::Skipped).len();
    let cancelled = summary.with(&pipeline::RunOutcome::Cancelled).len();
    let failed = summary.failures().len();
    let blocked = summary.blocked().len();
    let locked = summary.locked();
    for run in &locked {
        eprintln!("{run}");
    }
    let locked_note = match locked.len() {
        0 => String::new(),
        n => format!(", {n} left to the other trainer that holds them"),
    };
    let blocked_note = match blocked {
        0 => String::new(),
        n => format!(", {n} not started (what they train on did not come to be)"),
    };
    eprintln!(
        "train: {done} trained, {skipped} already complete, {cancelled} interrupted (rerun to \
         continue), {failed} failed{blocked_note}{locked_note}"
    );
}

/// `a2perf train`.
pub fn train(registry: &Registry, args: &TrainArgs) -> Result<()> {
    let loaded = load(registry, &args.configs, &args.set, args.seeds.as_deref())?;
    if let (Some(run), Some(report_to)) = (&args.run_dir, &args.report_to) {
        // The child side of `--isolate`: one run, in this process.
        let opts = TrainOptions {
            cancel: cancel_on_signals_with(args.preempt_grace, false)?,
            meters: pipeline::meters::system_meters(),
            ..TrainOptions::default()
        };
        let report = pipeline::run::train_run_at(registry, &loaded.plans, run, &opts)?;
        let json = serde_json::to_vec(&report)?;
        std::fs::write(report_to, json)
            .with_context(|| format!("writing {}", report_to.display()))?;
        return Ok(());
    }
    let shard = args.shard.as_deref().map(str::parse).transpose()?;
    let cancel = cancel_on_signals(args.preempt_grace)?;
    let isolation = isolation(
        args.isolate,
        &args.configs,
        &args.set,
        args.seeds.as_deref(),
        args.preempt_grace,
    )?;
    if let Some(plan) = loaded.plans.iter().find(|p| p.dataset_from.is_some()) {
        // A suite's dataset step needs its source runs trained first, which one shard of a
        // sweep cannot know.
        if shard.is_some() {
            anyhow::bail!(
                "experiment `{}` trains on a dataset its suite collects from other experiments \
                 (its entry's `dataset` step), which needs them trained first: train the suite \
                 without --shard, or shard a suite without dataset steps and run `a2perf \
                 collect` between the two",
                plan.name
            );
        }
        let opts = TrainOptions {
            jobs: args.jobs,
            cancel,
            meters: pipeline::meters::system_meters(),
            show_progress: !args.quiet,
            isolation,
        };
        pipeline::run::train_with_datasets(registry, &loaded.plans, &opts, &mut print_event)?;
        return Ok(());
    }
    train_plans(
        registry,
        &loaded.plans,
        shard,
        args.jobs,
        args.quiet,
        &cancel,
        isolation,
    )
}

pub(crate) fn print_inference(dir: &Path, r: &pipeline::InferenceResults) {
    println!(
        "{}: return {:.3} ± {:.3} over {} episodes; inference {:.4} ms/call (p99 {:.4})",
        dir.display(),
        r.returns.mean,
        r.returns.std,
        r.episodes,
        r.inference_time_ms.mean,
        r.inference_time_ms.p99
    );
}

fn infer_dirs(registry: &Registry, dirs: &[PathBuf], opts: &InferOptions) -> Result<()> {
    for dir in dirs {
        let r = pipeline::infer_run(registry, dir, opts)
            .with_context(|| format!("infer {}", dir.display()))?;
        print_inference(dir, &r);
    }
    Ok(())
}

/// `a2perf infer`.
pub fn infer(registry: &Registry, args: &InferArgs) -> Result<()> {
    let opts = InferOptions {
        episodes: args.episodes,
        observation_source: args.observations.map(|o| match o {
            ObsArg::Rollouts => ObservationSource::Rollouts,
            ObsArg::Random => ObservationSource::Random,
        }),
        timing_samples: args.timing_samples,
        meters: pipeline::meters::system_meters(),
        show_progress: !args.quiet,
    };
    infer_dirs(registry, &expand_runs(&args.dirs)?, &opts)
}

pub(crate) fn print_generalization(dir: &Path, r: &pipeline::GeneralizationResults) {
    let per_task: Vec<String> = r
        .tasks
        .iter()
        .map(|t| match (t.mean_return, &t.error) {
            (Some(m), _) => format!("{} {m:.3}", t.name),
            (None, Some(e)) => format!("{} failed ({e})", t.name),
            (None, None) => format!("{} —", t.name),
        })
        .collect();
    match r.sum_of_mean_returns {
        Some(s) => println!(
            "{}: generalization {s:.3} = {}",
            dir.display(),
            per_task.join(" + ")
        ),
        None => println!(
            "{}: generalization incomplete: {}",
            dir.display(),
            per_task.join(", ")
        ),
    }
}

fn generalize_dirs(
    registry: &Registry,
    dirs: &[PathBuf],
    episodes: Option<usize>,
    quiet: bool,
) -> Result<()> {
    for dir in dirs {
        let r = pipeline::generalize_run(registry, dir, episodes, !quiet)
            .with_context(|| format!("generalize {}", dir.display()))?;
        print_generalization(dir, &r);
    }
    Ok(())
}

/// `a2perf generalize`.
pub fn generalize(registry: &Registry, args: &GeneralizeArgs) -> Result<()> {
    generalize_dirs(
        registry,
        &expand_runs(&args.dirs)?,
        args.episodes,
        args.quiet,
    )
}

fn print_report(out: &Path, report: &pipeline::report::Report) {
    println!(
        "report: {} (task, algorithm) groups -> {}",
        report.groups.len(),
        out.display()
    );
    for (dir, why) in &report.skipped_runs {
        eprintln!("  left out {dir}: {why}");
    }
}

pub(crate) fn write_report(
    dirs: &[PathBuf],
    out: &Path,
    reps: Option<usize>,
    paper: Option<&pipeline::report::paper::PaperTables>,
    verified: &pipeline::report::VerifiedRuns,
) -> Result<()> {
    let opts = ReportOptions {
        bootstrap_reps: match reps {
            Some(r) => r,
            None => pipeline::run::recorded_bootstrap_reps(dirs)?,
        },
        seed: 0,
    };
    let report = pipeline::report::write_report_verified(dirs, out, &opts, paper, verified)?;
    print_report(out, &report);
    if paper.is_some() {
        println!(
            "paper: {} of the report's tables match a task of the paper's",
            report.paper.len()
        );
    }
    Ok(())
}

/// `a2perf report --from-reports`: one page from report directories.
fn page_from_reports(dirs: &[PathBuf], out: &Path) -> Result<()> {
    let same = |a: &Path, b: &Path| match (a.canonicalize(), b.canonicalize()) {
        (Ok(a), Ok(b)) => a == b,
        _ => false,
    };
    if let Some(d) = dirs.iter().find(|d| same(d, out)) {
        anyhow::bail!(
            "--from-reports: the output {} is one of the report directories read ({}); its \
             report.json would be replaced: give another -o",
            out.display(),
            d.display()
        );
    }
    // Everything is read and merged before anything is written.
    let (report, page) = pipeline::report::page_from_report_dirs(dirs)?;
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    a2perf_core::results::write_json_atomic(&out.join("report.json"), &report)?;
    let index = out.join("index.html");
    std::fs::write(&index, page).with_context(|| format!("writing {}", index.display()))?;
    println!(
        "page: {} (task, algorithm) groups from {} reports -> {}",
        report.groups.len(),
        dirs.len(),
        index.display()
    );
    Ok(())
}

/// `a2perf report`.
pub fn report(args: &ReportArgs) -> Result<()> {
    if args.from_reports {
        let out = args.output.as_deref().expect("clap requires -o");
        return page_from_reports(&args.dirs, out);
    }
    if args.output.is_none() && args.dirs[0].is_file() {
        anyhow::bail!(
            "{} is a bundle: give the report's directory with -o",
            args.dirs[0].display()
        );
    }
    let out = args
        .output
        .clone()
        .unwrap_or_else(|| args.dirs[0].join("report"));
    // Read before anything is written, so a bad file leaves an earlier report untouched.
    let tables = args
        .paper
        .as_deref()
        .map(pipeline::report::paper::PaperTables::load)
        .transpose()?;
    // Verified bundles' runs live in this directory until the report is written.
    let extracted = tempfile::tempdir().context("creating a temporary directory")?;
    let (dirs, runs) = crate::bundle_cmd::open_bundles(&args.dirs, extracted.path())?;
    let verified = pipeline::report::VerifiedRuns {
        runs,
        only: args.verified_only,
    };
    write_report(&dirs, &out, args.bootstrap_reps, tables.as_ref(), &verified)
}

/// `a2perf run`: train → infer → generalize → report.
pub fn run(registry: &Registry, args: &RunArgs) -> Result<()> {
    let loaded = load(registry, &args.configs, &args.set, args.seeds.as_deref())?;
    let opts = pipeline::RunOptions {
        jobs: args.jobs,
        cancel: cancel_on_signals(args.preempt_grace)?,
        meters: pipeline::meters::system_meters(),
        show_progress: !args.quiet,
        report_dir: args.output.clone().or(loaded.report_dir),
        isolation: isolation(
            args.isolate,
            &args.configs,
            &args.set,
            args.seeds.as_deref(),
            args.preempt_grace,
        )?,
    };
    pipeline::run_experiments(registry, &loaded.plans, &opts, &mut print_event)?;
    Ok(())
}

/// What `a2perf run` and `a2perf train` (of a suite with dataset steps) print as the pipeline
/// goes: phases, each dataset collection as it starts (runs go by on the progress bar), and
/// results.
fn print_event(event: pipeline::RunEvent<'_>) {
    match event {
        pipeline::RunEvent::Phase(name) => eprintln!("== {name}"),
        pipeline::RunEvent::Started(task @ pipeline::run::TrainTask::Collect(_)) => {
            eprintln!("{task}")
        }
        pipeline::RunEvent::Started(_) | pipeline::RunEvent::Finished(_) => {}
        pipeline::RunEvent::Trained(summary) => print_train_summary(summary),
        pipeline::RunEvent::Inferred(dir, r) => print_inference(dir, r),
        pipeline::RunEvent::Generalized(dir, r) => print_generalization(dir, r),
        pipeline::RunEvent::Reported(out, report) => print_report(out, report),
    }
}

/// `a2perf collect`.
pub fn collect(registry: &Registry, args: &CollectArgs) -> Result<()> {
    let runs = expand_runs(&args.dirs)?;
    let opts = CollectOptions {
        eval_episodes: args.eval_episodes,
        dataset_episodes: args.dataset_episodes,
        cost: match args.cost {
            CostArg::Measured => CostRule::Measured,
            CostArg::ProRata => CostRule::ProRata,
        },
        one_sigma: args.one_sigma,
        show_progress: !args.quiet,
        cancel: cancel_on_signals(args.preempt_grace)?,
    };
    let out = args.output.clone().unwrap_or_else(|| {
        runs[0]
            .parent()
            .map_or_else(|| PathBuf::from("datasets"), |p| p.join("datasets"))
    });
    let summary = pipeline::collect::collect(registry, &runs, &out, &opts)?;
    for d in &summary.datasets {
        println!(
            "{}: {} episodes, {} steps, training sample cost {} kWh",
            d.path.display(),
            d.episodes,
            d.steps,
            d.training_sample_cost_kwh
                .map_or_else(|| "unknown".into(), |c| format!("{c:.3e}"))
        );
    }
    Ok(())
}
