//! Environment behaviour: episodes, observation layout, masks, registry, determinism.

mod common;

use std::collections::BTreeMap;

use a2perf_circuit::env::{
    A2PERF_INFEASIBLE_REWARD, FEATURE_DIM, GRID_CHANNELS, INFEASIBLE_REWARD,
};
use a2perf_core::{Action, DType, Env, RngStream, Space, Value};
use common::{coarse_small, random_episode_actions, registry, replay, shared_circuit_dir};

fn random_episode(env: &mut dyn Env, seed: u64) -> (f64, usize, Vec<(String, f64)>) {
    let mut rng = RngStream::new(seed, "test/actions");
    let mut obs = env.reset(Some(seed)).unwrap();
    let space = env.spec().action_space.clone();
    let mut steps = 0;
    loop {
        let a = space
            .sample(&mut rng, obs.action_mask.as_deref())
            .expect("a legal action while the episode runs");
        let step = env.step(&a).unwrap();
        steps += 1;
        if step.done() {
            return (
                step.reward,
                steps,
                step.info.iter().map(|(k, v)| (k.to_string(), v)).collect(),
            );
        }
        assert_eq!(step.reward, 0.0, "reward is 0 until the last macro");
        obs = step.observation;
    }
}

#[test]
fn registered_ids_and_suite() {
    let reg = registry();
    for id in [
        "CircuitTraining-ToyMacro-v0",
        "CircuitTraining-Ariane-v0",
        "CircuitTraining-Synthetic-Small-v0",
        "CircuitTraining-Synthetic-Medium-v0",
        "CircuitTraining-Synthetic-Ariane-v0",
    ] {
        let e = reg.env(id).unwrap();
        assert_eq!(e.domain, "circuit_training");
    }
    // File-based ids refuse to build without a netlist, with a clear error.
    let err = reg
        .make_env("CircuitTraining-ToyMacro-v0", &BTreeMap::new())
        .err()
        .unwrap()
        .to_string();
    assert!(err.contains("netlist_file"), "{err}");
    let suite = reg.generalization("circuit_training");
    assert!(suite.len() >= 4);
    let mut hashes = std::collections::BTreeSet::new();
    for t in suite {
        let env = reg.make_env(&t.env_id, &t.params).unwrap();
        hashes.insert(env.spec().metadata["netlist_hash"].clone());
    }
    assert_eq!(
        hashes.len(),
        suite.len(),
        "every generalization task is a different circuit"
    );
}

#[test]
fn small_episode_layout_and_rewards() {
    let reg = registry();
    let mut env = reg
        .make_env("CircuitTraining-Synthetic-Small-v0", &BTreeMap::new())
        .unwrap();
    let spec = env.spec().clone();
    assert!(spec.metadata.contains_key("netlist_hash"));
    assert_eq!(spec.metadata["netlist"], "synthetic_small");
    let Space::Discrete { n } = spec.action_space else {
        panic!("discrete actions")
    };
    assert_eq!(n, 16 * 16);
    let obs = env.reset(Some(0)).unwrap();
    let Space::Dict(items) = &spec.observation_space else {
        panic!("dict observation")
    };
    assert_eq!(items.len(), obs.tensors.len());
    for ((name, space), t) in items.iter().zip(&obs.tensors) {
        assert_eq!(name, &t.name);
        let Space::Box { shape, .. } = space else {
            panic!()
        };
        assert_eq!(shape, &t.shape, "{name}");
        assert_eq!(t.data.len(), shape.iter().product::<usize>());
        // int32 exactly where A2Perf's observation config has it (node indices, types, flags).
        let int32 = [
            "is_node_placed",
            "current_node",
            "node_types",
            "sparse_adj_i",
            "sparse_adj_j",
        ]
        .contains(&name.as_str());
        let want = if int32 { DType::I32 } else { DType::F32 };
        assert_eq!(space.dtype(), Some(want), "{name}");
        assert_eq!(t.dtype(), want, "{name}");
        assert!(space.contains_tensor(t), "{name}");
    }
    assert_eq!(obs.tensors[0].name, "features");
    assert_eq!(obs.tensors[0].shape, vec![FEATURE_DIM]);
    assert_eq!(obs.tensors[1].name, "grid");
    assert_eq!(obs.tensors[1].shape, vec![GRID_CHANNELS, 16, 16]);
    // The mask channel equals the action mask.
    let mask = obs.action_mask.as_ref().unwrap();
    let grid = obs.tensors[1].data.as_f32().unwrap();
    for (c, &m) in mask.iter().enumerate() {
        assert_eq!(grid[2 * 256 + c] == 1.0, m);
    }
    let (r1, steps, info) = random_episode(env.as_mut(), 1);
    let (r2, _, _) = random_episode(env.as_mut(), 1);
    assert_eq!(r1, r2, "same actions give the same reward");
    if info.iter().any(|(k, v)| k == "infeasible" && *v == 1.0) {
        assert_eq!(r1, INFEASIBLE_REWARD);
    } else {
        assert_eq!(steps, 12);
        let get = |k: &str| info.iter().find(|(kk, _)| kk == k).unwrap().1;
        assert!((r1 + get("proxy")).abs() < 1e-12);
        assert!(
            (get("proxy") - (get("wirelength") + get("density") + 0.5 * get("congestion"))).abs()
                < 1e-12
        );
    }
    // A masked action is refused.
    let obs = env.reset(None).unwrap();
    if let Some(bad) = obs.action_mask.as_ref().unwrap().iter().position(|m| !*m) {
        assert!(env.step(&Action::Discrete(bad)).is_err());
    }
}

#[test]
fn greedy_wirelength_hint_beats_random_wirelength() {
    let reg = registry();
    let mut env = reg
        .make_env("CircuitTraining-Synthetic-Small-v0", &BTreeMap::new())
        .unwrap();
    let mut random = Vec::new();
    for s in 0..8 {
        let (_, _, info) = random_episode(env.as_mut(), s);
        random.push(info.iter().find(|(k, _)| k == "wirelength").unwrap().1);
    }
    let random_mean = random.iter().sum::<f64>() / random.len() as f64;
    let mut obs = env.reset(Some(0)).unwrap();
    let greedy = loop {
        let g = obs.tensors[1].data.as_f32().unwrap();
        let cells = obs.action_mask.as_ref().unwrap().len();
        let a = (0..cells)
            .filter(|&c| obs.action_mask.as_ref().unwrap()[c])
            .max_by(|&a, &b| {
                g[3 * cells + a]
                    .total_cmp(&g[3 * cells + b])
                    .then(b.cmp(&a))
            })
            .unwrap();
        let step = env.step(&Action::Discrete(a)).unwrap();
        if step.done() {
            break step.info.get("wirelength").unwrap();
        }
        obs = step.observation;
    };
    // The hint is about wirelength only (greedy piles macros up, so density gets worse).
    assert!(
        greedy < random_mean,
        "greedy {greedy} vs random mean {random_mean}"
    );
}

#[test]
fn padded_action_layout() {
    let reg = registry();
    let mut p = BTreeMap::new();
    p.insert("padded_action".to_string(), Value::Bool(true));
    let mut env = reg
        .make_env("CircuitTraining-Synthetic-Small-v0", &p)
        .unwrap();
    assert_eq!(env.spec().action_space, Space::Discrete { n: 128 * 128 });
    let obs = env.reset(Some(0)).unwrap();
    let mask = obs.action_mask.unwrap();
    // Legal actions only inside the centred 16x16 window: up pad 56, right pad 56.
    for (a, &m) in mask.iter().enumerate() {
        if m {
            let (r, c) = (a / 128, a % 128);
            assert!((56..72).contains(&r) && (56..72).contains(&c));
        }
    }
    let (reward, _, _) = random_episode(env.as_mut(), 3);
    assert!(reward.is_finite() && reward < 0.0);
}

#[test]
fn toy_macro_with_shared_files() {
    let Some(dir) = shared_circuit_dir("toy_macro_stdcell") else {
        return;
    };
    let reg = registry();
    let mut p = BTreeMap::new();
    p.insert(
        "netlist_file".to_string(),
        Value::Str(dir.join("netlist.pb.txt").display().to_string()),
    );
    p.insert("padded_action".to_string(), Value::Bool(true));
    let mut env = reg.make_env("CircuitTraining-ToyMacro-v0", &p).unwrap();
    assert_eq!(env.spec().max_episode_steps, Some(2));
    assert_eq!(env.spec().metadata["netlist"], "toy_macro_stdcell");
    let obs = env.reset(Some(0)).unwrap();
    // Golden mask example: MR (node 1) first, 108 legal cells (rows 2..7 x cols 1..18).
    let mask = obs.action_mask.clone().unwrap();
    assert_eq!(mask.iter().filter(|m| **m).count(), 108);
    assert_eq!(
        obs.tensor("current_node").unwrap().data.as_i32(),
        Some(&[1][..])
    );
    // Cell 41 -> padded action (41/20 + 59)*128 + 41%20 + 54 = 7863 (golden log).
    let step = env.step(&Action::Discrete(7863)).unwrap();
    assert!(!step.done());
    let mask = step.observation.action_mask.unwrap();
    assert_eq!(mask.iter().filter(|m| **m).count(), 96);
    let legal: Vec<usize> = mask
        .iter()
        .enumerate()
        .filter(|(_, m)| **m)
        .map(|(a, _)| a)
        .collect();
    let step = env.step(&Action::Discrete(legal[0])).unwrap();
    assert!(step.done() && step.reward < 0.0);
    assert!(step.info.get("wirelength").unwrap() > 0.0);
}

#[test]
fn infeasible_reward_is_below_feasible_placements_with_an_a2perf_switch() {
    // A coarser grid (12×12 instead of 16×16) leaves fewer legal cells, so some random
    // placements strand a macro.
    let reg = registry();
    let mut env = coarse_small(&reg, &[]);
    assert_eq!(
        env.spec()
            .metadata
            .get("infeasible_reward")
            .map(String::as_str),
        Some("-4")
    );
    let (mut infeasible_run, mut worst_feasible) = (None, f64::INFINITY);
    for seed in 0..200u64 {
        let (actions, reward, stranded) =
            random_episode_actions(env.as_mut(), seed, "test/infeasible");
        if stranded {
            assert_eq!(reward, INFEASIBLE_REWARD);
            infeasible_run.get_or_insert((seed, actions));
        } else {
            worst_feasible = worst_feasible.min(reward);
        }
    }
    let (seed, actions) = infeasible_run.expect("an infeasible episode in 200 random ones");
    assert!(worst_feasible.is_finite(), "some feasible episodes too");
    // The default ranks every infeasible episode below every feasible one met here; A2Perf's
    // value does not (a feasible placement of this netlist costs more than 1).
    assert!(INFEASIBLE_REWARD < worst_feasible, "{worst_feasible}");
    assert!(
        A2PERF_INFEASIBLE_REWARD > worst_feasible,
        "{worst_feasible}"
    );
    // The same actions under the compatibility switch end the same way, with A2Perf's reward.
    let mut a2perf = coarse_small(
        &reg,
        &[("infeasible_reward", Value::Float(A2PERF_INFEASIBLE_REWARD))],
    );
    assert_eq!(
        replay(a2perf.as_mut(), seed, &actions),
        (A2PERF_INFEASIBLE_REWARD, true, actions.len())
    );
    assert_eq!(
        replay(env.as_mut(), seed, &actions),
        (INFEASIBLE_REWARD, true, actions.len())
    );
    // A positive "penalty" is refused with the parameter's name.
    let err = reg
        .make_env(
            "CircuitTraining-Synthetic-Small-v0",
            &[("infeasible_reward".to_string(), Value::Float(0.5))]
                .into_iter()
                .collect(),
        )
        .err()
        .expect("a positive infeasible reward is an error")
        .to_string();
    assert!(err.contains("infeasible_reward"), "{err}");
}

/// A repeated episode's end is restored from the environment's cache of placed ends: its
/// reward and info must be bit-identical to placing it afresh (a new environment per episode),
/// for both placers, feasible and infeasible ends alike.
#[test]
fn repeated_episode_ends_equal_fresh_placements() {
    let reg = registry();
    for placer in ["fd", "dreamplace"] {
        let extra = [("std_cell_placer", Value::Str(placer.into()))];
        let mut env = coarse_small(&reg, &extra);
        // Eight random episodes, then the same eight again in reverse order.
        let mut episodes: Vec<Vec<usize>> = (0..8u64)
            .map(|seed| random_episode_actions(env.as_mut(), seed, "test/end-cache").0)
            .collect();
        let again: Vec<Vec<usize>> = episodes.iter().rev().cloned().collect();
        episodes.extend(again);
        let end = |env: &mut dyn Env, actions: &[usize]| {
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
                    return (step.reward.to_bits(), info);
                }
            }
            panic!("the episode did not end");
        };
        let mut infeasible_ends = 0;
        for actions in &episodes {
            let cached = end(env.as_mut(), actions);
            let mut fresh_env = coarse_small(&reg, &extra);
            let fresh = end(fresh_env.as_mut(), actions);
            assert_eq!(cached, fresh, "{placer}: episode {actions:?}");
            infeasible_ends +=
                usize::from(cached.1.contains(&("infeasible".into(), 1f64.to_bits())));
        }
        // Random placements on the coarse grid strand a macro now and then.
        println!(
            "{placer}: {infeasible_ends} of {} ends infeasible",
            episodes.len()
        );
    }
}
