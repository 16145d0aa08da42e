//! The paper suite (`configs/paper/suite.ron`) end to end at tiny budgets. Its own test binary:
//! it points `A2PERF_PAPER_DATA` at the shared data, and nothing else in this process reads the
//! environment meanwhile.

mod common;

use std::path::{Path, PathBuf};

use a2perf_pipeline::load_plans;
use a2perf_pipeline::plan::ExperimentPlan;
use a2perf_pipeline::registry::full_registry;

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// The paper's data under `../shared/data` (the profile's default `A2PERF_PAPER_DATA`), or why
/// not.
fn paper_data() -> Option<PathBuf> {
    let data = root().join("../shared/data");
    let needed = [
        "circuit/toy_macro_stdcell/netlist.pb.txt",
        "circuit/ariane133_ng45/netlist.pb.txt.gz",
        "locomotion/motions/dog_pace.txt",
        "locomotion/motions/dog_trot.txt",
        "locomotion/motions/dog_spin.txt",
        "web/a2perf_designs/01.json",
    ];
    match needed.iter().find(|f| !data.join(f).is_file()) {
        None => Some(data),
        Some(missing) => {
            assert!(
                std::env::var("A2PERF_REQUIRE_SHARED").as_deref() != Ok("1"),
                "A2PERF_REQUIRE_SHARED=1 but {} is missing",
                data.join(missing).display()
            );
            eprintln!(
                "skipped: {} is missing (the paper's data)",
                data.join(missing).display()
            );
            None
        }
    }
}

/// The paper suite end to end at tiny budgets, on one task per domain (toy_macro_stdcell,
/// dog_pace, web level 1 with one website: 9 of its 24 experiments, seed 0; the whole suite
/// takes several minutes even at these budgets, mostly Ariane's and the locomotion episodes of
/// collection and generalization): the online runs train, BC's datasets are collected from them
/// inside the suite, BC trains on them, and every run is inferred, generalized on the paper's
/// lists under the profile and reported.
#[test]
fn the_paper_suite_runs_end_to_end_at_tiny_budgets_on_one_task_per_domain() {
    let Some(data) = paper_data() else {
        return;
    };
    let registry = full_registry();
    let tmp = tempfile::tempdir().unwrap();
    let data = data.canonicalize().unwrap();
    // The profile's paths are relative to the working directory by default; the variable makes
    // them independent of where the test runs. SAFETY: the only test of this binary, and
    // no thread of it runs yet.
    unsafe { std::env::set_var("A2PERF_PAPER_DATA", &data) };
    let sets: Vec<String> = [
        format!("output.dir={}", tmp.path().display()),
        "seeds=[0]".into(),
        "training=(total_env_steps: 300, eval_interval: 150, eval_episodes: 1, \
         checkpoint_interval: 150, num_envs: 1)"
            .into(),
        "inference=(rollouts: 1, timing_samples: 3, observation_source: \"random\")".into(),
        "generalization.episodes=1".into(),
        "metrics.bootstrap_reps=100".into(),
    ]
    .into();
    // The shipped suite, with one change: its web BC entries draw DDQN's one-σ `expert` level,
    // which needs a checkpoint whose return is strictly above mean + std; DDQN's two
    // checkpoints of 300 steps cannot make one (the pipeline then refuses, naming the level,
    // as it should). Here they draw the `intermediate` level of PPO's and DDQN's checkpoints
    // together. The suite's own budgets populate `expert` (docs/paper/README.md). Config paths
    // are made absolute for the copy in `tmp`.
    let shipped = std::fs::read_to_string(root().join("configs/paper/suite.ron")).unwrap();
    let configs = root().join("configs/paper").canonicalize().unwrap();
    let mut text = shipped.replace("(config: \"", &format!("(config: \"{}/", configs.display()));
    for n in [1, 5, 10] {
        let exp = format!("paper_web_difficulty_level_1_num_websites_{n}");
        let expert = format!("from: [\"{exp}_ddqn\"], level: \"expert\", one_sigma: true");
        assert_eq!(text.matches(&expert).count(), 1, "{expert}");
        text = text.replace(
            &expert,
            &format!("from: [\"{exp}_ppo\", \"{exp}_ddqn\"], level: \"intermediate\""),
        );
    }
    let file = tmp.path().join("suite.ron");
    std::fs::write(&file, text).unwrap();
    let loaded = load_plans(std::slice::from_ref(&file), &sets, None, &registry)
        .unwrap_or_else(|e| panic!("{e}"));
    let keep = [
        "toy_macro_stdcell",
        "dog_pace",
        "difficulty_level_1_num_websites_1",
    ];
    let plans: Vec<ExperimentPlan> = loaded
        .plans
        .into_iter()
        .filter(|p| keep.iter().any(|t| p.name.contains(&format!("_{t}_"))))
        .collect();
    assert_eq!(plans.len(), 9);
    let report = tmp.path().join("report");
    let opts = a2perf_pipeline::RunOptions {
        meters: common::test_meters(),
        report_dir: Some(report.clone()),
        ..Default::default()
    };
    let mut phases = Vec::new();
    a2perf_pipeline::run_experiments(&registry, &plans, &opts, &mut |e| {
        if let a2perf_pipeline::RunEvent::Phase(p) = e {
            phases.push(p)
        }
    })
    .unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(phases, ["train", "infer", "generalize", "report"]);
    for plan in &plans {
        let run = a2perf_pipeline::LoadedRun::open(&plan.run_dir(0)).unwrap();
        let profile = run.record.task.profile.as_ref().expect("profile recorded");
        assert_eq!(profile.name, "a2perf");
        assert!(profile.in_force().count() >= 1, "{}", plan.name);
        let suite = run.record.generalization.suite.as_ref().unwrap();
        // The paper's lists (checked against the paper in paper_configs.rs), as planned.
        assert_eq!(
            Some(suite),
            plan.generalization.suite.as_ref(),
            "{}",
            plan.name
        );
        assert_eq!(suite.source, a2perf_pipeline::plan::SuiteSource::Profile);
        let generalization: serde_json::Value = serde_json::from_str(
            &std::fs::read_to_string(plan.run_dir(0).join("generalization.json")).unwrap(),
        )
        .unwrap();
        for name in suite.tasks.iter().map(|t| &t.name) {
            assert!(
                generalization.to_string().contains(name.as_str()),
                "{}: no {name} in generalization.json",
                plan.name
            );
        }
        assert!(plan.run_dir(0).join("inference.json").is_file());
        if plan.algorithm.name == "bc" {
            let source = plan.dataset_from.as_ref().unwrap();
            let provenance = run.record.dataset.as_ref().expect("dataset provenance");
            assert_eq!(provenance.path, source.samples.display().to_string());
            assert!(source.samples.is_file());
        } else {
            assert!(run.record.dataset.is_none());
        }
    }
    let md = std::fs::read_to_string(report.join("report.md")).unwrap();
    for plan in &plans {
        assert!(
            md.contains(&plan.task.name),
            "report.md has no table of {}",
            plan.task.name
        );
    }
    assert!(md.contains("Profile: a2perf"), "{md}");
    // Timed on random samples, and the report says so rather than claiming rollout observations.
    assert!(md.contains("on random observation-space samples"), "{md}");
    assert!(!md.contains("met in the rollouts"), "{md}");
}
