//! External agents (the Python harness's engine): a run recorded like `train` records a built-in
//! one, rolled out through a `PolicySource`, reported beside built-in runs; failures keep what
//! was written and write nothing half.

mod common;

use std::path::{Path, PathBuf};

use a2perf_core::{
    ActMode, Action, Checkpoint, Env, EnvSpec, Observation, Policy, PolicyError, RunState,
};
use a2perf_pipeline::external::{
    ExternalOutcome, ExternalRun, ExternalRunSpec, episode_seed, external_plan,
};
use a2perf_pipeline::{
    ExternalAgent, InferOptions, LoadedRun, PipelineError, PolicySource, RunOutcome, TrainOptions,
    collect::{CollectOptions, CostRule},
    report::ReportOptions,
};

/// Walks right; fails on its call number `fail_at` (counted from 1) when given.
struct Right {
    calls: usize,
    fail_at: Option<usize>,
}

impl Policy for Right {
    fn act(&mut self, _obs: &Observation, _mode: ActMode) -> Result<Action, PolicyError> {
        self.calls += 1;
        if Some(self.calls) == self.fail_at {
            return Err(PolicyError::BadObservation("test: fails on purpose".into()));
        }
        Ok(Action::Discrete(1))
    }
    fn checkpoint(&self) -> Result<Checkpoint, PolicyError> {
        Err(PolicyError::BadCheckpoint(
            "saved by the agent's own code".into(),
        ))
    }
}

/// The "agent's own" policies: every checkpoint file must hold `right`.
struct AgentPolicies {
    fail_at: Option<usize>,
    fatal: bool,
    loaded: Vec<PathBuf>,
}

impl AgentPolicies {
    fn new(fail_at: Option<usize>, fatal: bool) -> Self {
        Self {
            fail_at,
            fatal,
            loaded: Vec::new(),
        }
    }
}

impl PolicySource for AgentPolicies {
    fn policy(
        &mut self,
        _run: &LoadedRun,
        checkpoint: &Path,
        _spec: &EnvSpec,
    ) -> a2perf_pipeline::Result<Box<dyn Policy>> {
        self.loaded.push(checkpoint.to_path_buf());
        Ok(Box::new(Right {
            calls: 0,
            fail_at: self.fail_at,
        }))
    }
    fn errors_are_fatal(&self) -> bool {
        self.fatal
    }
}

fn agent() -> ExternalAgent {
    ExternalAgent {
        harness: "test harness".into(),
        runtime: "Rust test".into(),
    }
}

fn config(dir: &Path) -> PathBuf {
    let p = dir.join("corridor.ron");
    std::fs::write(
        &p,
        r#"(name: "corr", env: (id: "Corridor-v0", length: 6), algorithm: (name: "random_search"),
            seeds: [0], training: (total_env_steps: 600, eval_interval: 200, eval_episodes: 3,
            checkpoint_interval: 300), inference: (rollouts: 7))"#,
    )
    .unwrap();
    p
}

fn spec(out: &Path, config: &Path, seed: u64) -> ExternalRunSpec {
    let mut s = ExternalRunSpec::new(out, "my-agent", seed);
    s.config = Some(config.to_path_buf());
    s.experiment = Some("corr".into());
    s.hyperparameters = [
        ("learning_rate".to_string(), a2perf_core::Value::Float(0.1)),
        (
            "hidden".to_string(),
            a2perf_core::Value::List(vec![a2perf_core::Value::Int(8)]),
        ),
    ]
    .into();
    s
}

/// An external run that logs three points and two checkpoints, then completes.
fn train_external(out: &Path, config: &Path, seed: u64) -> PathBuf {
    let reg = common::registry();
    let plan = external_plan(&reg, &spec(out, config, seed)).unwrap();
    let mut run = ExternalRun::begin(&reg, plan, seed, agent(), &common::test_meters()).unwrap();
    let ckpt = out.join("agent.bin");
    std::fs::write(&ckpt, b"right").unwrap();
    for (i, step) in [200u64, 400, 600].into_iter().enumerate() {
        run.log_evaluation(step, 0.5 + i as f64 * 0.1, 0.1).unwrap();
    }
    run.save_checkpoint(300, &ckpt).unwrap();
    run.save_checkpoint(600, &ckpt).unwrap();
    let dir = run.dir().to_path_buf();
    assert_eq!(
        run.finish(ExternalOutcome::Completed).unwrap(),
        RunState::Complete
    );
    dir
}

/// A temporary directory with the corridor config and a complete external run (seed 0) in it:
/// the directory, the registry, the config and the run.
fn trained_external() -> (tempfile::TempDir, a2perf_core::Registry, PathBuf, PathBuf) {
    let tmp = tempfile::tempdir().unwrap();
    let reg = common::registry();
    let cfg = config(tmp.path());
    let dir = train_external(tmp.path(), &cfg, 0);
    (tmp, reg, cfg, dir)
}

fn files(dir: &Path) -> Vec<String> {
    let mut out: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    out.sort();
    out
}

fn json(path: &Path) -> serde_json::Value {
    serde_json::from_slice(&std::fs::read(path).unwrap()).unwrap()
}

#[test]
fn external_run_is_recorded_like_a_builtin_one() {
    let tmp = tempfile::tempdir().unwrap();
    let reg = common::registry();
    let cfg = config(tmp.path());
    let mut builtin = a2perf_pipeline::load_plans(
        std::slice::from_ref(&cfg),
        &[format!("output.dir={:?}", tmp.path().display().to_string())],
        None,
        &reg,
    )
    .unwrap()
    .plans;
    let builtin = builtin.remove(0);
    let summary = a2perf_pipeline::train(
        &reg,
        &a2perf_pipeline::grid(std::slice::from_ref(&builtin), None),
        &TrainOptions {
            meters: common::test_meters(),
            ..Default::default()
        },
    )
    .unwrap();
    assert_eq!(summary.with(&RunOutcome::Completed).len(), 1);
    let b = builtin.run_dir(0);
    let e = train_external(tmp.path(), &cfg, 0);

    // Same experiment directory and task name; only the algorithm part differs.
    assert_eq!(b.parent(), e.parent());
    assert_eq!(
        e.file_name().unwrap().to_string_lossy(),
        "Corridor-v0_length_6___my-agent__seed0"
    );
    assert_eq!(
        b.file_name().unwrap().to_string_lossy(),
        "Corridor-v0_length_6___random_search__seed0"
    );
    // The same files, less the built-in policy's own checkpoint format.
    let mut builtin_files = files(&b);
    builtin_files.retain(|f| f != "policy.ckpt");
    assert_eq!(files(&e), builtin_files);

    // run.json: everything equal but the algorithm and the external agent.
    let (mut rb, mut re) = (json(&b.join("run.json")), json(&e.join("run.json")));
    assert_eq!(re["algorithm"]["name"], "my-agent");
    assert_eq!(re["algorithm"]["params"]["learning_rate"], 0.1);
    assert_eq!(re["external"]["runtime"], "Rust test");
    assert!(rb.get("external").is_none(), "built-in run.json unchanged");
    for v in [&mut rb, &mut re] {
        let o = v.as_object_mut().unwrap();
        o.remove("algorithm");
        o.remove("external");
    }
    assert_eq!(rb, re);
    let operative = std::fs::read_to_string(e.join("operative_config.ron")).unwrap();
    assert!(operative.contains("name: \"my-agent\""), "{operative}");
    assert!(operative.contains("learning_rate: 0.1"), "{operative}");
    assert!(operative.contains("hidden: [8]"), "{operative}");

    // The curve as the built-in writes it, and the system figures of the whole block.
    let csv = std::fs::read_to_string(e.join("curve.csv")).unwrap();
    assert_eq!(
        csv.lines().next(),
        std::fs::read_to_string(b.join("curve.csv"))
            .unwrap()
            .lines()
            .next()
    );
    assert_eq!(csv.lines().count(), 4);
    let system = json(&e.join("train_system.json"));
    assert!(system["wall_clock_s"].as_f64().unwrap() >= 0.0);
    assert!(
        system["meters"]["measurements"]
            .as_array()
            .unwrap()
            .iter()
            .any(|m| m["name"] == "energy_total_kwh")
    );
    let ckpts = a2perf_pipeline::collect::checkpoints(&e).unwrap();
    assert_eq!(
        ckpts.iter().map(|c| c.0).collect::<Vec<_>>(),
        vec![300, 600]
    );
    assert_eq!(std::fs::read(&ckpts[0].1).unwrap(), b"right");
    assert_eq!(json(&e.join("status.json"))["state"], "complete");
}

#[test]
fn report_merges_external_and_builtin_runs_and_lists_failed_ones() {
    let tmp = tempfile::tempdir().unwrap();
    let reg = common::registry();
    let cfg = config(tmp.path());
    let builtin = a2perf_pipeline::load_plans(
        std::slice::from_ref(&cfg),
        &[
            format!("output.dir={:?}", tmp.path().display().to_string()),
            "seeds=[0, 1]".into(),
        ],
        None,
        &reg,
    )
    .unwrap()
    .plans;
    a2perf_pipeline::train(
        &reg,
        &a2perf_pipeline::grid(&builtin, None),
        &TrainOptions {
            meters: common::test_meters(),
            ..Default::default()
        },
    )
    .unwrap();
    let infer_opts = InferOptions {
        meters: common::test_meters(),
        ..Default::default()
    };
    for seed in [0, 1] {
        let b = builtin[0].run_dir(seed);
        a2perf_pipeline::infer_run(&reg, &b, &infer_opts).unwrap();
        a2perf_pipeline::generalize_run(&reg, &b, Some(2), false).unwrap();
        let e = train_external(tmp.path(), &cfg, seed);
        let mut source = AgentPolicies::new(None, true);
        let inf = a2perf_pipeline::infer_run_with(&reg, &e, &mut source, &infer_opts).unwrap();
        assert_eq!(inf.episodes, 7, "the config's inference.rollouts");
        assert!(inf.rollout_returns.iter().all(|r| *r > 0.9), "{inf:?}");
        assert!(inf.rollout_call_time_ms.count > 0);
        let gen_ =
            a2perf_pipeline::generalize_run_with(&reg, &e, &mut source, Some(2), false).unwrap();
        assert_eq!(gen_.tasks.len(), 3);
        assert!(gen_.sum_of_mean_returns.is_some());
    }
    // A third external run fails: kept on disk, listed, not used.
    let plan = external_plan(&reg, &spec(tmp.path(), &cfg, 2)).unwrap();
    let mut run = ExternalRun::begin(&reg, plan, 2, agent(), &common::test_meters()).unwrap();
    run.log_evaluation(200, 0.1, 0.0).unwrap();
    let failed = run.dir().to_path_buf();
    assert_eq!(
        run.finish(ExternalOutcome::Failed(
            "ZeroDivisionError: division by zero".into()
        ))
        .unwrap(),
        RunState::Failed
    );
    assert!(failed.join("curve.csv").is_file(), "logged points are kept");
    assert!(failed.join("train_segments.json").is_file());

    let out = tmp.path().join("report");
    let report = a2perf_pipeline::report::write_report(
        &[tmp.path().join("corr")],
        &out,
        &ReportOptions {
            bootstrap_reps: 200,
            seed: 0,
        },
    )
    .unwrap();
    let algos: Vec<&str> = report.groups.iter().map(|g| g.algorithm.as_str()).collect();
    assert_eq!(algos, ["my-agent", "random_search"]);
    assert!(
        report
            .groups
            .iter()
            .all(|g| g.task == "Corridor-v0[length=6]")
    );
    let ext = &report.groups[0];
    assert_eq!(ext.seeds, [0, 1]);
    for key in [
        "returns",
        "generalization",
        "energy",
        "peak_ram",
        "wall_clock",
    ] {
        assert!(ext.metric(key).unwrap().mean.is_some(), "{key}: {ext:?}");
    }
    let (dir, why) = report
        .skipped_runs
        .iter()
        .find(|(d, _)| d.ends_with("my-agent__seed2"))
        .expect("the failed run is listed");
    assert!(
        why.starts_with("training failed: ZeroDivisionError"),
        "{dir}: {why}"
    );
    let md = std::fs::read_to_string(out.join("report.md")).unwrap();
    assert!(md.contains("my-agent") && md.contains("random_search"));
    assert!(md.contains("training failed: ZeroDivisionError"), "{md}");
    let radar = std::fs::read_to_string(out.join("plots/radar_Corridor-v0_length_6_.svg"))
        .or_else(|_| {
            let p = std::fs::read_dir(out.join("plots"))
                .unwrap()
                .map(|e| e.unwrap().path())
                .find(|p| p.to_string_lossy().contains("radar"))
                .unwrap();
            std::fs::read_to_string(p)
        })
        .unwrap();
    // Legends are upper-cased.
    assert!(
        radar.contains("MY-AGENT") && radar.contains("RANDOM_SEARCH"),
        "{radar}"
    );
    assert!(!radar.contains("no radar"), "{radar}");
    let board = json(&out.join("leaderboard.json"));
    let entries = board["entries"].as_array().unwrap();
    assert_eq!(entries.len(), 2);
    assert_eq!(entries[0]["run"]["external"]["harness"], "test harness");
}

#[test]
fn builtin_pipelines_refuse_external_runs_with_a_clear_error() {
    let tmp = tempfile::tempdir().unwrap();
    let reg = common::registry();
    let e = train_external(tmp.path(), &config(tmp.path()), 0);
    let err = a2perf_pipeline::infer_run(&reg, &e, &InferOptions::default())
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("external agent") && err.contains("a2perf_rs"),
        "{err}"
    );
    let err = a2perf_pipeline::generalize_run(&reg, &e, Some(1), false).unwrap_err();
    assert!(err.to_string().contains("external agent"), "{err}");
    let err = a2perf_pipeline::collect::collect(
        &reg,
        std::slice::from_ref(&e),
        &tmp.path().join("datasets"),
        &CollectOptions::default(),
    )
    .unwrap_err();
    assert!(err.to_string().contains("external agent"), "{err}");
    assert!(!e.join("inference.json").exists() && !e.join("generalization.json").exists());
}

#[test]
fn a_failing_policy_names_the_episode_and_step_and_writes_nothing() {
    let tmp = tempfile::tempdir().unwrap();
    let reg = common::registry();
    let e = train_external(tmp.path(), &config(tmp.path()), 0);
    let emissions = e.join("inference_emissions.csv");
    std::fs::write(&emissions, "earlier row\n").unwrap();
    // The corridor of length 6 ends after at most 6 steps walking right; call 9 is in episode 1
    // or 2 depending on the start cell: the error says which.
    let mut source = AgentPolicies::new(Some(9), true);
    let err = a2perf_pipeline::infer_run_with(&reg, &e, &mut source, &InferOptions::default())
        .unwrap_err();
    let PipelineError::Rollout { episode, step, .. } = &err else {
        panic!("expected a rollout error, got {err}");
    };
    assert!(*episode >= 1, "{err}");
    assert!(
        err.to_string()
            .contains(&format!("episode {episode}, step {step}"))
    );
    assert!(err.to_string().contains("fails on purpose"), "{err}");
    assert!(!e.join("inference.json").exists());
    assert_eq!(
        std::fs::read_to_string(&emissions).unwrap(),
        "earlier row\n"
    );

    // Fatal errors stop generalization with nothing written; others are the task's failure.
    let err =
        a2perf_pipeline::generalize_run_with(&reg, &e, &mut source, Some(3), false).unwrap_err();
    assert!(matches!(err, PipelineError::Rollout { .. }), "{err}");
    assert!(!e.join("generalization.json").exists());
    let mut lenient = AgentPolicies::new(Some(9), false);
    let gr = a2perf_pipeline::generalize_run_with(&reg, &e, &mut lenient, Some(3), false).unwrap();
    assert!(gr.sum_of_mean_returns.is_none());
    assert!(gr.tasks.iter().all(|t| t.error.is_some()), "{gr:?}");
    assert!(e.join("generalization.json").exists());
}

#[test]
fn collect_reads_external_checkpoints_through_the_source() {
    let tmp = tempfile::tempdir().unwrap();
    let reg = common::registry();
    let cfg = config(tmp.path());
    let runs: Vec<PathBuf> = (0..2)
        .map(|s| train_external(tmp.path(), &cfg, s))
        .collect();
    let mut source = AgentPolicies::new(None, true);
    let summary = a2perf_pipeline::collect::collect_with(
        &reg,
        &runs,
        &tmp.path().join("datasets"),
        &mut source,
        &CollectOptions {
            eval_episodes: 2,
            dataset_episodes: 3,
            cost: CostRule::Measured,
            one_sigma: true,
            show_progress: false,
            cancel: Default::default(),
        },
    )
    .unwrap();
    assert_eq!(summary.evaluations.len(), 4);
    assert!(!summary.datasets.is_empty());
    assert!(
        source
            .loaded
            .iter()
            .all(|p| p.starts_with(tmp.path()) && p.is_file())
    );
    for d in &summary.datasets {
        assert!(d.path.join("samples.json").is_file());
        assert!(d.training_sample_cost_kwh.is_some(), "{d:?}");
    }
}

#[test]
fn reruns_start_unfinished_external_runs_again_and_refuse_complete_ones() {
    let (tmp, reg, cfg, dir) = trained_external();
    let plan = external_plan(&reg, &spec(tmp.path(), &cfg, 0)).unwrap();
    let err = ExternalRun::begin(&reg, plan.clone(), 0, agent(), &common::test_meters())
        .unwrap_err()
        .to_string();
    assert!(err.contains("already complete"), "{err}");

    // A run that logged nothing is marked failed, with an error; a rerun starts it afresh.
    std::fs::remove_dir_all(&dir).unwrap();
    let mut run =
        ExternalRun::begin(&reg, plan.clone(), 0, agent(), &common::test_meters()).unwrap();
    let ckpt = tmp.path().join("c.bin");
    std::fs::write(&ckpt, b"x").unwrap();
    run.save_checkpoint(5, &ckpt).unwrap();
    let err = run
        .finish(ExternalOutcome::Completed)
        .unwrap_err()
        .to_string();
    assert!(err.contains("logged no evaluation"), "{err}");
    assert_eq!(json(&dir.join("status.json"))["state"], "failed");
    assert!(dir.join("checkpoints").is_dir(), "kept");
    let run = ExternalRun::begin(&reg, plan, 0, agent(), &common::test_meters()).unwrap();
    assert!(
        !dir.join("checkpoints").exists(),
        "a rerun starts from an empty directory"
    );
    assert_eq!(
        run.finish(ExternalOutcome::Interrupted("KeyboardInterrupt".into()))
            .unwrap(),
        RunState::Interrupted
    );
}

#[test]
fn bad_requests_are_refused_naming_the_problem() {
    let tmp = tempfile::tempdir().unwrap();
    let reg = common::registry();
    let cfg = config(tmp.path());
    let check = |edit: &dyn Fn(&mut ExternalRunSpec), want: &str| {
        let mut s = spec(tmp.path(), &cfg, 0);
        edit(&mut s);
        let err = external_plan(&reg, &s).unwrap_err().to_string();
        assert!(err.contains(want), "{want}: {err}");
    };
    check(&|s| s.algorithm = " ".into(), "give the agent a name");
    check(
        &|s| s.algorithm = "random_search".into(),
        "built-in algorithm",
    );
    check(&|s| s.experiment = Some("a/b".into()), "experiment `a/b`");
    check(
        &|s| {
            s.hyperparameters
                .insert("learning-rate".into(), a2perf_core::Value::Int(1));
        },
        "hyperparameter `learning-rate`",
    );
    check(
        &|s| {
            s.hyperparameters
                .insert("net".into(), a2perf_core::Value::Map(Default::default()));
        },
        "hyperparameter `net`: a map",
    );
    check(
        &|s| {
            s.env_params
                .insert("lenght".into(), a2perf_core::Value::Int(3));
        },
        "did you mean `length`",
    );
    check(
        &|s| {
            s.config = None;
            s.env_id = None;
        },
        "env_id",
    );
    check(
        &|s| s.set = vec!["trainig.num_envs=2".into()],
        "did you mean `training`",
    );

    let plan = external_plan(&reg, &spec(tmp.path(), &cfg, 0)).unwrap();
    let mut run = ExternalRun::begin(&reg, plan, 0, agent(), &common::test_meters()).unwrap();
    run.log_evaluation(10, 1.0, 0.0).unwrap();
    for (steps, mean, std) in [(10, 1.0, 0.0), (20, f64::NAN, 0.0), (30, 1.0, -1.0)] {
        assert!(run.log_evaluation(steps, mean, std).is_err());
    }
    let err = run
        .save_checkpoint(10, &tmp.path().join("missing.bin"))
        .unwrap_err();
    assert!(err.to_string().contains("missing.bin"), "{err}");
    assert_eq!(run.curve().points.len(), 1);
    run.finish(ExternalOutcome::Completed).unwrap();
}

#[test]
fn episode_seeds_are_those_of_the_builtin_training_environments() {
    let reg = a2perf_pipeline::registry::full_registry();
    let id = "WebNavigation-Difficulty-01-v0";
    let params = Default::default();
    let envs: Vec<Box<dyn Env>> = (0..2).map(|_| reg.make_env(id, &params).unwrap()).collect();
    let mut vec = a2perf_core::VecEnv::new(envs, 7);
    let first: Vec<Observation> = vec
        .reset_all()
        .unwrap()
        .iter()
        .map(|s| s.step.observation.clone())
        .collect();
    let mut single = reg.make_env(id, &params).unwrap();
    for (i, obs) in first.iter().enumerate() {
        assert_eq!(*obs, single.reset(Some(episode_seed(7, i, 0))).unwrap());
    }
    assert_ne!(first[0], first[1]);
    // The next episode of environment 0 (after its first ends) starts from its second seed.
    // Action 0 (a click on the first element) is legal in every state of this task.
    let next = loop {
        let s = &vec
            .step_all(&[Action::Discrete(0), Action::Discrete(0)])
            .unwrap()[0];
        if s.step.done() {
            break s.step.observation.clone();
        }
    };
    assert_eq!(next, single.reset(Some(episode_seed(7, 0, 1))).unwrap());
}

/// Walks right; checks that every `act` was prepared with its own observation just before.
#[derive(Default)]
struct Prepared {
    pending: Option<Observation>,
    prepared: usize,
    unprepared_calls: usize,
}

impl Policy for Prepared {
    fn act(&mut self, obs: &Observation, _mode: ActMode) -> Result<Action, PolicyError> {
        match self.pending.take() {
            Some(p) if p == *obs => {}
            _ => self.unprepared_calls += 1,
        }
        Ok(Action::Discrete(1))
    }
    fn prepare(&mut self, obs: &Observation) -> Result<(), PolicyError> {
        self.prepared += 1;
        self.pending = Some(obs.clone());
        Ok(())
    }
    fn checkpoint(&self) -> Result<Checkpoint, PolicyError> {
        Err(PolicyError::BadCheckpoint(
            "saved by the agent's own code".into(),
        ))
    }
}

/// Hands out one shared [`Prepared`] policy and keeps its counts.
#[derive(Default)]
struct PreparedSource(std::sync::Arc<std::sync::Mutex<Prepared>>);

struct SharedPrepared(std::sync::Arc<std::sync::Mutex<Prepared>>);

impl Policy for SharedPrepared {
    fn act(&mut self, obs: &Observation, mode: ActMode) -> Result<Action, PolicyError> {
        self.0.lock().unwrap().act(obs, mode)
    }
    fn prepare(&mut self, obs: &Observation) -> Result<(), PolicyError> {
        self.0.lock().unwrap().prepare(obs)
    }
    fn checkpoint(&self) -> Result<Checkpoint, PolicyError> {
        self.0.lock().unwrap().checkpoint()
    }
}

impl PolicySource for PreparedSource {
    fn policy(
        &mut self,
        _run: &LoadedRun,
        _checkpoint: &Path,
        _spec: &EnvSpec,
    ) -> a2perf_pipeline::Result<Box<dyn Policy>> {
        Ok(Box::new(SharedPrepared(self.0.clone())))
    }
}

#[test]
fn inference_prepares_every_timed_call_with_its_own_observation() {
    let tmp = tempfile::tempdir().unwrap();
    let reg = common::registry();
    let e = train_external(tmp.path(), &config(tmp.path()), 0);
    for (source, samples) in [
        (a2perf_pipeline::ObservationSource::Rollouts, 0),
        (a2perf_pipeline::ObservationSource::Random, 11),
    ] {
        let mut policies = PreparedSource::default();
        let opts = InferOptions {
            observation_source: Some(source),
            timing_samples: Some(11),
            ..InferOptions::default()
        };
        let r = a2perf_pipeline::infer_run_with(&reg, &e, &mut policies, &opts).unwrap();
        let p = policies.0.lock().unwrap();
        let calls: usize = r.episode_lengths.iter().sum();
        assert_eq!(r.rollout_call_time_ms.count, calls);
        assert_eq!(p.prepared, calls + samples, "{source:?}");
        assert_eq!(p.unprepared_calls, 0, "{source:?}");
    }
}

#[test]
fn an_external_run_bundles_with_its_files_and_verifies_without_its_code() {
    use a2perf_pipeline::bundle::{ArchiveLimits, Bundle, Outcome, VerifyOptions, pack};
    let (tmp, reg, _, e) = trained_external();
    let mut source = AgentPolicies::new(None, true);
    let opts = InferOptions {
        meters: common::test_meters(),
        ..Default::default()
    };
    a2perf_pipeline::infer_run_with(&reg, &e, &mut source, &opts).unwrap();
    a2perf_pipeline::generalize_run_with(&reg, &e, &mut source, Some(2), false).unwrap();
    // A submission's folder, kept in the run: carried, never run.
    let folder = e.join(a2perf_pipeline::run_dir::PARTICIPANT_DIR);
    std::fs::create_dir_all(&folder).unwrap();
    std::fs::write(
        folder.join("train.py"),
        "raise SystemExit('must not run')\n",
    )
    .unwrap();

    let file = tmp.path().join("external.a2perf");
    pack(&reg, std::slice::from_ref(&e), &file).unwrap();
    let bundle = Bundle::read(&file, &ArchiveLimits::default()).unwrap();
    let names: Vec<&str> = bundle.archive().names().collect();
    let has = |suffix: &str| names.iter().any(|n| n.ends_with(suffix));
    assert!(
        has(&format!(
            "/{}/train.py",
            a2perf_pipeline::run_dir::PARTICIPANT_DIR
        )) && has("/episodes/inference.json"),
        "{names:?}"
    );
    assert_eq!(
        names.iter().filter(|n| n.contains("/checkpoints/")).count(),
        2
    );
    assert!(!has("/policy.ckpt"));

    let v = bundle.verify(&reg, &VerifyOptions { retrain: true });
    assert!(v.holds(), "{:#?}", v.checks);
    let outcome = |what: &str| {
        v.checks
            .iter()
            .find(|c| c.what.starts_with(what))
            .map(|c| c.outcome.clone())
    };
    assert!(matches!(
        outcome("inference returns"),
        Some(Outcome::Holds(_))
    ));
    assert!(matches!(
        outcome("generalization returns"),
        Some(Outcome::Holds(_))
    ));
    assert!(matches!(
        outcome("checkpoint re-run"),
        Some(Outcome::Skipped(_))
    ));
    assert!(matches!(outcome("retrain"), Some(Outcome::Skipped(_))));
}
