//! One DDQN update of the circuit network on A2Perf's padded 128×128 action canvas (batch 128,
//! as the toy's paper config), on a small grid and an Ariane-scale one, two ways in the same
//! run:
//! - `every_action`: the forward passes write all 16,384 logits per row (the padding as `−∞`),
//!   the masked argmax scans them, and the backward pass gathers the cells' gradients from a
//!   16,384-wide row — what the learner did before it learned through the scored logits;
//! - `scored`: [`DiscreteNet::forward_scored`], the argmax over the grid's cells and a
//!   gradient as wide as the grid — what `Ddqn` does, but for its two passes over the next
//!   observations, which take [`DiscreteNet::infer_scored`] (the same values, fewer bytes
//!   touched; not timed here). Both give the same bits.
//!
//! Each update: the online forward on the next observations and its masked argmax, the target
//! forward on them, the online forward on the observations, the backward pass and Adam's step.
//! The replay's decoding is not included.
//!
//! Run with `cargo bench -p a2perf-baselines --bench circuit_update`. Besides criterion's wall
//! time it prints the median on-CPU time of the update thread (from
//! `/proc/thread-self/schedstat`, Linux only, over rounds of updates), which a loaded machine
//! disturbs less.

mod common;

use std::collections::BTreeMap;
use std::hint::black_box;

use a2perf_baselines::batch::{ObsBatch, ObsLayout};
use a2perf_baselines::model::{DiscreteNet, NetOptions};
use a2perf_baselines::nn::dist::masked;
use a2perf_baselines::nn::optim::Adam;
use a2perf_core::{Action, Registry, RngStream, Value};
use criterion::{Criterion, criterion_group, criterion_main};

const BATCH: usize = 128;
/// Updates per timed round of thread CPU time.
const ROUND: usize = 40;
/// A small grid, where the padding is most of the 16,384 actions, and an Ariane-scale one.
const ENVS: [(&str, &str); 2] = [
    ("small", "CircuitTraining-Synthetic-Small-v0"),
    ("ariane_scale", "CircuitTraining-Synthetic-Ariane-v0"),
];

/// The network's logit rows, observations, next observations and the actions taken.
struct Setup {
    net: DiscreteNet,
    obs: ObsBatch,
    next: ObsBatch,
    actions: Vec<usize>,
}

/// `BATCH` transitions of random legal play on `env`'s padded layout (no standard-cell placer:
/// the bench is about the learner).
fn setup(env: &str) -> Option<Setup> {
    let mut reg = Registry::new();
    a2perf_circuit::register(&mut reg);
    let params = BTreeMap::from([
        ("std_cell_placer".to_string(), Value::Str("none".into())),
        ("padded_action".to_string(), Value::Bool(true)),
    ]);
    let mut env = reg.make_env(env, &params).ok()?;
    let spec = env.spec().clone();
    let layout = ObsLayout::from_spec(&spec).ok()?;
    let net = DiscreteNet::for_spec(&spec, &layout, &NetOptions::default(), false).ok()?;
    let (obs, next, played) = common::random_play(env.as_mut(), &layout, BATCH)?;
    let actions = played
        .iter()
        .map(|a| match a {
            Action::Discrete(a) => Some(*a),
            Action::Continuous(_) => None,
        })
        .collect::<Option<Vec<usize>>>()?;
    Some(Setup {
        net,
        obs,
        next,
        actions,
    })
}

/// Thread CPU per update, the median of seven rounds, printed under `name`.
fn report_cpu(name: &str, update: &mut dyn FnMut()) {
    let cpu = common::thread_cpu_rounds(7, ROUND, update);
    if !cpu.is_empty() {
        eprintln!(
            "{name}: thread CPU per update, median of {} rounds of {ROUND}: {:.3} ms",
            cpu.len(),
            cpu[cpu.len() / 2],
        );
    }
}

fn circuit_update(c: &mut Criterion) {
    for (label, env) in ENVS {
        bench_env(c, label, env);
    }
}

fn bench_env(c: &mut Criterion, label: &str, env: &str) {
    let Some(Setup {
        net,
        obs,
        next,
        actions,
    }) = setup(env)
    else {
        eprintln!("skipping circuit_update: cannot build or play {env}");
        return;
    };
    let p0 = net.init_params(&mut RngStream::new(0, "bench/init"));
    let mut scored = Vec::new();
    assert!(net.scored_actions_into(&mut scored), "padded layout");
    let cols: Vec<usize> = actions
        .iter()
        .map(|a| scored.binary_search(a).expect("a legal action is a cell"))
        .collect();
    let n = net.num_actions();
    for every_action in [true, false] {
        let (mut net, mut target) = (net.clone(), net.clone());
        let (mut p, target_p) = (p0.clone(), p0.clone());
        let mut grads = vec![0.0; p.len()];
        let mut adam = Adam::new(p.len());
        let width = if every_action { n } else { scored.len() };
        let mut dq = vec![0.0; BATCH * width];
        let mut update = || {
            let forward = |net: &mut DiscreteNet, p: &[f32], b: &ObsBatch| {
                if every_action {
                    net.forward(p, b);
                } else {
                    net.forward_scored(p, b);
                }
            };
            forward(&mut net, &p, &next);
            let mut best = [0usize; BATCH];
            for (k, slot) in best.iter_mut().enumerate() {
                let row = &net.logits()[k * width..(k + 1) * width];
                *slot = if every_action {
                    masked::argmax(row, next.mask(k))
                } else {
                    masked::argmax_at(row, &scored, next.mask(k))
                }
                .unwrap_or(0);
            }
            forward(&mut target, &target_p, &next);
            let boot: Vec<f32> = (0..BATCH)
                .map(|k| target.logits()[k * width + best[k]])
                .collect();
            forward(&mut net, &p, &obs);
            let col = |k: usize| if every_action { actions[k] } else { cols[k] };
            for (k, b) in boot.iter().enumerate() {
                let err = net.logits()[k * width + col(k)] - 0.99 * b.max(-1e3);
                dq[k * width + col(k)] = err.clamp(-1.0, 1.0) / BATCH as f32;
            }
            grads.fill(0.0);
            net.backward(&p, &mut grads, &obs, &dq, None);
            for k in 0..BATCH {
                dq[k * width + col(k)] = 0.0;
            }
            adam.step(&mut p, &grads, 4e-5);
            black_box(&p);
        };
        let name = format!(
            "ddqn_update/circuit_padded128_batch_128/{label}/{}",
            if every_action {
                "every_action"
            } else {
                "scored"
            }
        );
        report_cpu(&name, &mut update);
        c.bench_function(&name, |b| b.iter(&mut update));
    }
}

criterion_group! {
    name = benches;
    config = Criterion::default().sample_size(10).measurement_time(std::time::Duration::from_secs(8)).warm_up_time(std::time::Duration::from_secs(1));
    targets = circuit_update
}
criterion_main!(benches);
