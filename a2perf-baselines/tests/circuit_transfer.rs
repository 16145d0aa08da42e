//! A circuit placement policy runs on netlists it was not trained on (the generalization tasks):
//! its parameters depend only on the feature width and the grid's channels, not on the netlist's
//! size. Other networks still refuse observations that differ from their training ones.

use std::collections::BTreeMap;

use a2perf_baselines::register;
use a2perf_core::{
    ActMode, CancelToken, DiscardCheckpoints, Env, EnvError, Registry, TrainingContext,
    TrainingSettings, Value, rollout,
};

fn registry() -> Registry {
    let mut reg = Registry::new();
    register(&mut reg);
    a2perf_circuit::register(&mut reg);
    reg
}

fn params(id_seed: i64) -> BTreeMap<String, Value> {
    // No standard-cell placement: the test is about the policy, and it keeps debug builds quick.
    BTreeMap::from([
        ("std_cell_placer".to_string(), Value::Str("none".into())),
        ("netlist_seed".to_string(), Value::Int(id_seed)),
    ])
}

#[test]
fn circuit_policy_transfers_to_other_netlists() {
    let reg = registry();
    let small = "CircuitTraining-Synthetic-Small-v0";
    let reg2 = reg.clone();
    let factory = move |_i: usize| -> Result<Box<dyn Env>, EnvError> {
        reg2.make_env(small, &params(0))
            .map_err(|e| EnvError::Backend(e.to_string()))
    };
    let settings = TrainingSettings {
        total_env_steps: 96,
        eval_interval: 0,
        eval_episodes: 1,
        checkpoint_interval: 0,
        num_envs: 2,
    };
    let mut sink = DiscardCheckpoints;
    let mut ctx = TrainingContext::new(&factory, 0, settings, &mut sink, CancelToken::new());
    let hp = BTreeMap::from([("num_steps".to_string(), Value::Int(24))]);
    let mut ppo = reg.make_algorithm("ppo", &hp).expect("ppo");
    let policy = ppo.train(&mut ctx).expect("training");
    let ckpt = policy.checkpoint().expect("checkpoint");
    let load = reg.algorithm("ppo").unwrap().load_policy;

    for (id, seed) in [(small, 2), ("CircuitTraining-Synthetic-Medium-v0", 1)] {
        let mut env = reg.make_env(id, &params(seed)).expect("env");
        let mut loaded = load(&ckpt, env.spec()).unwrap_or_else(|e| panic!("{id}: {e}"));
        // Every action the policy takes is legal (rollout fails on a masked action), and it places
        // every macro of the new circuit.
        let ep = rollout(env.as_mut(), loaded.as_mut(), 3, ActMode::Greedy, false)
            .unwrap_or_else(|e| panic!("{id}: {e}"));
        assert!(ep.terminated, "{id}: episode did not finish");
        assert!(ep.length >= 2, "{id}: {} steps", ep.length);
        assert!(ep.episode_return.is_finite());
    }
}
