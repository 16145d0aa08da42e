//! One trainer per run directory, with the real `a2perf` binary: a second `a2perf train` (or
//! `a2perf run`) of a run another process is training leaves it alone, names the holder's pid
//! and host and exits with 73, while the first finishes normally; a trainer killed with
//! `kill -9` leaves a lock file that blocks nobody, and the next trainer resumes the run.
//!
//! The first trainer is stopped with SIGSTOP while the second one tries, so the test never
//! depends on how fast training is. Release builds only (`cargo test --release`).

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Output, Stdio};
use std::time::{Duration, Instant};

const EXIT_LOCKED: i32 = 73;

fn skip_in_debug(name: &str) -> bool {
    if cfg!(debug_assertions) {
        println!("skipping {name}: lock tests train for real and run only in release builds");
        return true;
    }
    false
}

/// A PPO experiment on the smallest synthetic netlist, writing into `out`.
fn config(dir: &Path, out: &Path, total: u64) -> PathBuf {
    let path = dir.join("lock.ron");
    std::fs::write(
        &path,
        format!(
            r#"(
    name: "lock",
    env: (id: "CircuitTraining-Synthetic-Small-v0"),
    algorithm: (name: "ppo", num_steps: 24, minibatch_size: 64, latent_dim: 16,
                hidden_sizes: [32, 32]),
    seeds: [0],
    training: (total_env_steps: {total}, eval_interval: 1_200, eval_episodes: 1,
               checkpoint_interval: 600, num_envs: 2),
    inference: (rollouts: 2),
    generalization: (episodes: 1),
    metrics: (energy_method: "estimate", ram_sample_interval_s: 0.2, bootstrap_reps: 100),
    output: (dir: "{}"),
)"#,
            out.display()
        ),
    )
    .unwrap();
    path
}

fn run_dir(out: &Path) -> PathBuf {
    out.join("lock/CircuitTraining-Synthetic-Small-v0__ppo__seed0")
}

fn a2perf(command: &str, config: &Path) -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_a2perf"));
    c.arg(command).arg(config).arg("--quiet");
    c
}

fn spawn_train(config: &Path) -> Child {
    a2perf("train", config)
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap()
}

fn signal(pid: u32, sig: &str) {
    let ok = Command::new("kill")
        .args([sig, &pid.to_string()])
        .status()
        .unwrap()
        .success();
    assert!(ok, "kill {sig} {pid}");
}

/// A stopped process, continued when this is dropped (also when an assertion fails meanwhile).
struct Frozen(u32);

impl Drop for Frozen {
    fn drop(&mut self) {
        signal(self.0, "-CONT");
    }
}

fn wait_for(what: &str, mut cond: impl FnMut() -> bool) {
    let t = Instant::now();
    while !cond() {
        assert!(
            t.elapsed() < Duration::from_secs(300),
            "timed out waiting for {what}"
        );
        std::thread::sleep(Duration::from_millis(10));
    }
}

/// The pid and host recorded in the run's lock file, if any.
fn recorded_holder(run: &Path) -> Option<(u32, String)> {
    let bytes = std::fs::read(run.join("train.lock")).ok()?;
    let v: serde_json::Value = serde_json::from_slice(&bytes).ok()?;
    Some((
        u32::try_from(v["pid"].as_u64()?).ok()?,
        v["host"].as_str()?.to_string(),
    ))
}

fn stderr(out: &Output) -> String {
    String::from_utf8_lossy(&out.stderr).into_owned()
}

fn state(run: &Path) -> String {
    let v: serde_json::Value =
        serde_json::from_slice(&std::fs::read(run.join("status.json")).unwrap()).unwrap();
    v["state"].as_str().unwrap().to_string()
}

#[test]
fn a_second_trainer_of_a_run_leaves_it_to_the_first_and_exits_73() {
    if skip_in_debug("a_second_trainer_of_a_run_leaves_it_to_the_first_and_exits_73") {
        return;
    }
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("out");
    let cfg = config(tmp.path(), &out, 2_400);
    let run = run_dir(&out);
    let first = spawn_train(&cfg);
    let pid = first.id();
    wait_for("the first trainer to hold the lock", || {
        recorded_holder(&run).is_some_and(|(p, _)| p == pid)
    });
    // Frozen while it holds the lock: the others cannot race it to the end of training.
    signal(pid, "-STOP");
    let frozen = Frozen(pid);
    let (_, host) = recorded_holder(&run).unwrap();

    let second = a2perf("train", &cfg).output().unwrap();
    let err = stderr(&second);
    assert_eq!(second.status.code(), Some(EXIT_LOCKED), "{err}");
    assert!(
        err.contains(&format!("pid {pid} on {host}")) && err.contains(&run.display().to_string()),
        "{err}"
    );
    assert!(err.contains("1 left to the other trainer"), "{err}");

    // `run` stops after training too: the locked run is neither inferred nor reported.
    let chained = a2perf("run", &cfg).output().unwrap();
    let err = stderr(&chained);
    assert_eq!(chained.status.code(), Some(EXIT_LOCKED), "{err}");
    assert!(err.contains(&format!("pid {pid} on {host}")), "{err}");
    assert!(!run.join("inference.json").exists());
    assert!(!out.join("lock/report").exists());
    assert_eq!(state(&run), "running");

    drop(frozen);
    let done = first.wait_with_output().unwrap();
    assert!(done.status.success(), "{}", stderr(&done));
    assert_eq!(state(&run), "complete");
    // Released and emptied: nobody trains the run now.
    assert_eq!(std::fs::read(run.join("train.lock")).unwrap(), b"");
    let again = a2perf("train", &cfg).output().unwrap();
    assert!(again.status.success(), "{}", stderr(&again));
    assert!(
        stderr(&again).contains("1 already complete"),
        "{}",
        stderr(&again)
    );
}

#[test]
fn a_lock_left_by_kill_9_blocks_nobody_and_the_next_trainer_resumes() {
    if skip_in_debug("a_lock_left_by_kill_9_blocks_nobody_and_the_next_trainer_resumes") {
        return;
    }
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("out");
    let cfg = config(tmp.path(), &out, 6_000);
    let run = run_dir(&out);
    let mut first = spawn_train(&cfg);
    let pid = first.id();
    // A finished resume point (written atomically: a temporary file, then this name).
    wait_for("a resume point", || {
        std::fs::read_dir(run.join("resume")).is_ok_and(|d| {
            d.flatten().any(|e| {
                let name = e.file_name().to_string_lossy().into_owned();
                name.starts_with("step_") && name.ends_with(".resume")
            })
        })
    });
    signal(pid, "-KILL");
    first.wait().unwrap();
    // The dead trainer's record is still there: only the lock (gone with it) means anything.
    assert_eq!(recorded_holder(&run).map(|(p, _)| p), Some(pid));
    assert_eq!(state(&run), "running");

    let next = a2perf("train", &cfg).output().unwrap();
    let err = stderr(&next);
    assert!(next.status.success(), "{err}");
    assert!(err.contains("resumed from step"), "{err}");
    assert_eq!(state(&run), "complete");
    let segments: serde_json::Value =
        serde_json::from_slice(&std::fs::read(run.join("train_segments.json")).unwrap()).unwrap();
    assert_eq!(segments["segments"][0]["outcome"], "killed");
    assert_eq!(segments["segments"][1]["outcome"], "completed");
}
