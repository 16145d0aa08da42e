//! Bundles end to end: a built-in run trained, rolled out and generalized records its episodes;
//! its bundle verifies (replays, statistics, checkpoint re-run, retraining); and a bundle whose
//! return, action, seed or checkpoint was changed — with a manifest made to match — fails at
//! the first difference.

use std::path::{Path, PathBuf};

use a2perf_core::replay::{ActionLog, EpisodeLog};
use a2perf_pipeline::bundle::{
    Archive, ArchiveLimits, Bundle, BundleError, Outcome, Verification, VerifyOptions, pack,
};
use a2perf_pipeline::run_dir::{
    INFERENCE_EPISODES_FILE, INFERENCE_FILE, InferenceResults, generalization_episodes_file,
};
use a2perf_pipeline::{InferOptions, TrainOptions};

/// A complete DDQN run on the small synthetic netlist with tiny budgets, rolled out and
/// generalized, in `out`; returns its directory.
fn tiny_run(out: &Path, seed: u64) -> PathBuf {
    let reg = a2perf_pipeline::registry::full_registry();
    let config = Path::new(env!("CARGO_MANIFEST_DIR")).join("../configs/circuit_training/ddqn.ron");
    let sets: Vec<String> = [
        format!("output.dir={}", out.display()),
        "training.total_env_steps=480".into(),
        "training.eval_interval=240".into(),
        "training.num_envs=2".into(),
        "algorithm.learning_starts=96".into(),
        "inference.rollouts=4".into(),
        "generalization.episodes=2".into(),
    ]
    .into();
    let loaded = a2perf_pipeline::load_plans(&[config], &sets, Some(&[seed]), &reg).unwrap();
    let plan = &loaded.plans[0];
    let jobs = a2perf_pipeline::grid(std::slice::from_ref(plan), None);
    a2perf_pipeline::train(&reg, &jobs, &TrainOptions::default()).unwrap();
    let dir = plan.run_dir(seed);
    a2perf_pipeline::infer_run(&reg, &dir, &InferOptions::default()).unwrap();
    a2perf_pipeline::generalize_run(&reg, &dir, None, false).unwrap();
    dir
}

fn verify(archive: Archive, retrain: bool) -> Verification {
    let reg = a2perf_pipeline::registry::full_registry();
    Bundle::from_archive(Path::new("test.a2perf"), archive)
        .unwrap()
        .verify(&reg, &VerifyOptions { retrain })
}

/// The text of the one failed check called `what`.
fn failure(v: &Verification, what: &str) -> String {
    let failed: Vec<_> = v.failures().collect();
    assert_eq!(failed.len(), 1, "{failed:#?}");
    assert!(failed[0].what.starts_with(what), "{:?}", failed[0]);
    match &failed[0].outcome {
        Outcome::Fails(d) => d.clone(),
        o => panic!("{o:?}"),
    }
}

/// `a` with member `name` decoded, changed by `f` and encoded again (the manifest follows, as
/// a forger's would).
fn edited<T: serde::de::DeserializeOwned + serde::Serialize>(
    a: &Archive,
    name: &str,
    f: impl FnOnce(&mut T),
) -> Archive {
    let mut value: T = serde_json::from_slice(a.get(name).unwrap()).unwrap();
    f(&mut value);
    let mut a = a.clone();
    a.insert(name, serde_json::to_vec(&value).unwrap()).unwrap();
    a
}

/// Moves the discrete action at (`episode`, `step`) of log member `name` by `by` cells.
fn shift_action(a: &Archive, name: &str, episode: usize, step: usize, by: usize) -> Archive {
    edited(a, name, |logs: &mut Vec<EpisodeLog>| {
        let ActionLog::Discrete(acts) = &mut logs[episode].actions else {
            panic!("circuit actions are discrete");
        };
        acts[step] = (acts[step] + by) % 256;
    })
}

#[test]
fn a_bundle_verifies_and_every_edit_is_found() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tiny_run(tmp.path(), 0);
    // The episode logs sit beside the results they prove.
    let logs: Vec<EpisodeLog> =
        serde_json::from_slice(&std::fs::read(dir.join(INFERENCE_EPISODES_FILE)).unwrap()).unwrap();
    let results: InferenceResults =
        serde_json::from_slice(&std::fs::read(dir.join(INFERENCE_FILE)).unwrap()).unwrap();
    assert_eq!(logs.len(), 4);
    for (log, ret) in logs.iter().zip(&results.rollout_returns) {
        assert_eq!(log.logged_return().to_bits(), ret.to_bits());
    }
    assert!(
        dir.join(generalization_episodes_file("small_seed1"))
            .is_file()
    );

    let reg = a2perf_pipeline::registry::full_registry();
    let file = tmp.path().join("run.a2perf");
    let summary = pack(&reg, &[tmp.path().join("circuit_ddqn")], &file).unwrap();
    assert_eq!(summary.info.runs.len(), 1);
    let bundle = Bundle::read(&file, &ArchiveLimits::default()).unwrap();
    let folder = bundle.runs()[0].clone();
    let member = |rel: &str| format!("{folder}/{rel}");
    for rel in [
        "run.json",
        "policy.ckpt",
        "env_identity.json",
        "operative_config.ron",
    ] {
        assert!(bundle.archive().get(&member(rel)).is_some(), "{rel}");
    }
    // Packing is deterministic.
    let again = tmp.path().join("again.a2perf");
    pack(&reg, std::slice::from_ref(&dir), &again).unwrap();
    assert_eq!(
        std::fs::read(&file).unwrap(),
        std::fs::read(&again).unwrap()
    );

    let honest = verify(bundle.archive().clone(), true);
    assert!(honest.holds(), "{:#?}", honest.checks);
    let held: Vec<&str> = honest.checks.iter().map(|c| c.what.as_str()).collect();
    for what in [
        "manifest",
        "environment identity",
        "inference returns (replayed)",
        "generalization returns (replayed)",
        "checkpoint re-run (greedy actions)",
        "retrain (final policy byte-identical)",
    ] {
        assert!(held.contains(&what), "{what} not checked: {held:?}");
    }
    assert!(
        honest
            .checks
            .iter()
            .all(|c| matches!(c.outcome, Outcome::Holds(_)))
    );

    // A return edited, the stated mean edited, one action changed, a chosen seed instead of
    // the run's seed stream, a generalization episode's action changed: each is found.
    let inference = member(INFERENCE_FILE);
    let logs = member(INFERENCE_EPISODES_FILE);
    let generalization = member(&generalization_episodes_file("medium_seed2"));
    let cases = [
        (
            edited(bundle.archive(), &inference, |r: &mut InferenceResults| {
                r.rollout_returns[2] += 0.01
            }),
            "inference returns",
            "episode 2: return",
        ),
        (
            edited(bundle.archive(), &inference, |r: &mut InferenceResults| {
                r.returns.mean += 0.5
            }),
            "inference returns",
            "summary",
        ),
        // Another cell of the 16x16 grid for the last macro: legal unless occupied.
        (
            shift_action(bundle.archive(), &logs, 1, 11, 17),
            "inference returns",
            "episode 1",
        ),
        (
            edited(bundle.archive(), &logs, |l: &mut Vec<EpisodeLog>| {
                l[3].seed ^= 1
            }),
            "inference returns",
            "episode 3: reset seed",
        ),
        (
            shift_action(bundle.archive(), &generalization, 0, 0, 1),
            "generalization returns",
            "task medium_seed2: episode 0",
        ),
    ];
    for (archive, what, says) in cases {
        let why = failure(&verify(archive, false), what);
        assert!(why.contains(says), "{why}");
    }

    // Another run's checkpoint swapped in: the returns replay, the actions are not its own.
    let other = tempfile::tempdir().unwrap();
    let other_dir = tiny_run(other.path(), 1);
    let mut a = bundle.archive().clone();
    a.insert(
        &member("policy.ckpt"),
        std::fs::read(other_dir.join("policy.ckpt")).unwrap(),
    )
    .unwrap();
    let why = failure(&verify(a, false), "checkpoint re-run");
    assert!(why.contains("action: expected"), "{why}");

    // A missing log.
    let mut b = Archive::default();
    for (name, bytes) in bundle.archive().iter() {
        if name != member(INFERENCE_EPISODES_FILE) {
            b.insert(name, bytes.to_vec()).unwrap();
        }
    }
    let why = failure(&verify(b, false), "inference returns");
    assert!(why.contains("no episode log"), "{why}");
}

#[test]
fn runs_without_logs_or_run_files_are_refused() {
    let tmp = tempfile::tempdir().unwrap();
    let reg = a2perf_pipeline::registry::full_registry();
    assert!(matches!(
        pack(
            &reg,
            &[tmp.path().to_path_buf()],
            &tmp.path().join("x.a2perf")
        ),
        Err(BundleError::Pipeline(_))
    ));
    let empty = Archive::default();
    assert!(matches!(
        Bundle::from_archive(Path::new("e.a2perf"), empty),
        Err(BundleError::Invalid(_))
    ));
}
