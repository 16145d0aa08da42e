//! End to end: train → infer → generalize → collect → offline training → report, on the example
//! crate's corridor with tiny budgets; every category of the table must be present and finite.

mod common;

use a2perf_pipeline::{
    self, InferOptions, RunOutcome, TrainOptions,
    collect::{CollectOptions, CostRule},
    report::{Category, ReportOptions},
};

#[test]
fn train_infer_generalize_collect_report() {
    let tmp = tempfile::tempdir().unwrap();
    let reg = common::registry();
    let online = common::plan(tmp.path(), "online", vec![0, 1, 2]);
    let opts = TrainOptions {
        jobs: 2,
        meters: common::test_meters(),
        ..Default::default()
    };
    let summary = a2perf_pipeline::train(
        &reg,
        &a2perf_pipeline::grid(std::slice::from_ref(&online), None),
        &opts,
    )
    .unwrap();
    assert_eq!(summary.with(&RunOutcome::Completed).len(), 3);
    for seed in 0..3 {
        let dir = online.run_dir(seed);
        for f in [
            "run.json",
            "curve.csv",
            "curve.json",
            "policy.ckpt",
            "system_info.json",
            "train_system.json",
        ] {
            assert!(dir.join(f).is_file(), "{} missing", f);
        }
        let ckpts = a2perf_pipeline::collect::checkpoints(&dir).unwrap();
        assert!(
            ckpts.len() >= 4,
            "interval checkpoints plus the final one: {ckpts:?}"
        );
        let inf = a2perf_pipeline::infer_run(
            &reg,
            &dir,
            &InferOptions {
                episodes: Some(10),
                meters: common::test_meters(),
                ..Default::default()
            },
        )
        .unwrap();
        assert_eq!(inf.rollout_returns.len(), 10);
        assert!(inf.inference_time_ms.count > 0 && inf.inference_time_ms.mean > 0.0);
        let gr = a2perf_pipeline::generalize_run(&reg, &dir, Some(4), false).unwrap();
        assert_eq!(gr.tasks.len(), 3);
        let sum: f64 = gr.tasks.iter().map(|t| t.mean_return.unwrap()).sum();
        assert!((gr.sum_of_mean_returns.unwrap() - sum).abs() < 1e-12);
    }

    // Offline data from the online runs' checkpoints, with its training sample cost.
    let runs: Vec<_> = (0..3).map(|s| online.run_dir(s)).collect();
    let collected = a2perf_pipeline::collect::collect(
        &reg,
        &runs,
        &tmp.path().join("datasets"),
        &CollectOptions {
            eval_episodes: 5,
            dataset_episodes: 6,
            cost: CostRule::ProRata,
            one_sigma: true,
            show_progress: false,
            cancel: Default::default(),
        },
    )
    .unwrap();
    let n_ckpts: usize = runs
        .iter()
        .map(|r| a2perf_pipeline::collect::checkpoints(r).unwrap().len())
        .sum();
    assert_eq!(collected.evaluations.len(), n_ckpts);
    let data = collected
        .datasets
        .iter()
        .max_by(|a, b| a.mean_return.total_cmp(&b.mean_return))
        .unwrap();
    assert!(data.training_sample_cost_kwh.unwrap() > 0.0);
    let samples = data.path.join("samples.json");

    let mut offline = common::plan(tmp.path(), "offline", vec![0, 1, 2]);
    offline.algorithm.name = "toy_bc".into();
    offline.algorithm.params.insert(
        "dataset".into(),
        a2perf_core::Value::Str(samples.display().to_string()),
    );
    let info = a2perf_pipeline::collect::dataset_info_for(&samples)
        .unwrap()
        .unwrap();
    offline.dataset = Some(a2perf_pipeline::DatasetProvenance::from_info(
        &info,
        &samples.display().to_string(),
    ));
    a2perf_pipeline::train(
        &reg,
        &a2perf_pipeline::grid(std::slice::from_ref(&offline), None),
        &opts,
    )
    .unwrap();
    for seed in 0..3 {
        let dir = offline.run_dir(seed);
        a2perf_pipeline::infer_run(
            &reg,
            &dir,
            &InferOptions {
                episodes: Some(5),
                meters: common::test_meters(),
                ..Default::default()
            },
        )
        .unwrap();
        a2perf_pipeline::generalize_run(&reg, &dir, Some(2), false).unwrap();
    }

    let out = tmp.path().join("report");
    let report = a2perf_pipeline::report::write_report(
        &[tmp.path().join("online"), tmp.path().join("offline")],
        &out,
        &ReportOptions {
            bootstrap_reps: 200,
            seed: 0,
        },
    )
    .unwrap();
    assert_eq!(report.groups.len(), 2);
    let off = report
        .groups
        .iter()
        .find(|g| g.algorithm == "toy_bc")
        .unwrap();
    let on = report
        .groups
        .iter()
        .find(|g| g.algorithm == "random_search")
        .unwrap();
    for cat in [
        Category::DataCost,
        Category::Application,
        Category::Reliability,
        Category::SystemTraining,
        Category::SystemInference,
    ] {
        let ms: Vec<_> = off.metrics.iter().filter(|m| m.category == cat).collect();
        assert!(!ms.is_empty(), "{cat:?} missing");
        for m in ms {
            if m.key.contains("gpu") {
                // No GPU here: reported absent, never as 0.
                assert!(m.mean.is_none() && m.note.as_deref().unwrap().starts_with("absent"));
                continue;
            }
            let v = m
                .mean
                .unwrap_or_else(|| panic!("{} has no value: {:?}", m.key, m.note));
            assert!(v.is_finite(), "{} = {v}", m.key);
        }
    }
    // Online runs have no dataset: data cost is marked not applicable, everything else finite.
    for m in &on.metrics {
        if m.category == Category::DataCost {
            assert!(m.mean.is_none() && m.note.as_deref().unwrap().contains("not applicable"));
        } else if m.key.contains("gpu") {
            assert!(m.mean.is_none());
        } else {
            assert!(
                m.mean.is_some_and(f64::is_finite),
                "{}: {:?}",
                m.key,
                m.note
            );
        }
    }
    let total = off.metric("total_energy").unwrap().mean.unwrap();
    let cost = off.metric("training_sample_cost").unwrap().mean.unwrap();
    assert!(
        total > cost,
        "total energy adds the training energy to the sample cost"
    );
    assert_eq!(report.iqm.len(), 2);
    assert_eq!(report.probability_of_improvement.len(), 2);
    let p = &report.probability_of_improvement;
    assert!((p[0].probability + p[1].probability - 1.0).abs() < 1e-12);

    for f in [
        "report.md",
        "report.tex",
        "metrics.csv",
        "report.json",
        "leaderboard.json",
        "curves.csv",
        "scores.csv",
        "plots/radar_Corridor-v0.svg",
        "plots/curves_Corridor-v0.svg",
    ] {
        let text = std::fs::read_to_string(out.join(f)).unwrap_or_else(|e| panic!("{f}: {e}"));
        assert!(!text.is_empty() && !text.contains("NaN"), "{f}");
    }
    let tex = std::fs::read_to_string(out.join("report.tex")).unwrap();
    assert!(tex.contains("\\toprule") && tex.contains("\\textbf{TOY\\_BC}"));
    let md = std::fs::read_to_string(out.join("report.md")).unwrap();
    assert!(md.contains("Dispersion across runs") && md.contains("RANDOM_SEARCH"));
    // Where training time went: every run records its split; evaluation always runs, the
    // offline learner times its learning, and no part claims more than the wall clock.
    for g in [on, off] {
        let t = g.time_split.expect("every run recorded its time split");
        assert!(t.parts.evaluation_s > 0.0, "{}: {t:?}", g.algorithm);
        assert!(t.parts.parts().iter().all(|&(_, x)| x >= 0.0));
        assert!(t.parts.total() <= t.wall_s * 1.01 + 0.01, "{t:?}");
    }
    assert!(md.contains("## Where training time went"));
    let radar = std::fs::read_to_string(out.join("plots/radar_Corridor-v0.svg")).unwrap();
    assert_eq!(
        radar.matches("<polygon").count(),
        4 + 2,
        "4 grid rings + 2 algorithms"
    );
    let lb: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("leaderboard.json")).unwrap())
            .unwrap();
    let entry = &lb["entries"][0];
    assert_eq!(entry["seeds"], serde_json::json!([0, 1, 2]));
    assert!(entry["run"]["algorithm"]["params"].is_object());
    assert!(lb["hardware_and_software"][0]["rustc_version"].is_string());
    // For eyeballing: A2PERF_KEEP_REPORT=DIR keeps a copy of the report.
    if let Ok(keep) = std::env::var("A2PERF_KEEP_REPORT") {
        let keep = std::path::Path::new(&keep);
        std::fs::create_dir_all(keep.join("plots")).unwrap();
        for f in [
            "report.md",
            "report.tex",
            "metrics.csv",
            "plots/radar_Corridor-v0.svg",
            "plots/curves_Corridor-v0.svg",
        ] {
            std::fs::copy(out.join(f), keep.join(f)).unwrap();
        }
    }
}

#[test]
fn real_system_meters_record_energy_ram_and_an_emissions_csv() {
    let tmp = tempfile::tempdir().unwrap();
    let reg = common::registry();
    let mut plan = common::plan(tmp.path(), "metered", vec![0]);
    plan.metrics.ram_sample_interval_s = 0.05;
    let opts = TrainOptions {
        meters: a2perf_pipeline::meters::system_meters(),
        ..Default::default()
    };
    a2perf_pipeline::train(
        &reg,
        &a2perf_pipeline::grid(std::slice::from_ref(&plan), None),
        &opts,
    )
    .unwrap();
    let dir = plan.run_dir(0);
    let sys: a2perf_pipeline::train::PhaseSystem =
        serde_json::from_slice(&std::fs::read(dir.join("train_system.json")).unwrap()).unwrap();
    assert!(sys.meter_errors.is_empty(), "{:?}", sys.meter_errors);
    assert!(sys.meters.value("energy_kwh").is_some_and(|e| e >= 0.0));
    assert!(sys.meters.value("peak_ram_gb").is_some_and(|r| r > 0.0));
    let csv = std::fs::read_to_string(dir.join("train_emissions.csv")).unwrap();
    assert!(
        csv.starts_with("timestamp,") && csv.lines().count() == 2,
        "{csv}"
    );
}

#[test]
fn two_experiments_of_one_algorithm_on_one_task_stay_apart() {
    let tmp = tempfile::tempdir().unwrap();
    let reg = common::registry();
    let a = common::plan(tmp.path(), "a", vec![0]);
    let mut b = common::plan(tmp.path(), "b", vec![0]);
    b.algorithm
        .params
        .insert("noise".into(), a2perf_core::Value::Float(0.1));
    a2perf_pipeline::train(
        &reg,
        &a2perf_pipeline::grid(&[a, b], None),
        &TrainOptions::default(),
    )
    .unwrap();
    let report = a2perf_pipeline::report::write_report(
        &[tmp.path().to_path_buf()],
        &tmp.path().join("report"),
        &ReportOptions {
            bootstrap_reps: 10,
            seed: 0,
        },
    )
    .unwrap();
    let labels: Vec<&str> = report.groups.iter().map(|g| g.algorithm.as_str()).collect();
    assert_eq!(labels, ["random_search:a", "random_search:b"]);
    // Not inferred yet: returns are missing with the reason, not zero.
    let m = report.groups[0].metric("returns").unwrap();
    assert!(m.mean.is_none() && m.note.as_deref().unwrap().contains("a2perf infer"));
}
