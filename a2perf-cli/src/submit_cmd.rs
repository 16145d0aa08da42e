//! `a2perf submit`: an A2Perf participant folder (`train.py`, `inference.py`,
//! `requirements.txt`) trained, inferred, generalized and reported by the harness.
//!
//! Each phase runs in a child Python process (`a2perf_rs.submission.main`, the package's side of
//! the protocol; the participant's `train` and `load_policy` run with the
//! folder as their working directory), so that the participant's code, its imports and whatever
//! it spawns are measured and nothing else: the
//! training child opens the run as `a2perf_rs.TrainingRun` does (the pipeline's `ExternalRun`,
//! whose meters cover that process and its descendants), and the inference and generalization
//! children roll the folder's policy out through the pipeline's own `infer` and `generalize`.
//! This side plans the runs (so that a bad config fails before any Python starts), prepares the
//! interpreter, hands each child its task and reports.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::Command;

use a2perf_core::Registry;
use a2perf_pipeline::external::{ExternalRunSpec, external_plan, is_identifier};
use a2perf_pipeline::{
    self as pipeline, GENERALIZATION_FILE, INFERENCE_FILE, LoadedRun, SUBMISSION_CODE_DIR,
    SUBMISSION_FILES_DIR,
};
use anyhow::{Context, Result, bail};
use clap::Args;

/// Arguments of `a2perf submit`.
#[derive(Args, Debug)]
pub struct SubmitArgs {
    /// `PARTICIPANT_DIR CONFIG`: the participant folder (`train.py`, `inference.py`,
    /// `requirements.txt`) and the experiment config whose task, profile, generalization suite
    /// and settings the submission is scored on (its algorithm is replaced by the folder), e.g.
    /// `configs/circuit_training/ppo.ron`. Only `CONFIG` with `--participant-module-path`.
    #[arg(value_name = "PARTICIPANT_DIR> <CONFIG", required = true, num_args = 1..=2)]
    pub paths: Vec<PathBuf>,
    /// The participant folder, as the original's flag.
    #[arg(
        long = "participant-module-path",
        visible_alias = "participant_module_path",
        value_name = "DIR"
    )]
    pub participant_module_path: Option<PathBuf>,
    /// Keyword arguments of `train(**participant_args)` and `load_policy(env,
    /// **participant_args)`: `key1=value1,key2=value2` (values are strings, as in the original).
    /// Recorded as the agent's hyperparameters.
    #[arg(
        long = "participant-args",
        visible_alias = "participant_args",
        value_name = "K=V,..."
    )]
    pub participant_args: Option<String>,
    /// The agent's name: the report's column (default: the folder's name).
    #[arg(long)]
    pub name: Option<String>,
    /// Output root of the runs (default: the config's `output.dir`); they go to
    /// `ROOT/<name>/<task>__<name>__seed<k>`.
    #[arg(long = "root-dir", visible_alias = "root_dir", value_name = "ROOT")]
    pub root_dir: Option<PathBuf>,
    /// Config override `dotted.path=value` (repeatable), e.g. `inference.rollouts=20`.
    #[arg(long = "set", value_name = "KEY=VALUE")]
    pub set: Vec<String>,
    /// Seeds, replacing the config's: `0..10`, `0..=9`, `1,3,5`.
    #[arg(long)]
    pub seeds: Option<String>,
    /// Seeds run at the same time (0 = one per CPU). Each phase of a seed is a process of its
    /// own, so its meters (RAM, energy, time) are its alone, as with `a2perf run --isolate`;
    /// only the machine is shared. Results are the same as one seed at a time.
    #[arg(long, default_value_t = 1, value_name = "N")]
    pub jobs: usize,
    /// Report directory (default: `report/` in the submission's experiment directory).
    #[arg(short = 'o', long)]
    pub output: Option<PathBuf>,
    /// Result directories to report beside the submission (e.g. the built-in baselines').
    #[arg(long = "with", value_name = "DIR")]
    pub with: Vec<PathBuf>,
    /// Use this Python interpreter (with `a2perf_rs` and the folder's requirements installed)
    /// instead of a venv made for the submission.
    #[arg(long, value_name = "PATH")]
    pub python: Option<PathBuf>,
    /// The `a2perf_rs` wheel installed into the submission's venv (default: `$A2PERF_WHEEL`,
    /// else an `a2perf_rs-*.whl` beside this binary).
    #[arg(long, value_name = "WHEEL", conflicts_with = "python")]
    pub wheel: Option<PathBuf>,
}

/// `key1=value1,key2=value2` as keyword arguments: keys must be Python identifiers and appear
/// once; values stay strings (the original's `parse_participant_args`). Empty text: none.
pub fn parse_participant_args(text: &str) -> Result<BTreeMap<String, String>> {
    let mut out = BTreeMap::new();
    if text.trim().is_empty() {
        return Ok(out);
    }
    for item in text.split(',') {
        let Some((key, value)) = item.split_once('=') else {
            bail!(
                "--participant-args: `{item}` is not `key=value` (the format is \
                 `key1=value1,key2=value2`)"
            );
        };
        let key = key.trim();
        if !is_identifier(key) {
            bail!(
                "--participant-args: `{key}` is not a Python identifier (letters, digits and `_`, \
                 not starting with a digit): it becomes a keyword argument of train()"
            );
        }
        if out.insert(key.to_string(), value.to_string()).is_some() {
            bail!("--participant-args: `{key}` is given twice");
        }
    }
    Ok(out)
}

/// The files a participant folder must have before anything is prepared for it (the child's
/// `check` phase looks at the functions).
fn check_folder(dir: &Path) -> Result<PathBuf> {
    if !dir.is_dir() {
        bail!("{}: no such participant folder", dir.display());
    }
    for file in ["train.py", "inference.py"] {
        if !dir.join(file).is_file() {
            bail!(
                "{}: no {file} (a participant folder holds train.py with train(**participant_args), \
                 inference.py with load_policy, preprocess_observation and infer_once, and \
                 requirements.txt; see docs/submissions.md)",
                dir.display()
            );
        }
    }
    dir.canonicalize()
        .with_context(|| format!("resolving {}", dir.display()))
}

/// The `a2perf_rs` wheel for a submission's venv: `--wheel`, `$A2PERF_WHEEL`, or the one beside
/// the binary (where a release puts it). A source build is not tried: it needs a Rust
/// toolchain, maturin and the network, and a wheel is what `scripts/wheel` and CI build anyway.
fn find_wheel(given: Option<&Path>) -> Result<PathBuf> {
    let from_env = std::env::var_os("A2PERF_WHEEL").map(PathBuf::from);
    if let Some(w) = given.map(Path::to_path_buf).or(from_env) {
        if !w.is_file() {
            bail!(
                "{}: no such wheel (from --wheel or $A2PERF_WHEEL)",
                w.display()
            );
        }
        return Ok(w);
    }
    let beside = std::env::current_exe()
        .ok()
        .and_then(|exe| exe.parent().map(Path::to_path_buf));
    if let Some(dir) = beside
        && let Ok(entries) = std::fs::read_dir(&dir)
    {
        let mut wheels: Vec<PathBuf> = entries
            .filter_map(|e| e.ok().map(|e| e.path()))
            .filter(|p| {
                p.file_name()
                    .and_then(|n| n.to_str())
                    .is_some_and(|n| n.starts_with("a2perf_rs-") && n.ends_with(".whl"))
            })
            .collect();
        wheels.sort();
        if let Some(w) = wheels.pop() {
            return Ok(w);
        }
    }
    bail!(
        "no a2perf_rs wheel to install into the submission's venv: build one (`scripts/wheel`, \
         which prints its path) and pass it with --wheel or $A2PERF_WHEEL, or give --python \
         with an interpreter that has a2perf_rs and the folder's requirements installed"
    )
}

fn run_quiet(cmd: &mut Command, what: &str) -> Result<()> {
    let out = cmd.output().with_context(|| format!("{what}: {cmd:?}"))?;
    if !out.status.success() {
        bail!(
            "{what} failed ({}):\n{}{}",
            out.status,
            String::from_utf8_lossy(&out.stdout),
            String::from_utf8_lossy(&out.stderr)
        );
    }
    Ok(())
}

/// The submission's venv in `dir` (`python3 -m venv`, the folder's `requirements.txt` and the
/// wheel installed by pip), reused while the requirements and the wheel are the same. pip
/// takes its usual settings from the environment (`PIP_INDEX_URL`, `PIP_FIND_LINKS`,
/// `PIP_NO_INDEX` for a wheelhouse offline).
fn venv(dir: &Path, folder: &Path, wheel: &Path) -> Result<PathBuf> {
    let requirements_path = folder.join("requirements.txt");
    let requirements = match std::fs::read_to_string(&requirements_path) {
        Ok(text) => text,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
            eprintln!(
                "warning: {}: no requirements.txt; the venv gets a2perf_rs (and numpy) only",
                folder.display()
            );
            String::new()
        }
        Err(e) => {
            return Err(e).with_context(|| format!("reading {}", requirements_path.display()));
        }
    };
    let meta = std::fs::metadata(wheel).with_context(|| format!("reading {}", wheel.display()))?;
    let key = serde_json::json!({
        "requirements": requirements,
        "wheel": wheel.file_name().map(|n| n.to_string_lossy().into_owned()),
        "wheel_bytes": meta.len(),
        "wheel_modified": meta.modified().ok().and_then(|t| t.duration_since(std::time::UNIX_EPOCH).ok()).map(|d| d.as_secs()),
    });
    let python = dir.join("bin").join("python");
    let marker = dir.join("a2perf-submit.json");
    let current = std::fs::read(&marker)
        .ok()
        .and_then(|b| serde_json::from_slice::<serde_json::Value>(&b).ok());
    if python.is_file() && current.as_ref() == Some(&key) {
        eprintln!("venv {} (reused)", dir.display());
        return Ok(python);
    }
    if dir.exists() {
        std::fs::remove_dir_all(dir).with_context(|| format!("removing {}", dir.display()))?;
    }
    eprintln!("venv {}: python3 -m venv, pip install", dir.display());
    run_quiet(
        Command::new("python3").arg("-m").arg("venv").arg(dir),
        "creating the submission's venv (python3 -m venv)",
    )?;
    let mut pip = Command::new(&python);
    pip.args(["-m", "pip", "install", "-q", "--disable-pip-version-check"]);
    if !requirements.trim().is_empty() {
        pip.arg("-r").arg(&requirements_path);
    }
    pip.arg(wheel).current_dir(folder);
    run_quiet(
        &mut pip,
        "installing requirements.txt and a2perf_rs into the venv",
    )?;
    // Written last: an interrupted install is redone.
    std::fs::write(&marker, serde_json::to_vec_pretty(&key)?)
        .with_context(|| format!("writing {}", marker.display()))?;
    Ok(python)
}

/// An interpreter given with `--python`, checked to have this version of `a2perf_rs`.
fn given_python(python: &Path) -> Result<PathBuf> {
    let out = Command::new(python)
        .args(["-c", "import a2perf_rs; print(a2perf_rs.__version__)"])
        .output()
        .with_context(|| format!("--python {}", python.display()))?;
    if !out.status.success() {
        bail!(
            "--python {}: cannot import a2perf_rs ({}); install the wheel into it (`pip install \
             dist/a2perf_rs-*.whl`) or leave --python out to get a venv",
            python.display(),
            String::from_utf8_lossy(&out.stderr).trim()
        );
    }
    let version = String::from_utf8_lossy(&out.stdout).trim().to_string();
    if version != env!("CARGO_PKG_VERSION") {
        bail!(
            "--python {}: a2perf_rs {version} is installed, this binary is {}: install the \
             matching wheel",
            python.display(),
            env!("CARGO_PKG_VERSION")
        );
    }
    Ok(python.to_path_buf())
}

/// Runs one phase of the submission in a child interpreter; `Ok(false)` when the participant's
/// code raised (its traceback is on stderr).
fn phase(python: &Path, folder: &Path, task: &serde_json::Value, name: &str) -> Result<bool> {
    let run_dir = task["run_dir"].as_str().unwrap_or_default();
    let status = Command::new(python)
        // Not `-m a2perf_rs.submission`: the participant's `from a2perf_rs import submission`
        // must find the module that holds the harness's state, not a second copy of it.
        .args([
            "-c",
            "import sys, a2perf_rs.submission as s; sys.exit(s.main())",
            name,
        ])
        .env("A2PERF_SUBMISSION", task.to_string())
        .env("ROOT_DIR", run_dir)
        .status()
        .with_context(|| format!("starting {} (a2perf_rs.submission)", python.display()))?;
    match status.code() {
        Some(0) => Ok(true),
        Some(1) => Ok(false),
        Some(2) => bail!(
            "{}: the participant folder cannot be run (see above)",
            folder.display()
        ),
        // Ctrl-C reached the child too: its run is marked interrupted.
        Some(130) => Err(pipeline::PipelineError::Cancelled.into()),
        _ => bail!("{name}: the child process stopped ({status})"),
    }
}

/// `a2perf submit`.
pub fn submit(registry: &Registry, args: &SubmitArgs) -> Result<()> {
    let (given, config) = match (&args.participant_module_path, args.paths.as_slice()) {
        (None, [dir, config]) => (dir, config),
        (Some(dir), [config]) => (dir, config),
        (None, _) => bail!("give the participant folder and the experiment config"),
        (Some(_), _) => {
            bail!("with --participant-module-path, give only the experiment config as an argument")
        }
    };
    let folder = check_folder(given)?;
    let participant_args = parse_participant_args(args.participant_args.as_deref().unwrap_or(""))?;
    let name = match &args.name {
        Some(n) => n.clone(),
        None => folder
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .context("name the agent with --name")?,
    };
    let invalid = |e: a2perf_core::config::ConfigError| anyhow::anyhow!("{e}");
    let exp = a2perf_core::Experiment::load(config, &args.set, registry).map_err(invalid)?;
    let seeds = match &args.seeds {
        Some(s) => pipeline::parse_seeds(s)?,
        None => exp.seeds.clone(),
    };
    // The children plan the same runs from another working directory.
    let output = std::path::absolute(args.root_dir.as_ref().unwrap_or(&exp.output.dir))?;
    let config = std::path::absolute(config)?;
    let cwd = std::env::current_dir().context("the working directory")?;
    // Every run is planned before any Python starts: a bad config, name or seed fails here.
    let mut plans = Vec::new();
    for &seed in &seeds {
        let spec = ExternalRunSpec {
            config: Some(config.clone()),
            set: args.set.clone(),
            hyperparameters: participant_args
                .iter()
                .map(|(k, v)| (k.clone(), a2perf_core::Value::Str(v.clone())))
                .collect(),
            ..ExternalRunSpec::new(&output, &name, seed)
        };
        plans.push((seed, external_plan(registry, &spec)?));
    }
    let Some((_, first)) = plans.first() else {
        bail!("no seeds to run");
    };
    let experiment_dir = first.output.join(&first.name);
    let python = match &args.python {
        Some(p) => given_python(p)?,
        None => {
            let wheel = find_wheel(args.wheel.as_deref())?;
            std::fs::create_dir_all(&experiment_dir)
                .with_context(|| format!("creating {}", experiment_dir.display()))?;
            venv(&experiment_dir.join(".venv"), &folder, &wheel)?
        }
    };
    let harness = format!(
        "a2perf submit {} ({})",
        env!("CARGO_PKG_VERSION"),
        folder.display()
    );
    let tasks: Vec<(u64, PathBuf, serde_json::Value)> = plans
        .iter()
        .map(|(seed, plan)| {
            let run_dir = plan.run_dir(*seed);
            let task = serde_json::json!({
                "participant_dir": folder,
                "participant_args": participant_args,
                "output": output,
                "experiment": plan.name,
                "config": config,
                "cwd": cwd,
                "set": args.set,
                "algorithm": name,
                "seed": seed,
                "run_dir": run_dir,
                "code_dir": run_dir.join(SUBMISSION_CODE_DIR),
                "files_dir": run_dir.join(SUBMISSION_FILES_DIR),
                "env_id": plan.task.env_id,
                "env_params": plan.task.env_params,
                "training": plan.training,
                "harness": harness,
            });
            (*seed, run_dir, task)
        })
        .collect();
    // The folder is checked once, before any seed trains.
    phase(&python, &folder, &tasks[0].2, "check")?;
    let failures = for_each_seed(&tasks, args.jobs, |(seed, run_dir, task)| {
        run_seed(&python, &folder, *seed, run_dir, task)
    })?;
    let mut dirs = vec![experiment_dir.clone()];
    dirs.extend(args.with.iter().cloned());
    let out = args
        .output
        .clone()
        .unwrap_or_else(|| experiment_dir.join("report"));
    if pipeline::find_runs(&experiment_dir)?.iter().any(|d| {
        LoadedRun::open(d)
            .and_then(|r| r.is_complete())
            .unwrap_or(false)
    }) {
        crate::pipeline_cmd::write_report(&dirs, &out, None, None, &Default::default())?;
    }
    if !failures.is_empty() {
        bail!(
            "{} of {} submission run(s) failed:\n  {}",
            failures.len(),
            plans.len(),
            failures.join("\n  ")
        );
    }
    Ok(())
}

/// Trains (unless complete), infers and generalizes one seed; `Ok(Some(why))` when the
/// participant's code raised, `Err` when the harness itself could not go on.
fn run_seed(
    python: &Path,
    folder: &Path,
    seed: u64,
    run_dir: &Path,
    task: &serde_json::Value,
) -> Result<Option<String>> {
    let complete = run_dir.exists() && LoadedRun::open(run_dir)?.is_complete()?;
    if complete {
        eprintln!("{}: already trained (complete)", run_dir.display());
    } else {
        eprintln!("== train {} (seed {seed})", folder.display());
        if !phase(python, folder, task, "train")? {
            eprintln!(
                "{}: training raised (traceback above: train(), or the evaluation of its \
                 final policy when it logged none); the run is marked failed",
                run_dir.display()
            );
            return Ok(Some(format!("{}: training raised", run_dir.display())));
        }
    }
    let mut failure = None;
    for (what, file) in [
        ("infer", INFERENCE_FILE),
        ("generalize", GENERALIZATION_FILE),
    ] {
        if complete && run_dir.join(file).is_file() {
            continue;
        }
        eprintln!("== {what} {}", run_dir.display());
        if !phase(python, folder, task, what)? {
            failure = Some(format!(
                "{}: {what}: the participant's inference code raised",
                run_dir.display()
            ));
            break;
        }
    }
    // What was written is shown even when a later phase raised (inference before generalization).
    print_results(run_dir)?;
    Ok(failure)
}

/// Runs `work` on every item, `jobs` at a time (the pipeline's pool), and gathers the failures
/// it reports in the items' order. An error stops the items not yet started (those running
/// finish); then the error of the earliest item is returned.
fn for_each_seed<T: Sync>(
    items: &[T],
    jobs: usize,
    work: impl Fn(&T) -> Result<Option<String>> + Sync,
) -> Result<Vec<String>> {
    let stop = pipeline::CancelToken::new();
    let outcomes = pipeline::for_each(items.len(), jobs, &stop, |i| {
        let outcome = work(&items[i]);
        if outcome.is_err() {
            stop.cancel();
        }
        outcome
    });
    let mut failures = Vec::new();
    for outcome in outcomes.into_iter().flatten() {
        failures.extend(outcome?);
    }
    Ok(failures)
}

fn print_results(run_dir: &Path) -> Result<()> {
    let read = |file: &str| -> Result<Option<serde_json::Value>> {
        let path = run_dir.join(file);
        if !path.is_file() {
            return Ok(None);
        }
        let bytes = std::fs::read(&path).with_context(|| format!("reading {}", path.display()))?;
        Ok(Some(serde_json::from_slice(&bytes)?))
    };
    if let Some(r) = read(INFERENCE_FILE)? {
        let r: pipeline::InferenceResults = serde_json::from_value(r)?;
        crate::pipeline_cmd::print_inference(run_dir, &r);
    }
    if let Some(r) = read(GENERALIZATION_FILE)? {
        let r: pipeline::GeneralizationResults = serde_json::from_value(r)?;
        crate::pipeline_cmd::print_generalization(run_dir, &r);
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser;

    #[derive(Parser)]
    struct Cli {
        #[command(flatten)]
        submit: SubmitArgs,
    }

    #[test]
    fn the_folder_comes_first_or_from_the_originals_flag() {
        let a = Cli::try_parse_from(["submit", "dir", "c.ron"])
            .unwrap()
            .submit;
        assert_eq!(a.paths, [PathBuf::from("dir"), PathBuf::from("c.ron")]);
        let a = Cli::try_parse_from([
            "submit",
            "--participant_module_path",
            "dir",
            "c.ron",
            "--participant_args",
            "a=1",
            "--root_dir",
            "out",
        ])
        .unwrap()
        .submit;
        assert_eq!(a.paths, [PathBuf::from("c.ron")]);
        assert_eq!(a.participant_module_path, Some(PathBuf::from("dir")));
        assert_eq!(a.participant_args.as_deref(), Some("a=1"));
        assert_eq!(a.root_dir, Some(PathBuf::from("out")));
        assert!(Cli::try_parse_from(["submit"]).is_err());
    }

    #[test]
    fn participant_args_are_strings_by_key() {
        let a = parse_participant_args("iterations=3,lr=0.1, name = x=y").unwrap();
        assert_eq!(a["iterations"], "3");
        assert_eq!(a["lr"], "0.1");
        assert_eq!(a["name"], " x=y");
        assert!(parse_participant_args("").unwrap().is_empty());
    }

    #[test]
    fn bad_participant_args_say_why() {
        let err = |t: &str| parse_participant_args(t).unwrap_err().to_string();
        assert!(
            err("a=1,b").contains("`b` is not `key=value`"),
            "{}",
            err("a=1,b")
        );
        assert!(err("1a=2").contains("not a Python identifier"));
        assert!(err("a=1,a=2").contains("`a` is given twice"));
        assert!(err("=3").contains("not a Python identifier"));
    }

    #[test]
    fn a_folder_without_inference_py_is_refused_before_anything_runs() {
        let dir = tempfile::tempdir().unwrap();
        std::fs::write(dir.path().join("train.py"), "def train(): pass\n").unwrap();
        let err = check_folder(dir.path()).unwrap_err().to_string();
        assert!(err.contains("no inference.py"), "{err}");
        let err = check_folder(&dir.path().join("absent"))
            .unwrap_err()
            .to_string();
        assert!(err.contains("no such participant folder"), "{err}");
    }

    #[test]
    fn seeds_side_by_side_report_failures_in_order_and_stop_after_an_error() {
        use std::sync::atomic::{AtomicUsize, Ordering};
        let seeds: Vec<u64> = (0..6).collect();
        let started = AtomicUsize::new(0);
        let failures = for_each_seed(&seeds, 2, |&s| {
            started.fetch_add(1, Ordering::SeqCst);
            Ok((s % 2 == 1).then(|| format!("seed {s} raised")))
        })
        .unwrap();
        assert_eq!(
            failures,
            ["seed 1 raised", "seed 3 raised", "seed 5 raised"]
        );
        assert_eq!(started.load(Ordering::SeqCst), 6);
        // One at a time, an error at seed 2 leaves seeds 3 to 5 unstarted.
        let started = AtomicUsize::new(0);
        let err = for_each_seed(&seeds, 1, |&s| {
            started.fetch_add(1, Ordering::SeqCst);
            if s == 2 {
                anyhow::bail!("harness stopped at seed {s}")
            }
            Ok(None)
        })
        .unwrap_err();
        assert_eq!(err.to_string(), "harness stopped at seed 2");
        assert_eq!(started.load(Ordering::SeqCst), 3);
    }
}
