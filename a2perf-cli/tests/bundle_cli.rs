//! `a2perf bundle`, `a2perf verify` and `a2perf report` on bundles, through the binary: a tiny
//! built-in run packed, verified, reported as verified; a damaged bundle fails with exit code 1
//! and a report refuses it.

use std::path::Path;
use std::process::{Command, Output};

fn a2perf(args: &[&str], cwd: &Path) -> Output {
    Command::new(env!("CARGO_BIN_EXE_a2perf"))
        .args(args)
        .current_dir(cwd)
        .output()
        .unwrap()
}

fn text(o: &Output) -> String {
    format!(
        "{}{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    )
}

#[test]
fn bundle_verify_and_report_from_the_binary() {
    let tmp = tempfile::tempdir().unwrap();
    let t = tmp.path();
    let config = Path::new(env!("CARGO_MANIFEST_DIR")).join("../configs/circuit_training/ddqn.ron");
    let run = a2perf(
        &[
            "run",
            config.to_str().unwrap(),
            "--seeds",
            "0",
            "--quiet",
            "--set",
            "output.dir=results",
            "--set",
            "training.total_env_steps=480",
            "--set",
            "training.eval_interval=240",
            "--set",
            "algorithm.learning_starts=96",
            "--set",
            "inference.rollouts=3",
            "--set",
            "generalization.episodes=1",
            "--set",
            "metrics.bootstrap_reps=100",
            "-o",
            "plain",
        ],
        t,
    );
    assert!(run.status.success(), "{}", text(&run));

    let packed = a2perf(&["bundle", "results/circuit_ddqn", "-o", "r.a2perf"], t);
    assert!(packed.status.success(), "{}", text(&packed));
    assert!(text(&packed).contains("1 runs"), "{}", text(&packed));

    let ok = a2perf(&["verify", "r.a2perf"], t);
    let out = text(&ok);
    assert!(ok.status.success(), "{out}");
    assert!(
        out.contains("holds   runs/circuit_ddqn/") && !out.contains("FAILS"),
        "{out}"
    );
    assert!(out.contains("inference returns (replayed)"), "{out}");

    let report = a2perf(
        &["report", "r.a2perf", "-o", "verified", "--verified-only"],
        t,
    );
    assert!(report.status.success(), "{}", text(&report));
    let md = std::fs::read_to_string(t.join("verified/report.md")).unwrap();
    assert!(md.contains("(seeds 1, **verified**)"), "{md}");
    let board = std::fs::read_to_string(t.join("verified/leaderboard.json")).unwrap();
    assert!(board.contains("\"verified\": true"), "{board}");
    let page = std::fs::read_to_string(t.join("verified/index.html")).unwrap();
    assert!(page.contains("&#10003; verified"));
    // The same runs from their directory: nothing is marked, and --verified-only leaves the
    // leaderboard empty.
    let plain = std::fs::read_to_string(t.join("plain/report.md")).unwrap();
    assert!(!plain.contains("verified"));
    let unverified = a2perf(
        &[
            "report",
            "results/circuit_ddqn",
            "-o",
            "u",
            "--verified-only",
        ],
        t,
    );
    assert!(unverified.status.success(), "{}", text(&unverified));
    let board: serde_json::Value =
        serde_json::from_slice(&std::fs::read(t.join("u/leaderboard.json")).unwrap()).unwrap();
    assert_eq!(board["entries"].as_array().map(Vec::len), Some(0));

    // A return edited, the manifest made to match: the replay tells, exit code 1.
    let limits = a2perf_pipeline::bundle::ArchiveLimits::default();
    let mut archive = a2perf_pipeline::bundle::Archive::read(&t.join("r.a2perf"), &limits).unwrap();
    let name = archive
        .names()
        .find(|n| n.ends_with("/inference.json") && !n.contains("/episodes/"))
        .unwrap()
        .to_string();
    let mut results: serde_json::Value =
        serde_json::from_slice(archive.get(&name).unwrap()).unwrap();
    let first = results["rollout_returns"][0].as_f64().unwrap();
    results["rollout_returns"][0] = serde_json::json!(first + 0.25);
    archive
        .insert(&name, serde_json::to_vec(&results).unwrap())
        .unwrap();
    archive.write(&t.join("edited.a2perf")).unwrap();
    let edited = a2perf(&["verify", "edited.a2perf"], t);
    assert_eq!(edited.status.code(), Some(1), "{}", text(&edited));
    assert!(
        text(&edited).contains("FAILS") && text(&edited).contains("episode 0: return"),
        "{}",
        text(&edited)
    );

    // A truncated bundle: exit code 1, the bundle named, no panic; a report refuses it.
    let bytes = std::fs::read(t.join("r.a2perf")).unwrap();
    std::fs::write(t.join("cut.a2perf"), &bytes[..bytes.len() / 2]).unwrap();
    let cut = a2perf(&["verify", "cut.a2perf"], t);
    assert_eq!(cut.status.code(), Some(1), "{}", text(&cut));
    assert!(
        text(&cut).contains("cut.a2perf") && !text(&cut).contains("panicked"),
        "{}",
        text(&cut)
    );
    let refused = a2perf(&["report", "cut.a2perf", "-o", "x"], t);
    assert_eq!(refused.status.code(), Some(1));
    assert!(!t.join("x/report.md").exists());
}
