//! Resumption: a training sweep interrupted mid-way (cancel token, as Ctrl-C) and rerun gives the
//! same results as an uninterrupted sweep, without redoing finished seeds.

mod common;

use std::sync::Arc;
use std::sync::atomic::{AtomicUsize, Ordering};

use a2perf_core::LearningCurve;
use a2perf_pipeline::{CancelToken, RunOutcome, TrainOptions};

fn curve(dir: &std::path::Path) -> Vec<(u64, f64)> {
    let c: LearningCurve =
        serde_json::from_slice(&std::fs::read(dir.join("curve.json")).unwrap()).unwrap();
    c.returns()
}

#[test]
fn interrupted_sweep_resumes_to_the_uninterrupted_result() {
    let reg = common::registry();
    let clean_dir = tempfile::tempdir().unwrap();
    let clean = common::plan(clean_dir.path(), "exp", vec![0, 1, 2]);
    let s = a2perf_pipeline::train(
        &reg,
        &a2perf_pipeline::grid(std::slice::from_ref(&clean), None),
        &TrainOptions::default(),
    )
    .unwrap();
    assert_eq!(s.with(&RunOutcome::Completed).len(), 3);

    // Interrupted: the token is cancelled as the second run starts (its meters are built), so
    // the first run finishes, the second stops at its first progress call, the third never starts.
    let tmp = tempfile::tempdir().unwrap();
    let plan = common::plan(tmp.path(), "exp", vec![0, 1, 2]);
    let cancel = CancelToken::new();
    let starts = Arc::new(AtomicUsize::new(0));
    let (c, n) = (cancel.clone(), starts.clone());
    let opts = TrainOptions {
        jobs: 1,
        cancel: cancel.clone(),
        meters: Arc::new(move |_, _, _| {
            if n.fetch_add(1, Ordering::SeqCst) == 1 {
                c.cancel();
            }
            Vec::new()
        }),
        show_progress: false,
    };
    let jobs = a2perf_pipeline::grid(std::slice::from_ref(&plan), None);
    let s = a2perf_pipeline::train(&reg, &jobs, &opts).unwrap();
    assert_eq!(
        s.runs.iter().map(|(_, o)| o.clone()).collect::<Vec<_>>(),
        vec![
            RunOutcome::Completed,
            RunOutcome::Cancelled,
            RunOutcome::Cancelled
        ]
    );
    let finished = std::fs::read(plan.run_dir(0).join("policy.ckpt")).unwrap();
    let finished_time = std::fs::metadata(plan.run_dir(0).join("status.json"))
        .unwrap()
        .modified()
        .unwrap();
    assert!(plan.run_dir(1).join("status.json").is_file());
    assert!(!plan.run_dir(1).join("policy.ckpt").exists());
    // A stale file in the interrupted run must not survive the redo.
    std::fs::write(plan.run_dir(1).join("checkpoints_stale.txt"), b"x").unwrap();

    let s = a2perf_pipeline::train(&reg, &jobs, &TrainOptions::default()).unwrap();
    assert_eq!(
        s.runs.iter().map(|(_, o)| o.clone()).collect::<Vec<_>>(),
        vec![
            RunOutcome::Skipped,
            RunOutcome::Completed,
            RunOutcome::Completed
        ]
    );
    assert_eq!(
        std::fs::read(plan.run_dir(0).join("policy.ckpt")).unwrap(),
        finished
    );
    assert_eq!(
        std::fs::metadata(plan.run_dir(0).join("status.json"))
            .unwrap()
            .modified()
            .unwrap(),
        finished_time,
        "the finished seed was not touched"
    );
    assert!(!plan.run_dir(1).join("checkpoints_stale.txt").exists());
    for seed in 0..3 {
        assert_eq!(
            curve(&plan.run_dir(seed)),
            curve(&clean.run_dir(seed)),
            "seed {seed}"
        );
        assert_eq!(
            std::fs::read(plan.run_dir(seed).join("policy.ckpt")).unwrap(),
            std::fs::read(clean.run_dir(seed).join("policy.ckpt")).unwrap(),
            "seed {seed}"
        );
    }

    // A third invocation does nothing.
    let s = a2perf_pipeline::train(&reg, &jobs, &TrainOptions::default()).unwrap();
    assert_eq!(s.with(&RunOutcome::Skipped).len(), 3);
}

#[test]
fn shards_cover_the_grid_and_parallel_runs_match_sequential_ones() {
    let reg = common::registry();
    let tmp = tempfile::tempdir().unwrap();
    let plan = common::plan(tmp.path(), "exp", vec![0, 1, 2, 3]);
    for i in 0..2 {
        let shard = a2perf_pipeline::Shard::new(i, 2).unwrap();
        let jobs = a2perf_pipeline::grid(std::slice::from_ref(&plan), Some(shard));
        assert_eq!(jobs.len(), 2);
        let opts = TrainOptions {
            jobs: 2,
            ..Default::default()
        };
        a2perf_pipeline::train(&reg, &jobs, &opts).unwrap();
    }
    let seq = tempfile::tempdir().unwrap();
    let seq_plan = common::plan(seq.path(), "exp", vec![0, 1, 2, 3]);
    a2perf_pipeline::train(
        &reg,
        &a2perf_pipeline::grid(std::slice::from_ref(&seq_plan), None),
        &TrainOptions::default(),
    )
    .unwrap();
    for seed in 0..4 {
        assert_eq!(curve(&plan.run_dir(seed)), curve(&seq_plan.run_dir(seed)));
    }
}
