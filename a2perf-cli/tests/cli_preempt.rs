//! Preemption of the real `a2perf` binary: SIGTERM writes a resume point at the next safe point
//! and exits with 75 (EX_TEMPFAIL) within the grace period; `kill -9` loses at most one
//! checkpoint interval; a rerun of the same command finishes with the uninterrupted result; a
//! second SIGINT exits at once with 130; with no safe point in the grace period the process exits
//! anyway with 75 and the run continues from its last interval point. One trainer per run: a
//! second `a2perf train` (or `a2perf run`) of a run another process trains leaves it alone,
//! names the holder's pid and host and exits with 73; the lock file a `kill -9`ed trainer leaves
//! behind blocks nobody.
//!
//! Release builds only (`cargo test --release`): each test trains a few thousand steps.

use std::path::{Path, PathBuf};
use std::process::{Child, Command, ExitStatus, Stdio};
use std::time::{Duration, Instant};

use a2perf_core::LearningCurve;

fn skip_in_debug(name: &str) -> bool {
    if cfg!(debug_assertions) {
        println!("skipping {name}: preemption tests train for real and run only in release builds");
        return true;
    }
    false
}

/// A PPO experiment on the smallest synthetic netlist, writing into `out`.
fn config(dir: &Path, out: &Path, num_steps: usize, total: u64, checkpoint: u64) -> PathBuf {
    let path = dir.join(format!("preempt_{num_steps}.ron"));
    std::fs::write(
        &path,
        format!(
            r#"(
    name: "preempt",
    env: (id: "CircuitTraining-Synthetic-Small-v0"),
    algorithm: (name: "ppo", num_steps: {num_steps}, minibatch_size: 64, latent_dim: 16,
                hidden_sizes: [32, 32]),
    seeds: [3],
    training: (total_env_steps: {total}, eval_interval: 2_400, eval_episodes: 1,
               checkpoint_interval: {checkpoint}, num_envs: 2),
    metrics: (energy_method: "estimate", ram_sample_interval_s: 0.2),
    output: (dir: "{}"),
)"#,
            out.display()
        ),
    )
    .unwrap();
    path
}

fn a2perf(args: &[&str], config: &Path) -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_a2perf"));
    c.args(args).arg(config).arg("--quiet");
    c
}

fn spawn(args: &[&str], config: &Path) -> Child {
    a2perf(args, config)
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap()
}

fn run_to_end(args: &[&str], config: &Path) -> (ExitStatus, String) {
    let out = a2perf(args, config).output().unwrap();
    (
        out.status,
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

fn signal(child: &Child, sig: &str) {
    let ok = Command::new("kill")
        .args([sig, &child.id().to_string()])
        .status()
        .unwrap()
        .success();
    assert!(ok, "kill {sig}");
}

fn wait_for(what: &str, mut cond: impl FnMut() -> bool) {
    let t = Instant::now();
    while !cond() {
        assert!(
            t.elapsed() < Duration::from_secs(300),
            "timed out waiting for {what}"
        );
        std::thread::sleep(Duration::from_millis(20));
    }
}

fn files(dir: &Path, prefix: &str, suffix: &str) -> Vec<u64> {
    let mut steps: Vec<u64> = std::fs::read_dir(dir)
        .into_iter()
        .flatten()
        .filter_map(|e| {
            let name = e.ok()?.file_name().to_string_lossy().into_owned();
            name.strip_prefix(prefix)?
                .strip_suffix(suffix)?
                .parse()
                .ok()
        })
        .collect();
    steps.sort();
    steps
}

fn json(path: &Path) -> serde_json::Value {
    serde_json::from_slice(&std::fs::read(path).unwrap()).unwrap()
}

fn stderr_of(child: Child) -> (ExitStatus, String) {
    let out = child.wait_with_output().unwrap();
    (
        out.status,
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

fn run_dir(out: &Path) -> PathBuf {
    out.join("preempt/CircuitTraining-Synthetic-Small-v0__ppo__seed3")
}

/// The deterministic results of a finished run: curve (steps and return bits) and policy bytes.
fn results(run: &Path) -> (Vec<(u64, u64)>, Vec<u8>) {
    let c: LearningCurve = serde_json::from_value(json(&run.join("curve.json"))).unwrap();
    (
        c.points
            .iter()
            .map(|p| (p.env_steps, p.mean_return.to_bits()))
            .collect(),
        std::fs::read(run.join("policy.ckpt")).unwrap(),
    )
}

#[test]
fn sigterm_writes_a_resume_point_and_exits_75_and_kill_9_loses_at_most_an_interval() {
    if skip_in_debug("sigterm_writes_a_resume_point_and_exits_75") {
        return;
    }
    let tmp = tempfile::tempdir().unwrap();
    let (total, interval) = (14_400, 1_200);
    let clean_out = tmp.path().join("clean");
    let cfg = config(tmp.path(), &clean_out, 24, total, interval);
    let (status, err) = run_to_end(&["train"], &cfg);
    assert!(status.success(), "{err}");
    let clean = results(&run_dir(&clean_out));

    // SIGTERM once the first interval checkpoint exists, i.e. mid-run.
    let out = tmp.path().join("preempted");
    let cfg = config(tmp.path(), &out, 24, total, interval);
    let run = run_dir(&out);
    let grace = 120.0;
    let child = spawn(&["train", "--preempt-grace", &grace.to_string()], &cfg);
    wait_for("the first checkpoint", || {
        !files(&run.join("checkpoints"), "step_", ".ckpt").is_empty()
    });
    let signalled = Instant::now();
    signal(&child, "-TERM");
    let (status, err) = stderr_of(child);
    let took = signalled.elapsed().as_secs_f64();
    assert_eq!(status.code(), Some(75), "{err}");
    assert!(took < grace, "exited {took:.1} s after SIGTERM");
    assert!(
        err.contains("SIGTERM") && err.contains("rerun the same command"),
        "{err}"
    );
    let st = json(&run.join("status.json"));
    assert_eq!(st["state"], "interrupted", "{st}");
    let points = files(&run.join("resume"), "step_", ".resume");
    let newest = *points.last().expect("a resume point");
    let note = st["note"].as_str().unwrap();
    assert!(
        note.contains(&format!("continues from step {newest}")),
        "{note}"
    );
    let last_ckpt = *files(&run.join("checkpoints"), "step_", ".ckpt")
        .last()
        .unwrap();
    assert!(
        newest >= last_ckpt && newest < total,
        "{newest} vs checkpoint {last_ckpt}"
    );
    let segs = json(&run.join("train_segments.json"));
    assert_eq!(segs["segments"][0]["outcome"], "interrupted");
    assert_eq!(
        segs["segments"][0]["resume_points"]
            .as_array()
            .unwrap()
            .last()
            .unwrap()["env_steps"],
        newest
    );

    // The same command again continues from there and ends where the clean run ended.
    let (status, err) = run_to_end(&["train"], &cfg);
    assert!(status.success(), "{err}");
    assert!(
        err.contains(&format!("resumed from step {newest}")),
        "{err}"
    );
    assert_eq!(results(&run), clean);
    let system = json(&run.join("train_system.json"));
    assert_eq!(system["segments"], 2, "{system}");

    // kill -9 once a resume point exists: the rerun continues from the newest one left.
    let out = tmp.path().join("killed");
    let cfg = config(tmp.path(), &out, 24, total, interval);
    let run = run_dir(&out);
    let mut child = spawn(&["train"], &cfg);
    wait_for("a resume point", || {
        !files(&run.join("resume"), "step_", ".resume").is_empty()
    });
    child.kill().unwrap(); // SIGKILL
    child.wait().unwrap();
    let left = files(&run.join("resume"), "step_", ".resume");
    let newest = *left.last().unwrap();
    assert_eq!(json(&run.join("status.json"))["state"], "running");
    // The dead trainer's record is still in the lock file; only the lock, gone with the process,
    // could block the rerun.
    assert_eq!(recorded_holder(&run).map(|(pid, _)| pid), Some(child.id()));
    let (status, err) = run_to_end(&["train"], &cfg);
    assert!(status.success(), "{err}");
    let segs = json(&run.join("train_segments.json"));
    assert_eq!(segs["segments"][0]["outcome"], "killed", "{segs}");
    assert_eq!(segs["segments"][1]["started_at_step"], newest, "{segs}");
    assert_eq!(results(&run), clean);
    let system = json(&run.join("train_system.json"));
    assert!(
        system["note"].as_str().unwrap().contains("killed"),
        "{system}"
    );
}

#[test]
fn a_second_sigint_exits_at_once_and_no_safe_point_in_time_still_exits_75() {
    if skip_in_debug("a_second_sigint_exits_at_once") {
        return;
    }
    let tmp = tempfile::tempdir().unwrap();
    // The first safe point comes after a rollout of 2 × 12,000 steps (many seconds): both
    // signals arrive before it.
    let out = tmp.path().join("twice");
    let cfg = config(tmp.path(), &out, 12_000, 48_000, 24_000);
    let run = run_dir(&out);
    let child = spawn(&["train"], &cfg);
    wait_for("the run to start", || {
        run.join("train_segments.json").is_file()
    });
    signal(&child, "-INT");
    std::thread::sleep(Duration::from_millis(100));
    signal(&child, "-INT");
    let (status, err) = stderr_of(child);
    assert_eq!(status.code(), Some(130), "{err}");
    assert!(err.contains("SIGINT again"), "{err}");

    // No grace at all, so no safe point comes in time (one comes every 2 × 1,200 steps): exit 75
    // anyway; the run keeps its last interval point and a rerun continues from it.
    let interval = 2_400;
    let out = tmp.path().join("late");
    let cfg = config(tmp.path(), &out, 1_200, 9_600, interval);
    let run = run_dir(&out);
    let child = spawn(&["train", "--preempt-grace", "0"], &cfg);
    wait_for("an interval resume point", || {
        !files(&run.join("resume"), "step_", ".resume").is_empty()
    });
    signal(&child, "-TERM");
    let (status, err) = stderr_of(child);
    assert_eq!(status.code(), Some(75), "{err}");
    assert!(err.contains("no safe point within 0 s"), "{err}");
    let after = files(&run.join("resume"), "step_", ".resume");
    assert!(after.iter().all(|s| s % interval == 0), "{after:?}");
    let (status, err) = run_to_end(&["train"], &cfg);
    assert!(status.success(), "{err}");
    assert!(
        err.contains(&format!("resumed from step {}", after.last().unwrap())),
        "{err}"
    );
}

#[test]
fn bad_grace_periods_are_refused() {
    let tmp = tempfile::tempdir().unwrap();
    let cfg = config(tmp.path(), &tmp.path().join("r"), 24, 48, 0);
    for bad in ["--preempt-grace=-1", "--preempt-grace=nan"] {
        let (status, err) = run_to_end(&["train", bad], &cfg);
        assert_eq!(status.code(), Some(1), "{bad}: {err}");
        assert!(err.contains("--preempt-grace"), "{err}");
    }
}

/// The pid and host recorded in a run's training lock file, if any.
fn recorded_holder(run: &Path) -> Option<(u32, String)> {
    let v: serde_json::Value =
        serde_json::from_slice(&std::fs::read(run.join("train.lock")).ok()?).ok()?;
    Some((
        u32::try_from(v["pid"].as_u64()?).ok()?,
        v["host"].as_str()?.to_string(),
    ))
}

/// A stopped process, continued when this is dropped (also when an assertion fails meanwhile).
struct Frozen<'a>(&'a Child);

impl Drop for Frozen<'_> {
    fn drop(&mut self) {
        signal(self.0, "-CONT");
    }
}

#[test]
fn a_second_trainer_of_a_run_leaves_it_to_the_first_and_exits_73() {
    if skip_in_debug("a_second_trainer_of_a_run_leaves_it_to_the_first_and_exits_73") {
        return;
    }
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("out");
    let cfg = config(tmp.path(), &out, 24, 2_400, 1_200);
    let run = run_dir(&out);
    let first = spawn(&["train"], &cfg);
    let pid = first.id();
    // Holding the lock, and past its first status (written under the lock).
    wait_for("the first trainer to hold the lock", || {
        recorded_holder(&run).is_some_and(|(p, _)| p == pid) && run.join("status.json").is_file()
    });
    // Stopped while it holds the lock, so that the others cannot race it to the end of training.
    signal(&first, "-STOP");
    let frozen = Frozen(&first);
    let (_, host) = recorded_holder(&run).unwrap();
    let holder = format!("pid {pid} on {host}");

    let (status, err) = run_to_end(&["train"], &cfg);
    assert_eq!(status.code(), Some(73), "{err}");
    assert!(
        err.contains(&holder) && err.contains(&run.display().to_string()),
        "{err}"
    );
    assert!(err.contains("1 left to the other trainer"), "{err}");
    // `run` stops after training too: the locked run is neither inferred nor reported.
    let (status, err) = run_to_end(&["run"], &cfg);
    assert_eq!(status.code(), Some(73), "{err}");
    assert!(err.contains(&holder), "{err}");
    assert!(!run.join("inference.json").exists());
    assert!(!out.join("preempt/report").exists());
    assert_eq!(json(&run.join("status.json"))["state"], "running");

    drop(frozen);
    let (status, err) = stderr_of(first);
    assert!(status.success(), "{err}");
    assert_eq!(json(&run.join("status.json"))["state"], "complete");
    // Released, its record emptied: nobody trains the run now.
    assert_eq!(std::fs::read(run.join("train.lock")).unwrap(), b"");
    let (status, err) = run_to_end(&["train"], &cfg);
    assert!(
        status.success() && err.contains("1 already complete"),
        "{err}"
    );
}

#[test]
fn sigterm_stops_a_collection_without_a_partial_dataset_and_a_rerun_collects_it() {
    if skip_in_debug("sigterm_stops_a_collection") {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("results");
    let cfg = config(dir.path(), &out, 200, 2_400, 1_200);
    let (status, err) = run_to_end(&["train"], &cfg);
    assert!(status.success(), "{err}");
    let experiment = out.join("preempt");
    let datasets = dir.path().join("datasets");
    let collect = |episodes: &str| {
        let mut c = Command::new(env!("CARGO_BIN_EXE_a2perf"));
        c.arg("collect")
            .arg(&experiment)
            .args([
                "--eval-episodes",
                "1",
                "--dataset-episodes",
                episodes,
                "--quiet",
            ])
            .arg("-o")
            .arg(&datasets);
        c
    };
    let names = || -> Vec<String> {
        std::fs::read_dir(&datasets)
            .into_iter()
            .flatten()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect()
    };
    // A dataset far too long to finish: SIGTERM once its staging directory exists.
    let child = collect("1000000")
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    wait_for("the staging directory", || {
        names().iter().any(|n| n.ends_with(".partial"))
    });
    signal(&child, "-TERM");
    let (status, err) = stderr_of(child);
    assert_eq!(status.code(), Some(75), "{err}");
    assert!(err.contains("SIGTERM"), "{err}");
    assert!(
        names().is_empty(),
        "a stopped collection left {:?}",
        names()
    );
    // The same command with a short dataset finishes, every dataset complete.
    let out = collect("2").output().unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let done = names();
    assert!(
        !done.is_empty() && done.iter().all(|n| !n.ends_with(".partial")),
        "{done:?}"
    );
    for name in &done {
        assert!(
            datasets.join(name).join("a2perf_dataset.json").is_file(),
            "{name} has no a2perf_dataset.json"
        );
    }
}
