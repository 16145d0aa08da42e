//! A suite entry with a `dataset` step: its offline experiment trains on a dataset that
//! `run_experiments` collects from other experiments of the same suite once they are trained.

mod common;

use std::path::{Path, PathBuf};

use a2perf_core::Value;
use a2perf_pipeline::{RunEvent, RunOptions, TrainTask, load_plans, run_experiments};

use common::write;

/// Two online experiments on the corridor and an offline one drawing from both.
fn suite(dir: &Path, dataset: &str) -> PathBuf {
    common::dataset_suite(
        dir,
        &[
            // The offline entry may come first: it is planned after the others.
            &format!(r#"(config: "offline.ron", dataset: {dataset})"#),
            r#"(config: "online.ron", set: ["name=a"])"#,
            r#"(config: "online.ron", set: ["name=b"])"#,
        ],
    )
}

const STEP: &str = r#"(from: ["a", "b"], level: "intermediate", eval_episodes: 2, episodes: 4)"#;

#[test]
fn a_dataset_step_collects_from_the_suites_runs_and_trains_on_it() {
    let tmp = tempfile::tempdir().unwrap();
    let reg = common::registry();
    let file = suite(tmp.path(), STEP);
    let loaded = load_plans(std::slice::from_ref(&file), &[], None, &reg).unwrap();
    // File order is kept.
    let names: Vec<&str> = loaded.plans.iter().map(|p| p.name.as_str()).collect();
    assert_eq!(names, ["offline", "a", "b"]);
    let offline = &loaded.plans[0];
    let source = offline
        .dataset_from
        .as_ref()
        .expect("dataset step resolved");
    assert_eq!(
        source.runs,
        [
            loaded.plans[1].run_dir(0),
            loaded.plans[1].run_dir(1),
            loaded.plans[2].run_dir(0),
            loaded.plans[2].run_dir(1),
        ]
    );
    assert_eq!(source.out, offline.experiment_dir().join("datasets"));
    assert_eq!(
        source.samples,
        source
            .out
            .join("Corridor-intermediate-v0")
            .join("samples.json")
    );
    // The experiment's own parameter names the dataset (so its operative config and run.json
    // do); nothing is collected yet.
    assert_eq!(
        offline.algorithm.params["dataset"],
        Value::Str(source.samples.display().to_string())
    );
    assert!(offline.dataset.is_none() && !source.samples.exists());

    let mut phases = Vec::new();
    let opts = RunOptions {
        meters: common::test_meters(),
        ..Default::default()
    };
    run_experiments(&reg, &loaded.plans, &opts, &mut |e| match e {
        RunEvent::Phase(p) => phases.push(p.to_string()),
        RunEvent::Started(TrainTask::Collect(name)) => phases.push(format!("collect {name}")),
        _ => {}
    })
    .unwrap();
    // The dataset is collected in the training pool, once its sources are trained.
    assert_eq!(
        phases,
        ["train", "collect offline", "infer", "generalize", "report"]
    );
    assert!(source.samples.is_file());
    for seed in [0, 1] {
        let run = a2perf_pipeline::LoadedRun::open(&offline.run_dir(seed)).unwrap();
        let provenance = run.record.dataset.as_ref().expect("dataset provenance");
        assert_eq!(provenance.dataset_id, "Corridor-intermediate-v0");
        assert_eq!(provenance.path, source.samples.display().to_string());
        assert!(provenance.training_sample_cost_kwh.unwrap() > 0.0);
        assert_eq!(
            run.record.algorithm.params["dataset"],
            Value::Str(source.samples.display().to_string())
        );
        let operative =
            std::fs::read_to_string(offline.run_dir(seed).join("operative_config.ron")).unwrap();
        assert!(
            operative.contains(&format!("dataset: \"{}\"", source.samples.display())),
            "{operative}"
        );
        assert!(offline.run_dir(seed).join("inference.json").is_file());
    }
    // Every source run's checkpoints were evaluated for the levels.
    for run in &source.runs {
        assert!(
            run.join("collect/evaluation.json").is_file(),
            "{}",
            run.display()
        );
    }

    // A second run finds everything complete: nothing is collected or trained again.
    let stamp = std::fs::metadata(&source.samples)
        .unwrap()
        .modified()
        .unwrap();
    let before = std::fs::read(offline.run_dir(0).join("policy.ckpt")).unwrap();
    run_experiments(&reg, &loaded.plans, &opts, &mut |_| {}).unwrap();
    assert_eq!(
        std::fs::metadata(&source.samples)
            .unwrap()
            .modified()
            .unwrap(),
        stamp
    );
    assert_eq!(
        std::fs::read(offline.run_dir(0).join("policy.ckpt")).unwrap(),
        before
    );

    // An unfinished offline run finds its dataset: the recorded request (the step and the
    // sources' checkpoints) matches, so it is not collected again.
    let samples_before = std::fs::read(&source.samples).unwrap();
    let request = source.out.join("request.json");
    assert!(request.is_file(), "the dataset step records its request");
    std::fs::remove_dir_all(offline.run_dir(1)).unwrap();
    run_experiments(&reg, &loaded.plans, &opts, &mut |_| {}).unwrap();
    let modified = |p: &Path| std::fs::metadata(p).unwrap().modified().unwrap();
    assert_eq!(modified(&source.samples), stamp);
    assert_eq!(
        std::fs::read(offline.run_dir(0).join("policy.ckpt")).unwrap(),
        before
    );

    // A request that no longer matches (here: edited) collects the dataset again, identical
    // (collection is seeded).
    std::fs::write(&request, b"{}").unwrap();
    std::fs::remove_dir_all(offline.run_dir(1)).unwrap();
    run_experiments(&reg, &loaded.plans, &opts, &mut |_| {}).unwrap();
    assert_ne!(modified(&source.samples), stamp);
    assert_eq!(std::fs::read(&source.samples).unwrap(), samples_before);
    assert_ne!(std::fs::read(&request).unwrap(), b"{}");
}

#[test]
fn dataset_step_errors_name_the_suite_the_experiment_and_the_problem() {
    let reg = common::registry();
    let cases: [(&str, &str); 6] = [
        (
            r#"(from: ["a", "bb"])"#,
            "no experiment named `bb` in this suite (did you mean `b`?)",
        ),
        (r#"(from: [])"#, "dataset.from names no experiment"),
        (
            r#"(from: ["a"], level: "guru")"#,
            "dataset.level `guru`: expected `novice`, `intermediate` or `expert`",
        ),
        (
            r#"(from: ["a"], cost: "free")"#,
            "dataset.cost `free`: expected `measured` or `pro_rata`",
        ),
        (
            r#"(from: ["a"], episodes: 0)"#,
            "`eval_episodes` and `episodes` must be at least 1",
        ),
        (r#"(form: ["a"])"#, "form"),
    ];
    for (step, expected) in cases {
        let tmp = tempfile::tempdir().unwrap();
        let file = suite(tmp.path(), step);
        let err = load_plans(std::slice::from_ref(&file), &[], None, &reg)
            .unwrap_err()
            .to_string();
        assert!(err.contains(expected), "{step}: {err}");
        assert!(err.contains("suite.ron"), "{step}: {err}");
    }

    // Sources on different tasks, and an offline experiment on another environment.
    let tmp = tempfile::tempdir().unwrap();
    let file = suite(tmp.path(), STEP);
    let text = std::fs::read_to_string(&file)
        .unwrap()
        .replace(r#"set: ["name=b"]"#, r#"set: ["name=b", "env.length=5"]"#);
    std::fs::write(&file, text).unwrap();
    let err = load_plans(std::slice::from_ref(&file), &[], None, &reg)
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("experiment `offline` (offline.ron)")
            && err.contains("a dataset is collected from one task"),
        "{err}"
    );
    // An offline experiment on another task than its sources.
    let tmp = tempfile::tempdir().unwrap();
    let file = suite(tmp.path(), STEP);
    write(
        tmp.path(),
        "offline.ron",
        r#"(include: ["online.ron"], name: "offline", algorithm: (name: "toy_bc"),
            env: (id: "Corridor-v0", length: 5))"#,
    );
    let err = load_plans(std::slice::from_ref(&file), &[], None, &reg)
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("experiment `offline` (offline.ron)") && err.contains("not the task of `a`"),
        "{err}"
    );
    // An algorithm without a `dataset` parameter cannot take one.
    let tmp = tempfile::tempdir().unwrap();
    let file = suite(tmp.path(), STEP);
    write(
        tmp.path(),
        "offline.ron",
        r#"(include: ["online.ron"], name: "offline")"#,
    );
    let err = load_plans(std::slice::from_ref(&file), &[], None, &reg)
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("algorithm `random_search` has no `dataset` parameter"),
        "{err}"
    );
}
