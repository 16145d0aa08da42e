//! Resumption: a training sweep interrupted mid-way (cancel token, as SIGTERM or Ctrl-C) and
//! rerun continues its interrupted run from the newest resume point, without redoing finished
//! seeds, and gives the same results as an uninterrupted sweep. An algorithm that does not save
//! resume points, and a run whose configuration changed, are trained again from scratch.
//!
//! (Before resume points existed, an interrupted run was always redone from scratch; the first
//! test asserted that. It now asserts that the run continues, in a second segment.)

mod common;

use std::collections::BTreeMap;
use std::path::Path;
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, AtomicUsize, Ordering};

use a2perf_core::{
    Action, Env, EnvEntry, EnvError, EnvSpec, LearningCurve, Observation, ParamKind, ParamSpec,
    Params, Registry, RunState, RunStatus, Step, Value,
};
use a2perf_example_custom::Corridor;
use a2perf_pipeline::train::{PhaseSystem, SegmentOutcome, TrainSegments};
use a2perf_pipeline::{CancelToken, ExperimentPlan, RunOutcome, TrainOptions};

fn curve(dir: &Path) -> Vec<(u64, f64)> {
    read::<LearningCurve>(&dir.join("curve.json")).returns()
}

fn read<T: serde::de::DeserializeOwned>(path: &Path) -> T {
    serde_json::from_slice(&std::fs::read(path).unwrap()).unwrap()
}

fn status(dir: &Path) -> RunStatus {
    read(&dir.join("status.json"))
}

fn resume_steps(dir: &Path) -> Vec<u64> {
    a2perf_core::ResumeDir::new(dir.join("resume"))
        .list()
        .unwrap()
        .into_iter()
        .map(|(s, _)| s)
        .collect()
}

/// Cancels a token once armed and `left` more environment steps have been taken, in any
/// environment of the registry's `Tripwire-v0` (a corridor): a deterministic point in training.
#[derive(Clone, Default)]
struct Tripwire {
    left: Arc<AtomicU64>,
    cancel: CancelToken,
}

impl Tripwire {
    fn arm(&self, steps: u64) {
        self.left.store(steps, Ordering::SeqCst);
    }
}

struct TrippingCorridor {
    inner: Corridor,
    wire: Tripwire,
}

impl Env for TrippingCorridor {
    fn spec(&self) -> &EnvSpec {
        self.inner.spec()
    }
    fn reset_into(&mut self, seed: Option<u64>, obs: &mut Observation) -> Result<(), EnvError> {
        self.inner.reset_into(seed, obs)
    }
    fn step_into(&mut self, action: &Action, out: &mut Step) -> Result<(), EnvError> {
        let left = &self.wire.left;
        if left.load(Ordering::SeqCst) > 0 && left.fetch_sub(1, Ordering::SeqCst) == 1 {
            self.wire.cancel.cancel();
        }
        self.inner.step_into(action, out)
    }
}

/// The test registry plus `Tripwire-v0`.
fn registry(wire: &Tripwire) -> Registry {
    let mut reg = common::registry();
    let wire = wire.clone();
    reg.register_env(EnvEntry {
        id: "Tripwire-v0".into(),
        domain: a2perf_example_custom::DOMAIN.into(),
        summary: "test: a corridor that cancels a token after a set number of steps".into(),
        params: vec![ParamSpec::new(
            "length",
            ParamKind::Int,
            Value::Int(8),
            "cells",
        )],
        make: Arc::new(move |p: &Params| {
            let length = p.usize("length").map_err(|e| EnvError::InvalidParameter {
                name: "length".into(),
                reason: e.to_string(),
            })?;
            Ok(Box::new(TrippingCorridor {
                inner: Corridor::new(length)?,
                wire: wire.clone(),
            }) as Box<dyn Env>)
        }),
    });
    reg
}

fn tripwire_plan(out: &Path, seeds: Vec<u64>) -> ExperimentPlan {
    let mut plan = common::plan(out, "exp", seeds);
    plan.task.env_id = "Tripwire-v0".into();
    plan.task.name = "Tripwire-v0".into();
    plan
}

/// Trains `plan` with the test meters, arming `wire` to cancel `after` steps into the run of the
/// `run_index`-th job.
fn train_interrupted(
    reg: &Registry,
    plan: &ExperimentPlan,
    wire: &Tripwire,
    run_index: usize,
    after: u64,
) -> a2perf_pipeline::TrainSummary {
    let starts = Arc::new(AtomicUsize::new(0));
    let (w, n) = (wire.clone(), starts.clone());
    let meters = common::test_meters();
    let opts = TrainOptions {
        jobs: 1,
        cancel: wire.cancel.clone(),
        meters: Arc::new(move |phase, dir, settings| {
            if n.fetch_add(1, Ordering::SeqCst) == run_index {
                w.arm(after);
            }
            meters(phase, dir, settings)
        }),
        show_progress: false,
        isolation: Default::default(),
    };
    let jobs = a2perf_pipeline::grid(std::slice::from_ref(plan), None);
    a2perf_pipeline::train(reg, &jobs, &opts).unwrap()
}

fn train_clean(reg: &Registry, plan: &ExperimentPlan) {
    let s = a2perf_pipeline::train(
        reg,
        &a2perf_pipeline::grid(std::slice::from_ref(plan), None),
        &TrainOptions {
            meters: common::test_meters(),
            ..Default::default()
        },
    )
    .unwrap();
    assert!(s.runs.iter().all(|(_, o)| *o == RunOutcome::Completed));
}

fn outcomes(s: &a2perf_pipeline::TrainSummary) -> Vec<RunOutcome> {
    s.runs.iter().map(|(_, o)| o.clone()).collect()
}

fn rerun(reg: &Registry, plan: &ExperimentPlan) -> a2perf_pipeline::TrainSummary {
    a2perf_pipeline::train(
        reg,
        &a2perf_pipeline::grid(std::slice::from_ref(plan), None),
        &TrainOptions {
            meters: common::test_meters(),
            ..Default::default()
        },
    )
    .unwrap()
}

fn assert_same_results(a: &Path, b: &Path) {
    assert_eq!(curve(a), curve(b), "{}", a.display());
    assert_eq!(
        std::fs::read(a.join("policy.ckpt")).unwrap(),
        std::fs::read(b.join("policy.ckpt")).unwrap(),
        "{}",
        a.display()
    );
    let steps = |d: &Path| -> Vec<(u64, Vec<u8>)> {
        a2perf_pipeline::collect::checkpoints(d)
            .unwrap()
            .into_iter()
            .map(|(s, p)| (s, std::fs::read(p).unwrap()))
            .collect()
    };
    assert_eq!(steps(a), steps(b), "{}: interval checkpoints", a.display());
}

fn energy(system: &PhaseSystem) -> f64 {
    system.meters.value("energy_total_kwh").unwrap()
}

#[test]
fn interrupted_sweep_resumes_to_the_uninterrupted_result() {
    let wire = Tripwire::default();
    let reg = registry(&wire);
    let clean_dir = tempfile::tempdir().unwrap();
    let clean = tripwire_plan(clean_dir.path(), vec![0, 1, 2]);
    train_clean(&reg, &clean);

    // Interrupted 700 steps into the second run: the first run finishes, the second stops at its
    // next progress call (writing a resume point there), the third never starts.
    let tmp = tempfile::tempdir().unwrap();
    let plan = tripwire_plan(tmp.path(), vec![0, 1, 2]);
    let s = train_interrupted(&reg, &plan, &wire, 1, 700);
    assert_eq!(
        outcomes(&s),
        vec![
            RunOutcome::Completed,
            RunOutcome::Cancelled,
            RunOutcome::Cancelled
        ]
    );
    let run1 = plan.run_dir(1);
    let st = status(&run1);
    assert_eq!(st.state, RunState::Interrupted);
    let points = resume_steps(&run1);
    let newest = *points.last().expect("a resume point");
    // The interval point (at the first progress call at or after 300 steps) and the
    // interruption's own point, mid-interval (the 700 steps counted include evaluations).
    assert!(points[0] >= 300 && newest > points[0], "{points:?}");
    assert_eq!(points.len(), 2, "{points:?}: the newest two are kept");
    assert!(
        st.note.contains(&format!("continues from step {newest}")),
        "{}",
        st.note
    );
    assert!(!run1.join("policy.ckpt").exists());
    let segs: TrainSegments = read(&run1.join("train_segments.json"));
    assert_eq!(segs.segments.len(), 1);
    assert_eq!(segs.segments[0].outcome, SegmentOutcome::Interrupted);
    assert_eq!(
        segs.segments[0]
            .resume_points
            .iter()
            .map(|w| w.env_steps)
            .next_back(),
        Some(newest)
    );
    let first_energy = energy(segs.segments[0].system.as_ref().unwrap());
    let finished = std::fs::read(plan.run_dir(0).join("policy.ckpt")).unwrap();
    let finished_time = std::fs::metadata(plan.run_dir(0).join("status.json"))
        .unwrap()
        .modified()
        .unwrap();
    // The interrupted run keeps its directory: it is continued, not redone.
    std::fs::write(run1.join("kept.txt"), b"x").unwrap();

    let s = rerun(&reg, &plan);
    assert_eq!(
        outcomes(&s),
        vec![
            RunOutcome::Skipped,
            RunOutcome::Completed,
            RunOutcome::Completed
        ]
    );
    assert_eq!(s.resumed, vec![(run1.clone(), newest)]);
    assert!(s.warnings.is_empty(), "{:?}", s.warnings);
    assert!(run1.join("kept.txt").is_file());
    assert_eq!(
        std::fs::read(plan.run_dir(0).join("policy.ckpt")).unwrap(),
        finished
    );
    assert_eq!(
        std::fs::metadata(plan.run_dir(0).join("status.json"))
            .unwrap()
            .modified()
            .unwrap(),
        finished_time,
        "the finished seed was not touched"
    );
    for seed in 0..3 {
        assert_same_results(&plan.run_dir(seed), &clean.run_dir(seed));
    }

    // Two segments, combined in train_system.json; the resume points are gone.
    let st = status(&run1);
    assert_eq!(st.state, RunState::Complete);
    assert!(st.note.contains("2 segments"), "{}", st.note);
    assert!(!run1.join("resume").exists());
    let segs: TrainSegments = read(&run1.join("train_segments.json"));
    let outcomes: Vec<_> = segs.segments.iter().map(|s| s.outcome).collect();
    assert_eq!(
        outcomes,
        vec![SegmentOutcome::Interrupted, SegmentOutcome::Completed]
    );
    assert_eq!(segs.segments[1].started_at_step, newest);
    let second = segs.segments[1].system.as_ref().unwrap();
    let system: PhaseSystem = read(&run1.join("train_system.json"));
    assert_eq!(system.segments, 2);
    assert!(
        system
            .note
            .as_deref()
            .unwrap()
            .contains("combined from 2 training segments")
    );
    assert_eq!(energy(&system), first_energy + energy(second));
    let first_wall = segs.segments[0].system.as_ref().unwrap().wall_clock_s;
    assert_eq!(system.wall_clock_s, first_wall + second.wall_clock_s);
    // The curve's clock goes on across segments.
    let c: LearningCurve = read(&run1.join("curve.json"));
    assert!(
        c.points
            .windows(2)
            .all(|w| w[0].wall_seconds <= w[1].wall_seconds)
    );
    assert!(c.points.last().unwrap().wall_seconds >= first_wall);
    // A seed trained in one go has a single-segment system file, as before.
    let one: PhaseSystem = read(&plan.run_dir(2).join("train_system.json"));
    assert_eq!((one.segments, one.note), (1, None));

    // A third invocation does nothing.
    let s = rerun(&reg, &plan);
    assert_eq!(s.with(&RunOutcome::Skipped).len(), 3);
}

#[test]
fn a_corrupt_newest_resume_point_falls_back_to_the_previous_one() {
    let wire = Tripwire::default();
    let reg = registry(&wire);
    let clean_dir = tempfile::tempdir().unwrap();
    let clean = tripwire_plan(clean_dir.path(), vec![4]);
    train_clean(&reg, &clean);

    let tmp = tempfile::tempdir().unwrap();
    let plan = tripwire_plan(tmp.path(), vec![4]);
    train_interrupted(&reg, &plan, &wire, 0, 700);
    let run = plan.run_dir(4);
    let points = resume_steps(&run);
    assert_eq!(points.len(), 2, "{points:?}");
    // The newest point is torn (as a disk error would leave it).
    let newest = run.join(format!("resume/step_{:012}.resume", points[1]));
    let bytes = std::fs::read(&newest).unwrap();
    std::fs::write(&newest, &bytes[..bytes.len() / 2]).unwrap();

    let s = rerun(&reg, &plan);
    assert_eq!(outcomes(&s), vec![RunOutcome::Completed]);
    assert_eq!(s.resumed, vec![(run.clone(), points[0])]);
    let warnings: Vec<&str> = s.warnings.iter().map(|(_, w)| w.as_str()).collect();
    assert_eq!(warnings.len(), 2, "{warnings:?}");
    assert!(
        warnings[0].contains(&format!("step_{:012}.resume", points[1]))
            && warnings[0].contains("truncated"),
        "{warnings:?}"
    );
    assert!(
        warnings[1].contains(&format!(
            "fell back to the resume point at step {}",
            points[0]
        )),
        "{warnings:?}"
    );
    // Recorded with the segment, too.
    let segs: TrainSegments = read(&run.join("train_segments.json"));
    assert_eq!(segs.segments[1].started_at_step, points[0]);
    assert_eq!(segs.segments[1].warnings.len(), 2);
    assert_same_results(&run, &clean.run_dir(4));
}

/// Demonstrations for `toy_bc`: walk right from every position.
fn samples(path: &Path) {
    let samples: Vec<serde_json::Value> = (0..8)
        .map(|x| {
            serde_json::json!({
                "observation": Observation::flat(vec![x as f32 / 8.0, 1.0]),
                "action": Action::Discrete(1),
            })
        })
        .collect();
    std::fs::write(
        path,
        serde_json::to_vec(&serde_json::json!({
            "format": a2perf_baselines::dataset::DATASET_FORMAT,
            "samples": samples,
        }))
        .unwrap(),
    )
    .unwrap();
}

#[test]
fn an_algorithm_that_does_not_opt_in_restarts_from_scratch() {
    let wire = Tripwire::default();
    let reg = registry(&wire);
    let data = tempfile::tempdir().unwrap();
    let path = data.path().join("samples.json");
    samples(&path);
    let offline = |out: &Path| {
        let mut plan = tripwire_plan(out, vec![0]);
        plan.algorithm.name = "toy_bc".into();
        plan.algorithm.params = BTreeMap::from([(
            "dataset".to_string(),
            Value::Str(path.display().to_string()),
        )]);
        plan
    };
    let clean_dir = tempfile::tempdir().unwrap();
    let clean = offline(clean_dir.path());
    train_clean(&reg, &clean);

    // Interrupted during its first evaluation (toy_bc's first progress call evaluates).
    let tmp = tempfile::tempdir().unwrap();
    let plan = offline(tmp.path());
    let s = train_interrupted(&reg, &plan, &wire, 0, 5);
    assert_eq!(outcomes(&s), vec![RunOutcome::Cancelled]);
    let run = plan.run_dir(0);
    let st = status(&run);
    assert_eq!(st.state, RunState::Interrupted);
    assert!(st.note.contains("from scratch"), "{}", st.note);
    assert!(resume_steps(&run).is_empty());
    std::fs::write(run.join("stale.txt"), b"x").unwrap();

    let s = rerun(&reg, &plan);
    assert_eq!(outcomes(&s), vec![RunOutcome::Completed]);
    assert!(s.resumed.is_empty());
    assert!(
        !run.join("stale.txt").exists(),
        "a stale file survived the redo"
    );
    let segs: TrainSegments = read(&run.join("train_segments.json"));
    assert_eq!(segs.segments.len(), 1);
    assert_same_results(&run, &clean.run_dir(0));
}

#[test]
fn a_changed_configuration_trains_from_scratch() {
    let wire = Tripwire::default();
    let reg = registry(&wire);
    let tmp = tempfile::tempdir().unwrap();
    let plan = tripwire_plan(tmp.path(), vec![1]);
    train_interrupted(&reg, &plan, &wire, 0, 700);
    let run = plan.run_dir(1);
    assert!(!resume_steps(&run).is_empty());
    std::fs::write(run.join("stale.txt"), b"x").unwrap();

    let mut changed = plan.clone();
    changed.training.eval_episodes = 4;
    let s = rerun(&reg, &changed);
    assert_eq!(outcomes(&s), vec![RunOutcome::Completed]);
    assert!(s.resumed.is_empty());
    assert!(
        s.warnings[0].1.contains("configuration changed"),
        "{:?}",
        s.warnings
    );
    assert!(!run.join("stale.txt").exists());

    let clean_dir = tempfile::tempdir().unwrap();
    let mut clean = tripwire_plan(clean_dir.path(), vec![1]);
    clean.training.eval_episodes = 4;
    train_clean(&reg, &clean);
    assert_same_results(&run, &clean.run_dir(1));
}

/// A resume point whose algorithm state cannot be read (written by another version of the
/// algorithm, say) is not retried forever: the run is trained from scratch, with a warning.
#[test]
fn an_unreadable_algorithm_state_trains_from_scratch() {
    let wire = Tripwire::default();
    let reg = registry(&wire);
    let tmp = tempfile::tempdir().unwrap();
    let plan = tripwire_plan(tmp.path(), vec![3]);
    train_interrupted(&reg, &plan, &wire, 0, 700);
    let run = plan.run_dir(3);
    let newest = *resume_steps(&run).last().unwrap();
    let path = run.join(format!("resume/step_{newest:012}.resume"));
    let mut point = a2perf_core::ResumePoint::from_bytes(&std::fs::read(&path).unwrap()).unwrap();
    point.state = b"{\"from\": \"another version\"}".to_vec();
    std::fs::write(&path, point.to_bytes()).unwrap();

    let s = rerun(&reg, &plan);
    assert_eq!(outcomes(&s), vec![RunOutcome::Completed]);
    assert!(s.resumed.is_empty());
    assert!(
        s.warnings[0]
            .1
            .contains(&format!("cannot resume from step {newest}")),
        "{:?}",
        s.warnings
    );
    let segs: TrainSegments = read(&run.join("train_segments.json"));
    assert_eq!(
        segs.segments.len(),
        1,
        "the failed attempt's directory was emptied"
    );
    let clean_dir = tempfile::tempdir().unwrap();
    let clean = tripwire_plan(clean_dir.path(), vec![3]);
    train_clean(&reg, &clean);
    assert_same_results(&run, &clean.run_dir(3));
}

/// A segment killed without a chance to record anything (as by `kill -9`) is counted, and the
/// combined system figures say that its time and energy are missing.
#[test]
fn a_killed_segment_is_reported_in_the_combined_figures() {
    let wire = Tripwire::default();
    let reg = registry(&wire);
    let tmp = tempfile::tempdir().unwrap();
    let plan = tripwire_plan(tmp.path(), vec![2]);
    train_interrupted(&reg, &plan, &wire, 0, 700);
    let run = plan.run_dir(2);
    // What a killed process leaves: status and its segment still "running", no meters.
    let mut segs: TrainSegments = read(&run.join("train_segments.json"));
    segs.segments[0].outcome = SegmentOutcome::Running;
    segs.segments[0].system = None;
    a2perf_core::write_json_atomic(&run.join("train_segments.json"), &segs).unwrap();
    a2perf_core::RunDir::new(&run)
        .set_status(RunState::Running, "")
        .unwrap();

    let s = rerun(&reg, &plan);
    assert_eq!(outcomes(&s), vec![RunOutcome::Completed]);
    let segs: TrainSegments = read(&run.join("train_segments.json"));
    assert_eq!(segs.segments[0].outcome, SegmentOutcome::Killed);
    let system: PhaseSystem = read(&run.join("train_system.json"));
    assert_eq!(system.segments, 2);
    assert_eq!(
        system.wall_clock_s,
        segs.segments[1].system.as_ref().unwrap().wall_clock_s
    );
    assert!(
        system.note.unwrap().contains("1 segment(s) killed"),
        "the note says what is missing"
    );
}

#[test]
fn shards_cover_the_grid_and_parallel_runs_match_sequential_ones() {
    let reg = common::registry();
    let tmp = tempfile::tempdir().unwrap();
    let plan = common::plan(tmp.path(), "exp", vec![0, 1, 2, 3]);
    for i in 0..2 {
        let shard = a2perf_pipeline::Shard::new(i, 2).unwrap();
        let jobs = a2perf_pipeline::grid(std::slice::from_ref(&plan), Some(shard));
        assert_eq!(jobs.len(), 2);
        let opts = TrainOptions {
            jobs: 2,
            ..Default::default()
        };
        a2perf_pipeline::train(&reg, &jobs, &opts).unwrap();
    }
    let seq = tempfile::tempdir().unwrap();
    let seq_plan = common::plan(seq.path(), "exp", vec![0, 1, 2, 3]);
    a2perf_pipeline::train(
        &reg,
        &a2perf_pipeline::grid(std::slice::from_ref(&seq_plan), None),
        &TrainOptions::default(),
    )
    .unwrap();
    for seed in 0..4 {
        assert_eq!(curve(&plan.run_dir(seed)), curve(&seq_plan.run_dir(seed)));
    }
}
