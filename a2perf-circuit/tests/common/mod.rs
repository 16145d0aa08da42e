//! Helpers shared by the environment tests.
#![allow(dead_code)]

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use a2perf_core::{Action, Env, Registry, RngStream, Value};

/// A registry with the circuit environments.
pub fn registry() -> Registry {
    let mut reg = Registry::new();
    a2perf_circuit::register(&mut reg);
    reg
}

/// Environment parameters from `(name, value)` pairs.
pub fn params(pairs: &[(&str, Value)]) -> BTreeMap<String, Value> {
    pairs
        .iter()
        .map(|(k, v)| (k.to_string(), v.clone()))
        .collect()
}

/// `../shared/data/circuit/<name>`, or `None` (with the reason printed) when it is absent;
/// absent data fails the test when `A2PERF_REQUIRE_SHARED=1`.
pub fn shared_circuit_dir(name: &str) -> Option<PathBuf> {
    let dir = Path::new(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../shared/data/circuit"
    ))
    .join(name);
    if dir.exists() {
        return Some(dir);
    }
    if std::env::var("A2PERF_REQUIRE_SHARED").as_deref() == Ok("1") {
        panic!("A2PERF_REQUIRE_SHARED=1 but {} is missing", dir.display());
    }
    eprintln!("skipping: {} not present", dir.display());
    None
}

/// Whether a step's info flags an infeasible end.
pub fn infeasible(info: &a2perf_core::Info) -> bool {
    info.get("infeasible") == Some(1.0)
}

/// One episode of random legal actions from a reset (actions drawn from the stream
/// `(seed, stream)`): the actions, the final reward and whether the end was infeasible.
pub fn random_episode_actions(
    env: &mut dyn Env,
    seed: u64,
    stream: &str,
) -> (Vec<usize>, f64, bool) {
    let space = env.spec().action_space.clone();
    let mut rng = RngStream::new(seed, stream);
    let mut obs = env.reset(Some(seed)).unwrap();
    let mut actions = Vec::new();
    loop {
        let Some(Action::Discrete(a)) = space.sample(&mut rng, obs.action_mask.as_deref()) else {
            panic!("a legal action while the episode runs");
        };
        actions.push(a);
        let step = env.step(&Action::Discrete(a)).unwrap();
        if step.done() {
            return (actions, step.reward, infeasible(&step.info));
        }
        obs = step.observation;
    }
}

/// Random legal episodes (episode seeds `0..200`) until one strands a macro; returns its seed and
/// actions. The environment must be able to strand one (e.g. a coarse grid).
pub fn find_infeasible_episode(env: &mut dyn Env) -> (u64, Vec<usize>) {
    (0..200u64)
        .find_map(|seed| {
            let (actions, _, stranded) = random_episode_actions(env, seed, "test/infeasible");
            stranded.then_some((seed, actions))
        })
        .expect("an infeasible episode in 200 random ones")
}

/// Synthetic-Small on a coarser 12×12 grid (instead of 16×16): fewer legal cells, so some random
/// placements strand a macro.
pub fn coarse_small(reg: &Registry, extra: &[(&str, Value)]) -> Box<dyn Env> {
    let mut p = params(&[("grid_cols", Value::Int(12)), ("grid_rows", Value::Int(12))]);
    p.extend(params(extra));
    reg.make_env("CircuitTraining-Synthetic-Small-v0", &p)
        .unwrap()
}

/// Replays `actions` from a reset and returns the final reward, whether the episode ended
/// infeasible, and the number of steps taken.
pub fn replay(env: &mut dyn Env, seed: u64, actions: &[usize]) -> (f64, bool, usize) {
    env.reset(Some(seed)).unwrap();
    for (i, &a) in actions.iter().enumerate() {
        let step = env.step(&Action::Discrete(a)).unwrap();
        if step.done() {
            return (step.reward, infeasible(&step.info), i + 1);
        }
    }
    panic!("the episode did not end");
}

/// Synthetic-Small of netlist seed `seed` on the 12×12 grid of [`coarse_small`], built directly
/// (so that its cache of episode ends can be inspected or turned off); `edit` changes the
/// generated circuit, its settings or the environment's options first.
pub fn coarse_small_env(
    seed: u64,
    edit: impl FnOnce(
        &mut a2perf_circuit::GeneratedCircuit,
        &mut a2perf_circuit::CostSettings,
        &mut a2perf_circuit::CircuitEnvConfig,
    ),
) -> a2perf_circuit::CircuitEnv {
    let mut g = a2perf_circuit::generate(&a2perf_circuit::GeneratorConfig::small(), seed);
    let mut settings = g.settings.clone();
    settings.grid_cols = 12;
    settings.grid_rows = 12;
    let mut config = a2perf_circuit::CircuitEnvConfig {
        id: "CircuitTraining-Synthetic-Small-v0".into(),
        ..Default::default()
    };
    edit(&mut g, &mut settings, &mut config);
    a2perf_circuit::CircuitEnv::new(&g.netlist, Some(&g.placement), settings, config).unwrap()
}

/// Everything the last step of an episode returns, floats as bits: replays `actions` from a
/// reset and returns the final step's reward, info (sorted) and observation.
pub fn episode_end(env: &mut dyn Env, actions: &[usize]) -> (u64, Vec<(String, u64)>, String) {
    env.reset(Some(0)).unwrap();
    for &a in actions {
        let step = env.step(&Action::Discrete(a)).unwrap();
        if step.done() {
            let mut info: Vec<(String, u64)> = step
                .info
                .iter()
                .map(|(k, v)| (k.to_string(), v.to_bits()))
                .collect();
            info.sort();
            // Debug prints floats exactly (shortest round-trip form).
            return (
                step.reward.to_bits(),
                info,
                format!("{:?}", step.observation),
            );
        }
    }
    panic!("the episode did not end");
}
