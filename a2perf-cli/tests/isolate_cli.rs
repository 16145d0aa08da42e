//! `--isolate`: every run trains, infers and generalizes in child processes of its own, so its
//! system figures are its alone. Checked on the real binary: the results are those of runs in
//! one process (policies to the byte, inference returns), each phase of each run was measured
//! by a process that is neither the parent nor another run's, no run shares its process with
//! another even at `--jobs 2`; and preemption still works through the parent: SIGTERM to it,
//! and to the child at the same time (as `pkill a2perf` does), writes a resume point, exits with
//! 75, and a rerun finishes with the uninterrupted result.
//!
//! Release builds only (`cargo test --release`): the runs train for real.

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use serde_json::Value as Json;

fn skip_in_debug(name: &str) -> bool {
    if cfg!(debug_assertions) {
        println!("skipping {name}: --isolate tests train for real and run only in release builds");
        return true;
    }
    false
}

/// PPO on the smallest synthetic netlist, seeds 0 and 1, writing into `out`.
fn config(dir: &Path, out: &Path, total: u64, checkpoint: u64) -> PathBuf {
    let path = dir.join(format!("isolate_{total}.ron"));
    std::fs::write(
        &path,
        format!(
            r#"(
    name: "isolate",
    env: (id: "CircuitTraining-Synthetic-Small-v0"),
    algorithm: (name: "ppo", num_steps: 64, minibatch_size: 64, latent_dim: 16,
                hidden_sizes: [32, 32]),
    seeds: [0, 1],
    training: (total_env_steps: {total}, eval_interval: 600, eval_episodes: 1,
               checkpoint_interval: {checkpoint}, num_envs: 2),
    inference: (rollouts: 2, timing_samples: 10),
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

fn json(path: &Path) -> Json {
    let bytes = std::fs::read(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    serde_json::from_slice(&bytes).unwrap()
}

fn run_dirs(out: &Path) -> Vec<PathBuf> {
    let mut dirs: Vec<PathBuf> = std::fs::read_dir(out.join("isolate"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.join("run.json").is_file())
        .collect();
    dirs.sort();
    assert_eq!(dirs.len(), 2, "{dirs:?}");
    dirs
}

/// The process that measured the training of `run` (its one segment) and how many runs shared it.
fn train_process(run: &Path) -> (u64, u64) {
    let segments = json(&run.join("train_segments.json"));
    let system = &segments["segments"][0]["system"];
    (
        system["pid"].as_u64().expect("pid recorded"),
        system["concurrent_runs"].as_u64().unwrap(),
    )
}

#[test]
fn isolated_runs_measure_processes_of_their_own_and_give_the_same_results() {
    if skip_in_debug("isolated_runs_measure_processes_of_their_own_and_give_the_same_results") {
        return;
    }
    let tmp = tempfile::tempdir().unwrap();
    let mut outcomes = Vec::new();
    for isolate in [false, true] {
        let out = tmp.path().join(if isolate { "isolated" } else { "shared" });
        let cfg = config(tmp.path(), &out, 1_200, 0);
        let mut cmd = Command::new(env!("CARGO_BIN_EXE_a2perf"));
        cmd.arg("run")
            .arg(&cfg)
            .args(["--jobs", "2", "--quiet", "-o"])
            .arg(out.join("report"));
        if isolate {
            cmd.arg("--isolate");
        }
        let child = cmd
            .stdout(Stdio::null())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        let parent = u64::from(child.id());
        let done = child.wait_with_output().unwrap();
        let stderr = String::from_utf8_lossy(&done.stderr);
        assert!(done.status.success(), "isolate={isolate}: {stderr}");
        assert!(out.join("report").join("report.json").is_file());
        outcomes.push((out, parent));
    }
    let (shared, shared_parent) = &outcomes[0];
    let (isolated, isolated_parent) = &outcomes[1];
    let mut pids = Vec::new();
    for (a, b) in run_dirs(shared).iter().zip(run_dirs(isolated)) {
        // The same training and the same rollouts.
        assert_eq!(
            std::fs::read(a.join("policy.ckpt")).unwrap(),
            std::fs::read(b.join("policy.ckpt")).unwrap(),
            "{}",
            b.display()
        );
        let (ia, ib) = (
            json(&a.join("inference.json")),
            json(&b.join("inference.json")),
        );
        assert_eq!(ia["returns"], ib["returns"]);
        assert!(b.join("generalization.json").is_file());
        // In one process: the parent measured every run.
        let (pid, _) = train_process(a);
        assert_eq!(pid, *shared_parent, "{}", a.display());
        assert_eq!(ia["system"]["pid"].as_u64(), Some(*shared_parent));
        // Isolated: a process per run and phase, each holding one run.
        let (train_pid, concurrent) = train_process(&b);
        let infer_pid = ib["system"]["pid"].as_u64().expect("inference pid");
        assert_eq!(concurrent, 1, "{}", b.display());
        assert_ne!(train_pid, *isolated_parent);
        assert_ne!(infer_pid, *isolated_parent);
        assert_ne!(infer_pid, train_pid);
        pids.extend([train_pid, infer_pid]);
    }
    pids.sort_unstable();
    pids.dedup();
    assert_eq!(
        pids.len(),
        4,
        "each run's phases in processes of their own: {pids:?}"
    );
}

/// Waits until the run directory `run` holds a resume point, or panics after a minute.
fn wait_for_resume_point(run: &Path) {
    let start = Instant::now();
    loop {
        let n = std::fs::read_dir(run.join("resume"))
            .map(|d| d.count())
            .unwrap_or(0);
        if n > 0 {
            return;
        }
        assert!(
            start.elapsed() < Duration::from_secs(60),
            "no resume point in {}",
            run.display()
        );
        std::thread::sleep(Duration::from_millis(20));
    }
}

fn kill(sig: &str, pid: u32) {
    let ok = Command::new("kill")
        .args([sig, &pid.to_string()])
        .status()
        .unwrap()
        .success();
    assert!(ok, "kill {sig} {pid}");
}

/// The children of `parent`, as `pgrep -P` lists them.
fn children(parent: u32) -> Vec<u32> {
    let out = Command::new("pgrep")
        .args(["-P", &parent.to_string()])
        .output()
        .unwrap();
    String::from_utf8_lossy(&out.stdout)
        .split_whitespace()
        .filter_map(|p| p.parse().ok())
        .collect()
}

#[test]
fn sigterm_to_an_isolated_training_writes_a_resume_point_and_a_rerun_finishes_it() {
    if skip_in_debug(
        "sigterm_to_an_isolated_training_writes_a_resume_point_and_a_rerun_finishes_it",
    ) {
        return;
    }
    let tmp = tempfile::tempdir().unwrap();
    let train = |cfg: &Path| {
        let mut c = Command::new(env!("CARGO_BIN_EXE_a2perf"));
        c.arg("train")
            .arg(cfg)
            .args(["--seeds", "0", "--isolate", "--quiet"]);
        c
    };
    // Uninterrupted.
    let whole = tmp.path().join("whole");
    let cfg = config(tmp.path(), &whole, 6_000, 600);
    let out = train(&cfg).output().unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let whole_policy = std::fs::read(
        whole
            .join("isolate")
            .read_dir()
            .unwrap()
            .next()
            .unwrap()
            .unwrap()
            .path()
            .join("policy.ckpt"),
    )
    .unwrap();

    // Interrupted: SIGTERM to the parent and to its child at once, as `pkill a2perf` sends it.
    let cut = tmp.path().join("cut");
    std::fs::create_dir_all(&cut).unwrap();
    let cfg = config(&cut, &cut, 6_000, 600);
    let child = train(&cfg)
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let run = {
        let start = Instant::now();
        loop {
            let found = std::fs::read_dir(cut.join("isolate"))
                .ok()
                .and_then(|mut d| d.next())
                .map(|e| e.unwrap().path());
            if let Some(r) = found {
                break r;
            }
            assert!(
                start.elapsed() < Duration::from_secs(60),
                "no run directory"
            );
            std::thread::sleep(Duration::from_millis(20));
        }
    };
    wait_for_resume_point(&run);
    let kids = children(child.id());
    assert_eq!(kids.len(), 1, "one training process: {kids:?}");
    kill("-TERM", child.id());
    kill("-TERM", kids[0]);
    let done = child.wait_with_output().unwrap();
    let stderr = String::from_utf8_lossy(&done.stderr);
    assert_eq!(done.status.code(), Some(75), "{stderr}");
    let status = json(&run.join("status.json"));
    assert_eq!(status["state"], "interrupted", "{status}");

    // The rerun continues from the resume point and ends where the uninterrupted run did.
    let again = train(&cfg).output().unwrap();
    let stderr = String::from_utf8_lossy(&again.stderr);
    assert!(again.status.success(), "{stderr}");
    assert!(stderr.contains("resumed from step"), "{stderr}");
    assert_eq!(
        std::fs::read(run.join("policy.ckpt")).unwrap(),
        whole_policy
    );
}

/// A suite whose BC experiment trains on a dataset the suite collects from its PPO runs: the
/// isolated BC run (its plan rebuilt in the child, the dataset's provenance attached there)
/// records and learns exactly what the in-process one does.
#[test]
fn an_isolated_suite_with_a_dataset_step_matches_the_in_process_one() {
    if skip_in_debug("an_isolated_suite_with_a_dataset_step_matches_the_in_process_one") {
        return;
    }
    let configs = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("..")
        .join("configs")
        .join("circuit_training");
    let tmp = tempfile::tempdir().unwrap();
    let mut bc_runs = Vec::new();
    for isolate in [false, true] {
        let out = tmp.path().join(if isolate { "isolated" } else { "shared" });
        let suite = tmp.path().join(format!("suite_{isolate}.ron"));
        std::fs::write(
            &suite,
            format!(
                r#"(
    name: "iso_suite",
    set: ["seeds=[0]", "output.dir={out}", "inference.rollouts=2", "inference.timing_samples=10",
          "generalization.episodes=1", "metrics.bootstrap_reps=100"],
    experiments: [
        (config: "{ppo}", set: ["training=(total_env_steps: 1_200, eval_interval: 600, eval_episodes: 1, checkpoint_interval: 600, num_envs: 2)"]),
        (config: "{bc}", set: ["training=(total_env_steps: 640, eval_interval: 320, eval_episodes: 1, checkpoint_interval: 0, num_envs: 1)"],
         dataset: (from: ["circuit_ppo"], level: "intermediate", eval_episodes: 1, episodes: 2)),
    ],
)"#,
                out = out.display(),
                ppo = configs.join("ppo.ron").display(),
                bc = configs.join("bc.ron").display(),
            ),
        )
        .unwrap();
        let mut cmd = Command::new(env!("CARGO_BIN_EXE_a2perf"));
        cmd.arg("run").arg(&suite).arg("--quiet");
        if isolate {
            cmd.arg("--isolate");
        }
        let done = cmd.output().unwrap();
        assert!(
            done.status.success(),
            "isolate={isolate}: {}",
            String::from_utf8_lossy(&done.stderr)
        );
        let bc = std::fs::read_dir(out.join("circuit_bc"))
            .unwrap()
            .map(|e| e.unwrap().path())
            .find(|p| p.join("run.json").is_file())
            .expect("the BC run");
        bc_runs.push(bc);
    }
    let (shared, isolated) = (&bc_runs[0], &bc_runs[1]);
    let (a, b) = (
        json(&shared.join("run.json")),
        json(&isolated.join("run.json")),
    );
    assert!(
        !b["dataset"].is_null(),
        "the dataset's provenance is recorded: {b}"
    );
    // The records differ only where the output directory is named.
    let strip = |v: &Json| {
        v.to_string()
            .replace(&tmp.path().join("shared").display().to_string(), "OUT")
            .replace(&tmp.path().join("isolated").display().to_string(), "OUT")
    };
    // The same dataset (its cost is the PPO runs' measured energy, which differs run to run).
    assert_eq!(strip(&a["dataset"]["path"]), strip(&b["dataset"]["path"]));
    assert_eq!(a["dataset"]["dataset_id"], b["dataset"]["dataset_id"]);
    assert!(
        b["dataset"]["training_sample_cost_kwh"]
            .as_f64()
            .is_some_and(|c| c > 0.0)
    );
    assert_eq!(
        std::fs::read(shared.join("policy.ckpt")).unwrap(),
        std::fs::read(isolated.join("policy.ckpt")).unwrap()
    );
    let (pid, concurrent) = train_process(isolated);
    assert_eq!(concurrent, 1);
    assert_ne!(pid, train_process(shared).0);
}
