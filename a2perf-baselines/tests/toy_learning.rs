//! The algorithms learn small toy tasks, deterministically.

mod common;

use std::sync::Arc;

use a2perf_baselines::Bc;
use a2perf_baselines::dataset::{Dataset, Sample};
use a2perf_core::{ActMode, Action, Env, Policy, RandomPolicy, TrainingSettings, Value};
use common::*;

fn settings(total: u64, num_envs: usize) -> TrainingSettings {
    TrainingSettings {
        total_env_steps: total,
        eval_interval: total / 4,
        eval_episodes: 8,
        checkpoint_interval: 0,
        num_envs,
    }
}

fn bandit_success(policy: &mut dyn Policy) -> f64 {
    let mut env = MaskedBandit::new();
    mean_return(&mut env, policy, 40)
}

#[test]
fn ppo_learns_masked_bandit() {
    let mut alg = make_alg(
        "ppo",
        &[
            ("learning_rate", Value::Float(3e-3)),
            ("num_steps", Value::Int(32)),
            ("minibatch_size", Value::Int(32)),
            ("hidden_sizes", ints(&[16])),
        ],
    );
    let (mut policy, curve) = train(
        alg.as_mut(),
        || Box::new(MaskedBandit::new()),
        1,
        settings(3000, 2),
    );
    let s = bandit_success(policy.as_mut());
    assert!(s >= 0.95, "greedy success {s}, curve {:?}", curve.returns());
}

#[test]
fn ddqn_learns_masked_bandit() {
    let mut alg = make_alg(
        "ddqn",
        &[
            ("learning_rate", Value::Float(3e-3)),
            ("batch_size", Value::Int(32)),
            ("learning_starts", Value::Int(64)),
            ("updates_per_step", Value::Float(0.5)),
            ("target_update_period", Value::Int(20)),
            ("hidden_sizes", ints(&[16])),
        ],
    );
    let (mut policy, curve) = train(
        alg.as_mut(),
        || Box::new(MaskedBandit::new()),
        2,
        settings(1500, 2),
    );
    let s = bandit_success(policy.as_mut());
    assert!(s >= 0.95, "greedy success {s}, curve {:?}", curve.returns());
}

#[test]
fn ppo_and_ddqn_solve_gridworld() {
    let optimal = 1.0 - 0.01 * 5.0;
    let mut ppo = make_alg(
        "ppo",
        &[
            ("learning_rate", Value::Float(3e-3)),
            ("num_steps", Value::Int(64)),
            ("hidden_sizes", ints(&[32])),
            ("gamma", Value::Float(0.95)),
        ],
    );
    let (mut p, curve) = train(
        ppo.as_mut(),
        || Box::new(Grid::new()),
        3,
        settings(12_000, 2),
    );
    let r = mean_return(&mut Grid::new(), p.as_mut(), 1);
    assert!(
        (r - optimal).abs() < 1e-9,
        "PPO return {r}, curve {:?}",
        curve.returns()
    );

    let mut ddqn = make_alg(
        "ddqn",
        &[
            ("learning_rate", Value::Float(2e-3)),
            ("batch_size", Value::Int(32)),
            ("learning_starts", Value::Int(200)),
            ("updates_per_step", Value::Float(0.5)),
            ("target_update_period", Value::Int(50)),
            ("epsilon_greedy", Value::Float(0.1)),
            ("epsilon_decay_fraction", Value::Float(0.5)),
            ("gamma", Value::Float(0.95)),
            ("hidden_sizes", ints(&[32])),
        ],
    );
    let (mut q, curve) = train(
        ddqn.as_mut(),
        || Box::new(Grid::new()),
        4,
        settings(8_000, 2),
    );
    let r = mean_return(&mut Grid::new(), q.as_mut(), 1);
    assert!(
        (r - optimal).abs() < 1e-9,
        "DDQN return {r}, curve {:?}",
        curve.returns()
    );
}

fn point_baseline() -> f64 {
    // The untrained (zero-mean) policy leaves x where it starts.
    struct Zero;
    impl Policy for Zero {
        fn act(
            &mut self,
            _o: &a2perf_core::Observation,
            _m: ActMode,
        ) -> Result<Action, a2perf_core::PolicyError> {
            Ok(Action::Continuous(vec![0.0]))
        }
        fn checkpoint(&self) -> Result<a2perf_core::Checkpoint, a2perf_core::PolicyError> {
            Err(a2perf_core::PolicyError::BadCheckpoint("none".into()))
        }
    }
    mean_return(&mut Point::new(), &mut Zero, 40)
}

#[test]
fn ppo_improves_continuous_point() {
    let base = point_baseline();
    let mut alg = make_alg(
        "ppo",
        &[
            ("learning_rate", Value::Float(3e-3)),
            ("num_steps", Value::Int(64)),
            ("hidden_sizes", ints(&[32])),
        ],
    );
    let (mut p, curve) = train(
        alg.as_mut(),
        || Box::new(Point::new()),
        5,
        settings(20_000, 2),
    );
    let r = mean_return(&mut Point::new(), p.as_mut(), 40);
    assert!(
        r > 0.5 * base,
        "PPO {r} vs zero-action {base}; curve {:?}",
        curve.returns()
    );
}

#[test]
fn sac_improves_continuous_point() {
    let base = point_baseline();
    // With raw observations and with running observation normalisation.
    for normalize in [false, true] {
        let mut alg = make_alg(
            "sac",
            &[
                ("learning_rate", Value::Float(1e-3)),
                ("batch_size", Value::Int(64)),
                ("learning_starts", Value::Int(200)),
                ("init_alpha", Value::Float(0.1)),
                ("hidden_sizes", ints(&[32, 32])),
                ("normalize_observations", Value::Bool(normalize)),
            ],
        );
        let (mut p, curve) = train(
            alg.as_mut(),
            || Box::new(Point::new()),
            6,
            settings(2_500, 1),
        );
        let r = mean_return(&mut Point::new(), p.as_mut(), 40);
        assert!(
            r > 0.5 * base,
            "SAC (normalize_observations {normalize}) {r} vs zero-action {base}; curve {:?}",
            curve.returns()
        );
    }
}

#[test]
fn ppo_keeps_a_fixed_log_std_when_asked() {
    let log_stds = |learn: bool| {
        let mut alg = make_alg(
            "ppo",
            &[
                ("learning_rate", Value::Float(3e-3)),
                ("num_steps", Value::Int(64)),
                ("hidden_sizes", ints(&[8])),
                ("init_log_std", Value::Float(-1.25)),
                ("learn_log_std", Value::Bool(learn)),
            ],
        );
        let (p, _) = train(
            alg.as_mut(),
            || Box::new(Point::new()),
            5,
            settings(1_000, 2),
        );
        let ckpt = p.checkpoint().unwrap();
        let policy =
            a2perf_baselines::NetPolicy::from_checkpoint(&ckpt, Point::new().spec(), "ppo")
                .unwrap();
        match &policy.head {
            a2perf_baselines::policy::Head::Gaussian(g) => {
                policy.params[g.log_std..g.log_std + g.act_dim].to_vec()
            }
            _ => panic!("PPO on a box action space has a Gaussian head"),
        }
    };
    assert!(log_stds(false).iter().all(|s| *s == -1.25));
    assert!(log_stds(true).iter().any(|s| *s != -1.25));
}

fn bandit_oracle_dataset(n: usize) -> Dataset {
    let mut env = MaskedBandit::new();
    let mut samples = Vec::new();
    for i in 0..n {
        let obs = env.reset(Some(i as u64)).unwrap();
        let ctx = obs.tensors[0]
            .data
            .as_f32()
            .unwrap()
            .iter()
            .position(|v| *v > 0.5)
            .unwrap();
        samples.push(Sample {
            observation: obs,
            action: Action::Discrete(MaskedBandit::best(ctx)),
        });
    }
    Dataset {
        env_id: Some("MaskedBandit-v0".into()),
        samples,
    }
}

#[test]
fn bc_clones_discrete_and_continuous_experts() {
    let data = bandit_oracle_dataset(64);
    let bc = Bc::from_params(
        &a2perf_core::Params::resolve(
            &Bc::params(),
            &[
                ("learning_rate".to_string(), Value::Float(3e-3)),
                ("batch_size".to_string(), Value::Int(32)),
                ("hidden_sizes".to_string(), ints(&[16])),
            ]
            .into_iter()
            .collect(),
        )
        .unwrap(),
    )
    .unwrap();
    let mut bc = bc.with_loader(Arc::new(data));
    let (mut p, _) = train(
        &mut bc,
        || Box::new(MaskedBandit::new()),
        7,
        settings(32 * 300, 1),
    );
    assert!(bandit_success(p.as_mut()) >= 0.99);

    // Continuous expert on the point task: a = clamp(−4x).
    let mut env = Point::new();
    let mut samples = Vec::new();
    for i in 0..200 {
        let obs = env.reset(Some(i)).unwrap();
        let x = obs.tensors[0].data.as_f32().unwrap()[0];
        samples.push(Sample {
            observation: obs,
            action: Action::Continuous(vec![(-4.0 * x).clamp(-1.0, 1.0)]),
        });
    }
    for loss in ["nll", "mse"] {
        let bc = Bc::from_params(
            &a2perf_core::Params::resolve(
                &Bc::params(),
                &[
                    ("learning_rate".to_string(), Value::Float(3e-3)),
                    ("loss".to_string(), Value::Str(loss.into())),
                    ("hidden_sizes".to_string(), ints(&[32])),
                ]
                .into_iter()
                .collect(),
            )
            .unwrap(),
        )
        .unwrap();
        let mut bc = bc.with_loader(Arc::new(Dataset {
            env_id: None,
            samples: samples.clone(),
        }));
        let (mut p, _) = train(
            &mut bc,
            || Box::new(Point::new()),
            8,
            settings(128 * 400, 1),
        );
        let r = mean_return(&mut Point::new(), p.as_mut(), 40);
        assert!(r > 0.5 * point_baseline(), "BC ({loss}) return {r}");
    }
}

#[test]
fn bc_without_dataset_is_a_clear_error() {
    let mut alg = make_alg("bc", &[]);
    let factory = |_i: usize| -> Result<Box<dyn Env>, a2perf_core::EnvError> {
        Ok(Box::new(MaskedBandit::new()))
    };
    let mut sink = a2perf_core::DiscardCheckpoints;
    let mut ctx = a2perf_core::TrainingContext::new(
        &factory,
        0,
        settings(100, 1),
        &mut sink,
        a2perf_core::CancelToken::new(),
    );
    let err = alg.train(&mut ctx).err().expect("must fail");
    assert!(err.to_string().contains("dataset"), "{err}");
}

#[test]
fn same_seed_gives_same_curve_and_parallel_envs_are_deterministic() {
    for name in ["ppo", "ddqn"] {
        let run = |seed| {
            let mut alg = make_alg(
                name,
                &[
                    ("hidden_sizes", ints(&[8])),
                    ("learning_starts", Value::Int(16)),
                ]
                .iter()
                .filter(|(k, _)| name == "ddqn" || *k != "learning_starts")
                .cloned()
                .collect::<Vec<_>>(),
            );
            let (p, curve) = train(
                alg.as_mut(),
                || Box::new(MaskedBandit::new()),
                seed,
                settings(800, 3),
            );
            (curve.returns(), p.checkpoint().unwrap())
        };
        let (a, ca) = run(11);
        let (b, cb) = run(11);
        assert_eq!(a, b, "{name}: curves differ for the same seed");
        assert_eq!(ca, cb, "{name}: parameters differ for the same seed");
        let (c, cc) = run(12);
        assert!(
            a != c || ca != cc,
            "{name}: different seeds gave identical runs"
        );
    }
    let sac = || {
        make_alg(
            "sac",
            &[
                ("hidden_sizes", ints(&[8])),
                ("learning_starts", Value::Int(50)),
                ("batch_size", Value::Int(16)),
            ],
        )
    };
    let (_, a) = train(
        sac().as_mut(),
        || Box::new(Point::new()),
        3,
        settings(200, 2),
    );
    let (_, b) = train(
        sac().as_mut(),
        || Box::new(Point::new()),
        3,
        settings(200, 2),
    );
    assert_eq!(a.returns(), b.returns());
}

#[test]
fn cancellation_is_honoured() {
    let mut alg = make_alg("ppo", &[("hidden_sizes", ints(&[8]))]);
    let factory = |_i: usize| -> Result<Box<dyn Env>, a2perf_core::EnvError> {
        Ok(Box::new(MaskedBandit::new()))
    };
    let mut sink = a2perf_core::DiscardCheckpoints;
    let cancel = a2perf_core::CancelToken::new();
    cancel.cancel();
    let mut ctx =
        a2perf_core::TrainingContext::new(&factory, 0, settings(100_000, 1), &mut sink, cancel);
    assert!(matches!(
        alg.train(&mut ctx),
        Err(a2perf_core::RunError::Cancelled)
    ));
}

#[test]
fn random_policy_is_worse_than_trained_bandit_policy() {
    // Sanity of the success measure itself: a random legal policy scores about 1/4.
    let mut rp = RandomPolicy::new(a2perf_core::Space::Discrete { n: 6 }, 0);
    let mut env = MaskedBandit::new();
    let mut total = 0.0;
    for i in 0..400 {
        total += a2perf_core::rollout(&mut env, &mut rp, i, ActMode::Explore, false)
            .unwrap()
            .episode_return;
    }
    let s = total / 400.0;
    assert!((0.15..0.35).contains(&s), "{s}");
}

/// Every online algorithm times its acting, stepping and learning into the context's split
/// (issue 38), and the parts stay within the run's wall clock.
#[test]
fn online_algorithms_time_their_parts() {
    use a2perf_core::{CancelToken, DiscardCheckpoints, EnvError, TrainingContext};
    for name in ["ppo", "ddqn"] {
        let mut alg = make_alg(
            name,
            &[
                ("hidden_sizes", ints(&[16])),
                ("learning_starts", Value::Int(16)),
            ]
            .into_iter()
            .filter(|(k, _)| name == "ddqn" || *k != "learning_starts")
            .collect::<Vec<_>>(),
        );
        let factory =
            |_i: usize| -> Result<Box<dyn Env>, EnvError> { Ok(Box::new(MaskedBandit::new())) };
        let mut sink = DiscardCheckpoints;
        let mut ctx =
            TrainingContext::new(&factory, 0, settings(512, 2), &mut sink, CancelToken::new());
        let started = std::time::Instant::now();
        alg.train(&mut ctx).expect("training failed");
        let wall = started.elapsed().as_secs_f64();
        let t = *ctx.time_split();
        for (part, x) in t.parts() {
            if part != "io" {
                assert!(x > 0.0, "{name}: {part} not timed: {t:?}");
            }
        }
        assert!(t.total() <= wall, "{name}: {t:?} over {wall} s");
    }
}
