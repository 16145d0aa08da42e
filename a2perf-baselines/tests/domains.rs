//! Learning tests on the real domains (release builds only: `cargo test --release`).
//!
//! Each test uses fixed seeds and a budget that finishes well under a minute on one core; in debug
//! builds they print why they are skipped.

mod common;

use std::collections::BTreeMap;
use std::sync::Arc;

use a2perf_baselines::Bc;
use a2perf_baselines::dataset::{Dataset, Sample};
use a2perf_core::{
    ActMode, Action, Algorithm, CancelToken, DiscardCheckpoints, Env, EnvError, Params, Policy,
    RandomPolicy, Registry, Step, TrainingContext, TrainingSettings, Value,
};
use common::{domains_registry, env_params, ints, skip_in_debug};

fn train_on(
    reg: &Registry,
    alg: &mut dyn Algorithm,
    env_id: &str,
    params: &BTreeMap<String, Value>,
    seed: u64,
    settings: TrainingSettings,
) -> (Box<dyn Policy>, a2perf_core::LearningCurve) {
    let reg2 = reg.clone();
    let id = env_id.to_string();
    let p = params.clone();
    let factory = move |_i: usize| -> Result<Box<dyn Env>, EnvError> {
        reg2.make_env(&id, &p)
            .map_err(|e| EnvError::Backend(e.to_string()))
    };
    let mut sink = DiscardCheckpoints;
    let mut ctx = TrainingContext::new(&factory, seed, settings, &mut sink, CancelToken::new());
    let policy = alg.train(&mut ctx).expect("training");
    let curve = ctx.take_curve();
    (policy, curve)
}

fn make(reg: &Registry, name: &str, hp: &[(&str, Value)]) -> Box<dyn Algorithm> {
    reg.make_algorithm(name, &env_params(hp))
        .expect("hyperparameters")
}

/// Runs one episode; returns (return, final info "success", final info "proxy").
fn episode(
    env: &mut dyn Env,
    policy: &mut dyn Policy,
    seed: u64,
    mode: ActMode,
) -> (f64, f64, Option<f64>) {
    let limit = env.spec().max_episode_steps.unwrap_or(10_000);
    let mut step = Step::default();
    env.reset_into(Some(seed), &mut step.observation)
        .expect("reset");
    let mut ret = 0.0;
    for _ in 0..limit {
        let a = policy.act(&step.observation, mode).expect("act");
        env.step_into(&a, &mut step).expect("step");
        ret += step.reward;
        if step.done() {
            break;
        }
    }
    (
        ret,
        step.info.get("success").unwrap_or(0.0),
        step.info.get("proxy"),
    )
}

// ---------------------------------------------------------------- web navigation

const WEB: &str = "WebNavigation-Difficulty-01-v0";

fn web_params() -> BTreeMap<String, Value> {
    env_params(&[("num_websites", Value::Int(1))])
}

fn web_success(reg: &Registry, policy: &mut dyn Policy, episodes: u64) -> f64 {
    let mut env = reg.make_env(WEB, &web_params()).unwrap();
    (0..episodes)
        .map(|s| episode(env.as_mut(), policy, 50_000 + s, ActMode::Greedy).1)
        .sum::<f64>()
        / episodes as f64
}

fn web_net() -> Vec<(&'static str, Value)> {
    vec![
        ("embedding_dim", Value::Int(32)),
        ("latent_dim", Value::Int(32)),
    ]
}

/// Trains `algo` (the web network plus `hp`) on one level-1 website and asserts ≥ 90% greedy
/// success over 50 episodes.
fn assert_learns_web(algo: &str, hp: &[(&'static str, Value)]) {
    let reg = domains_registry();
    let mut all = web_net();
    all.extend_from_slice(hp);
    let mut alg = make(&reg, algo, &all);
    let s = TrainingSettings {
        total_env_steps: 6_000,
        eval_interval: 2_000,
        eval_episodes: 10,
        checkpoint_interval: 0,
        num_envs: 4,
    };
    let (mut p, curve) = train_on(&reg, alg.as_mut(), WEB, &web_params(), 0, s);
    let success = web_success(&reg, p.as_mut(), 50);
    let name = algo.to_uppercase();
    println!("{name} web success {success}, curve {:?}", curve.returns());
    assert!(
        success >= 0.9,
        "{name} greedy success {success}; curve {:?}",
        curve.returns()
    );
}

#[test]
fn ppo_learns_web_navigation_level_1() {
    if skip_in_debug("ppo_learns_web_navigation_level_1", "domain learning tests") {
        return;
    }
    assert_learns_web(
        "ppo",
        &[
            ("learning_rate", Value::Float(1e-3)),
            ("num_steps", Value::Int(64)),
            ("minibatch_size", Value::Int(64)),
            ("gamma", Value::Float(0.95)),
        ],
    );
}

#[test]
fn ddqn_learns_web_navigation_level_1() {
    if skip_in_debug(
        "ddqn_learns_web_navigation_level_1",
        "domain learning tests",
    ) {
        return;
    }
    assert_learns_web(
        "ddqn",
        &[
            ("learning_rate", Value::Float(1e-3)),
            ("batch_size", Value::Int(64)),
            ("replay_capacity", Value::Int(5_000)),
            ("learning_starts", Value::Int(500)),
            ("updates_per_step", Value::Float(0.25)),
            ("target_update_period", Value::Int(100)),
            ("epsilon_greedy", Value::Float(0.1)),
            ("epsilon_decay_fraction", Value::Float(0.3)),
            ("gamma", Value::Float(0.95)),
        ],
    );
}

#[test]
fn bc_clones_the_web_oracle() {
    if skip_in_debug("bc_clones_the_web_oracle", "domain learning tests") {
        return;
    }
    let reg = domains_registry();
    let mut cfg = a2perf_web::WebNavConfig::new(1);
    cfg.num_websites = 1;
    let mut env = a2perf_web::WebNavEnv::new(cfg).expect("web env");
    let mut samples = Vec::new();
    let mut oracle_success = 0.0;
    let episodes = 60;
    for e in 0..episodes {
        let mut obs = env.reset(Some(e)).unwrap();
        while let Some(a) = env.oracle_action() {
            samples.push(Sample {
                observation: obs.clone(),
                action: Action::Discrete(a),
            });
            let step = env.step(&Action::Discrete(a)).unwrap();
            if step.done() {
                oracle_success += step.info.get("success").unwrap_or(0.0);
                break;
            }
            obs = step.observation;
        }
    }
    let oracle_success = oracle_success / episodes as f64;
    let mut given: BTreeMap<String, Value> = BTreeMap::new();
    for (k, v) in web_net() {
        given.insert(k.into(), v);
    }
    given.insert("learning_rate".into(), Value::Float(1e-3));
    given.insert("batch_size".into(), Value::Int(64));
    let bc = Bc::from_params(&Params::resolve(&Bc::params(), &given).unwrap()).unwrap();
    let mut bc = bc.with_loader(Arc::new(Dataset {
        env_id: Some(WEB.into()),
        samples,
    }));
    let s = TrainingSettings {
        total_env_steps: 64 * 600,
        eval_interval: 0,
        eval_episodes: 5,
        checkpoint_interval: 0,
        num_envs: 1,
    };
    let (mut p, _) = train_on(&reg, &mut bc, WEB, &web_params(), 0, s);
    let success = web_success(&reg, p.as_mut(), 50);
    println!("BC web success {success}, oracle {oracle_success}");
    assert!(oracle_success > 0.9, "oracle success {oracle_success}");
    assert!(
        success >= 0.9 * oracle_success,
        "BC success {success} vs oracle {oracle_success}"
    );
}

// ---------------------------------------------------------------- circuit training

const CIRCUIT: &str = "CircuitTraining-Synthetic-Small-v0";

/// Proxy costs of 100 random legal placements (policy seed 7, episode seeds 0..100).
fn random_costs(reg: &Registry) -> Vec<f64> {
    let mut env = reg.make_env(CIRCUIT, &BTreeMap::new()).unwrap();
    let mut rp = RandomPolicy::new(env.spec().action_space.clone(), 7);
    (0..100)
        .map(|s| {
            let (_, _, proxy) = episode(env.as_mut(), &mut rp, s, ActMode::Explore);
            proxy.expect("random legal placements of this netlist are feasible")
        })
        .collect()
}

fn random_mean_cost(reg: &Registry) -> f64 {
    random_costs(reg).iter().sum::<f64>() / 100.0
}

/// The proxy cost of the greedy placement. An infeasible episode (a macro left without a legal
/// cell) fails the test rather than being read off its reward (−4 by default, A2Perf's −1 would
/// look better than any placement here).
fn greedy_cost(reg: &Registry, policy: &mut dyn Policy) -> f64 {
    let mut env = reg.make_env(CIRCUIT, &BTreeMap::new()).unwrap();
    let (_, _, proxy) = episode(env.as_mut(), policy, 0, ActMode::Greedy);
    proxy.expect("the greedy placement is feasible")
}

// The target: 10% below the mean proxy cost of 100 random legal placements. On this netlist
// (seed 0 of `GeneratorConfig::small()`) the random mean is ~1.48 (std 0.08), the best of 100
// random placements ~12% below it and a 1,500-step hill climb ~23% below (see
// `circuit_cost_landscape`).
fn assert_beats_random_placement(algo: &str, hp: &[(&str, Value)], total_env_steps: u64) {
    let reg = domains_registry();
    let random = random_mean_cost(&reg);
    let mut alg = make(&reg, algo, hp);
    let settings = TrainingSettings {
        total_env_steps,
        eval_interval: 4_000,
        eval_episodes: 1,
        checkpoint_interval: 0,
        num_envs: 4,
    };
    let (mut p, curve) = train_on(&reg, alg.as_mut(), CIRCUIT, &BTreeMap::new(), 0, settings);
    let cost = greedy_cost(&reg, p.as_mut());
    println!(
        "{algo} circuit cost {cost} vs random {random} ({:.1}% below); curve {:?}",
        100.0 * (1.0 - cost / random),
        curve.returns()
    );
    assert!(
        cost <= 0.90 * random,
        "{algo} cost {cost} vs random mean {random}"
    );
}

#[test]
fn circuit_ppo_beats_random_placement() {
    if skip_in_debug(
        "circuit_ppo_beats_random_placement",
        "domain learning tests",
    ) {
        return;
    }
    // Today 18.0% below.
    assert_beats_random_placement(
        "ppo",
        &[
            ("learning_rate", Value::Float(3e-3)),
            ("entropy_coef", Value::Float(0.0)),
            ("num_steps", Value::Int(48)),
            ("minibatch_size", Value::Int(64)),
            ("gamma", Value::Float(1.0)),
            ("gae_lambda", Value::Float(1.0)),
            ("latent_dim", Value::Int(16)),
            ("hidden_sizes", ints(&[64, 64])),
        ],
        20_000,
    );
}

#[test]
fn circuit_ddqn_beats_random_placement() {
    if skip_in_debug(
        "circuit_ddqn_beats_random_placement",
        "domain learning tests",
    ) {
        return;
    }
    // Today 14.7% below.
    assert_beats_random_placement(
        "ddqn",
        &[
            ("learning_rate", Value::Float(1e-3)),
            ("batch_size", Value::Int(64)),
            ("learning_starts", Value::Int(300)),
            ("updates_per_step", Value::Float(0.5)),
            ("target_update_period", Value::Int(50)),
            ("epsilon_greedy", Value::Float(0.1)),
            ("epsilon_decay_fraction", Value::Float(0.5)),
            ("gamma", Value::Float(1.0)),
            ("latent_dim", Value::Int(16)),
            ("hidden_sizes", ints(&[64, 64])),
        ],
        12_000,
    );
}

// ---------------------------------------------------------------- locomotion

const PACE: &str = "QuadrupedLocomotion-DogPace-v0";

struct Zero(usize);
impl Policy for Zero {
    fn act(
        &mut self,
        _o: &a2perf_core::Observation,
        _m: ActMode,
    ) -> Result<Action, a2perf_core::PolicyError> {
        Ok(Action::Continuous(vec![0.0; self.0]))
    }
    fn checkpoint(&self) -> Result<a2perf_core::Checkpoint, a2perf_core::PolicyError> {
        Err(a2perf_core::PolicyError::BadCheckpoint(
            "zero policy".into(),
        ))
    }
}

fn pace_return(reg: &Registry, policy: &mut dyn Policy) -> f64 {
    let mut env = reg.make_env(PACE, &BTreeMap::new()).unwrap();
    (0..5)
        .map(|s| episode(env.as_mut(), policy, 70_000 + s, ActMode::Greedy).0)
        .sum::<f64>()
        / 5.0
}

#[test]
fn ppo_improves_the_pace_task() {
    if skip_in_debug("ppo_improves_the_pace_task", "domain learning tests") {
        return;
    }
    let reg = domains_registry();
    let base = pace_return(&reg, &mut Zero(12));
    let mut ppo = make(
        &reg,
        "ppo",
        &[
            ("learning_rate", Value::Float(3e-4)),
            ("num_steps", Value::Int(256)),
            ("minibatch_size", Value::Int(128)),
            ("hidden_sizes", ints(&[64, 64])),
            // The recorded config's exploration (configs/quadruped_locomotion/ppo.ron): std
            // 0.135 rad and no entropy bonus.
            ("init_log_std", Value::Float(-2.0)),
            ("entropy_coef", Value::Float(0.0)),
        ],
    );
    let s = TrainingSettings {
        total_env_steps: 12_000,
        eval_interval: 0,
        eval_episodes: 2,
        checkpoint_interval: 0,
        num_envs: 2,
    };
    let (mut p, curve) = train_on(&reg, ppo.as_mut(), PACE, &BTreeMap::new(), 0, s.clone());
    let r = pace_return(&reg, p.as_mut());
    println!(
        "PPO pace return {r} vs zero-action {base}; curve {:?}",
        curve.returns()
    );
    // Today 9.48 vs 2.80 (3.4x; 15.6 vs 2.77 before locomotion rebuilt its physics world at
    // every reset); with the earlier exploration (std 0.22, entropy bonus 1e-2) this budget
    // only just beat standing still.
    assert!(r > 3.0 * base, "PPO {r} vs untrained {base}");
}

#[test]
fn sac_improves_the_pace_task() {
    if skip_in_debug("sac_improves_the_pace_task", "domain learning tests") {
        return;
    }
    let reg = domains_registry();
    let base = pace_return(&reg, &mut Zero(12));
    let mut sac = make(
        &reg,
        "sac",
        &[
            ("learning_rate", Value::Float(1e-3)),
            ("batch_size", Value::Int(128)),
            ("learning_starts", Value::Int(1000)),
            ("updates_per_step", Value::Float(1.0)),
            ("init_alpha", Value::Float(0.01)),
            ("action_limit", Value::Float(0.3)),
            ("hidden_sizes", ints(&[64, 64])),
            // A shorter horizon than the default 0.99 learns faster at this tiny budget.
            ("gamma", Value::Float(0.97)),
        ],
    );
    // At budgets this small SAC's return still depends on the seed. Since locomotion rebuilds
    // its physics world at every reset (episodes no longer depend on the ones before), 12k steps
    // give 0.81, 1.12, 1.45, 1.04 × standing still for seeds 0-3 and 20k steps 1.48, 1.07 for
    // seeds 0-1 (before that change: 1.34 for seed 0 at 12k).
    let s = TrainingSettings {
        total_env_steps: 20_000,
        eval_interval: 0,
        eval_episodes: 2,
        checkpoint_interval: 0,
        num_envs: 2,
    };
    let (mut q, curve) = train_on(&reg, sac.as_mut(), PACE, &BTreeMap::new(), 0, s);
    let r = pace_return(&reg, q.as_mut());
    println!(
        "SAC pace return {r} vs zero-action {base}; curve {:?}",
        curve.returns()
    );
    // A clear improvement, not a rounding one: today 4.16 vs 2.80 (+48%).
    assert!(r > 1.2 * base, "SAC {r} vs untrained {base}");
}

/// Diagnostic (ignored): spread of random placements, the wirelength-hint greedy policy and the
/// best placement a local search finds (a practical ceiling for the learning tests) on
/// Synthetic-Small (netlist seed 0, the bank-structured generator). Run it with
/// `cargo test --release -p a2perf-baselines --test domains circuit_cost_landscape -- --ignored --nocapture`.
#[test]
#[ignore]
fn circuit_cost_landscape() {
    let reg = domains_registry();
    let costs = random_costs(&reg);
    let mut env = reg.make_env(CIRCUIT, &BTreeMap::new()).unwrap();
    let min = costs.iter().cloned().fold(f64::INFINITY, f64::min);
    struct Hint;
    impl Policy for Hint {
        fn act(
            &mut self,
            o: &a2perf_core::Observation,
            _m: ActMode,
        ) -> Result<Action, a2perf_core::PolicyError> {
            let g = o.tensor("grid").unwrap();
            let n = g.shape[1] * g.shape[2];
            let d = g.data.as_f32().unwrap();
            let mask = o.action_mask.as_ref().unwrap();
            let best = (0..n)
                .filter(|i| mask[*i])
                .max_by(|a, b| d[3 * n + a].total_cmp(&d[3 * n + b]))
                .unwrap();
            Ok(Action::Discrete(best))
        }
        fn checkpoint(&self) -> Result<a2perf_core::Checkpoint, a2perf_core::PolicyError> {
            unimplemented!()
        }
    }
    let hint = -episode(env.as_mut(), &mut Hint, 0, ActMode::Greedy).0;
    let mean = costs.iter().sum::<f64>() / 100.0;
    println!("random mean {mean} min {min}; hint-greedy {hint}");
    // The ceiling: hill climbing over the (deterministic) episode's action sequence, then one
    // exhaustive sweep over every cell for every macro. An illegal cell is replaced by the
    // nearest legal one (Manhattan distance on the grid).
    let g = env.spec().metadata.get("grid").cloned().unwrap_or_default();
    let cols: usize = g
        .split('x')
        .next()
        .and_then(|c| c.parse().ok())
        .unwrap_or(16);
    let n = match env.spec().action_space {
        a2perf_core::Space::Discrete { n } => n,
        _ => unreachable!(),
    };
    let mut cost_of = |acts: &mut Vec<usize>| -> f64 {
        let mut step = Step::default();
        env.reset_into(Some(0), &mut step.observation).unwrap();
        for k in 0.. {
            let mask = step.observation.action_mask.as_ref().unwrap();
            if k == acts.len() {
                acts.push(0);
            }
            let (r0, c0) = ((acts[k] / cols) as i64, (acts[k] % cols) as i64);
            let a = (0..n)
                .filter(|i| mask[*i])
                .min_by_key(|i| ((i / cols) as i64 - r0).abs() + ((i % cols) as i64 - c0).abs())
                .unwrap();
            acts[k] = a;
            env.step_into(&Action::Discrete(a), &mut step).unwrap();
            if step.done() {
                break;
            }
        }
        // An infeasible episode ranks below every placement, whatever its reward.
        step.info.get("proxy").unwrap_or(f64::INFINITY)
    };
    let mut rng = a2perf_core::RngStream::new(1, "landscape");
    let mut acts: Vec<usize> = Vec::new();
    let mut best = cost_of(&mut acts);
    for _ in 0..1_000 {
        let mut cand = acts.clone();
        let k = rng.index(cand.len());
        cand[k] = rng.index(n);
        let c = cost_of(&mut cand);
        if c < best {
            (best, acts) = (c, cand);
        }
    }
    for k in 0..acts.len() {
        for cell in 0..n {
            let mut cand = acts.clone();
            cand[k] = cell;
            let c = cost_of(&mut cand);
            if c < best {
                (best, acts) = (c, cand);
            }
        }
    }
    println!(
        "local search best {best} ({:.1}% below the random mean), actions {acts:?}",
        100.0 * (1.0 - best / mean)
    );
}
