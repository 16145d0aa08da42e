//! One DDQN update of the web navigation network at the paper's dimensions (embedding 100,
//! latent 50, batch 256): the online forward on the next observations, the target forward on
//! them, the online forward on the observations, the backward pass and Adam's step — the
//! learner's work per update, which is nearly all of a paper-scale web DDQN run's time.
//!
//! Run with `cargo bench -p a2perf-baselines --bench web_update`. Besides criterion's wall
//! time it prints the median on-CPU time of the update thread (from
//! `/proc/thread-self/schedstat`, Linux only, over rounds of updates), which a loaded machine
//! disturbs less.

mod common;

use std::collections::BTreeMap;
use std::hint::black_box;

use a2perf_baselines::batch::{ObsBatch, ObsLayout};
use a2perf_baselines::model::{DiscreteNet, NetOptions};
use a2perf_baselines::nn::optim::Adam;
use a2perf_core::{Registry, RngStream, Value};
use criterion::{Criterion, criterion_group, criterion_main};

const BATCH: usize = 256;
/// Updates per timed round of thread CPU time.
const ROUND: usize = 40;

/// `2 * BATCH` observations of random legal play on five generated difficulty-1 websites, as
/// consecutive (observation, next observation) rows.
fn transitions(layout: &ObsLayout) -> Option<(ObsBatch, ObsBatch)> {
    let mut reg = Registry::new();
    a2perf_web::register(&mut reg);
    let params = BTreeMap::from([("num_websites".to_string(), Value::Int(5))]);
    let mut env = reg
        .make_env("WebNavigation-Difficulty-01-v0", &params)
        .ok()?;
    let (obs, next, _) = common::random_play(env.as_mut(), layout, BATCH)?;
    Some((obs, next))
}

fn web_update(c: &mut Criterion) {
    let mut reg = Registry::new();
    a2perf_web::register(&mut reg);
    let params = BTreeMap::from([("num_websites".to_string(), Value::Int(5))]);
    let Ok(env) = reg.make_env("WebNavigation-Difficulty-01-v0", &params) else {
        eprintln!("skipping web_update: cannot build the environment");
        return;
    };
    let spec = env.spec().clone();
    let layout = ObsLayout::from_spec(&spec).expect("web layout");
    let Some((obs, next)) = transitions(&layout) else {
        eprintln!("skipping web_update: cannot play the environment");
        return;
    };
    if let Some(m) = layout.index("dom_mask") {
        let active: f32 = obs.tensor(m).iter().filter(|&&x| x > 0.5).count() as f32;
        eprintln!(
            "web_update: {:.1} active elements per page",
            active / BATCH as f32
        );
    }
    let mut net =
        DiscreteNet::for_spec(&spec, &layout, &NetOptions::default(), false).expect("web network");
    let mut target = net.clone();
    let mut p = net.init_params(&mut RngStream::new(0, "bench/init"));
    let target_p = p.clone();
    let n = net.num_actions();
    let mut grads = vec![0.0; p.len()];
    let mut adam = Adam::new(p.len());
    let mut dq = vec![0.0; BATCH * n];
    let mut rng = RngStream::new(1, "bench/actions");
    let actions: Vec<usize> = (0..BATCH)
        .map(|k| {
            let mask = obs.mask(k).expect("web observations carry a mask");
            let legal: Vec<usize> = (0..n).filter(|&a| mask[a]).collect();
            legal[rng.index(legal.len())]
        })
        .collect();
    let mut update = || {
        net.forward(&p, &next);
        target.forward(&target_p, &next);
        net.forward(&p, &obs);
        for (k, &a) in actions.iter().enumerate() {
            let err = net.logits()[k * n + a] - target.logits()[k * n + a];
            dq[k * n + a] = 2.0 * err / BATCH as f32;
        }
        grads.fill(0.0);
        net.backward(&p, &mut grads, &obs, &dq, None);
        // As the DDQN learner: clear the entries set, keeping `dq` zero between updates.
        for (k, &a) in actions.iter().enumerate() {
            dq[k * n + a] = 0.0;
        }
        adam.step(&mut p, &grads, 4e-5);
        black_box(&p);
    };
    let cpu = common::thread_cpu_rounds(7, ROUND, &mut update);
    if !cpu.is_empty() {
        eprintln!(
            "ddqn_update/web_paper_dims_batch_256: thread CPU per update, median of {} rounds of \
             {ROUND}: {:.2} ms (rounds {:.2?} ms)",
            cpu.len(),
            cpu[cpu.len() / 2],
            cpu
        );
    }
    c.bench_function("ddqn_update/web_paper_dims_batch_256", |b| {
        b.iter(&mut update)
    });
}

criterion_group! {
    name = benches;
    config = Criterion::default().sample_size(10).measurement_time(std::time::Duration::from_secs(10)).warm_up_time(std::time::Duration::from_secs(1));
    targets = web_update
}
criterion_main!(benches);
