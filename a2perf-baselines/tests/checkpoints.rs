//! Checkpoints round-trip bit-exactly and bad payloads are rejected with clear errors; taking
//! them (and evaluating) does not change what is trained.

mod common;

use a2perf_baselines::NetPolicy;
use a2perf_core::{ActMode, Checkpoint, Env, Policy, Registry, TrainingSettings, Value};
use common::*;

fn settings() -> TrainingSettings {
    TrainingSettings {
        total_env_steps: 300,
        eval_interval: 0,
        eval_episodes: 2,
        checkpoint_interval: 0,
        num_envs: 2,
    }
}

fn registry() -> Registry {
    let mut reg = Registry::new();
    a2perf_baselines::register(&mut reg);
    reg
}

fn trained(name: &str, continuous: bool) -> (Box<dyn Policy>, a2perf_core::EnvSpec) {
    trained_with(name, continuous, &[])
}

fn trained_with(
    name: &str,
    continuous: bool,
    extra: &[(&'static str, Value)],
) -> (Box<dyn Policy>, a2perf_core::EnvSpec) {
    let mut alg = make_alg(name, &hyperparameters(extra));
    let (p, _) = train(alg.as_mut(), move || test_env(continuous), 1, settings());
    (p, test_env(continuous).spec().clone())
}

/// The continuous (`Point`) or discrete (`MaskedBandit`) test environment.
fn test_env(continuous: bool) -> Box<dyn Env> {
    if continuous {
        Box::new(Point::new())
    } else {
        Box::new(MaskedBandit::new())
    }
}

/// A small network, with `extra` hyperparameters.
fn hyperparameters(extra: &[(&'static str, Value)]) -> Overrides {
    let mut hp = vec![("hidden_sizes", ints(&[8]))];
    hp.extend(extra.iter().cloned());
    hp
}

/// Extra hyperparameters, by name.
type Overrides = Vec<(&'static str, Value)>;

/// Every online algorithm, on the discrete (`false`) or continuous (`true`) test env, with extra
/// hyperparameters.
fn online_variants() -> Vec<(&'static str, bool, Overrides)> {
    let sac_norm = vec![("normalize_observations", Value::Bool(true))];
    vec![
        ("ppo", false, vec![]),
        ("ppo", true, vec![]),
        ("ddqn", false, vec![]),
        ("sac", true, vec![]),
        ("sac", true, sac_norm),
    ]
}

#[test]
fn round_trip_is_bit_exact_for_every_algorithm() {
    let reg = registry();
    for (name, continuous, extra) in online_variants() {
        let (mut policy, spec) = trained_with(name, continuous, &extra);
        let ckpt = policy.checkpoint().unwrap();
        let bytes = ckpt.to_bytes();
        let back = Checkpoint::from_bytes(&bytes).unwrap();
        let mut loaded = (reg.algorithm(name).unwrap().load_policy)(&back, &spec).unwrap();
        // Re-encoding the loaded policy gives the same bytes: parameters and statistics are exact.
        assert_eq!(loaded.checkpoint().unwrap().to_bytes(), bytes, "{name}");
        let mut env = test_env(continuous);
        let mut obs = env.reset(Some(3)).unwrap();
        for _ in 0..5 {
            let a = policy.act(&obs, ActMode::Greedy).unwrap();
            assert_eq!(a, loaded.act(&obs, ActMode::Greedy).unwrap(), "{name}");
            let s = env.step(&a).unwrap();
            obs = if s.done() {
                env.reset(None).unwrap()
            } else {
                s.observation
            };
        }
    }
}

#[test]
fn corrupt_and_mismatched_payloads_are_rejected() {
    let (policy, spec) = trained("ppo", false);
    let good = policy.checkpoint().unwrap();
    let load = |c: &Checkpoint, s: &a2perf_core::EnvSpec| {
        NetPolicy::from_checkpoint(c, s, "ppo")
            .map(|_| ())
            .unwrap_err()
            .to_string()
    };

    let mut c = good.clone();
    c.payload.truncate(c.payload.len() - 3);
    assert!(load(&c, &spec).contains("truncated"), "{}", load(&c, &spec));

    let mut c = good.clone();
    c.payload.push(0);
    assert!(load(&c, &spec).contains("trailing"));

    let mut c = good.clone();
    c.payload[0] = b'X';
    assert!(load(&c, &spec).contains("magic"));

    let mut c = good.clone();
    c.format_version = 99;
    assert!(load(&c, &spec).contains("version 99"));

    let mut c = good.clone();
    c.algorithm = "ddqn".into();
    assert!(load(&c, &spec).contains("written by `ddqn`"));

    let mut c = good.clone();
    c.payload[12] = b'#'; // inside the JSON header
    assert!(load(&c, &spec).contains("malformed header"));

    // A checkpoint for the bandit does not load on the gridworld.
    let other = Grid::new().spec().clone();
    assert!(load(&good, &other).contains("trained on observations"));

    // Non-finite parameters are refused.
    let mut c = good.clone();
    let n = c.payload.len();
    let hlen = u32::from_le_bytes(c.payload[8..12].try_into().unwrap()) as usize;
    let first_param = 12 + hlen + 8;
    c.payload[first_param..first_param + 4].copy_from_slice(&f32::NAN.to_le_bytes());
    assert!(n > first_param);
    assert!(load(&c, &spec).contains("non-finite"));

    // The container's checksum catches bit flips anywhere in the file.
    let mut bytes = good.to_bytes();
    let mid = bytes.len() / 2;
    bytes[mid] ^= 0x10;
    assert!(Checkpoint::from_bytes(&bytes).is_err());
}

#[test]
fn checkpoints_flow_through_the_training_context() {
    let dir = tempfile::tempdir().unwrap();
    let mut alg = make_alg(
        "ppo",
        &[("hidden_sizes", ints(&[8])), ("num_steps", Value::Int(16))],
    );
    let factory = |_i: usize| -> Result<Box<dyn Env>, a2perf_core::EnvError> {
        Ok(Box::new(MaskedBandit::new()))
    };
    let mut sink = a2perf_core::DirectoryCheckpoints::new(dir.path());
    let s = TrainingSettings {
        total_env_steps: 320,
        eval_interval: 64,
        eval_episodes: 2,
        checkpoint_interval: 100,
        num_envs: 2,
    };
    let mut ctx = a2perf_core::TrainingContext::new(
        &factory,
        0,
        s,
        &mut sink,
        a2perf_core::CancelToken::new(),
    );
    let _ = a2perf_core::Algorithm::train(alg.as_mut(), &mut ctx).unwrap();
    assert!(ctx.curve().points.len() >= 4);
    let files = std::fs::read_dir(dir.path()).unwrap().count();
    assert!(files >= 3, "{files} checkpoints");
}

/// Evaluations and checkpoints observe training and must not steer it: with the same seed, a run
/// that never evaluates or checkpoints and runs that do both, at different intervals, end with
/// byte-identical policies, for every online algorithm.
#[test]
fn training_does_not_depend_on_eval_or_checkpoint_intervals() {
    for (name, continuous, extra) in online_variants() {
        let hp = hyperparameters(&extra);
        let mut finals = Vec::new();
        for (eval, checkpoint) in [(0, 0), (64, 100), (37, 50)] {
            let dir = tempfile::tempdir().unwrap();
            let mut sink = a2perf_core::DirectoryCheckpoints::new(dir.path());
            let factory = move |_i: usize| -> Result<Box<dyn Env>, a2perf_core::EnvError> {
                Ok(test_env(continuous))
            };
            let s = TrainingSettings {
                eval_interval: eval,
                checkpoint_interval: checkpoint,
                ..settings()
            };
            let mut ctx = a2perf_core::TrainingContext::new(
                &factory,
                1,
                s,
                &mut sink,
                a2perf_core::CancelToken::new(),
            );
            let policy =
                a2perf_core::Algorithm::train(make_alg(name, &hp).as_mut(), &mut ctx).unwrap();
            // The observers did run: beyond the final evaluation and checkpoint that every run
            // takes, there are interval ones exactly when intervals are set.
            let points = ctx.curve().points.len();
            assert_eq!(points > 1, eval > 0, "{name}: {points} curve points");
            let files = std::fs::read_dir(dir.path()).unwrap().count();
            assert_eq!(
                files > 1,
                checkpoint > 0,
                "{name}: {files} checkpoint files"
            );
            finals.push(policy.checkpoint().unwrap().to_bytes());
        }
        assert!(
            finals.windows(2).all(|w| w[0] == w[1]),
            "{name} (continuous: {continuous}, {extra:?}): the trained policy changed with the eval or checkpoint interval"
        );
    }
}

/// The trained policies' bytes, pinned: a refactoring of the algorithms must keep every
/// floating-point operation and its order, so these fingerprints must not move. They were
/// computed from the code at commit 9603bb3, before the training loops were split into named
/// steps (issue 35); `resume.rs` pins the domain runs the same way.
#[test]
fn trained_policies_match_the_pinned_fingerprints() {
    let pinned: [u64; 5] = [
        0xae30_2762_6c0b_acea,
        0x5736_cc0b_1664_d8f1,
        0x6b8b_bbdb_2420_7c4c,
        0x4675_813f_bc79_eb02,
        0xa8a0_743e_bee4_1ff5,
    ];
    let got: Vec<u64> = online_variants()
        .into_iter()
        .map(|(name, continuous, extra)| {
            let (policy, _) = trained_with(name, continuous, &extra);
            fingerprint([policy.checkpoint().unwrap().to_bytes().as_slice()])
        })
        .collect();
    println!("fingerprints: {got:#018x?}");
    if reproduces_pinned_bits("trained_policies_match_the_pinned_fingerprints") {
        assert_eq!(got, pinned, "{:?}", online_variants());
    }
}
