//! Bad inputs give errors naming the problem, never panics.

mod common;

use a2perf_pipeline::{InferOptions, TrainOptions, report::ReportOptions};

fn trained() -> (tempfile::TempDir, std::path::PathBuf) {
    let tmp = tempfile::tempdir().unwrap();
    let plan = common::plan(tmp.path(), "exp", vec![0]);
    a2perf_pipeline::train(
        &common::registry(),
        &a2perf_pipeline::grid(std::slice::from_ref(&plan), None),
        &TrainOptions::default(),
    )
    .unwrap();
    (tmp, plan.run_dir(0))
}

#[test]
fn corrupt_checkpoint_is_an_error_naming_the_file() {
    let (_tmp, run) = trained();
    let reg = common::registry();
    let ckpt = run.join("policy.ckpt");
    let mut bytes = std::fs::read(&ckpt).unwrap();
    let last = bytes.len() - 1;
    bytes[last] ^= 0xff;
    std::fs::write(&ckpt, &bytes).unwrap();
    let err = a2perf_pipeline::infer_run(&reg, &run, &InferOptions::default())
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("policy.ckpt") && err.contains("checksum"),
        "{err}"
    );
    std::fs::write(&ckpt, b"garbage").unwrap();
    let err = a2perf_pipeline::generalize_run(&reg, &run, Some(1), false).unwrap();
    assert!(err.sum_of_mean_returns.is_none());
    assert!(
        err.tasks
            .iter()
            .all(|t| t.error.as_deref().unwrap().contains("policy.ckpt"))
    );
    std::fs::remove_file(&ckpt).unwrap();
    let err = a2perf_pipeline::infer_run(&reg, &run, &InferOptions::default())
        .unwrap_err()
        .to_string();
    assert!(err.contains("policy.ckpt"), "{err}");
}

#[test]
fn corrupt_run_directory_is_an_error_naming_the_file() {
    let (tmp, run) = trained();
    let reg = common::registry();
    std::fs::write(run.join("run.json"), b"{\"format_version\": 1,").unwrap();
    let err = a2perf_pipeline::infer_run(&reg, &run, &InferOptions::default())
        .unwrap_err()
        .to_string();
    assert!(err.contains("run.json"), "{err}");
    let err = a2perf_pipeline::report::write_report(
        &[tmp.path().to_path_buf()],
        &tmp.path().join("r"),
        &ReportOptions::default(),
    )
    .unwrap_err()
    .to_string();
    assert!(err.contains("run.json"), "{err}");

    let (tmp, run) = trained();
    std::fs::write(run.join("status.json"), b"[").unwrap();
    let plan = common::plan(tmp.path(), "exp", vec![0]);
    let err = a2perf_pipeline::train(
        &reg,
        &a2perf_pipeline::grid(&[plan], None),
        &TrainOptions::default(),
    )
    .unwrap_err()
    .to_string();
    assert!(err.contains("status.json"), "{err}");

    let (_tmp, run) = trained();
    std::fs::write(run.join("curve.json"), b"{}").unwrap();
    let err = a2perf_pipeline::report::write_report(
        std::slice::from_ref(&run),
        &run.join("r"),
        &ReportOptions::default(),
    )
    .unwrap_err()
    .to_string();
    assert!(err.contains("curve.json"), "{err}");

    let nothing = tempfile::tempdir().unwrap();
    let err = a2perf_pipeline::infer_run(&reg, nothing.path(), &InferOptions::default())
        .unwrap_err()
        .to_string();
    assert!(err.contains("not a run directory"), "{err}");
}

#[test]
fn a_directory_that_is_not_a_run_is_never_overwritten() {
    let tmp = tempfile::tempdir().unwrap();
    let plan = common::plan(tmp.path(), "exp", vec![0]);
    std::fs::create_dir_all(plan.run_dir(0)).unwrap();
    std::fs::write(plan.run_dir(0).join("precious.txt"), b"keep").unwrap();
    let err = a2perf_pipeline::train(
        &common::registry(),
        &a2perf_pipeline::grid(std::slice::from_ref(&plan), None),
        &TrainOptions::default(),
    )
    .unwrap_err()
    .to_string();
    assert!(err.contains("refusing to overwrite"), "{err}");
    assert!(plan.run_dir(0).join("precious.txt").is_file());
}

#[test]
fn unwritable_output_directory_is_an_error() {
    // A path below a regular file cannot be created, whatever the user's permissions (tests may
    // run as root, which ignores mode bits).
    let tmp = tempfile::tempdir().unwrap();
    let file = tmp.path().join("a-file");
    std::fs::write(&file, b"").unwrap();
    let plan = common::plan(&file.join("out"), "exp", vec![0]);
    let err = a2perf_pipeline::train(
        &common::registry(),
        &a2perf_pipeline::grid(&[plan], None),
        &TrainOptions::default(),
    )
    .unwrap_err()
    .to_string();
    assert!(err.contains("a-file"), "{err}");

    let (_t, run) = trained();
    let err = a2perf_pipeline::report::write_report(
        &[run],
        &file.join("report"),
        &ReportOptions::default(),
    )
    .unwrap_err()
    .to_string();
    assert!(err.contains("a-file"), "{err}");
}

#[test]
fn unknown_environment_or_algorithm_fails_before_any_run() {
    let tmp = tempfile::tempdir().unwrap();
    let mut plan = common::plan(tmp.path(), "exp", vec![0]);
    plan.algorithm.name = "random_serch".into();
    let err = a2perf_pipeline::train(
        &common::registry(),
        &a2perf_pipeline::grid(&[plan], None),
        &TrainOptions::default(),
    )
    .unwrap_err()
    .to_string();
    assert!(err.contains("did you mean `random_search`"), "{err}");
    assert!(!tmp.path().join("exp").exists());
}
