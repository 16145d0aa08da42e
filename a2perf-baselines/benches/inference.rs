//! Policy inference latency (one observation → one action, one core), one PPO minibatch update,
//! and a masked softmax gradient right after a GEMM with and without `vzeroupper` in between.
//!
//! Run with `cargo bench -p a2perf-baselines --bench inference`.

use std::collections::BTreeMap;
use std::hint::black_box;

use a2perf_baselines::batch::ObsLayout;
use a2perf_baselines::model::{DiscreteNet, GaussianArch, NetOptions};
use a2perf_baselines::nn::dist::masked;
use a2perf_baselines::nn::optim::Adam;
use a2perf_baselines::nn::{MlpWs, clear_upper_simd};
use a2perf_baselines::{Head, NetPolicy};
use a2perf_core::{ActMode, EnvSpec, Observation, Policy, Registry, RngStream, Space, Value};
use criterion::{Criterion, criterion_group, criterion_main};

fn locomotion_spec() -> EnvSpec {
    EnvSpec {
        id: "Bench-Locomotion".into(),
        observation_space: Space::uniform_box(&[160], -10.0, 10.0),
        action_space: Space::uniform_box(&[12], -std::f32::consts::TAU, std::f32::consts::TAU),
        max_episode_steps: None,
        metadata: BTreeMap::new(),
    }
}

fn locomotion(c: &mut Criterion) {
    let spec = locomotion_spec();
    let arch = GaussianArch::new(160, 12, &[512, 256], true);
    let params = arch.init_params(&mut RngStream::new(0, "bench"), -0.5);
    let mut policy = NetPolicy::new(
        "ppo",
        &spec,
        Head::Gaussian(arch.clone()),
        params.clone(),
        None,
        0,
    )
    .unwrap();
    let mut rng = RngStream::new(1, "obs");
    let obs = Observation::flat((0..160).map(|_| rng.normal() as f32).collect());
    c.bench_function("inference/locomotion_mlp_160_512_256_12", |b| {
        b.iter(|| black_box(policy.act(black_box(&obs), ActMode::Greedy).unwrap()))
    });

    // One PPO minibatch step of the locomotion actor-critic: forward, backward, Adam (batch 64).
    let batch = 64;
    let x: Vec<f32> = (0..batch * 160).map(|_| rng.normal() as f32).collect();
    let dmean: Vec<f32> = (0..batch * 12)
        .map(|_| rng.normal() as f32 * 0.01)
        .collect();
    let dv: Vec<f32> = (0..batch).map(|_| rng.normal() as f32 * 0.01).collect();
    let mut p = params;
    let mut grads = vec![0.0; p.len()];
    let mut adam = Adam::new(p.len());
    let (mut wa, mut wc) = (MlpWs::default(), MlpWs::default());
    let critic = arch.critic.clone().unwrap();
    c.bench_function("ppo_update/locomotion_minibatch_64", |b| {
        b.iter(|| {
            grads.fill(0.0);
            arch.actor.forward(&p, &x, batch, &mut wa);
            critic.forward(&p, &x, batch, &mut wc);
            arch.actor
                .backward(&p, &mut grads, &x, &dmean, &mut wa, None);
            critic.backward(&p, &mut grads, &x, &dv, &mut wc, None);
            adam.step(&mut p, &grads, 3e-4);
            black_box(&p);
        })
    });
}

fn domain_policy(
    c: &mut Criterion,
    name: &str,
    env_id: &str,
    env_params: &[(&str, Value)],
    opts: NetOptions,
) {
    let mut reg = Registry::new();
    a2perf_web::register(&mut reg);
    a2perf_circuit::register(&mut reg);
    let params: BTreeMap<String, Value> = env_params
        .iter()
        .map(|(k, v)| (k.to_string(), v.clone()))
        .collect();
    let Ok(mut env) = reg.make_env(env_id, &params) else {
        eprintln!("skipping {name}: cannot build {env_id}");
        return;
    };
    let spec = env.spec().clone();
    let obs = env.reset(Some(0)).unwrap();
    let layout = ObsLayout::from_spec(&spec).unwrap();
    let net = DiscreteNet::for_spec(&spec, &layout, &opts, false).unwrap();
    let params = net.init_params(&mut RngStream::new(0, "bench"));
    eprintln!(
        "{name}: {} network, {} parameters",
        net.kind(),
        params.len()
    );
    let mut policy = NetPolicy::new("ppo", &spec, Head::Discrete(net), params, None, 0).unwrap();
    c.bench_function(&format!("inference/{name}"), |b| {
        b.iter(|| black_box(policy.act(black_box(&obs), ActMode::Greedy).unwrap()))
    });
}

fn domains(c: &mut Criterion) {
    domain_policy(
        c,
        "web_difficulty_01_paper_dims",
        "WebNavigation-Difficulty-01-v0",
        &[("num_websites", Value::Int(1))],
        NetOptions::default(),
    );
    domain_policy(
        c,
        "circuit_synthetic_small",
        "CircuitTraining-Synthetic-Small-v0",
        &[],
        NetOptions {
            hidden_sizes: vec![64, 64],
            latent_dim: 32,
            ..NetOptions::default()
        },
    );
    domain_policy(
        c,
        "circuit_synthetic_ariane",
        "CircuitTraining-Synthetic-Ariane-v0",
        &[],
        NetOptions {
            hidden_sizes: vec![64, 64],
            latent_dim: 32,
            ..NetOptions::default()
        },
    );
}

/// One 64×64 faer GEMM, then the softmax gradient of a 12,500-action web page with 3,738 legal
/// actions (a BC row): over the mask (`log_softmax` + `grad_logp`) and over the legal list
/// (`grad_logp_legal`), each with the GEMM's upper register halves left in use (`dirty`) and
/// cleared (`clean`, [`clear_upper_simd`], what the networks' own GEMMs do).
fn softmax_after_gemm(c: &mut Criterion) {
    use faer::linalg::matmul::matmul;
    use faer::{Accum, MatMut, MatRef, Par};
    let n = 12_500;
    let mut rng = RngStream::new(2, "logits");
    let z: Vec<f32> = (0..n).map(|_| (rng.normal() * 3.0) as f32).collect();
    let mask: Vec<bool> = (0..n).map(|i| i % 10 < 3).collect();
    let legal: Vec<usize> = (0..n).filter(|&i| mask[i]).collect();
    let a = vec![0.5f32; 64 * 64];
    let mut out = vec![0.0f32; 64 * 64];
    let (mut lp, mut d) = (vec![0.0f32; n], vec![0.0f32; n]);
    for clean in [false, true] {
        let mut gemm = || {
            let am = MatRef::from_row_major_slice(&a, 64, 64);
            let om = MatMut::from_row_major_slice_mut(&mut out, 64, 64);
            matmul(om, Accum::Replace, am, am, 1.0f32, Par::Seq);
            if clean {
                clear_upper_simd();
            }
        };
        let state = if clean { "clean" } else { "dirty" };
        c.bench_function(&format!("softmax_after_gemm/mask_{state}"), |b| {
            b.iter(|| {
                gemm();
                masked::log_softmax(black_box(&z), Some(&mask), &mut lp);
                masked::grad_logp(&lp, 3, -0.01, &mut d);
            })
        });
        c.bench_function(&format!("softmax_after_gemm/legal_{state}"), |b| {
            b.iter(|| {
                gemm();
                masked::grad_logp_legal(black_box(&z), &legal, 3, -0.01, &mut d);
            })
        });
    }
    black_box(&d);
}

criterion_group! {
    name = benches;
    config = Criterion::default().sample_size(30).measurement_time(std::time::Duration::from_secs(3)).warm_up_time(std::time::Duration::from_secs(1));
    targets = locomotion, domains, softmax_after_gemm
}
criterion_main!(benches);
