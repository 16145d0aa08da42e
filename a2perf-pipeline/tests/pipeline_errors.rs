//! Bad inputs give errors naming the problem, never panics.

mod common;

use a2perf_pipeline::{InferOptions, TrainOptions, report::ReportOptions};

fn trained() -> (tempfile::TempDir, std::path::PathBuf) {
    let tmp = tempfile::tempdir().unwrap();
    let plan = common::trained_plan(&common::registry(), tmp.path(), "exp", vec![0]);
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

/// Cancels `token` when asked for its `after`-th policy (counting from 0): with one policy per
/// checkpoint evaluated first, that is the first policy a dataset episode rolls out.
struct CancelAt<'a> {
    inner: a2perf_pipeline::RegistryPolicies<'a>,
    calls: usize,
    after: usize,
    token: a2perf_pipeline::CancelToken,
}

impl a2perf_pipeline::PolicySource for CancelAt<'_> {
    fn policy(
        &mut self,
        run: &a2perf_pipeline::run_dir::LoadedRun,
        checkpoint: &std::path::Path,
        spec: &a2perf_core::EnvSpec,
    ) -> a2perf_pipeline::Result<Box<dyn a2perf_core::Policy>> {
        if self.calls == self.after {
            self.token.cancel();
        }
        self.calls += 1;
        self.inner.policy(run, checkpoint, spec)
    }
}

#[test]
fn an_interrupted_collection_leaves_no_partial_dataset_and_resumes_exactly() {
    use a2perf_pipeline::collect::{CollectOptions, checkpoints, collect, collect_with};
    let tmp = tempfile::tempdir().unwrap();
    let reg = common::registry();
    let plan = common::trained_plan(&reg, tmp.path(), "exp", vec![0, 1]);
    let runs = [plan.run_dir(0), plan.run_dir(1)];
    let opts = CollectOptions {
        eval_episodes: 2,
        dataset_episodes: 3,
        one_sigma: true,
        ..Default::default()
    };
    let fresh = tmp.path().join("fresh");
    let reference = collect(&reg, &runs, &fresh, &opts).unwrap();
    assert!(!reference.datasets.is_empty());
    let ids: Vec<&str> = reference
        .datasets
        .iter()
        .map(|d| d.dataset_id.as_str())
        .collect();

    // Interrupted during its first dataset's first episode: `Cancelled`, and neither a dataset
    // nor its stage is left; a stale stage from a killed attempt is replaced, not trusted.
    let out = tmp.path().join("out");
    for id in &ids {
        std::fs::create_dir_all(out.join(format!(".{id}.partial"))).unwrap();
        std::fs::write(out.join(format!(".{id}.partial/stale.txt")), b"old").unwrap();
    }
    let evaluated: usize = runs.iter().map(|r| checkpoints(r).unwrap().len()).sum();
    let token = a2perf_pipeline::CancelToken::new();
    let mut cancelling = CancelAt {
        inner: a2perf_pipeline::RegistryPolicies(&reg),
        calls: 0,
        after: evaluated,
        token: token.clone(),
    };
    let cancelled = CollectOptions {
        cancel: token,
        ..opts.clone()
    };
    let err = collect_with(&reg, &runs, &out, &mut cancelling, &cancelled).unwrap_err();
    assert!(
        matches!(err, a2perf_pipeline::PipelineError::Cancelled),
        "{err}"
    );
    assert!(
        cancelling.calls > evaluated,
        "the dataset phase was reached"
    );
    let left: Vec<_> = std::fs::read_dir(&out)
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .filter(|n| ids.iter().any(|id| n.to_string_lossy().contains(id)))
        .collect();
    assert_eq!(
        left.len(),
        ids.len() - 1,
        "only the untouched stales: {left:?}"
    );
    assert!(!out.join(ids[0]).exists());

    // Collected again: the same samples as a collection never interrupted, no stage left.
    let again = collect(&reg, &runs, &out, &opts).unwrap();
    assert_eq!(again.datasets.len(), reference.datasets.len());
    for id in &ids {
        let a = std::fs::read(fresh.join(id).join("samples.json")).unwrap();
        let b = std::fs::read(out.join(id).join("samples.json")).unwrap();
        assert!(a == b, "{id}: samples differ after the interruption");
        assert!(!out.join(format!(".{id}.partial")).exists());
    }

    // A directory in a dataset's place that `collect` did not finish is never overwritten.
    let foreign = tmp.path().join("foreign");
    std::fs::create_dir_all(foreign.join(ids[0])).unwrap();
    std::fs::write(foreign.join(ids[0]).join("precious.txt"), b"keep").unwrap();
    let err = collect(&reg, &runs, &foreign, &opts)
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("refusing to overwrite") && err.contains(ids[0]),
        "{err}"
    );
    assert!(foreign.join(ids[0]).join("precious.txt").is_file());
}
