//! An environment whose rewards are not finite numbers: what the pipeline writes must read back.

mod common;

use std::collections::BTreeMap;
use std::sync::Arc;

use a2perf_core::results::read_json;
use a2perf_core::{
    Action, Env, EnvEntry, EnvError, EnvSpec, LearningCurve, Observation, Params, Step, TaskRef,
};
use a2perf_example_custom::Corridor;
use a2perf_pipeline::{
    GENERALIZATION_FILE, GeneralizationResults, INFERENCE_FILE, InferOptions, InferenceResults,
    RunOutcome, TrainOptions,
    report::{Report, ReportOptions},
};

/// The example corridor, but every episode's third step pays `odd_reward`.
struct OddCorridor {
    inner: Corridor,
    odd_reward: f64,
    t: usize,
}

impl Env for OddCorridor {
    fn spec(&self) -> &EnvSpec {
        self.inner.spec()
    }
    fn reset_into(&mut self, seed: Option<u64>, obs: &mut Observation) -> Result<(), EnvError> {
        self.t = 0;
        self.inner.reset_into(seed, obs)
    }
    fn step_into(&mut self, action: &Action, out: &mut Step) -> Result<(), EnvError> {
        self.inner.step_into(action, out)?;
        self.t += 1;
        if self.t == 3 {
            out.reward = self.odd_reward;
        }
        Ok(())
    }
}

/// A run on an environment that pays a NaN reward at every episode's third step trains,
/// infers and generalizes; every file it wrote reads back (JSON has no NaN: `null`, read as NaN),
/// and the report says the returns are not finite instead of failing on the files (before, it
/// stopped at `curve.json`: "invalid type: null, expected f64").
#[test]
fn a_run_with_nan_rewards_stays_readable_and_is_reported_as_not_finite() {
    let tmp = tempfile::tempdir().unwrap();
    let mut reg = common::registry();
    reg.register_env(EnvEntry {
        id: "NanCorridor-v0".into(),
        domain: "odd".into(),
        summary: "test: the corridor paying NaN at every episode's third step".into(),
        params: vec![],
        make: Arc::new(|_: &Params| {
            Ok(Box::new(OddCorridor {
                inner: Corridor::new(8)?,
                odd_reward: f64::NAN,
                t: 0,
            }) as Box<dyn Env>)
        }),
    });
    reg.register_generalization(
        "odd",
        vec![
            TaskRef {
                name: "nan_corridor".into(),
                env_id: "NanCorridor-v0".into(),
                params: BTreeMap::new(),
            },
            TaskRef {
                name: "corridor_8".into(),
                env_id: "Corridor-v0".into(),
                params: BTreeMap::new(),
            },
        ],
    );
    let mut plan = common::plan(tmp.path(), "nan", vec![0]);
    plan.task.name = "NanCorridor-v0".into();
    plan.task.env_id = "NanCorridor-v0".into();
    plan.task.env_params = BTreeMap::new();
    let summary = a2perf_pipeline::train(
        &reg,
        &a2perf_pipeline::grid(std::slice::from_ref(&plan), None),
        &TrainOptions {
            meters: common::test_meters(),
            ..Default::default()
        },
    )
    .unwrap();
    assert_eq!(summary.with(&RunOutcome::Completed).len(), 1);
    let dir = plan.run_dir(0);

    let curve: LearningCurve = read_json(&dir.join("curve.json")).unwrap();
    assert!(!curve.points.is_empty());
    assert!(curve.points.iter().all(|p| p.mean_return.is_nan()));

    let inf = a2perf_pipeline::infer_run(
        &reg,
        &dir,
        &InferOptions {
            episodes: Some(3),
            meters: common::test_meters(),
            ..Default::default()
        },
    )
    .unwrap();
    assert!(inf.returns.mean.is_nan());
    let back: InferenceResults = read_json(&dir.join(INFERENCE_FILE)).unwrap();
    assert_eq!(back.rollout_returns.len(), 3);
    assert!(back.rollout_returns.iter().all(|r| r.is_nan()));
    assert!(back.returns.mean.is_nan() && back.returns.max.is_nan());
    assert_eq!(back.episode_lengths, inf.episode_lengths);

    // Generalization: the NaN task says why it has no mean, the plain corridor has one.
    let gr = a2perf_pipeline::generalize_run(&reg, &dir, Some(2), false).unwrap();
    let back: GeneralizationResults = read_json(&dir.join(GENERALIZATION_FILE)).unwrap();
    assert_eq!(
        format!("{back:?}"),
        format!("{gr:?}"),
        "NaN != NaN: compared as printed"
    );
    assert_eq!(gr.tasks[0].mean_return, None);
    assert!(gr.tasks[0].returns.iter().all(|r| r.is_nan()));
    assert!(
        gr.tasks[0]
            .error
            .as_deref()
            .is_some_and(|e| e.contains("not finite")),
        "{:?}",
        gr.tasks[0].error
    );
    assert!(gr.tasks[1].mean_return.is_some_and(f64::is_finite));
    assert_eq!(gr.sum_of_mean_returns, None);

    let report = a2perf_pipeline::report::write_report(
        &[tmp.path().join("nan")],
        &tmp.path().join("report"),
        &ReportOptions {
            bootstrap_reps: 50,
            seed: 0,
        },
    )
    .unwrap();
    let returns = report.groups[0].metric("returns").unwrap();
    assert_eq!(returns.mean, None);
    assert_eq!(
        returns.note.as_deref(),
        Some("not finite for these runs (1 of 1 runs)")
    );
    let generalization = report.groups[0].metric("generalization").unwrap();
    assert_eq!(generalization.mean, None);
    assert!(
        generalization
            .note
            .as_deref()
            .is_some_and(|n| n.contains("nan_corridor") && n.contains("not finite")),
        "{:?}",
        generalization.note
    );
    // The report's own file reads back as what was written.
    let back: Report = read_json(&tmp.path().join("report").join("report.json")).unwrap();
    assert_eq!(back.groups[0].metric("returns"), Some(returns));
}
