//! `a2perf train`: one resumable run per (task, algorithm, seed).
//!
//! A run that stops before completing (SIGTERM, Ctrl-C, `kill -9`, a failure) continues from its
//! newest valid resume point when the same command is run again, if its algorithm saves resume
//! points (every built-in one does; see [`a2perf_core::TrainingContext`]); otherwise, or when its
//! configuration changed, it is trained again from scratch. Each process that trains a run is a
//! *segment*, recorded in `train_segments.json` with its own system meters; `train_system.json`
//! combines them (see [`combine_segments`]).

use a2perf_core::{
    CancelToken, DirectoryCheckpoints, Registry, ResumeDir, ResumePoint, RunDir, RunError,
    RunState, TrainingContext, write_atomic, write_json_atomic,
};

use crate::error::{PipelineError, Result, io_err};
use crate::isolate::Isolation;
use crate::phase::measured;
use crate::plan::RunJob;
use crate::pool::{self, Event};
use crate::progress;
use crate::run_dir::{
    CHECKPOINT_DIR, POLICY_FILE, PlannedRun, RESUME_DIR, Start, TRAIN_SEGMENTS_FILE, prepare,
    remove_checkpoints_after, wipe, write_curve, write_run_files, write_train_system,
};
use crate::run_lock::TrainingLock;
use crate::spec::AlgorithmSpec;

// Where these lived before the run directory and the phase measurements got modules of their
// own; front ends and the report still name them here.
pub use crate::outcome::{RunOutcome, RunReport, TrainSummary};
pub use crate::phase::{
    MeterFactory, MeteredPhase, Phase, PhaseSystem, combine_segments, no_meters,
};
pub use crate::run_dir::{SegmentOutcome, TrainSegment, TrainSegments};

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
    let bar = progress::bar(jobs.len() as u64, "train", opts.show_progress);
    let slots = pool::run(
        &vec![Vec::new(); jobs.len()],
        pool::workers(opts.jobs),
        &opts.cancel,
        &|i| train_job(registry, &jobs[i], opts),
        &|_| true,
        &mut |event| match event {
            Event::Started(i) => bar.set_message(run_name(&jobs[i].plan.run_dir(jobs[i].seed))),
            Event::Finished(_) => bar.inc(1),
        },
    );
    bar.finish_and_clear();
    let mut summary = TrainSummary::default();
    for (job, slot) in jobs.iter().zip(slots) {
        summary.add(job.plan.run_dir(job.seed), slot, |_| String::new())?;
    }
    Ok(summary)
}

/// The name of a run directory, for progress bars.
pub(crate) fn run_name(dir: &std::path::Path) -> String {
    dir.file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default()
}

/// Trains one job where `opts.isolation` says: in this process or in a child process.
pub(crate) fn train_job(
    registry: &Registry,
    job: &RunJob,
    opts: &TrainOptions,
) -> Result<RunReport> {
    match &opts.isolation {
        Isolation::InProcess => train_run(registry, job, opts),
        Isolation::Children(command) => {
            crate::isolate::train_in_child(command, &job.plan.run_dir(job.seed), &opts.cancel)
        }
    }
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
    if dir.exists() && run.status()?.is_some_and(|s| s.state.is_complete()) {
        return Ok(untrained(RunOutcome::Skipped));
    }
    // Held until this function returns; `prepare` reads the status again under the lock.
    let _lock = match TrainingLock::acquire(&dir) {
        Ok(lock) => lock,
        Err(PipelineError::Locked(mut runs)) => {
            return Ok(untrained(RunOutcome::Locked(
                runs.pop().and_then(|r| r.holder),
            )));
        }
        Err(e) => return Err(e),
    };
    let PlannedRun {
        record_json,
        env,
        env_params,
        ..
    } = PlannedRun::new(registry, job, resolved_algorithm(registry, job)?, None)?;
    let factory = move |_i: usize| (env.make)(&env_params);
    let mut warnings = Vec::new();
    let mut retried = false;
    loop {
        let (point, mut segments) = match prepare(&run, &record_json, &mut warnings)? {
            Start::Skip => return Ok(untrained(RunOutcome::Skipped)),
            Start::Fresh => (None, TrainSegments::default()),
            Start::Resume(point, segments) => (Some(*point), segments),
        };
        write_run_files(&run, &record_json, plan.operative.as_ref())?;
        let point = match point {
            Some(p) => Some(continue_from(&run, p, &segments)?),
            None => None,
        };
        let offered = point.is_some();
        begin_segment(&run, &mut segments, point.as_ref(), &warnings)?;
        let mut segment = train_segment(registry, job, opts, &factory, point)?;
        warnings.append(&mut segment.warnings);
        end_segment(&run, &mut segments, offered, &segment, &warnings)?;
        let resumed_from = segment.resumed_from;
        let report = |outcome| RunReport {
            outcome,
            resumed_from,
            warnings: warnings.clone(),
        };
        let policy = match segment.result {
            Ok(p) => p,
            Err(RunError::Cancelled) => {
                let note = match segment.writes.last().map(|w| w.env_steps).or(resumed_from) {
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
        complete(&run, policy.as_ref(), &segment.curve, &segments)?;
        return Ok(report(RunOutcome::Completed));
    }
}

/// The report of a run left untouched (already complete, or held by another trainer).
fn untrained(outcome: RunOutcome) -> RunReport {
    RunReport {
        outcome,
        resumed_from: None,
        warnings: Vec::new(),
    }
}

/// The job's algorithm with every hyperparameter resolved (defaults included), as `run.json`
/// records it.
fn resolved_algorithm(registry: &Registry, job: &RunJob) -> Result<AlgorithmSpec> {
    let plan = &job.plan;
    let algo_entry = registry.algorithm(&plan.algorithm.name)?;
    let algo_params = a2perf_core::Params::resolve(&algo_entry.params, &plan.algorithm.params)
        .map_err(|source| a2perf_core::RegistryError::Param {
            context: format!("algorithm {}", plan.algorithm.name),
            source,
        })?;
    Ok(AlgorithmSpec {
        name: plan.algorithm.name.clone(),
        params: algo_params.values().clone(),
    })
}

/// Readies a resume point for the next segment: drops the checkpoints written after it and
/// marks the run running again.
fn continue_from(
    run: &RunDir,
    mut p: ResumePoint,
    segments: &TrainSegments,
) -> Result<ResumePoint> {
    remove_checkpoints_after(run, p.progress.env_steps)?;
    // The curve's clock goes on from the time already spent on the run, so that it stays
    // comparable with the summed wall-clock time of `train_system.json`.
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
    Ok(p)
}

/// Records a new segment as running, before it starts.
fn begin_segment(
    run: &RunDir,
    segments: &mut TrainSegments,
    point: Option<&ResumePoint>,
    warnings: &[String],
) -> Result<()> {
    let started_at_step = point.map_or(0, |p| p.progress.env_steps);
    segments.segments.push(TrainSegment {
        started_at_step,
        outcome: SegmentOutcome::Running,
        system: None,
        resume_points: Vec::new(),
        warnings: warnings.to_vec(),
        time_split: None,
    });
    write_json_atomic(&run.file(TRAIN_SEGMENTS_FILE), segments)?;
    Ok(())
}

/// What one segment's training produced.
struct Segment {
    result: std::result::Result<Box<dyn a2perf_core::Policy>, RunError>,
    curve: a2perf_core::LearningCurve,
    resumed_from: Option<u64>,
    warnings: Vec<String>,
    writes: Vec<a2perf_core::ResumeWrite>,
    split: a2perf_core::TimeSplit,
    system: PhaseSystem,
}

/// Trains the job in this process, from `point` when given, under the phase's meters.
fn train_segment(
    registry: &Registry,
    job: &RunJob,
    opts: &TrainOptions,
    factory: &a2perf_core::EnvFactory,
    point: Option<ResumePoint>,
) -> Result<Segment> {
    let plan = &job.plan;
    let dir = plan.run_dir(job.seed);
    let run = RunDir::new(&dir);
    let mut algorithm = registry.make_algorithm(&plan.algorithm.name, &plan.algorithm.params)?;
    let mut sink =
        DirectoryCheckpoints::new(run.file(CHECKPOINT_DIR)).with_resume_dir(run.file(RESUME_DIR));
    let meters = (opts.meters)(Phase::Train, &dir, &plan.metrics);
    let ((result, curve, resumed_from, warnings, writes, split), system) = measured(meters, || {
        let mut ctx = TrainingContext::new(
            factory,
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
        let split = *ctx.time_split();
        (r, ctx.take_curve(), resumed_from, warnings, writes, split)
    });
    Ok(Segment {
        result,
        curve,
        resumed_from,
        warnings,
        writes,
        split,
        system,
    })
}

/// Records how the segment ended, with its meters and resume points.
fn end_segment(
    run: &RunDir,
    segments: &mut TrainSegments,
    offered: bool,
    segment: &Segment,
    warnings: &[String],
) -> Result<()> {
    if offered && segment.resumed_from.is_none() {
        // The algorithm trained from scratch: earlier segments' work is not part of this run.
        let this = segments.segments.pop();
        segments.segments = this.into_iter().collect();
    }
    let outcome = match &segment.result {
        Ok(_) => SegmentOutcome::Completed,
        Err(RunError::Cancelled) => SegmentOutcome::Interrupted,
        Err(_) => SegmentOutcome::Failed,
    };
    if let Some(seg) = segments.segments.last_mut() {
        seg.outcome = outcome;
        seg.system = Some(segment.system.clone());
        seg.resume_points = segment.writes.clone();
        seg.time_split = Some(segment.split);
        seg.warnings = warnings.to_vec();
    }
    write_json_atomic(&run.file(TRAIN_SEGMENTS_FILE), segments)?;
    Ok(())
}

/// Writes the finished run's policy, curve and system figures, drops its resume points and
/// marks it complete.
fn complete(
    run: &RunDir,
    policy: &dyn a2perf_core::Policy,
    curve: &a2perf_core::LearningCurve,
    segments: &TrainSegments,
) -> Result<()> {
    let ckpt = policy.checkpoint().map_err(|e| PipelineError::Run {
        run: run.path().display().to_string(),
        source: e.into(),
    })?;
    write_atomic(&run.file(POLICY_FILE), &ckpt.to_bytes())
        .map_err(io_err(&run.file(POLICY_FILE)))?;
    write_curve(run, curve)?;
    write_train_system(run, segments)?;
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
    Ok(())
}
