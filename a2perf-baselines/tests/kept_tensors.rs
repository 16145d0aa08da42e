//! A batch that keeps only the tensors a network reads ([`DiscreteNet::inputs`],
//! [`ObsBatch::keep_tensors`]) gives that network the same logits, values and gradients, bit for
//! bit, as a batch holding every tensor: the list of inputs is complete. The learners fill their
//! minibatches this way (DDQN's replay samples, PPO's rollouts), so a tensor missing from the
//! list would make this test fail, not a run silently learn from empty rows. It also checks
//! [`DiscreteNet::infer_scored`], the pass DDQN's targets take, against the kept-activations one.

mod common;

use a2perf_baselines::{DiscreteNet, NetOptions, ObsBatch, ObsLayout};
use a2perf_core::{Action, Observation, RngStream, Value};
use common::{domains_registry, env_params};

/// A few observations of `id`, from random legal moves.
fn observations(id: &str, params: &[(&str, Value)]) -> (a2perf_core::EnvSpec, Vec<Observation>) {
    let reg = domains_registry();
    let mut env = reg
        .make_env(id, &env_params(params))
        .unwrap_or_else(|e| panic!("{id}: {e}"));
    let spec = env.spec().clone();
    let mut rng = RngStream::new(5, "moves");
    let mut obs = vec![env.reset(Some(2)).unwrap()];
    while obs.len() < 4 {
        let last = obs.last().unwrap();
        let Some(a @ Action::Discrete(_)) = spec
            .action_space
            .sample(&mut rng, last.action_mask.as_deref())
        else {
            break;
        };
        let step = env.step(&a).unwrap();
        let done = step.done();
        obs.push(step.observation);
        if done {
            obs.push(env.reset(None).unwrap());
        }
    }
    (spec, obs)
}

fn same_bits(a: &[f32], b: &[f32]) -> bool {
    a.len() == b.len() && a.iter().zip(b).all(|(x, y)| x.to_bits() == y.to_bits())
}

fn check(id: &str, params: &[(&str, Value)], kind: &str, opts: NetOptions) {
    let (spec, obs) = observations(id, params);
    let layout = ObsLayout::from_spec(&spec).unwrap();
    let mut net = DiscreteNet::for_spec(&spec, &layout, &opts, true).unwrap();
    assert_eq!(net.kind(), kind, "{id}");
    let keep = net
        .inputs()
        .unwrap_or_else(|| panic!("{id}: the {kind} network reads named tensors"));
    assert!(
        keep.len() < layout.tensors.len(),
        "{id}: the {kind} network reads {} of {} tensors",
        keep.len(),
        layout.tensors.len()
    );
    let p = net.init_params(&mut RngStream::new(3, "weights"));

    let mut full = ObsBatch::new(&layout);
    let mut kept = ObsBatch::new(&layout);
    kept.keep_tensors(&keep);
    for o in &obs {
        full.push(o).unwrap();
        kept.push(o).unwrap();
    }
    // Rows copied from a full batch into a kept one, in another order (PPO's minibatches).
    let order: Vec<usize> = (0..obs.len()).rev().collect();
    let mut gathered = ObsBatch::new(&layout);
    gathered.keep_tensors(&keep);
    gathered.gather(&full, &order);
    let mut reversed = ObsBatch::new(&layout);
    reversed.gather(&full, &order);

    for (a, b) in [(&full, &kept), (&reversed, &gathered)] {
        let mut results = Vec::new();
        for batch in [a, b] {
            net.forward(&p, batch);
            let logits = net.logits().to_vec();
            let values = net.values().to_vec();
            // A gradient on every finite logit, so that every parameter receives one.
            let dlogits: Vec<f32> = logits
                .iter()
                .enumerate()
                .map(|(i, z)| {
                    if z.is_finite() {
                        0.01 * (i % 7) as f32
                    } else {
                        0.0
                    }
                })
                .collect();
            let dvalues = vec![0.5; batch.len()];
            let mut grads = vec![0.0; p.len()];
            net.backward(&p, &mut grads, batch, &dlogits, Some(&dvalues));
            results.push((logits, values, grads));
        }
        let [(l0, v0, g0), (l1, v1, g1)] = [results[0].clone(), results[1].clone()];
        assert!(same_bits(&l0, &l1), "{id}: logits");
        assert!(same_bits(&v0, &v1), "{id}: values");
        assert!(same_bits(&g0, &g1), "{id}: gradients");
        assert!(g0.iter().any(|g| *g != 0.0), "{id}: no gradient at all");
    }
    // A pass no backward follows (`infer_scored`) gives the scored pass's values, bit for bit.
    for batch in [&full, &kept] {
        net.forward_scored(&p, batch);
        let (logits, values) = (net.logits().to_vec(), net.values().to_vec());
        net.infer_scored(&p, batch);
        assert!(same_bits(net.logits(), &logits), "{id}: inferred logits");
        assert!(same_bits(net.values(), &values), "{id}: inferred values");
    }
    // The kept batch holds nothing of the other tensors.
    for i in (0..layout.tensors.len()).filter(|i| !keep.contains(i)) {
        assert!(
            kept.tensor(i).is_empty() && kept.ints(i).is_empty(),
            "{id}: tensor {i}"
        );
    }
}

#[test]
fn the_circuit_network_reads_only_its_inputs() {
    for padded in [false, true] {
        check(
            "CircuitTraining-Synthetic-Small-v0",
            &[
                ("std_cell_placer", Value::Str("none".into())),
                ("padded_action", Value::Bool(padded)),
            ],
            "circuit",
            NetOptions {
                hidden_sizes: vec![16, 16],
                latent_dim: 8,
                ..NetOptions::default()
            },
        );
    }
}

#[test]
fn the_web_network_reads_only_its_inputs() {
    check(
        "WebNavigation-Difficulty-01-v0",
        &[("num_websites", Value::Int(1))],
        "web",
        NetOptions::default(),
    );
}

#[test]
#[should_panic(expected = "a backward pass needs a forward that keeps its activations")]
fn a_backward_pass_after_an_inference_pass_is_refused() {
    let (spec, obs) = observations(
        "CircuitTraining-Synthetic-Small-v0",
        &[("std_cell_placer", Value::Str("none".into()))],
    );
    let layout = ObsLayout::from_spec(&spec).unwrap();
    let mut net = DiscreteNet::for_spec(&spec, &layout, &NetOptions::default(), false).unwrap();
    let p = net.init_params(&mut RngStream::new(3, "weights"));
    let mut batch = ObsBatch::new(&layout);
    for o in &obs {
        batch.push(o).unwrap();
    }
    net.infer_scored(&p, &batch);
    let d = vec![0.0; net.logits().len()];
    let mut grads = vec![0.0; p.len()];
    net.backward(&p, &mut grads, &batch, &d, None);
}
