//! The shipped Slurm scripts (deploy/slurm) on a real single-node Slurm cluster.
//!
//! `deploy/slurm/local-cluster.sh` brings up munged, slurmctld and slurmd from Debian's
//! packages with every file in a temporary directory and ports of their own. The test submits
//! `deploy/smoke.ron` (6 runs) as 4 array tasks with `deploy/slurm/submit.sh`, stops two tasks in
//! the middle of a run - one the way a time limit does (`--signal=B:TERM`, by
//! `scancel --signal=TERM --batch`), one the way a preemption does (`scontrol requeue`) - waits
//! for the array and the report job, and checks that the merged report equals the report of the
//! same sweep run locally in one piece: returns, curves, generalization, reliability, final
//! policies. System figures (time, energy, RAM) differ and are only checked to be present.
//!
//! Without Slurm (or not as root) the test is skipped with the reason; `A2PERF_REQUIRE_SLURM=1`
//! makes that a failure. The cluster is torn down when the test ends, passed or failed; on a
//! failure the daemons' and the jobs' logs are printed first.

use std::collections::BTreeMap;
use std::io::Read;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant, SystemTime};

use serde_json::Value;

const SHARDS: usize = 4;

fn repo_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("a2perf-cli sits in the workspace root")
        .to_path_buf()
}

fn deploy(path: &str) -> PathBuf {
    repo_root().join("deploy").join(path)
}

/// Why this machine cannot run the test, if it cannot.
fn missing_prerequisite() -> Option<String> {
    for tool in [
        "munged",
        "slurmctld",
        "slurmd",
        "sbatch",
        "scontrol",
        "squeue",
        "scancel",
        "sinfo",
    ] {
        let found = std::env::var_os("PATH")
            .map(|paths| std::env::split_paths(&paths).any(|d| d.join(tool).is_file()))
            .unwrap_or(false)
            || ["/usr/sbin", "/usr/bin"]
                .iter()
                .any(|d| Path::new(d).join(tool).is_file());
        if !found {
            return Some(format!(
                "{tool} not found (apt-get install slurmctld slurmd slurm-client munge)"
            ));
        }
    }
    let status = std::fs::read_to_string("/proc/self/status").unwrap_or_default();
    let root = status
        .lines()
        .find_map(|l| l.strip_prefix("Uid:"))
        .and_then(|l| l.split_whitespace().next())
        == Some("0");
    if !root {
        return Some("not running as root (slurmd must start jobs as their owner)".into());
    }
    None
}

/// Output of a finished command.
struct Ran {
    ok: bool,
    /// Exit status (`None` when ended by a signal).
    code: Option<i32>,
    stdout: String,
    stderr: String,
}

/// Runs `cmd` to completion, killing it and failing after `limit`.
fn run(cmd: &mut Command, limit: Duration) -> Ran {
    let what = format!("{cmd:?}");
    let mut child = cmd
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap_or_else(|e| panic!("cannot start {what}: {e}"));
    // Read both pipes on their own threads, so a chatty command never blocks on a full pipe.
    let drain = |pipe: Option<Box<dyn Read + Send>>| {
        std::thread::spawn(move || {
            let mut text = String::new();
            if let Some(mut p) = pipe {
                let _ = p.read_to_string(&mut text);
            }
            text
        })
    };
    let out = drain(
        child
            .stdout
            .take()
            .map(|p| Box::new(p) as Box<dyn Read + Send>),
    );
    let err = drain(
        child
            .stderr
            .take()
            .map(|p| Box::new(p) as Box<dyn Read + Send>),
    );
    let start = Instant::now();
    let status = loop {
        if let Some(s) = child.try_wait().expect("waiting for a child process") {
            break s;
        }
        if start.elapsed() > limit {
            let _ = child.kill();
            let _ = child.wait();
            panic!(
                "{what} did not finish within {} s; stderr: {}",
                limit.as_secs(),
                err.join().unwrap_or_default()
            );
        }
        std::thread::sleep(Duration::from_millis(50));
    };
    Ran {
        ok: status.success(),
        code: status.code(),
        stdout: out.join().unwrap_or_default(),
        stderr: err.join().unwrap_or_default(),
    }
}

/// A command running beside the test, with its output in a file; killed if the test fails
/// before it ends.
struct Background {
    child: std::process::Child,
    log: PathBuf,
}

impl Background {
    fn start(cmd: &mut Command, log: &Path) -> Self {
        let file = std::fs::File::create(log).expect("create a log file");
        let child = cmd
            .stdin(Stdio::null())
            .stdout(file.try_clone().expect("clone a file handle"))
            .stderr(file)
            .spawn()
            .unwrap_or_else(|e| panic!("cannot start {cmd:?}: {e}"));
        Self {
            child,
            log: log.to_path_buf(),
        }
    }

    /// Waits for the command; its output, as `Err` if it failed.
    fn finish(mut self, limit: Duration) -> Result<String, String> {
        let status = wait_for("the local sweep", limit, || {
            self.child.try_wait().expect("waiting for a child process")
        });
        let out = std::fs::read_to_string(&self.log).unwrap_or_default();
        if status.success() { Ok(out) } else { Err(out) }
    }
}

impl Drop for Background {
    fn drop(&mut self) {
        if let Ok(None) = self.child.try_wait() {
            let _ = self.child.kill();
            let _ = self.child.wait();
        }
    }
}

/// The cluster of `local-cluster.sh`, torn down on drop (after printing the logs if the test
/// is failing).
struct Cluster {
    dir: PathBuf,
    job_logs: PathBuf,
    /// Pids of munged, slurmctld and slurmd.
    daemons: Vec<u32>,
    down: bool,
}

impl Cluster {
    fn up(dir: PathBuf, job_logs: PathBuf) -> Self {
        // Created first, so that a half-started cluster is torn down too.
        let mut cluster = Cluster {
            dir,
            job_logs,
            daemons: Vec::new(),
            down: false,
        };
        // As many CPUs as shards, so that no task is pending when the test signals one:
        // Slurm 22.05's `scancel --batch` on an array task with pending siblings answers
        // "Job can not be altered now" and keeps retrying, signalling it again after its
        // requeue.
        let up = run(
            Command::new(deploy("slurm/local-cluster.sh"))
                .arg("up")
                .arg(&cluster.dir)
                .env("A2PERF_CLUSTER_CPUS", SHARDS.to_string()),
            Duration::from_secs(180),
        );
        assert!(
            up.ok,
            "local-cluster.sh up failed:\n{}\n{}",
            up.stdout, up.stderr
        );
        eprintln!("{}", up.stdout.trim());
        for daemon in ["munged", "slurmctld", "slurmd"] {
            let pidfile = cluster.dir.join(format!("run/{daemon}.pid"));
            let pid = std::fs::read_to_string(&pidfile)
                .ok()
                .and_then(|t| t.trim().parse().ok())
                .unwrap_or_else(|| panic!("{}: no pid", pidfile.display()));
            cluster.daemons.push(pid);
        }
        cluster
    }

    fn tear_down(&mut self) -> Ran {
        self.down = true;
        run(
            Command::new(deploy("slurm/local-cluster.sh"))
                .arg("down")
                .arg(&self.dir),
            Duration::from_secs(180),
        )
    }

    /// Stops the cluster and checks that nothing of it is left running: no daemon, and no
    /// process that names a file under `work` (the jobs' a2perf runs).
    fn shut_down(mut self, work: &Path) {
        let down = self.tear_down();
        assert!(
            down.ok,
            "local-cluster.sh down failed:\n{}{}",
            down.stdout, down.stderr
        );
        for pid in &self.daemons {
            assert!(
                !Path::new(&format!("/proc/{pid}")).exists(),
                "daemon {pid} still runs after local-cluster.sh down"
            );
        }
        let needle = work.to_string_lossy().into_owned();
        let leftovers: Vec<String> = std::fs::read_dir("/proc")
            .into_iter()
            .flatten()
            .flatten()
            .filter(|e| e.file_name().to_string_lossy().parse::<u32>().is_ok())
            .filter_map(|e| {
                let cmdline = std::fs::read(e.path().join("cmdline")).ok()?;
                let cmdline = String::from_utf8_lossy(&cmdline).replace('\0', " ");
                cmdline.contains(&needle).then_some(cmdline)
            })
            .collect();
        assert!(
            leftovers.is_empty(),
            "processes outlived the cluster: {leftovers:?}"
        );
    }

    fn conf(&self) -> PathBuf {
        self.dir.join("slurm.conf")
    }

    /// A Slurm client command talking to this cluster.
    fn client(&self, program: &str) -> Command {
        let mut c = Command::new(program);
        c.env("SLURM_CONF", self.conf());
        c
    }

    /// Runs a Slurm client command that must succeed; returns its standard output.
    fn ask(&self, program: &str, args: &[&str]) -> String {
        let r = run(self.client(program).args(args), Duration::from_secs(60));
        assert!(
            r.ok,
            "{program} {}: {}{}",
            args.join(" "),
            r.stdout,
            r.stderr
        );
        r.stdout
    }

    /// `scontrol show job -o ID`: one map of fields per job (all tasks of an array).
    fn jobs(&self, id: &str) -> Vec<BTreeMap<String, String>> {
        self.ask("scontrol", &["show", "job", "-o", id])
            .lines()
            .filter(|l| !l.trim().is_empty())
            .map(|l| {
                l.split_whitespace()
                    .filter_map(|kv| kv.split_once('='))
                    .map(|(k, v)| (k.to_string(), v.to_string()))
                    .collect()
            })
            .collect()
    }

    /// The job id and state of array task `task` of `array`.
    fn task(&self, array: &str, task: usize) -> (String, String) {
        let jobs = self.jobs(&format!("{array}_{task}"));
        let job = jobs
            .first()
            .unwrap_or_else(|| panic!("no job {array}_{task}"));
        (job["JobId"].clone(), job["JobState"].clone())
    }
}

impl Drop for Cluster {
    fn drop(&mut self) {
        if std::thread::panicking() {
            let logs = run(
                Command::new(deploy("slurm/local-cluster.sh"))
                    .arg("logs")
                    .arg(&self.dir),
                Duration::from_secs(30),
            );
            eprintln!("---- Slurm daemon logs\n{}", logs.stdout);
            if let Ok(entries) = std::fs::read_dir(&self.job_logs) {
                for e in entries.flatten() {
                    let text = std::fs::read_to_string(e.path()).unwrap_or_default();
                    eprintln!("---- {}\n{text}", e.path().display());
                }
            }
        }
        if self.down {
            return;
        }
        let down = self.tear_down();
        if !down.ok {
            eprintln!(
                "local-cluster.sh down failed:\n{}\n{}",
                down.stdout, down.stderr
            );
        }
    }
}

/// Polls `check` every 100 ms until it returns `Some`, failing with `what` after `limit`.
fn wait_for<T>(what: &str, limit: Duration, mut check: impl FnMut() -> Option<T>) -> T {
    let start = Instant::now();
    loop {
        if let Some(v) = check() {
            return v;
        }
        assert!(
            start.elapsed() < limit,
            "timed out after {} s waiting for {what}",
            limit.as_secs()
        );
        std::thread::sleep(Duration::from_millis(100));
    }
}

/// The run directory of `experiment` with seed `seed` under `output`, once it exists.
fn run_dir(output: &Path, experiment: &str, seed: u64) -> Option<PathBuf> {
    let suffix = format!("__seed{seed}");
    std::fs::read_dir(output.join(experiment))
        .ok()?
        .flatten()
        .map(|e| e.path())
        .find(|p| {
            p.file_name()
                .is_some_and(|n| n.to_string_lossy().ends_with(&suffix))
        })
}

fn run_state(dir: &Path) -> String {
    std::fs::read_to_string(dir.join("status.json"))
        .ok()
        .and_then(|t| serde_json::from_str::<Value>(&t).ok())
        .and_then(|v| v["state"].as_str().map(str::to_string))
        .unwrap_or_default()
}

fn has_checkpoint(dir: &Path) -> bool {
    std::fs::read_dir(dir.join("checkpoints"))
        .map(|mut entries| entries.next().is_some())
        .unwrap_or(false)
}

fn modified(path: &Path) -> SystemTime {
    std::fs::metadata(path)
        .and_then(|m| m.modified())
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// A task to stop in the middle of one of its runs, and how.
struct Preemption {
    task: usize,
    /// The run it is stopped in (experiment, seed): its second, after a finished one.
    run: (&'static str, u64),
    /// The task's first run, complete when the task is stopped and to be skipped on requeue.
    finished: (&'static str, u64),
    how: &'static [&'static str],
    done: bool,
}

fn read_json(path: &Path) -> Value {
    let text = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    serde_json::from_str(&text).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// Every run directory under the experiment directories of `output`, by relative path.
fn runs(output: &Path) -> BTreeMap<String, PathBuf> {
    let mut out = BTreeMap::new();
    for experiment in ["circuit_ppo", "web_ppo"] {
        let dir = output.join(experiment);
        for e in std::fs::read_dir(&dir)
            .unwrap_or_else(|e| panic!("{}: {e}", dir.display()))
            .flatten()
        {
            if e.path().join("run.json").exists() {
                let name = format!("{experiment}/{}", e.file_name().to_string_lossy());
                out.insert(name, e.path());
            }
        }
    }
    out
}

/// Asserts that the sharded sweep under `sharded` and the local one under `local` agree on
/// everything that training, inference and generalization determine.
fn assert_same_results(sharded: &Path, local: &Path) {
    let (a, b) = (runs(sharded), runs(local));
    assert_eq!(
        a.keys().collect::<Vec<_>>(),
        b.keys().collect::<Vec<_>>(),
        "run directories"
    );
    assert_eq!(a.len(), 6, "deploy/smoke.ron has 6 runs");
    for (name, dir) in &a {
        let other = &b[name];
        let bytes = |d: &Path, f: &str| {
            std::fs::read(d.join(f)).unwrap_or_else(|e| panic!("{}/{f}: {e}", d.display()))
        };
        assert_eq!(run_state(dir), "complete", "{name}");
        assert!(
            bytes(dir, "policy.ckpt") == bytes(other, "policy.ckpt"),
            "{name}: final policy differs from the local sweep's"
        );
        let curve = |d: &Path| -> Vec<(Value, Value, Value)> {
            read_json(&d.join("curve.json"))["points"]
                .as_array()
                .expect("curve points")
                .iter()
                .map(|p| {
                    (
                        p["env_steps"].clone(),
                        p["mean_return"].clone(),
                        p["std_return"].clone(),
                    )
                })
                .collect()
        };
        assert_eq!(curve(dir), curve(other), "{name}: training curve");
        assert!(!curve(dir).is_empty(), "{name}: empty curve");
        assert_eq!(
            read_json(&dir.join("generalization.json")),
            read_json(&other.join("generalization.json")),
            "{name}: generalization"
        );
        let inference = |d: &Path| {
            let v = read_json(&d.join("inference.json"));
            (v["returns"].clone(), v["rollout_returns"].clone())
        };
        assert_eq!(
            inference(dir),
            inference(other),
            "{name}: inference returns"
        );
    }

    let (ra, rb) = (sharded.join("report"), local.join("report"));
    for file in ["curves.csv", "scores.csv"] {
        let read = |d: &Path| {
            std::fs::read_to_string(d.join(file))
                .unwrap_or_else(|e| panic!("{}/{file}: {e}", d.display()))
        };
        assert_eq!(read(&ra), read(&rb), "report {file}");
    }
    let (ja, jb) = (
        read_json(&ra.join("report.json")),
        read_json(&rb.join("report.json")),
    );
    for key in ["iqm", "probability_of_improvement", "skipped_runs"] {
        assert_eq!(ja[key], jb[key], "report.json {key}");
    }
    assert_eq!(ja["skipped_runs"], Value::Array(vec![]), "runs left out");
    let groups = |j: &Value| j["groups"].as_array().expect("report groups").clone();
    let (ga, gb) = (groups(&ja), groups(&jb));
    assert_eq!(ga.len(), 2, "two (task, algorithm) groups");
    assert_eq!(ga.len(), gb.len());
    for (x, y) in ga.iter().zip(&gb) {
        let name = format!("{} / {}", x["task"], x["algorithm"]);
        for key in ["task", "algorithm", "seeds"] {
            assert_eq!(x[key], y[key], "{name}: {key}");
        }
        let metrics = |g: &Value| g["metrics"].as_array().expect("metrics").clone();
        let (ma, mb) = (metrics(x), metrics(y));
        assert_eq!(ma.len(), mb.len(), "{name}: metric count");
        let mut compared = 0;
        for (m, n) in ma.iter().zip(&mb) {
            assert_eq!(m["key"], n["key"], "{name}: metric order");
            let category = m["category"].as_str().unwrap_or_default();
            if category.starts_with("system") {
                // Measured, so different every time; the figure must exist in both.
                if m["key"] == "wall_clock" {
                    for r in [m, n] {
                        assert!(
                            r["per_seed"].as_array().is_some_and(|s| s.len() == 3),
                            "{name}: wall-clock time missing: {r}"
                        );
                    }
                }
            } else {
                assert_eq!(m, n, "{name}: {category} metric {}", m["key"]);
                compared += 1;
            }
        }
        let returns = ma
            .iter()
            .find(|m| m["key"] == "returns")
            .expect("a returns metric");
        assert_eq!(returns["per_seed"].as_array().map(Vec::len), Some(3));
        assert!(compared >= 4, "{name}: too few metrics compared");
    }
}

#[test]
fn sharded_sweep_with_preemptions_matches_a_local_sweep() {
    if let Some(why) = missing_prerequisite() {
        if std::env::var("A2PERF_REQUIRE_SLURM").as_deref() == Ok("1") {
            panic!("A2PERF_REQUIRE_SLURM=1 but Slurm cannot run here: {why}");
        }
        eprintln!("skipped: {why}");
        return;
    }
    let started = Instant::now();
    let tmp = tempfile::tempdir().expect("a temporary directory");
    // munged wants every directory above its socket searchable by all.
    {
        use std::os::unix::fs::PermissionsExt;
        std::fs::set_permissions(tmp.path(), std::fs::Permissions::from_mode(0o755))
            .expect("chmod 755 the temporary directory");
    }
    let output = tmp.path().join("slurm-results");
    let local = tmp.path().join("local-results");
    let a2perf = env!("CARGO_BIN_EXE_a2perf");
    let config = deploy("smoke.ron");
    // The same sweep in one piece, meanwhile: the machine's cores are shared either way.
    let local_sweep = Background::start(
        Command::new(a2perf)
            .arg("run")
            .arg(&config)
            .arg("--set")
            .arg(format!("output.dir={}", local.display()))
            .arg("-o")
            .arg(local.join("report"))
            .arg("--quiet"),
        &tmp.path().join("local-run.log"),
    );
    let cluster = Cluster::up(tmp.path().join("cluster"), output.join("slurm-logs"));
    eprintln!("cluster up after {:.1} s", started.elapsed().as_secs_f64());

    let submitted = run(
        cluster
            .client(deploy("slurm/submit.sh").to_str().expect("utf-8 path"))
            .args(["--shards", &SHARDS.to_string(), "--output"])
            .arg(&output)
            .args(["--bin", a2perf, "--time", "20:00", "--report-time", "20:00"])
            .arg(&config),
        Duration::from_secs(60),
    );
    assert!(
        submitted.ok,
        "submit.sh failed:\n{}{}",
        submitted.stdout, submitted.stderr
    );
    eprint!("{}", submitted.stdout);
    let job_id = |prefix: &str| {
        submitted
            .stdout
            .lines()
            .find_map(|l| l.strip_prefix(prefix))
            .and_then(|rest| rest.split(':').next())
            .map(|id| id.trim().to_string())
            .unwrap_or_else(|| panic!("no `{prefix}` line in submit.sh's output"))
    };
    let (array, report) = (job_id("array job "), job_id("report job "));

    // Grid order is experiments, then seeds: cells 0-2 circuit_ppo seeds 0-2, cells 3-5
    // web_ppo seeds 0-2. Shard i of 4 runs cells i and i + 4, so tasks 0 and 1 each train a
    // circuit run, then a web run: stopping them during the web run leaves one complete run
    // to skip and one to resume (or redo) on requeue.
    let mut preemptions = [
        Preemption {
            task: 0,
            run: ("web_ppo", 1),
            finished: ("circuit_ppo", 0),
            // What `--signal=B:TERM@60` does before a time limit: SIGTERM to the batch
            // script only, which passes it on to a2perf and requeues the job itself.
            how: &["scancel", "--signal=TERM", "--batch"],
            done: false,
        },
        Preemption {
            task: 1,
            run: ("web_ppo", 2),
            finished: ("circuit_ppo", 1),
            // What a preemption or an administrator does: Slurm signals every process of the
            // job and requeues it.
            how: &["scontrol", "requeue"],
            done: false,
        },
    ];
    let mut finished_policies = Vec::new();
    wait_for(
        "both preempted runs to write their first checkpoint",
        Duration::from_secs(600),
        || {
            for p in preemptions.iter_mut().filter(|p| !p.done) {
                let Some(dir) = run_dir(&output, p.run.0, p.run.1) else {
                    continue;
                };
                if !has_checkpoint(&dir) {
                    continue;
                }
                let state = run_state(&dir);
                assert_ne!(
                    state,
                    "complete",
                    "{}: finished before the test could stop it mid-run",
                    dir.display()
                );
                let (job, job_state) = cluster.task(&array, p.task);
                assert_eq!(job_state, "RUNNING", "task {} while its run trains", p.task);
                let policy = run_dir(&output, p.finished.0, p.finished.1)
                    .expect("the task's first run")
                    .join("policy.ckpt");
                finished_policies.push((policy.clone(), modified(&policy)));
                let (program, flags) = p.how.split_first().expect("a command");
                let mut args = flags.to_vec();
                args.push(&job);
                cluster.ask(program, &args);
                eprintln!(
                    "after {:.1} s: stopped task {} (job {job}) during {} with `{}`",
                    started.elapsed().as_secs_f64(),
                    p.task,
                    dir.display(),
                    p.how.join(" ")
                );
                p.done = true;
            }
            preemptions.iter().all(|p| p.done).then_some(())
        },
    );
    // Each stopped task must go back to the queue with its run unfinished on disk.
    for p in &preemptions {
        wait_for(
            &format!("task {} to be requeued", p.task),
            Duration::from_secs(180),
            || {
                let jobs = cluster.jobs(&format!("{array}_{}", p.task));
                let restarts: u32 = jobs.first()?.get("Restarts")?.parse().ok()?;
                (restarts >= 1).then_some(())
            },
        );
        // A requeued job waits (cred_expire, 10 s) before it starts again, so this is the
        // state the stop left behind.
        let dir = run_dir(&output, p.run.0, p.run.1).expect("the stopped run");
        assert_ne!(
            run_state(&dir),
            "complete",
            "{}: complete although its task was stopped in the middle of it",
            dir.display()
        );
    }

    let ids = format!("{array},{report}");
    wait_for(
        "the array and the report job to finish",
        Duration::from_secs(1200),
        || {
            cluster
                .ask("squeue", &["-h", "-j", &ids, "-o", "%i %T %r"])
                .trim()
                .is_empty()
                .then_some(())
        },
    );
    eprintln!(
        "Slurm sweep done after {:.1} s",
        started.elapsed().as_secs_f64()
    );
    let tasks = cluster.jobs(&array);
    assert_eq!(tasks.len(), SHARDS, "array tasks: {tasks:?}");
    for t in &tasks {
        let id = format!("{array}_{}", t["ArrayTaskId"]);
        assert_eq!(t["JobState"], "COMPLETED", "{id}: {t:?}");
        assert_eq!(t["ExitCode"], "0:0", "{id}");
        let restarts: u32 = t["Restarts"].parse().expect("Restarts is a number");
        let preempted = preemptions
            .iter()
            .any(|p| t["ArrayTaskId"] == p.task.to_string());
        assert_eq!(restarts >= 1, preempted, "{id}: restarted {restarts} times");
    }
    let report_job = cluster.jobs(&report);
    assert_eq!(
        report_job.first().map(|j| j["JobState"].as_str()),
        Some("COMPLETED"),
        "report job {report}: {report_job:?}"
    );
    let log = |task: usize| {
        let path = output.join(format!("slurm-logs/train-{array}_{task}.out"));
        std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
    };
    let (log0, log1) = (log(0), log(1));
    eprintln!("---- task 0's log\n{log0}---- task 1's log\n{log1}----");
    // Task 0 got SIGTERM alone (as from --signal=B:TERM): the script passes it on and
    // requeues the job itself. Task 1 was requeued by Slurm, which signals a2perf directly.
    assert!(
        log0.contains("passing it on to a2perf") && log0.contains("requeueing job"),
        "task 0 did not pass SIGTERM on and requeue itself:\n{log0}"
    );
    assert!(
        log1.contains("Slurm is ending the job")
            && log1.contains("Slurm has requeued the job already"),
        "task 1's script did not see that Slurm was requeueing it:\n{log1}"
    );
    // The run each stopped task had finished was skipped on requeue, not trained again.
    for (policy, before) in &finished_policies {
        assert_eq!(
            modified(policy),
            *before,
            "{} was rewritten after its task was requeued",
            policy.display()
        );
    }

    let local_log = local_sweep.finish(Duration::from_secs(1200));
    eprintln!(
        "local sweep done after {:.1} s",
        started.elapsed().as_secs_f64()
    );
    assert!(local_log.is_ok(), "local a2perf run failed:\n{local_log:?}");
    assert_same_results(&output, &local);
    cluster.shut_down(tmp.path());
    eprintln!(
        "Slurm sweep test: {:.1} s in all",
        started.elapsed().as_secs_f64()
    );
}

/// Runs a script of deploy/slurm with `args` and extra environment, outside Slurm.
fn script(name: &str, args: &[&str], env: &[(&str, &str)]) -> Ran {
    let mut cmd = Command::new("bash");
    cmd.arg(deploy(&format!("slurm/{name}"))).args(args);
    for var in [
        "A2PERF_CONFIG",
        "A2PERF_OUTPUT",
        "A2PERF_SHARDS",
        "A2PERF_BIN",
        "SLURM_ARRAY_TASK_ID",
        "SLURM_ARRAY_TASK_COUNT",
        "SLURM_JOB_ID",
    ] {
        cmd.env_remove(var);
    }
    cmd.envs(env.iter().copied());
    run(&mut cmd, Duration::from_secs(60))
}

#[test]
fn the_scripts_reject_bad_arguments_with_a_clear_message() {
    let smoke = deploy("smoke.ron");
    let smoke = smoke.to_str().expect("utf-8 path");
    let fails = |name: &str, args: &[&str], env: &[(&str, &str)], expected: &str| {
        let r = script(name, args, env);
        assert_eq!(r.code, Some(2), "{name} {args:?}: {}", r.stderr);
        assert!(
            r.stderr.contains(expected),
            "{name} {args:?}: expected `{expected}` in:\n{}",
            r.stderr
        );
    };
    fails("submit.sh", &[], &[], "submit.sh [OPTIONS] CONFIG");
    fails("submit.sh", &["--shards", "0", smoke], &[], "--shards '0'");
    fails("submit.sh", &["--output"], &[], "--output needs a value");
    fails(
        "submit.sh",
        &["/no/such/config.ron"],
        &[],
        "config /no/such/config.ron: no such file",
    );
    fails(
        "submit.sh",
        &["--bin", "/no/such/a2perf", smoke],
        &[],
        "/no/such/a2perf is not executable",
    );
    fails("sweep.sbatch", &["train"], &[], "set A2PERF_CONFIG");
    let configured = [("A2PERF_CONFIG", smoke), ("A2PERF_OUTPUT", "/tmp/x")];
    fails("sweep.sbatch", &["train"], &configured, "not an array task");
    fails(
        "sweep.sbatch",
        &["test"],
        &configured,
        "unknown phase 'test'",
    );
    fails(
        "sweep.sbatch",
        &["train"],
        &[
            configured[0],
            configured[1],
            ("SLURM_ARRAY_TASK_ID", "3"),
            ("A2PERF_SHARDS", "2"),
        ],
        "array task 3 is not a shard of A2PERF_SHARDS='2'",
    );
}

/// What `sweep.sbatch train` did with a stand-in for a2perf and scontrol: its exit status and
/// the stand-ins' log. The stand-in a2perf exits with `status` at once, or, without one, waits
/// for SIGTERM and then exits with 75. `job_state` is what the stand-in scontrol reports.
/// `signal_script` sends SIGTERM to the batch script (as `--signal=B:TERM` does);
/// `signal_a2perf` to a2perf too (as Slurm does when it ends the job).
fn fake_task(
    status: Option<&str>,
    job_state: &str,
    signal_script: bool,
    signal_a2perf: bool,
) -> (Option<i32>, String) {
    use std::os::unix::fs::PermissionsExt;
    let tmp = tempfile::tempdir().expect("a temporary directory");
    let log = tmp.path().join("log");
    let bin = tmp.path().join("bin");
    std::fs::create_dir(&bin).expect("mkdir");
    let write_exe = |path: &Path, text: &str| {
        std::fs::write(path, text).expect("write a stand-in");
        std::fs::set_permissions(path, std::fs::Permissions::from_mode(0o755)).expect("chmod");
    };
    write_exe(
        &bin.join("a2perf"),
        r#"#!/bin/bash
echo "a2perf $$ $*" >> "$FAKE_LOG"
[ -n "${FAKE_STATUS:-}" ] && exit "$FAKE_STATUS"
stop=
trap 'echo "a2perf got TERM" >> "$FAKE_LOG"; stop=1' TERM
for ((i = 0; i < 600; i++)); do
    # Lingers a little after the first signal, so that a second one would be logged.
    [ -n "$stop" ] && { sleep 0.5; exit 75; }
    sleep 0.1
done
exit 1
"#,
    );
    write_exe(
        &bin.join("scontrol"),
        r#"#!/bin/bash
echo "scontrol $*" >> "$FAKE_LOG"
[ "$1" = show ] && echo "JobId=$SLURM_JOB_ID JobState=$FAKE_JOB_STATE Restarts=0"
exit 0
"#,
    );
    let path = format!(
        "{}:{}",
        bin.display(),
        std::env::var("PATH").unwrap_or_default()
    );
    let mut cmd = Command::new("bash");
    cmd.arg(deploy("slurm/sweep.sbatch"))
        .args(["train", "--seeds", "0..2"])
        .env("PATH", path)
        .env("FAKE_LOG", &log)
        .env("FAKE_JOB_STATE", job_state)
        .env("A2PERF_BIN", bin.join("a2perf"))
        .env("A2PERF_CONFIG", "/sweep.ron")
        .env("A2PERF_OUTPUT", "/results")
        .env("A2PERF_SHARDS", "2")
        .env("SLURM_ARRAY_TASK_ID", "1")
        .env("SLURM_JOB_ID", "42")
        .env_remove("FAKE_STATUS")
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::null());
    if let Some(s) = status {
        cmd.env("FAKE_STATUS", s);
    }
    let mut child = cmd.spawn().expect("bash runs");
    let read_log = || std::fs::read_to_string(&log).unwrap_or_default();
    let a2perf_pid = wait_for(
        "the stand-in a2perf to start",
        Duration::from_secs(30),
        || {
            read_log()
                .lines()
                .find_map(|l| l.strip_prefix("a2perf "))
                .and_then(|rest| rest.split_whitespace().next().map(str::to_string))
        },
    );
    let kill = |pid: &str| {
        let r = run(
            Command::new("bash").args(["-c", &format!("kill -TERM {pid}")]),
            Duration::from_secs(10),
        );
        assert!(r.ok, "kill -TERM {pid}: {}", r.stderr);
    };
    if signal_script {
        kill(&child.id().to_string());
    }
    if signal_a2perf {
        kill(&a2perf_pid);
    }
    let code = wait_for("sweep.sbatch to end", Duration::from_secs(60), || {
        child
            .try_wait()
            .expect("waiting for bash")
            .map(|s| s.code())
    });
    (code, read_log())
}

#[test]
fn sweep_sbatch_passes_sigterm_on_and_requeues_a_resumable_run() {
    // SIGTERM to the batch shell alone (--signal=B:TERM@60): passed on once, then requeued.
    let (code, log) = fake_task(None, "RUNNING", true, false);
    assert_eq!(code, Some(0), "{log}");
    assert!(
        log.contains(
            " train /sweep.ron --set output.dir=/results --shard 1/2 --jobs 1 --quiet --seeds 0..2"
        ),
        "{log}"
    );
    assert_eq!(log.matches("a2perf got TERM").count(), 1, "{log}");
    assert!(log.contains("scontrol requeue 42"), "{log}");

    // Slurm ending the job signals every process itself: the script must not signal again.
    let (code, log) = fake_task(None, "PENDING", true, true);
    assert_eq!(code, Some(0), "{log}");
    assert_eq!(log.matches("a2perf got TERM").count(), 1, "{log}");
    assert!(log.contains("scontrol requeue 42"), "{log}");

    // a2perf stopped on its own signal (exit 75): requeued as well.
    let (code, log) = fake_task(Some("75"), "RUNNING", false, false);
    assert_eq!(code, Some(0), "{log}");
    assert!(log.contains("scontrol requeue 42"), "{log}");
}

#[test]
fn sweep_sbatch_does_not_requeue_a_finished_or_failed_shard() {
    let (code, log) = fake_task(Some("0"), "RUNNING", false, false);
    assert_eq!(code, Some(0), "{log}");
    assert!(!log.contains("requeue"), "{log}");
    let (code, log) = fake_task(Some("3"), "RUNNING", false, false);
    assert_eq!(code, Some(3), "a failure must fail the array task: {log}");
    assert!(!log.contains("requeue"), "{log}");
}

#[test]
fn the_slurm_scripts_pass_shellcheck() {
    let scripts =
        ["submit.sh", "sweep.sbatch", "local-cluster.sh"].map(|s| deploy(&format!("slurm/{s}")));
    for s in &scripts {
        let r = run(
            Command::new("bash").arg("-n").arg(s),
            Duration::from_secs(30),
        );
        assert!(r.ok, "bash -n {}: {}", s.display(), r.stderr);
    }
    let Ok(r) = Command::new("shellcheck").arg("--version").output() else {
        if std::env::var("A2PERF_REQUIRE_SLURM").as_deref() == Ok("1") {
            panic!("A2PERF_REQUIRE_SLURM=1 but shellcheck is not installed");
        }
        eprintln!("skipped shellcheck: not installed (apt-get install shellcheck)");
        return;
    };
    assert!(r.status.success());
    let r = run(
        Command::new("shellcheck").args(&scripts),
        Duration::from_secs(120),
    );
    assert!(r.ok, "shellcheck:\n{}{}", r.stdout, r.stderr);
}
