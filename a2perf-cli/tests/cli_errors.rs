//! The `a2perf` binary's error paths: exit code 1, messages that name the file, causes printed once.

use std::process::Command;

#[test]
fn missing_config_file_is_an_error_from_the_binary() {
    let tmp = tempfile::tempdir().unwrap();
    let missing = tmp.path().join("no-such-config.ron");
    for sub in ["train", "run"] {
        let out = Command::new(env!("CARGO_BIN_EXE_a2perf"))
            .arg(sub)
            .arg(&missing)
            .output()
            .unwrap();
        assert_eq!(out.status.code(), Some(1), "{sub}");
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(
            err.contains("no-such-config.ron") && !err.contains("panicked"),
            "{err}"
        );
    }
    let out = Command::new(env!("CARGO_BIN_EXE_a2perf"))
        .args(["train", "x.ron", "--shard", "3/2"])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(1));
    let out = Command::new(env!("CARGO_BIN_EXE_a2perf"))
        .args(["infer"])
        .arg(tmp.path())
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&out.stderr).contains("no run directories"));
}

#[test]
fn a_cause_is_printed_once() {
    // The registry's error already includes its cause; the binary must not print it again.
    let out = Command::new(env!("CARGO_BIN_EXE_a2perf"))
        .args([
            "bench",
            "WebNavigation-Difficulty-01-v0",
            "--steps",
            "1",
            "--set",
            "num_websites=-1",
        ])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(1));
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(
        err.matches("expected non-negative integer").count(),
        1,
        "{err}"
    );
    assert!(err.contains("num_websites"), "{err}");
}

#[test]
fn a_suite_with_dataset_steps_cannot_be_trained_by_shards() {
    // BC's dataset is collected from runs of other shards: one shard cannot wait for them.
    let tmp = tempfile::tempdir().unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_a2perf"))
        .current_dir(concat!(env!("CARGO_MANIFEST_DIR"), "/.."))
        .args([
            "train",
            "configs/paper/suite.ron",
            "--shard",
            "0/2",
            "--set",
        ])
        .arg(format!("output.dir={}", tmp.path().display()))
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(1));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("experiment `paper_circuit_toy_macro_stdcell_bc`")
            && err.contains("`dataset` step")
            && err.contains("without --shard"),
        "{err}"
    );
    // Refused before anything was trained.
    assert_eq!(std::fs::read_dir(tmp.path()).unwrap().count(), 0);
}
