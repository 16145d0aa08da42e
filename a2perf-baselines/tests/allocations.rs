//! "Batched forward/backward with no allocation in the steady state": heap allocations of one
//! minibatch update (gather rows, forward, loss gradient, backward, gradient clipping, Adam) of
//! every network family, counted by a per-thread counting global allocator once the workspaces
//! have met the minibatches (see [`steady_state_allocations`]).

use std::collections::BTreeMap;

use a2perf_baselines::batch::{ObsBatch, ObsLayout};
use a2perf_baselines::model::{DiscreteNet, GaussianArch, NetOptions, SquashedArch};
use a2perf_baselines::nn::dist::masked;
use a2perf_baselines::nn::optim::Adam;
use a2perf_baselines::nn::{MlpWs, clip_grad_norm};
use a2perf_core::alloc_count::{CountingAllocator, count_allocations};
use a2perf_core::{Action, Env, Registry, RngStream, Space, Step, Value};

#[global_allocator]
static ALLOC: CountingAllocator = CountingAllocator;

fn normals(rng: &mut RngStream, n: usize, scale: f32) -> Vec<f32> {
    (0..n).map(|_| rng.normal() as f32 * scale).collect()
}

/// Allocations of a second epoch over four minibatches (in another order), after a first epoch
/// over the same four. Workspaces only grow, to the largest minibatch met: for networks whose work
/// depends on the contents (the web network runs its MLPs on the active fields and elements only),
/// a minibatch with more active rows than any before grows them once (amortised doubling, as
/// `Vec`); after that, updates allocate nothing. PPO's later epochs are exactly this case.
fn steady_state_allocations(mut update: impl FnMut(usize)) -> usize {
    for k in 0..4 {
        update(k);
    }
    count_allocations(|| {
        for k in [3, 1, 0, 2] {
            update(k);
        }
    })
    .0
}

/// Steady-state allocations of the locomotion PPO network's update at the paper's size, batch
/// 128 (the paper's minibatch): `passes(arch, params, x, batch, dmean, dvalues, grads)` runs the
/// forward and backward passes; then gradient clipping and Adam.
fn gaussian_update_allocations(
    mut passes: impl FnMut(&GaussianArch, &[f32], &[f32], usize, &[f32], &[f32], &mut [f32]) + Send,
    on_pool: bool,
) -> usize {
    let (obs_dim, act_dim, batch) = (160, 12, 128);
    let arch = GaussianArch::new(obs_dim, act_dim, &[512, 256], true);
    let mut rng = RngStream::new(0, "alloc");
    let mut p = arch.init_params(&mut rng, -1.0);
    let data = normals(&mut rng, 4 * batch * obs_dim, 1.0);
    let dmean = normals(&mut rng, batch * act_dim, 0.01);
    let dv = normals(&mut rng, batch, 0.01);
    let mut grads = vec![0.0; p.len()];
    let mut adam = Adam::new(p.len());
    let mut count = || {
        steady_state_allocations(|k| {
            let x = &data[k * batch * obs_dim..(k + 1) * batch * obs_dim];
            grads.fill(0.0);
            passes(&arch, &p, x, batch, &dmean, &dv, &mut grads);
            clip_grad_norm(&mut grads, 0.5);
            adam.step(&mut p, &grads, 3e-4);
        })
    };
    let n = if on_pool {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(2)
            .build()
            .expect("a pool of two threads");
        pool.install(count)
    } else {
        count()
    };
    assert!(p.iter().all(|v| v.is_finite()));
    n
}

#[test]
fn gaussian_actor_critic_update_allocates_nothing() {
    let (mut wa, mut wc) = (MlpWs::default(), MlpWs::default());
    let n = gaussian_update_allocations(
        |arch, p, x, batch, dmean, dv, grads| {
            let critic = arch.critic.as_ref().expect("value head");
            arch.actor.forward(p, x, batch, &mut wa);
            critic.forward(p, x, batch, &mut wc);
            arch.actor.backward(p, grads, x, dmean, &mut wa, None);
            critic.backward(p, grads, x, dv, &mut wc, None);
        },
        false,
    );
    assert_eq!(n, 0, "{n} allocations in 4 steady-state Gaussian updates");
}

#[test]
fn gaussian_update_on_two_threads_allocates_nothing() {
    // PPO's update as PPO runs it: on a thread of rayon's pool, the actor's and critic's
    // passes side by side and Adam in two halves. Allocations counted on that thread, where
    // every hand-off to the other thread is made.
    let (mut wa, mut wc) = (MlpWs::default(), MlpWs::default());
    let n = gaussian_update_allocations(
        |arch, p, x, batch, dmean, dv, grads| {
            arch.forward_both(p, x, batch, &mut wa, &mut wc);
            arch.backward_both(p, grads, x, dmean, dv, &mut wa, &mut wc);
        },
        true,
    );
    assert_eq!(n, 0, "{n} allocations in 4 steady-state two-thread updates");
}

#[test]
fn squashed_actor_update_allocates_nothing() {
    // SAC's actor (mean and log-std heads in one MLP) with an input gradient, as its update
    // back-propagates through the critic into the action.
    let (obs_dim, act_dim, batch) = (160, 12, 256);
    let arch = SquashedArch::new(obs_dim, act_dim, &[256, 256]);
    let mut rng = RngStream::new(1, "alloc");
    let mut p = vec![0.0; arch.num_params];
    arch.actor.init(&mut p, &mut rng, 0.01);
    let data = normals(&mut rng, 4 * batch * obs_dim, 1.0);
    let dout = normals(&mut rng, batch * 2 * act_dim, 0.01);
    let mut dx = vec![0.0; batch * obs_dim];
    let mut grads = vec![0.0; p.len()];
    let mut adam = Adam::new(p.len());
    let mut ws = MlpWs::default();
    let n = steady_state_allocations(|k| {
        let x = &data[k * batch * obs_dim..(k + 1) * batch * obs_dim];
        grads.fill(0.0);
        arch.actor.forward(&p, x, batch, &mut ws);
        arch.actor
            .backward(&p, &mut grads, x, &dout, &mut ws, Some(&mut dx));
        adam.step(&mut p, &grads, 3e-4);
    });
    assert_eq!(
        n, 0,
        "{n} allocations in 4 steady-state squashed-actor updates"
    );
}

/// One masked policy-gradient minibatch update of a domain's discrete network on observations
/// collected from the real environment.
fn discrete_update_allocations(env_id: &str, env_params: &[(&str, Value)], opts: NetOptions) {
    let mut reg = Registry::new();
    a2perf_web::register(&mut reg);
    a2perf_circuit::register(&mut reg);
    let params: BTreeMap<String, Value> = env_params
        .iter()
        .map(|(k, v)| (k.to_string(), v.clone()))
        .collect();
    let mut env = reg.make_env(env_id, &params).expect("built-in environment");
    let spec = env.spec().clone();
    let layout = ObsLayout::from_spec(&spec).expect("layout");
    let Space::Discrete { n: num_actions } = spec.action_space else {
        panic!("{env_id}: expected a discrete action space");
    };

    // A store of real observations (with their masks) from random legal episodes.
    let batch = 32;
    let mut store = ObsBatch::new(&layout);
    let mut rng = RngStream::new(2, "alloc");
    let mut step = Step::default();
    let mut seed = 0;
    env.reset_into(Some(seed), &mut step.observation).unwrap();
    while store.len() < 4 * batch {
        store.push(&step.observation).unwrap();
        let legal: Vec<usize> = match &step.observation.action_mask {
            Some(m) => (0..m.len()).filter(|&i| m[i]).collect(),
            None => (0..num_actions).collect(),
        };
        let a = legal[rng.index(legal.len())];
        env.step_into(&Action::Discrete(a), &mut step).unwrap();
        if step.done() {
            seed += 1;
            env.reset_into(Some(seed), &mut step.observation).unwrap();
        }
    }

    let mut net = DiscreteNet::for_spec(&spec, &layout, &opts, true).expect("network");
    let mut p = net.init_params(&mut rng);
    let mut grads = vec![0.0; p.len()];
    let mut adam = Adam::new(p.len());
    let mut mb = ObsBatch::new(&layout);
    let mut rows = vec![0; batch];
    let mut logp = vec![0.0; num_actions];
    let mut dlogits = vec![0.0; batch * num_actions];
    let mut dv = vec![0.0; batch];
    let actions: Vec<usize> = (0..4 * batch)
        .map(|r| {
            let legal: Vec<usize> = (0..num_actions)
                .filter(|&i| store.mask(r).is_none_or(|m| m[i]))
                .collect();
            legal[rng.index(legal.len())]
        })
        .collect();
    let n = steady_state_allocations(|k| {
        for (i, r) in rows.iter_mut().enumerate() {
            *r = k * batch + i;
        }
        mb.gather(&store, &rows);
        grads.fill(0.0);
        net.forward(&p, &mb);
        dlogits.fill(0.0);
        for i in 0..batch {
            let logits = &net.logits()[i * num_actions..(i + 1) * num_actions];
            assert!(masked::log_softmax(logits, mb.mask(i), &mut logp));
            let out = &mut dlogits[i * num_actions..(i + 1) * num_actions];
            masked::grad_logp(&logp, actions[rows[i]], -1.0 / batch as f32, out);
            masked::grad_entropy(&logp, -0.01 / batch as f32, out);
            dv[i] = net.values()[i] / batch as f32;
        }
        net.backward(&p, &mut grads, &mb, &dlogits, Some(&dv));
        clip_grad_norm(&mut grads, 1.0);
        adam.step(&mut p, &grads, 1e-3);
    });
    assert_eq!(
        n,
        0,
        "{env_id}: {n} allocations in 4 steady-state {} updates",
        net.kind()
    );
    assert!(p.iter().all(|v| v.is_finite()));
}

#[test]
fn web_network_update_allocates_nothing() {
    discrete_update_allocations(
        "WebNavigation-Difficulty-01-v0",
        &[("num_websites", Value::Int(1))],
        NetOptions::default(),
    );
}

#[test]
fn circuit_network_update_allocates_nothing() {
    discrete_update_allocations(
        "CircuitTraining-Synthetic-Small-v0",
        &[],
        NetOptions {
            hidden_sizes: vec![64, 64],
            latent_dim: 16,
            ..NetOptions::default()
        },
    );
}
