//! A suite with a dataset step trains in one pool: the dataset of an offline entry is collected
//! as soon as its source runs are trained, beside the other runs, and the results do not depend
//! on how many workers the pool has.

mod common;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::{Duration, Instant};

use a2perf_core::{
    Algorithm, AlgorithmEntry, ParamKind, ParamSpec, Params, Policy, Registry, RunError,
    TrainingContext, Value,
};
use a2perf_pipeline::run::train_with_datasets;
use a2perf_pipeline::train::TrainOptions;
use a2perf_pipeline::{
    ExperimentPlan, RunEvent, RunOptions, TrainTask, load_plans, run_experiments,
};

/// How long a `gated_search` run waits for its file before it gives up (and fails).
const GATE_TIMEOUT: Duration = Duration::from_secs(60);

/// `random_search` that first waits for the file `wait_for` to exist, or fails at once with
/// `fail: true`: a run whose end the test controls.
struct GatedSearch {
    inner: Box<dyn Algorithm>,
    wait_for: Option<PathBuf>,
    fail: bool,
}

impl Algorithm for GatedSearch {
    fn name(&self) -> &str {
        "gated_search"
    }
    fn train(&mut self, ctx: &mut TrainingContext<'_>) -> Result<Box<dyn Policy>, RunError> {
        if self.fail {
            return Err(RunError::Unsupported("told to fail".into()));
        }
        if let Some(file) = &self.wait_for {
            let start = Instant::now();
            while !file.exists() {
                if start.elapsed() > GATE_TIMEOUT {
                    return Err(RunError::Unsupported(format!(
                        "{} did not appear while this run trained",
                        file.display()
                    )));
                }
                std::thread::sleep(Duration::from_millis(10));
            }
        }
        self.inner.train(ctx)
    }
}

/// The shared registry plus `gated_search`.
fn registry() -> Registry {
    let mut reg = common::registry();
    let search = reg.algorithm("random_search").unwrap();
    let (inner_specs, inner_make, load_policy) = (
        search.params.clone(),
        search.make.clone(),
        search.load_policy,
    );
    let mut params = inner_specs.clone();
    params.push(ParamSpec::new(
        "wait_for",
        ParamKind::Path,
        Value::Null,
        "file to wait for",
    ));
    params.push(ParamSpec::new(
        "fail",
        ParamKind::Bool,
        Value::Bool(false),
        "fail at once",
    ));
    reg.register_algorithm(AlgorithmEntry {
        name: "gated_search".into(),
        summary: "test: random search that waits for a file, or fails".into(),
        params,
        make: Arc::new(move |p: &Params| {
            let own = ["wait_for", "fail"];
            let rest: BTreeMap<String, Value> = p
                .values()
                .iter()
                .filter(|(k, _)| !own.contains(&k.as_str()))
                .map(|(k, v)| (k.clone(), v.clone()))
                .collect();
            let inner_params = Params::resolve(&inner_specs, &rest).map_err(|e| {
                RunError::InvalidHyperparameter {
                    name: "random_search".into(),
                    reason: e.to_string(),
                }
            })?;
            Ok(Box::new(GatedSearch {
                inner: inner_make(&inner_params)?,
                wait_for: p.opt_str("wait_for").ok().flatten().map(PathBuf::from),
                fail: p.bool("fail").unwrap_or(false),
            }) as Box<dyn Algorithm>)
        }),
        load_policy,
    });
    reg
}

fn plans(file: &Path, reg: &Registry) -> Vec<ExperimentPlan> {
    load_plans(std::slice::from_ref(&file.to_path_buf()), &[], None, reg)
        .unwrap()
        .plans
}

fn plan<'a>(plans: &'a [ExperimentPlan], name: &str) -> &'a ExperimentPlan {
    plans.iter().find(|p| p.name == name).unwrap()
}

const OFFLINE_FROM_AB: &str = r#"(config: "offline.ron",
    dataset: (from: ["a", "b"], level: "intermediate", eval_episodes: 2, episodes: 4))"#;

/// What a run wrote that training, collection, inference and generalization decide (not the
/// clock, the meters or the run's own path): file name -> bytes.
fn results_of(run: &Path) -> BTreeMap<String, Vec<u8>> {
    let mut out = BTreeMap::new();
    let mut put = |name: &str, bytes: Vec<u8>| {
        out.insert(name.to_string(), bytes);
    };
    let curve = std::fs::read_to_string(run.join("curve.csv")).unwrap();
    // Every column but the last (wall-clock seconds).
    let curve: Vec<&str> = curve.lines().map(|l| &l[..l.rfind(',').unwrap()]).collect();
    put("curve.csv", curve.join("\n").into_bytes());
    put(
        "policy.ckpt",
        std::fs::read(run.join("policy.ckpt")).unwrap(),
    );
    let mut ckpts: Vec<PathBuf> = std::fs::read_dir(run.join("checkpoints"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .collect();
    ckpts.sort();
    assert!(!ckpts.is_empty());
    for c in ckpts {
        let name = format!("checkpoints/{}", c.file_name().unwrap().to_string_lossy());
        put(&name, std::fs::read(&c).unwrap());
    }
    let json = |name: &str| -> serde_json::Value {
        serde_json::from_slice(&std::fs::read(run.join(name)).unwrap()).unwrap()
    };
    let inference = json("inference.json");
    put(
        "inference.json returns",
        inference["rollout_returns"].to_string().into_bytes(),
    );
    put(
        "generalization.json",
        std::fs::read(run.join("generalization.json")).unwrap(),
    );
    let record = json("run.json");
    if let Some(d) = record.get("dataset").filter(|d| !d.is_null()) {
        put("dataset id", d["dataset_id"].to_string().into_bytes());
        let samples = PathBuf::from(d["path"].as_str().unwrap());
        put("samples.json", std::fs::read(samples).unwrap());
    }
    out
}

#[test]
fn one_worker_and_two_give_the_same_results() {
    let reg = common::registry();
    let mut results = Vec::new();
    for jobs in [1, 2] {
        let tmp = tempfile::tempdir().unwrap();
        let entries = [
            OFFLINE_FROM_AB,
            r#"(config: "online.ron", set: ["name=a"])"#,
            r#"(config: "online.ron", set: ["name=b"])"#,
        ];
        let plans = plans(&common::dataset_suite(tmp.path(), &entries), &reg);
        let opts = RunOptions {
            jobs,
            meters: common::test_meters(),
            ..Default::default()
        };
        let mut collects = 0;
        run_experiments(&reg, &plans, &opts, &mut |e| {
            if let RunEvent::Started(TrainTask::Collect(name)) = e {
                assert_eq!(name, "offline");
                collects += 1;
            }
        })
        .unwrap();
        assert_eq!(collects, 1);
        let mut files = BTreeMap::new();
        for p in &plans {
            for s in &p.seeds {
                let run = p.run_dir(*s);
                let name = run.file_name().unwrap().to_string_lossy().into_owned();
                files.insert(format!("{}/{name}", p.name), results_of(&run));
            }
        }
        results.push(files);
    }
    assert_eq!(results[0].len(), 6);
    assert!(results[0]["offline/Corridor-v0__toy_bc__seed0"].contains_key("samples.json"));
    for (run, files) in &results[0] {
        for (name, bytes) in files {
            assert!(
                results[1][run][name] == *bytes,
                "{run}/{name} differs between --jobs 1 and --jobs 2"
            );
        }
    }
    assert_eq!(results[0], results[1]);
}

#[test]
fn a_dataset_is_collected_while_an_unrelated_run_still_trains() {
    let reg = registry();
    let tmp = tempfile::tempdir().unwrap();
    // `slow` trains beside `a` and cannot finish before the dataset `offline` collects from
    // `a` has been collected (its request file written): with training in two stages (every
    // run, then every dataset) it would wait in vain and fail.
    let request = tmp.path().join("results/offline/datasets/request.json");
    let slow = format!(
        r#"(config: "online.ron", set: ["name=slow", "seeds=[0]",
            "algorithm.name=gated_search", "algorithm.wait_for={}"])"#,
        request.display()
    );
    let entries = [
        r#"(config: "online.ron", set: ["name=a", "seeds=[0]"])"#,
        &slow,
        r#"(config: "offline.ron", set: ["seeds=[0]"],
            dataset: (from: ["a"], level: "intermediate", one_sigma: true, eval_episodes: 2,
                      episodes: 4))"#,
    ];
    let plans = plans(&common::dataset_suite(tmp.path(), &entries), &reg);
    let opts = TrainOptions {
        jobs: 2,
        meters: common::test_meters(),
        ..Default::default()
    };
    let mut log: Vec<String> = Vec::new();
    let mut trained = None;
    train_with_datasets(&reg, &plans, &opts, &mut |e| match e {
        RunEvent::Started(t) => log.push(format!("start {t}")),
        RunEvent::Finished(t) => log.push(format!("end {t}")),
        RunEvent::Trained(s) => trained = Some(s.runs.len()),
        _ => {}
    })
    .unwrap_or_else(|e| panic!("{e}\n{log:#?}"));
    assert_eq!(trained, Some(3));
    let at = |line: String| {
        log.iter()
            .position(|l| *l == line)
            .unwrap_or_else(|| panic!("no `{line}` in {log:#?}"))
    };
    let run = |name: &str| plan(&plans, name).run_dir(0);
    let collect = TrainTask::Collect("offline".into());
    let (a, slow, offline) = (
        TrainTask::Run(run("a")),
        TrainTask::Run(run("slow")),
        TrainTask::Run(run("offline")),
    );
    assert!(
        at(format!("start {collect}")) > at(format!("end {a}")),
        "{log:#?}"
    );
    assert!(
        at(format!("start {collect}")) < at(format!("end {slow}")),
        "{log:#?}"
    );
    assert!(
        at(format!("start {offline}")) > at(format!("end {collect}")),
        "{log:#?}"
    );
    assert_eq!(log.len(), 8, "every task starts and ends once: {log:#?}");
    for name in ["a", "slow", "offline"] {
        assert!(run(name).join("policy.ckpt").is_file(), "{name}");
    }
}

#[test]
fn a_failing_source_run_stops_the_offline_entry_and_no_other_run() {
    let reg = registry();
    for jobs in [1, 2] {
        let tmp = tempfile::tempdir().unwrap();
        let entries = [
            OFFLINE_FROM_AB,
            r#"(config: "online.ron", set: ["name=a", "algorithm.name=gated_search",
                "algorithm.fail=true", "seeds=[0]"])"#,
            r#"(config: "online.ron", set: ["name=b"])"#,
        ];
        let plans = plans(&common::dataset_suite(tmp.path(), &entries), &reg);
        let opts = TrainOptions {
            jobs,
            meters: common::test_meters(),
            ..Default::default()
        };
        let mut summary = None;
        let mut started = Vec::new();
        let err = train_with_datasets(&reg, &plans, &opts, &mut |e| match e {
            RunEvent::Trained(s) => summary = Some(s.clone()),
            RunEvent::Started(t) => started.push(t.clone()),
            _ => {}
        })
        .unwrap_err()
        .to_string();
        let failed = plan(&plans, "a").run_dir(0);
        let offline = plan(&plans, "offline");
        assert!(
            err.contains(&format!("{}: ", failed.display())) && err.contains("told to fail"),
            "{jobs}: {err}"
        );
        for seed in [0, 1] {
            let dir = offline.run_dir(seed);
            assert!(err.contains(&dir.display().to_string()), "{jobs}: {err}");
            assert!(!dir.join("policy.ckpt").exists());
            assert!(!started.contains(&TrainTask::Run(dir)));
        }
        assert!(
            err.contains("2 run(s) not started")
                && err.contains(&format!(
                    "is collected from {}, which did not complete",
                    failed.display()
                )),
            "{jobs}: {err}"
        );
        assert!(!started.contains(&TrainTask::Collect("offline".into())));
        // The unrelated runs trained and stay trained.
        let summary = summary.unwrap();
        assert_eq!(summary.blocked().len(), 2);
        assert_eq!(summary.failures().len(), 1);
        for seed in [0, 1] {
            let b = plan(&plans, "b").run_dir(seed);
            assert!(b.join("policy.ckpt").is_file(), "{jobs}: {}", b.display());
        }
        assert_eq!(
            a2perf_core::RunDir::new(&failed)
                .status()
                .unwrap()
                .unwrap()
                .state,
            a2perf_core::RunState::Failed
        );
    }
}

#[test]
fn a_cancel_starts_nothing_more_and_a_rerun_finishes_the_suite() {
    let reg = registry();
    let tmp = tempfile::tempdir().unwrap();
    // `a`'s first run waits for `go`, which the test writes only after it has cancelled.
    let go = tmp.path().join("go");
    let a = format!(
        r#"(config: "online.ron", set: ["name=a", "algorithm.name=gated_search",
            "algorithm.wait_for={}"])"#,
        go.display()
    );
    let entries = [
        OFFLINE_FROM_AB,
        &a,
        r#"(config: "online.ron", set: ["name=b"])"#,
    ];
    let plans = plans(&common::dataset_suite(tmp.path(), &entries), &reg);
    let opts = TrainOptions {
        jobs: 1,
        meters: common::test_meters(),
        ..Default::default()
    };
    let mut started = Vec::new();
    let mut summary = None;
    let err = train_with_datasets(&reg, &plans, &opts, &mut |e| match e {
        RunEvent::Started(t) => {
            started.push(t.clone());
            opts.cancel.cancel();
            std::fs::write(&go, b"").unwrap();
        }
        RunEvent::Trained(s) => summary = Some(s.clone()),
        _ => {}
    })
    .unwrap_err();
    assert!(
        matches!(err, a2perf_pipeline::PipelineError::Cancelled),
        "{err}"
    );
    let first = plan(&plans, "a").run_dir(0);
    assert_eq!(started, [TrainTask::Run(first.clone())]);
    let summary = summary.unwrap();
    assert_eq!(summary.runs.len(), 6);
    assert!(
        summary
            .runs
            .iter()
            .all(|(_, o)| *o == a2perf_pipeline::RunOutcome::Cancelled),
        "{summary:?}"
    );
    let offline = plan(&plans, "offline");
    let source = offline.dataset_from.as_ref().unwrap();
    assert!(!source.samples.exists() && !offline.run_dir(0).exists());

    // A rerun trains everything, collects the dataset and trains on it.
    let opts = TrainOptions {
        cancel: a2perf_core::CancelToken::new(),
        ..opts
    };
    let mut summary = None;
    train_with_datasets(&reg, &plans, &opts, &mut |e| {
        if let RunEvent::Trained(s) = e {
            summary = Some(s.clone());
        }
    })
    .unwrap();
    let summary = summary.unwrap();
    assert_eq!(
        summary.with(&a2perf_pipeline::RunOutcome::Completed).len(),
        6
    );
    assert!(source.samples.is_file() && offline.run_dir(1).join("policy.ckpt").is_file());
    assert!(first.join("policy.ckpt").is_file());
}
