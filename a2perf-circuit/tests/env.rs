//! Environment behaviour: episodes, observation layout, masks, registry, determinism.

mod common;

use std::collections::BTreeMap;

use a2perf_circuit::env::{
    A2PERF_INFEASIBLE_REWARD, FEATURE_DIM, GRID_CHANNELS, INFEASIBLE_REWARD,
};
use a2perf_circuit::{
    CircuitEnvConfig, CostSettings, GeneratedCircuit, InitialLocations, NodeKind, StdCellPlacer,
};
use a2perf_core::{Action, DType, Env, RngStream, Space, Value};
use common::{
    coarse_small, coarse_small_env, episode_end, random_episode_actions, registry, replay,
    shared_circuit_dir,
};

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
/// reward, info and observation must be bit-identical to placing it afresh (an environment with
/// the cache off), for both placers, feasible and infeasible ends alike.
#[test]
fn repeated_episode_ends_equal_fresh_placements() {
    let reg = registry();
    for (name, placer) in [
        ("fd", StdCellPlacer::Fd),
        ("dreamplace", StdCellPlacer::DreamPlace),
    ] {
        let extra = [("std_cell_placer", Value::Str(name.into()))];
        let mut env = coarse_small(&reg, &extra);
        // Eight random episodes, then the same eight again in reverse order.
        let mut episodes: Vec<Vec<usize>> = (0..8u64)
            .map(|seed| random_episode_actions(env.as_mut(), seed, "test/end-cache").0)
            .collect();
        let again: Vec<Vec<usize>> = episodes.iter().rev().cloned().collect();
        episodes.extend(again);
        let mut fresh_env = coarse_small_env(0, |_, _, c| c.std_cell_placer = placer);
        fresh_env.set_end_cache_bytes(0);
        let mut infeasible_ends = 0;
        for actions in &episodes {
            let cached = episode_end(env.as_mut(), actions);
            let fresh = episode_end(&mut fresh_env, actions);
            assert_eq!(cached, fresh, "{name}: episode {actions:?}");
            infeasible_ends +=
                usize::from(cached.1.contains(&("infeasible".into(), 1f64.to_bits())));
        }
        assert_eq!(fresh_env.end_cache_hits(), 0);
        // Random placements on the coarse grid strand a macro now and then.
        println!(
            "{name}: {infeasible_ends} of {} ends infeasible",
            episodes.len()
        );
    }
}

/// Random legal episodes of `env` (seeds `0..n`).
fn random_episodes(env: &mut dyn Env, n: u64) -> Vec<Vec<usize>> {
    (0..n)
        .map(|seed| random_episode_actions(env, seed, "test/shared-ends").0)
        .collect()
}

/// Environments built separately from the same circuit and options share their episode ends:
/// the second one restores what the first placed, bit-identical to placing it afresh.
#[test]
fn environments_of_one_start_state_share_episode_ends() {
    for placer in [StdCellPlacer::Fd, StdCellPlacer::DreamPlace] {
        let make = || coarse_small_env(37, |_, _, c| c.std_cell_placer = placer);
        let (mut a, mut b, mut fresh) = (make(), make(), make());
        fresh.set_end_cache_bytes(0);
        let episodes = random_episodes(&mut a, 4);
        for (k, actions) in episodes.iter().enumerate() {
            let from_b = episode_end(&mut b, actions);
            assert_eq!(b.end_cache_hits(), k as u64 + 1, "{placer:?}: {actions:?}");
            assert_eq!(from_b, episode_end(&mut a, actions), "{placer:?}");
            assert_eq!(from_b, episode_end(&mut fresh, actions), "{placer:?}");
        }
        assert_eq!(a.end_cache_len(), b.end_cache_len());
        assert!(a.end_cache_len() >= episodes.len().min(2));
        assert_eq!((fresh.end_cache_len(), fresh.end_cache_hits()), (0, 0));
    }
}

/// Environments that differ in anything their episode ends depend on do not share them, and
/// each gives what a fresh environment with the cache off gives. Each variant changes one input
/// of a base environment that is alive beside it (with `initial_locations = plc` the start
/// states are equal unless the change is to them, so the options alone must keep them apart).
#[test]
fn environments_of_different_start_states_or_placers_do_not_share() {
    type Edit = fn(&mut GeneratedCircuit, &mut CostSettings, &mut CircuitEnvConfig);
    let dreamplace: Edit = |_, _, c| c.std_cell_placer = StdCellPlacer::DreamPlace;
    let dreamplace_plc: Edit = |_, _, c| {
        c.std_cell_placer = StdCellPlacer::DreamPlace;
        c.initial_locations = InitialLocations::Plc;
    };
    let fd_plc: Edit = |_, _, c| {
        c.std_cell_placer = StdCellPlacer::Fd;
        c.initial_locations = InitialLocations::Plc;
    };
    let cases: [(&str, Edit, Edit); 11] = [
        ("placer", dreamplace_plc, |_, _, c| {
            c.std_cell_placer = StdCellPlacer::Fd;
        }),
        ("initial locations", dreamplace, |_, _, c| {
            c.initial_locations = InitialLocations::Plc;
        }),
        ("init placement", dreamplace_plc, |g, _, _| {
            // A soft macro of the .plc elsewhere.
            let soft = g
                .placement
                .entries
                .iter_mut()
                .rev()
                .find(|e| g.netlist.nodes[e.index].kind == NodeKind::SoftMacro)
                .expect("a soft macro in the placement");
            soft.x += 1.0;
        }),
        (
            "init placement, placed at construction",
            dreamplace,
            |g, _, _| {
                let soft = g
                    .placement
                    .entries
                    .iter_mut()
                    .find(|e| g.netlist.nodes[e.index].kind == NodeKind::SoftMacro)
                    .expect("a soft macro in the placement");
                soft.y += 1.0;
            },
        ),
        ("analytical parameter", dreamplace_plc, |_, _, c| {
            c.analytical.noise_ratio *= 2.0;
        }),
        ("analytical seed", dreamplace_plc, |_, _, c| {
            c.analytical.seed += 1
        }),
        ("fd schedule", fd_plc, |_, _, c| {
            c.fd_schedule.attract[0] *= 2.0
        }),
        ("congestion weight", dreamplace_plc, |_, _, c| {
            c.weights.congestion = 0.25;
        }),
        ("smooth range", dreamplace_plc, |_, s, _| {
            s.smooth_range = 2.0
        }),
        ("routing allocation", fd_plc, |_, s, _| {
            s.hrouting_alloc *= 0.5
        }),
        ("padded actions", dreamplace_plc, |_, _, c| {
            c.padded_action = true
        }),
    ];
    for (name, base_edit, edit) in cases {
        let mut base = coarse_small_env(38, base_edit);
        let cells = random_episodes(&mut base, 3);
        let make = || {
            coarse_small_env(38, |g, s, c| {
                base_edit(g, s, c);
                edit(g, s, c);
            })
        };
        let (mut variant, mut fresh) = (make(), make());
        fresh.set_end_cache_bytes(0);
        // The recorded actions are cells (the base's actions); the variant's may be padded.
        let episodes: Vec<Vec<usize>> = cells
            .iter()
            .map(|cells| cells.iter().map(|&c| variant.cell_to_action(c)).collect())
            .collect();
        for actions in &episodes {
            let end = episode_end(&mut variant, actions);
            assert_eq!(variant.end_cache_hits(), 0, "{name}: shares a cache");
            assert_eq!(end, episode_end(&mut fresh, actions), "{name}");
        }
        // Its own cache works: the same episodes again are restored.
        for actions in &episodes {
            episode_end(&mut variant, actions);
        }
        assert_eq!(variant.end_cache_hits(), episodes.len() as u64, "{name}");
        // And the base's is still there.
        assert_eq!(base.end_cache_len(), cells.len(), "{name}");
    }
}

/// `cost_mut` detaches an environment from the shared cache (it may change what the ends depend
/// on): it gets an empty private cache, and the others keep theirs.
#[test]
fn cost_mut_detaches_from_the_shared_cache() {
    let make = || coarse_small_env(39, |_, _, c| c.std_cell_placer = StdCellPlacer::DreamPlace);
    let (mut a, mut b) = (make(), make());
    let episodes = random_episodes(&mut a, 2);
    let held = a.end_cache_len();
    assert!(held >= 1);
    assert_eq!(b.end_cache_len(), held);
    b.cost_mut();
    assert_eq!(b.end_cache_len(), 0);
    assert_eq!(a.end_cache_len(), held, "the others keep theirs");
    for actions in &episodes {
        episode_end(&mut b, actions);
    }
    assert_eq!(b.end_cache_hits(), 0);
    assert_eq!(b.end_cache_len(), episodes.len());
    for actions in &episodes {
        episode_end(&mut b, actions);
        episode_end(&mut a, actions);
    }
    assert_eq!(b.end_cache_hits(), episodes.len() as u64, "a private cache");
    assert_eq!(a.end_cache_hits(), episodes.len() as u64);
    assert_eq!(a.end_cache_len(), held);
}
