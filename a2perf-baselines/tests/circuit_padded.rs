//! The circuit network on A2Perf's padded action layout (`padded_action = true`, metadata
//! `action_layout = "padded128"`: `Discrete(128·128)`, the grid centred on the canvas) is the
//! network of the unpadded layout: the same parameters, the same scores placed at the circuit
//! crate's padded actions, the same gradients — so PPO and DDQN train identically and pick the
//! same cells under either layout.

use std::collections::BTreeMap;

use a2perf_baselines::{DiscreteNet, NetOptions, ObsBatch, ObsLayout, register};
use a2perf_circuit::env::{cell_to_padded_action, padded_action_to_cell};
use a2perf_core::{
    ActMode, Action, CancelToken, Checkpoint, DiscardCheckpoints, Env, EnvError, Registry,
    RngStream, TrainingContext, TrainingSettings, Value, rollout,
};

fn registry() -> Registry {
    let mut reg = Registry::new();
    register(&mut reg);
    a2perf_circuit::register(&mut reg);
    reg
}

fn params(padded: bool) -> BTreeMap<String, Value> {
    // No standard-cell placement: the test is about the policy, and it keeps debug builds quick.
    BTreeMap::from([
        ("std_cell_placer".to_string(), Value::Str("none".into())),
        ("padded_action".to_string(), Value::Bool(padded)),
    ])
}

fn make(reg: &Registry, id: &str, padded: bool) -> Box<dyn Env> {
    reg.make_env(id, &params(padded))
        .unwrap_or_else(|e| panic!("{id}: {e}"))
}

fn grid_of(env: &dyn Env) -> (usize, usize) {
    let grid = env.spec().metadata["grid"].clone();
    let (cols, rows) = grid.split_once('x').expect("grid metadata is COLSxROWS");
    (cols.parse().unwrap(), rows.parse().unwrap())
}

const IDS: [&str; 3] = [
    "CircuitTraining-Synthetic-Small-v0",
    "CircuitTraining-Synthetic-Medium-v0",
    "CircuitTraining-Synthetic-Ariane-v0",
];

#[test]
fn padded_scores_and_gradients_are_the_grid_ones_at_the_circuit_crates_padded_actions() {
    let reg = registry();
    for id in IDS {
        let mut plain = make(&reg, id, false);
        let mut padded = make(&reg, id, true);
        assert_eq!(padded.spec().metadata["action_layout"], "padded128");
        let (cols, rows) = grid_of(plain.as_ref());
        let cells = cols * rows;
        let opts = NetOptions::default();
        let layouts = [plain.spec(), padded.spec()].map(|s| ObsLayout::from_spec(s).unwrap());
        let mut nets = [
            DiscreteNet::for_spec(plain.spec(), &layouts[0], &opts, true).unwrap(),
            DiscreteNet::for_spec(padded.spec(), &layouts[1], &opts, true).unwrap(),
        ];
        assert_eq!(nets[0].kind(), "circuit", "{id}");
        assert_eq!(
            nets[1].kind(),
            "circuit",
            "{id}: the padded layout fell back to an MLP"
        );
        assert_eq!(nets[0].num_params(), nets[1].num_params(), "{id}");
        assert_eq!(nets[1].num_actions(), 128 * 128);
        let weights = nets[0].init_params(&mut RngStream::new(7, "weights"));

        // Two observations: the first macro, and after a few legal placements.
        let first = [
            plain.reset(Some(3)).unwrap(),
            padded.reset(Some(3)).unwrap(),
        ];
        let mut rng = RngStream::new(1, "moves");
        let mut last = first.clone();
        for _ in 0..3 {
            let mask = last[0].action_mask.clone().unwrap();
            let Some(Action::Discrete(cell)) =
                plain.spec().action_space.sample(&mut rng, Some(&mask))
            else {
                break;
            };
            let a = plain.step(&Action::Discrete(cell)).unwrap();
            let b = padded
                .step(&Action::Discrete(cell_to_padded_action(cell, cols, rows)))
                .unwrap();
            last = [a.observation, b.observation];
        }
        let pairs = [first, last];
        // The environments agree on what is legal, through the same map.
        for [p, q] in &pairs {
            let (pm, qm) = (
                p.action_mask.as_ref().unwrap(),
                q.action_mask.as_ref().unwrap(),
            );
            assert_eq!((pm.len(), qm.len()), (cells, 128 * 128));
            for (cell, &legal) in pm.iter().enumerate() {
                assert_eq!(qm[cell_to_padded_action(cell, cols, rows)], legal, "{id}");
            }
            assert_eq!(
                qm.iter().filter(|m| **m).count(),
                pm.iter().filter(|m| **m).count()
            );
        }
        let mut batches = layouts.clone().map(|l| ObsBatch::new(&l));
        for pair in &pairs {
            batches[0].push(&pair[0]).unwrap();
            batches[1].push(&pair[1]).unwrap();
        }
        for (net, batch) in nets.iter_mut().zip(&batches) {
            net.forward(&weights, batch);
        }
        let n = 128 * 128;
        for row in 0..2 {
            let plain_logits = &nets[0].logits()[row * cells..(row + 1) * cells];
            let padded_logits = &nets[1].logits()[row * n..(row + 1) * n];
            let mut cell_of = vec![None; n];
            for (cell, &z) in plain_logits.iter().enumerate() {
                let a = cell_to_padded_action(cell, cols, rows);
                assert_eq!(padded_logits[a].to_bits(), z.to_bits(), "{id}: cell {cell}");
                cell_of[a] = Some(cell);
            }
            for (a, &z) in padded_logits.iter().enumerate() {
                assert_eq!(
                    padded_action_to_cell(a, cols, rows),
                    cell_of[a],
                    "{id}: action {a}"
                );
                if cell_of[a].is_none() {
                    assert_eq!(z, f32::NEG_INFINITY, "{id}: padding action {a} scored {z}");
                }
            }
        }
        assert_eq!(nets[0].values(), nets[1].values(), "{id}: value head");

        // Gradients: the same upstream gradient, placed at the padded actions, gives the same
        // parameter gradient (whatever the padding entries hold).
        let mut grng = RngStream::new(5, "dlogits");
        let dplain: Vec<f32> = (0..2 * cells).map(|_| grng.normal() as f32).collect();
        let mut dpadded: Vec<f32> = (0..2 * n).map(|_| grng.normal() as f32).collect();
        for row in 0..2 {
            for cell in 0..cells {
                dpadded[row * n + cell_to_padded_action(cell, cols, rows)] =
                    dplain[row * cells + cell];
            }
        }
        let dvalues = [0.3f32, -1.2];
        let mut grads = [vec![0.0f32; weights.len()], vec![0.0f32; weights.len()]];
        nets[0].backward(
            &weights,
            &mut grads[0],
            &batches[0],
            &dplain,
            Some(&dvalues),
        );
        nets[1].backward(
            &weights,
            &mut grads[1],
            &batches[1],
            &dpadded,
            Some(&dvalues),
        );
        assert!(grads[0].iter().any(|g| *g != 0.0));
        let bits = |g: &[f32]| g.iter().map(|g| g.to_bits()).collect::<Vec<_>>();
        assert_eq!(bits(&grads[0]), bits(&grads[1]), "{id}: gradients differ");

        // The scored pass (what DDQN learns through): the padded network's logits over its
        // scored actions, the circuit crate's padded actions of the cells in cell order, are
        // the grid's logits bit for bit, and so are the gradients from them.
        let mut scored = Vec::new();
        assert!(!nets[0].scored_actions_into(&mut scored), "{id}");
        assert!(nets[1].scored_actions_into(&mut scored), "{id}");
        let expected: Vec<usize> = (0..cells)
            .map(|cell| cell_to_padded_action(cell, cols, rows))
            .collect();
        assert_eq!(scored, expected, "{id}: scored actions");
        nets[0].forward(&weights, &batches[0]);
        nets[1].forward_scored(&weights, &batches[1]);
        assert_eq!(nets[1].logit_width(), cells, "{id}");
        assert_eq!(bits(nets[0].logits()), bits(nets[1].logits()), "{id}");
        assert_eq!(nets[0].values(), nets[1].values(), "{id}: value head");
        let mut scored_grads = vec![0.0f32; weights.len()];
        nets[1].backward(
            &weights,
            &mut scored_grads,
            &batches[1],
            &dplain,
            Some(&dvalues),
        );
        assert_eq!(
            bits(&grads[0]),
            bits(&scored_grads),
            "{id}: scored gradients"
        );
        // A full forward afterwards is the padded one again.
        nets[1].forward(&weights, &batches[1]);
        assert_eq!(nets[1].logit_width(), n, "{id}");
    }
}

fn train(reg: &Registry, algo: &str, padded: bool) -> (Checkpoint, Vec<(u64, f64)>) {
    let small = "CircuitTraining-Synthetic-Small-v0";
    let reg2 = reg.clone();
    let factory = move |_i: usize| -> Result<Box<dyn Env>, EnvError> {
        reg2.make_env(small, &params(padded))
            .map_err(|e| EnvError::Backend(e.to_string()))
    };
    let settings = TrainingSettings {
        total_env_steps: 144,
        eval_interval: 48,
        eval_episodes: 1,
        checkpoint_interval: 0,
        num_envs: 2,
    };
    let mut sink = DiscardCheckpoints;
    let mut ctx = TrainingContext::new(&factory, 3, settings, &mut sink, CancelToken::new());
    let hp: Vec<(&str, Value)> = match algo {
        "ppo" => vec![
            ("num_steps", Value::Int(24)),
            ("minibatch_size", Value::Int(16)),
        ],
        _ => vec![
            ("learning_starts", Value::Int(24)),
            ("batch_size", Value::Int(16)),
            ("target_update_period", Value::Int(10)),
        ],
    };
    let hp: BTreeMap<String, Value> = hp.into_iter().map(|(k, v)| (k.to_string(), v)).collect();
    let mut alg = reg.make_algorithm(algo, &hp).expect(algo);
    let policy = alg
        .train(&mut ctx)
        .unwrap_or_else(|e| panic!("{algo}: {e}"));
    (
        policy.checkpoint().expect("checkpoint"),
        ctx.curve().returns(),
    )
}

/// The cells a policy picks over one episode (padded actions mapped back to cells).
fn cells_picked(
    reg: &Registry,
    algo: &str,
    ckpt: &Checkpoint,
    padded: bool,
    mode: ActMode,
) -> (Vec<usize>, f64) {
    let id = "CircuitTraining-Synthetic-Small-v0";
    let mut env = make(reg, id, padded);
    let (cols, rows) = grid_of(env.as_ref());
    let load = reg.algorithm(algo).unwrap().load_policy;
    let mut policy = load(ckpt, env.spec()).unwrap_or_else(|e| panic!("{algo}: {e}"));
    let ep = rollout(env.as_mut(), policy.as_mut(), 11, mode, true).expect("rollout");
    let cells = ep
        .transitions
        .iter()
        .map(|t| match t.action {
            Action::Discrete(a) if padded => padded_action_to_cell(a, cols, rows).expect("in grid"),
            Action::Discrete(a) => a,
            _ => panic!("continuous action"),
        })
        .collect();
    (cells, ep.episode_return)
}

#[test]
fn ppo_and_ddqn_train_identically_and_pick_the_same_cells_on_the_padded_layout() {
    let reg = registry();
    for algo in ["ppo", "ddqn"] {
        let (plain_ckpt, plain_curve) = train(&reg, algo, false);
        let (padded_ckpt, padded_curve) = train(&reg, algo, true);
        assert_eq!(plain_curve.len(), 3, "{algo}: {plain_curve:?}");
        // Same evaluation returns at every point of training, bit for bit.
        assert_eq!(
            plain_curve
                .iter()
                .map(|(s, r)| (*s, r.to_bits()))
                .collect::<Vec<_>>(),
            padded_curve
                .iter()
                .map(|(s, r)| (*s, r.to_bits()))
                .collect::<Vec<_>>(),
            "{algo}: training differs between the layouts"
        );
        for mode in [ActMode::Greedy, ActMode::Explore] {
            let reference = cells_picked(&reg, algo, &plain_ckpt, false, mode);
            assert_eq!(reference.0.len(), 12, "{algo}: one step per hard macro");
            // The policy trained on the padded layout, and the unpadded policy's weights loaded
            // onto the padded environment, choose the same cells.
            let trained = cells_picked(&reg, algo, &padded_ckpt, true, mode);
            let same_weights = cells_picked(&reg, algo, &plain_ckpt, true, mode);
            assert_eq!(trained.0, reference.0, "{algo} {mode:?}: trained on padded");
            assert_eq!(same_weights.0, reference.0, "{algo} {mode:?}: same weights");
            assert_eq!(trained.1.to_bits(), reference.1.to_bits());
            assert_eq!(same_weights.1.to_bits(), reference.1.to_bits());
        }
    }
}

#[test]
fn a_padded_policy_runs_on_other_netlists_under_either_layout() {
    let reg = registry();
    let (ckpt, _) = train(&reg, "ppo", true);
    let load = reg.algorithm("ppo").unwrap().load_policy;
    // Retargeted to a larger padded grid (the generalization tasks), every action is legal.
    let mut env = make(&reg, "CircuitTraining-Synthetic-Medium-v0", true);
    let mut policy = load(&ckpt, env.spec()).expect("retarget to Medium");
    let ep = rollout(env.as_mut(), policy.as_mut(), 2, ActMode::Greedy, false).expect("rollout");
    assert!(ep.terminated && ep.length == 32, "{} steps", ep.length);
    // And back onto an unpadded environment: the cells' scores need no padding.
    let mut env = make(&reg, "CircuitTraining-Synthetic-Medium-v0", false);
    let mut policy = load(&ckpt, env.spec()).expect("retarget to the unpadded layout");
    rollout(env.as_mut(), policy.as_mut(), 2, ActMode::Greedy, false).expect("rollout");
}
