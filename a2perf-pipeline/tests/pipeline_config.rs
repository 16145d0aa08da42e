//! Experiment configs and suite files become plans: overrides, seeds, task names, errors.

mod common;

fn write(dir: &std::path::Path, name: &str, text: &str) -> std::path::PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, text).unwrap();
    p
}

#[test]
fn suites_apply_their_overrides_in_order() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    write(
        d,
        "corridor.ron",
        r#"(name: "corr", env: (id: "Corridor-v0"), algorithm: (name: "random_search"),
            seeds: [0], training: (total_env_steps: 500, eval_interval: 100))"#,
    );
    let suite = write(
        d,
        "suite.ron",
        r#"// two variants of one experiment
        (
            name: "s",
            set: ["seeds=[0, 1, 2]", "training.total_env_steps=300"],
            experiments: [
                (config: "corridor.ron", set: ["name=short", "env.length=6"]),
                (config: "corridor.ron", set: ["name=default"]),
            ],
            report_dir: "out/report",
        )"#,
    );
    let reg = common::registry();
    let loaded = a2perf_pipeline::load_plans(
        std::slice::from_ref(&suite),
        &["inference.rollouts=7".into()],
        None,
        &reg,
    )
    .unwrap();
    assert_eq!(loaded.plans.len(), 2);
    assert_eq!(
        loaded.report_dir.as_deref(),
        Some(std::path::Path::new("out/report"))
    );
    let (a, b) = (&loaded.plans[0], &loaded.plans[1]);
    assert_eq!((a.name.as_str(), b.name.as_str()), ("short", "default"));
    assert_eq!(a.seeds, [0, 1, 2]);
    assert_eq!(a.training.total_env_steps, 300);
    assert_eq!(a.inference.episodes, 7);
    // Non-default environment parameters name the task; defaults keep the bare id.
    assert_eq!(a.task.name, "Corridor-v0[length=6]");
    assert_eq!(b.task.name, "Corridor-v0");

    let seeds = [5, 6];
    let loaded = a2perf_pipeline::load_plans(&[suite], &[], Some(&seeds), &reg).unwrap();
    assert!(loaded.plans.iter().all(|p| p.seeds == seeds));
}

#[test]
fn config_errors_name_the_file_and_the_problem() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    let reg = common::registry();
    let suite = write(
        d,
        "suite.ron",
        r#"(experiments: [(config: "missing.ron")])"#,
    );
    let err = a2perf_pipeline::load_plans(&[suite], &[], None, &reg)
        .unwrap_err()
        .to_string();
    assert!(err.contains("missing.ron"), "{err}");

    let suite = write(
        d,
        "bad.ron",
        "(experiments: [(config: \"a.ron\", sett: [])])",
    );
    let err = a2perf_pipeline::load_plans(&[suite], &[], None, &reg)
        .unwrap_err()
        .to_string();
    assert!(err.contains("bad.ron:1:") && err.contains("sett"), "{err}");

    let exp = write(
        d,
        "e.ron",
        r#"(env: (id: "Corridor-v0"), algorithm: (name: "random_search"), seeds: [0])"#,
    );
    let err = a2perf_pipeline::load_plans(
        std::slice::from_ref(&exp),
        &["algorithm.noize=1.0".into()],
        None,
        &reg,
    )
    .unwrap_err()
    .to_string();
    assert!(err.contains("noize") && err.contains("noise"), "{err}");

    // Two experiments writing the same run directories.
    let err = a2perf_pipeline::load_plans(&[exp.clone(), exp], &[], None, &reg)
        .unwrap_err()
        .to_string();
    assert!(err.contains("different `name`s"), "{err}");

    let base = write(d, "base.ron", "(seeds: [0])");
    let err = a2perf_pipeline::load_plans(&[base], &[], None, &reg)
        .unwrap_err()
        .to_string();
    assert!(err.contains("env"), "{err}");
}
