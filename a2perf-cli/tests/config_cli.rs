//! `a2perf config show`: prints the operative config, and fails naming the key on bad input.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn configs() -> PathBuf {
    PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/../configs"))
}

fn a2perf(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_a2perf"))
        .args(args)
        .output()
        .expect("the a2perf binary runs")
}

fn show(file: &Path, sets: &[&str]) -> Output {
    let mut args = vec!["config", "show", file.to_str().expect("utf-8 path")];
    for s in sets {
        args.extend(["--set", s]);
    }
    a2perf(&args)
}

fn text(bytes: &[u8]) -> String {
    String::from_utf8_lossy(bytes).into_owned()
}

#[test]
fn unknown_override_key_fails_naming_it() {
    let out = show(&configs().join("examples/minimal.ron"), &["no_such_key=1"]);
    assert!(!out.status.success(), "exit status {:?}", out.status);
    let stderr = text(&out.stderr);
    assert!(stderr.contains("`no_such_key`"), "{stderr}");
    assert!(stderr.contains("--set no_such_key=1"), "{stderr}");
    assert!(out.stdout.is_empty(), "nothing printed on error");
}

#[test]
fn typo_gets_a_suggestion_and_file_errors_name_the_place() {
    let out = show(
        &configs().join("examples/minimal.ron"),
        &["trainig.num_envs=2"],
    );
    assert!(!out.status.success());
    assert!(
        text(&out.stderr).contains("did you mean `training`?"),
        "{}",
        text(&out.stderr)
    );

    let dir = tempfile::tempdir().expect("temp dir");
    let bad = dir.path().join("bad.ron");
    std::fs::write(&bad, "(\n  training: (num_envs: \"four\"),\n)").expect("write");
    let out = show(&bad, &[]);
    assert!(!out.status.success());
    let stderr = text(&out.stderr);
    assert!(
        stderr.contains(&format!("{}:2:24", bad.display())),
        "{stderr}"
    );
    assert!(
        stderr.contains("`training.num_envs`: expected integer"),
        "{stderr}"
    );

    let out = show(&dir.path().join("missing.ron"), &[]);
    assert!(!out.status.success());
    assert!(
        text(&out.stderr).contains("missing.ron"),
        "{}",
        text(&out.stderr)
    );
}

#[test]
fn show_prints_every_value_in_force_and_round_trips() {
    let out = show(
        &configs().join("examples/minimal.ron"),
        &["seeds=[4, 5]", "metrics.energy_method=estimate"],
    );
    assert!(out.status.success(), "{}", text(&out.stderr));
    let stdout = text(&out.stdout);
    for needle in [
        "name: \"minimal\"",
        "seeds: [4, 5]",
        "total_env_steps: 2000",       // the example file
        "checkpoint_interval: 20000",  // base.ron
        "energy_method: \"estimate\"", // the override
        "bootstrap_reps: 50000",
    ] {
        assert!(stdout.contains(needle), "missing {needle:?} in\n{stdout}");
    }
    // The printed operative config is itself a config that shows identically.
    let dir = tempfile::tempdir().expect("temp dir");
    let operative = dir.path().join("minimal.ron");
    std::fs::write(&operative, &stdout).expect("write");
    let again = show(&operative, &[]);
    assert!(again.status.success(), "{}", text(&again.stderr));
    assert_eq!(text(&again.stdout), stdout);
}

#[test]
fn full_example_shows_when_its_env_and_algorithm_are_registered() {
    let list = a2perf(&["list"]);
    let listed = text(&list.stdout);
    let registered = listed.contains("WebNavigation-Difficulty-01-v0")
        && listed.lines().any(|l| l.trim_start().starts_with("ppo "));
    if !registered {
        eprintln!("skipped: WebNavigation-Difficulty-01-v0 or ppo is not registered in this build");
        return;
    }
    let out = show(
        &configs().join("examples/web_ppo.ron"),
        &["env.num_websites=5"],
    );
    assert!(out.status.success(), "{}", text(&out.stderr));
    let stdout = text(&out.stdout);
    assert!(stdout.contains("num_websites: 5"), "{stdout}");
    assert!(stdout.contains("learning_rate: 0.0003"), "{stdout}");
}
