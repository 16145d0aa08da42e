//! Soft Actor-Critic (Haarnoja et al.) with twin Q networks, Polyak-averaged targets
//! (τ = 0.005) and automatic entropy tuning (target entropy −|A|), as the paper's TF-Agents
//! `SacAgent`. Actions are a tanh-squashed Gaussian mapped affinely onto the box bounds.

use a2perf_core::{
    Action, Algorithm, Control, ParamKind, ParamSpec, Params, Policy, RunError, Space,
    TrainingContext, Value,
};

use crate::batch::{ObsBatch, ObsLayout};
use crate::common::*;
use crate::model::SquashedArch;
use crate::nn::dist::tanh_gaussian;
use crate::nn::optim::{Adam, LrSchedule};
use crate::nn::{Activation, Mlp, MlpWs, ParamAlloc, clip_grad_norm, ensure, polyak};
use crate::policy::{Head, NetPolicy, ObsNorm, squash_to_bounds};
use crate::replay::{ReplayBuffer, ReplaySample};
use crate::resume::{StateReader, StateWriter};

/// Version of SAC's resumable training state (2: observations are typed, so the
/// observation hashes and the stored observations of version 1 no longer apply).
const STATE_VERSION: u32 = 2;

/// SAC hyperparameters (see [`Sac::params`]).
#[derive(Clone, Debug, PartialEq)]
pub struct SacConfig {
    /// Learning rate schedule (actor, critics and temperature).
    pub lr: LrSchedule,
    /// Minibatch size.
    pub batch_size: usize,
    /// Replay capacity.
    pub replay_capacity: usize,
    /// Discount.
    pub gamma: f32,
    /// Target smoothing coefficient.
    pub tau: f32,
    /// Random-action steps before learning.
    pub learning_starts: usize,
    /// Gradient updates per environment step.
    pub updates_per_step: f32,
    /// Initial temperature α.
    pub init_alpha: f32,
    /// Gradient-norm clip.
    pub max_grad_norm: f32,
    /// Hidden sizes of actor and critics.
    pub hidden: Vec<usize>,
    /// Half-range of the squashed actions around the box centre (0 = full bounds).
    pub action_limit: f32,
    /// Normalise observations by running statistics (frozen into the policy).
    pub normalize_observations: bool,
}

/// The SAC algorithm.
#[derive(Clone, Debug)]
pub struct Sac {
    /// Hyperparameters.
    pub config: SacConfig,
}

impl Sac {
    /// Documented hyperparameters (paper: batch 256, lr 3e-4, τ 0.005, γ 0.99, target update
    /// period 1, networks 512-256; replay 2e6 in the paper).
    pub fn params() -> Vec<ParamSpec> {
        let mut v = vec![
            ParamSpec::new(
                "learning_rate",
                ParamKind::Float,
                Value::Float(3e-4),
                "Adam learning rate for actor, critics and temperature (paper: 3e-4)",
            ),
            ParamSpec::new(
                "batch_size",
                ParamKind::Int,
                Value::Int(256),
                "minibatch size (paper: 256)",
            ),
            ParamSpec::new(
                "replay_capacity",
                ParamKind::Int,
                Value::Int(1_000_000),
                "replay capacity in transitions (paper: 2e6)",
            ),
            ParamSpec::new(
                "gamma",
                ParamKind::Float,
                Value::Float(0.99),
                "discount (paper: 0.99)",
            ),
            ParamSpec::new(
                "tau",
                ParamKind::Float,
                Value::Float(0.005),
                "target smoothing coefficient (paper: 0.005, period 1)",
            ),
            ParamSpec::new(
                "learning_starts",
                ParamKind::Int,
                Value::Int(1000),
                "uniformly random steps before learning starts",
            ),
            ParamSpec::new(
                "updates_per_step",
                ParamKind::Float,
                Value::Float(1.0),
                "gradient updates per environment step",
            ),
            ParamSpec::new(
                "init_alpha",
                ParamKind::Float,
                Value::Float(1.0),
                "initial entropy temperature (tuned automatically towards entropy −|A|)",
            ),
            ParamSpec::new(
                "max_grad_norm",
                ParamKind::Float,
                Value::Float(0.0),
                "global gradient-norm clipping, 0 = off",
            ),
            ParamSpec::new(
                "action_limit",
                ParamKind::Float,
                Value::Float(0.0),
                "squash actions into centre ± action_limit instead of the full bounds, 0 = full bounds (locomotion's ±2π pose offsets are far wider than useful)",
            ),
            ParamSpec::new(
                "normalize_observations",
                ParamKind::Bool,
                Value::Bool(false),
                "running observation normalisation, as PPO's (the replay keeps raw observations; minibatches are normalised with the current statistics)",
            ),
        ];
        v.extend(schedule_specs());
        v.extend(
            net_specs(&[512, 256])
                .into_iter()
                .filter(|s| s.name == "hidden_sizes"),
        );
        v
    }

    /// Builds SAC from resolved hyperparameters.
    pub fn from_params(p: &Params) -> Result<Self, RunError> {
        let lr = positive_f32(p, "learning_rate")?;
        let hidden = match p.get("hidden_sizes") {
            Some(Value::List(items)) => items
                .iter()
                .map(|v| {
                    v.as_i64()
                        .and_then(|i| usize::try_from(i).ok())
                        .filter(|i| *i > 0)
                })
                .collect::<Option<Vec<_>>>()
                .filter(|h| !h.is_empty())
                .ok_or_else(|| {
                    invalid(
                        "hidden_sizes",
                        "must be a non-empty list of positive integers",
                    )
                })?,
            _ => {
                return Err(invalid(
                    "hidden_sizes",
                    "must be a list of positive integers",
                ));
            }
        };
        Ok(Self {
            config: SacConfig {
                lr: schedule(p, lr)?,
                batch_size: positive_usize(p, "batch_size")?,
                replay_capacity: positive_usize(p, "replay_capacity")?,
                gamma: unit_f32(p, "gamma")?,
                tau: unit_f32(p, "tau")?,
                learning_starts: p.usize("learning_starts").map_err(hp)?,
                updates_per_step: nonneg_f32(p, "updates_per_step")?,
                init_alpha: positive_f32(p, "init_alpha")?,
                max_grad_norm: nonneg_f32(p, "max_grad_norm")?,
                action_limit: nonneg_f32(p, "action_limit")?,
                normalize_observations: p.bool("normalize_observations").map_err(hp)?,
                hidden,
            },
        })
    }
}

/// One Q network with its parameters, target copy, optimiser and workspaces.
struct Critic {
    params: Vec<f32>,
    target: Vec<f32>,
    grads: Vec<f32>,
    adam: Adam,
    ws: MlpWs,
    ws_t: MlpWs,
}

impl Algorithm for Sac {
    fn name(&self) -> &str {
        "sac"
    }

    /// Resumable: the state saved at every checkpoint interval holds the actor (parameters,
    /// observation statistics), both critics with their targets and optimisers, the temperature
    /// and its optimiser, the three random streams, the update credit, the whole replay buffer
    /// and every environment's current episode.
    fn train(&mut self, ctx: &mut TrainingContext<'_>) -> Result<Box<dyn Policy>, RunError> {
        let cfg = self.config.clone();
        let resume = ctx.take_resume_state();
        let (mut venv, spec) = make_vec_env(ctx)?;
        let n_env = venv.len();
        let d = match &spec.action_space {
            Space::Box { low, high, .. } => {
                if low.iter().chain(high).any(|x| !x.is_finite()) {
                    return Err(RunError::Unsupported(
                        "SAC needs finite action bounds to squash into".into(),
                    ));
                }
                low.len()
            }
            _ => return Err(RunError::Unsupported("SAC needs a box action space".into())),
        };
        let layout = ObsLayout::from_spec(&spec)?;
        let od = layout.total_dim();
        let arch = SquashedArch::new(od, d, &cfg.hidden);
        let mut init = ctx.rng("sac/init");
        let mut actor_params = vec![0.0; arch.num_params];
        arch.actor.init(&mut actor_params, &mut init, 0.01);
        let mut qsizes = vec![od + d];
        qsizes.extend_from_slice(&cfg.hidden);
        qsizes.push(1);
        let mut qalloc = ParamAlloc::new();
        let qnet = Mlp::new(&mut qalloc, &qsizes, Activation::Relu);
        let mut critics: Vec<Critic> = (0..2)
            .map(|_| {
                let mut p = vec![0.0; qalloc.len()];
                qnet.init(&mut p, &mut init, 1.0);
                Critic {
                    target: p.clone(),
                    grads: vec![0.0; p.len()],
                    adam: Adam::new(p.len()),
                    params: p,
                    ws: MlpWs::default(),
                    ws_t: MlpWs::default(),
                }
            })
            .collect();
        let actor = arch.actor.clone();
        let mut policy = NetPolicy::new(
            "sac",
            &spec,
            Head::Squashed(arch),
            actor_params,
            None,
            ctx.seed(),
        )?;
        policy.action_limit = cfg.action_limit;
        if cfg.normalize_observations {
            policy.obs_norm = ObsNorm::for_head(&policy.head, &layout);
        }
        let mut actor_adam = Adam::new(policy.params.len());
        let mut actor_grads = vec![0.0f32; policy.params.len()];
        let mut log_alpha = cfg.init_alpha.ln();
        let mut alpha_adam = Adam::new(1);
        let target_entropy = -(d as f32);

        let mut replay = ReplayBuffer::new(&layout, cfg.replay_capacity, d);
        let mut sample = ReplaySample::new(&layout);
        let mut idx = Vec::new();
        let mut rng = ctx.rng("sac/explore");
        let mut noise_rng = ctx.rng("sac/update-noise");
        let mut sample_rng = ctx.rng("sac/replay");
        let mut cur = ObsBatch::new(&layout);
        // `cur` normalised for acting; the replay stores raw observations.
        let mut cur_n = ObsBatch::new(&layout);
        let mut actions = vec![Action::Continuous(vec![0.0; d]); n_env];
        let mut a_norm = vec![0.0f32; n_env * d];
        let mut ws_actor = MlpWs::default();
        let (mut x, mut xn) = (Vec::new(), Vec::new());
        let (mut qin, mut eps, mut a_pi, mut logp) =
            (Vec::new(), Vec::new(), Vec::new(), Vec::new());
        let (mut y, mut dq, mut dqin, mut dout, mut scratch) =
            (Vec::new(), Vec::new(), Vec::new(), Vec::new(), Vec::new());
        let (low, high) = match &spec.action_space {
            Space::Box { low, high, .. } => (
                low.iter().map(|x| *x as f32).collect::<Vec<f32>>(),
                high.iter().map(|x| *x as f32).collect::<Vec<f32>>(),
            ),
            _ => (Vec::new(), Vec::new()),
        };
        let (mut qa, mut qb, mut out_buf) = (Vec::new(), Vec::new(), Vec::new());
        let total = ctx.settings().total_env_steps.max(1);
        let mut env_steps = 0u64;
        let mut credit = 0.0f32;

        cur.resize(n_env);
        match &resume {
            Some(bytes) => {
                let mut r = StateReader::new(bytes, "sac", STATE_VERSION)?;
                policy.load_training_state(&mut r)?;
                for (k, c) in critics.iter_mut().enumerate() {
                    r.f32s_into(&format!("critic {k} parameters"), &mut c.params)?;
                    r.f32s_into(&format!("critic {k} target"), &mut c.target)?;
                    c.adam.load(&format!("critic {k}"), &mut r)?;
                }
                actor_adam.load("actor", &mut r)?;
                log_alpha = r.f32()?;
                alpha_adam.load("temperature", &mut r)?;
                rng = r.rng()?;
                noise_rng = r.rng()?;
                sample_rng = r.rng()?;
                credit = r.f32()?;
                env_steps = r.u64()?;
                replay.load(&mut r)?;
                for (i, out) in r.envs(&mut venv, &mut |m| ctx.warn(m))?.iter().enumerate() {
                    cur.write_row(i, &out.step.observation)?;
                }
                r.finish()?;
            }
            None => {
                for (i, out) in venv.reset_all()?.iter().enumerate() {
                    cur.write_row(i, &out.step.observation)?;
                }
            }
        }
        loop {
            if let Some(n) = &mut policy.obs_norm {
                n.update(&cur, n_env);
            }
            if (env_steps as usize) < cfg.learning_starts {
                for v in a_norm.iter_mut() {
                    *v = rng.range(-1.0, 1.0) as f32;
                }
            } else {
                match &policy.obs_norm {
                    Some(n) => {
                        cur_n.resize(n_env);
                        for i in 0..n_env {
                            cur_n.copy_row(i, &cur, i);
                            n.apply(&mut cur_n, i);
                        }
                        cur_n.concat_into(&mut x);
                    }
                    None => cur.concat_into(&mut x),
                }
                let out = actor.forward(&policy.params, &x, n_env, &mut ws_actor);
                ensure(&mut eps, d);
                for i in 0..n_env {
                    for e in eps[..d].iter_mut() {
                        *e = rng.normal() as f32;
                    }
                    let row = &out[i * 2 * d..(i + 1) * 2 * d];
                    tanh_gaussian::sample(
                        &row[..d],
                        &row[d..],
                        &eps[..d],
                        &mut a_norm[i * d..(i + 1) * d],
                    );
                }
            }
            for (i, slot) in actions.iter_mut().enumerate() {
                if let Action::Continuous(v) = slot {
                    for k in 0..d {
                        v[k] =
                            squash_to_bounds(a_norm[i * d + k], low[k], high[k], cfg.action_limit);
                    }
                }
            }
            let outs = venv.step_all(&actions)?;
            for (i, out) in outs.iter().enumerate() {
                let next = if out.step.done() {
                    &out.final_observation
                } else {
                    &out.step.observation
                };
                replay.push(
                    i,
                    &cur,
                    i,
                    next,
                    0,
                    &a_norm[i * d..(i + 1) * d],
                    out.step.reward as f32,
                    out.step.terminated,
                )?;
            }
            for (i, out) in outs.iter().enumerate() {
                cur.write_row(i, &out.step.observation)?;
            }
            env_steps += n_env as u64;

            if !replay.is_empty() && env_steps as usize >= cfg.learning_starts {
                credit += cfg.updates_per_step * n_env as f32;
                let lr = cfg.lr.at(env_steps as f64 / total as f64);
                while credit >= 1.0 {
                    credit -= 1.0;
                    replay.sample(cfg.batch_size, &mut sample_rng, &mut idx, &mut sample);
                    let b = sample.obs.len();
                    if let Some(n) = &policy.obs_norm {
                        for r in 0..b {
                            n.apply(&mut sample.obs, r);
                            n.apply(&mut sample.next, r);
                        }
                    }
                    let alpha = log_alpha.exp();
                    sample.obs.concat_into(&mut x);
                    sample.next.concat_into(&mut xn);
                    // Targets: y = r + γ(1−done)(min Q'(s', a') − α log π(a'|s')).
                    let out = actor.forward(&policy.params, &xn, b, &mut ws_actor);
                    ensure(&mut eps, b * d);
                    ensure(&mut a_pi, b * d);
                    ensure(&mut logp, b);
                    for e in eps[..b * d].iter_mut() {
                        *e = noise_rng.normal() as f32;
                    }
                    for k in 0..b {
                        let row = &out[k * 2 * d..(k + 1) * 2 * d];
                        logp[k] = tanh_gaussian::sample(
                            &row[..d],
                            &row[d..],
                            &eps[k * d..(k + 1) * d],
                            &mut a_pi[k * d..(k + 1) * d],
                        );
                    }
                    concat_obs_action(&xn, &a_pi, b, od, d, &mut qin);
                    ensure(&mut y, b);
                    let (c0, c1) = critics.split_at_mut(1);
                    let (c0, c1) = (&mut c0[0], &mut c1[0]);
                    let q1 = qnet.forward(&c0.target, &qin, b, &mut c0.ws_t);
                    let q2 = qnet.forward(&c1.target, &qin, b, &mut c1.ws_t);
                    for k in 0..b {
                        let boot = if sample.terminated[k] {
                            0.0
                        } else {
                            q1[k].min(q2[k]) - alpha * logp[k]
                        };
                        y[k] = sample.rewards[k] + cfg.gamma * boot;
                    }
                    // Critic regression on the stored actions.
                    concat_obs_action(&x, &sample.act_c, b, od, d, &mut qin);
                    ensure(&mut dq, b);
                    for c in critics.iter_mut() {
                        let q = qnet.forward(&c.params, &qin, b, &mut c.ws);
                        for k in 0..b {
                            dq[k] = 2.0 * (q[k] - y[k]) / b as f32;
                        }
                        c.grads.fill(0.0);
                        qnet.backward(&c.params, &mut c.grads, &qin, &dq, &mut c.ws, None);
                        clip_grad_norm(&mut c.grads, cfg.max_grad_norm);
                        c.adam.step(&mut c.params, &c.grads, lr);
                    }
                    // Actor: minimise α log π(a|s) − min Q(s, a), a reparameterised.
                    ensure(&mut out_buf, b * 2 * d);
                    out_buf[..b * 2 * d].copy_from_slice(actor.forward(
                        &policy.params,
                        &x,
                        b,
                        &mut ws_actor,
                    ));
                    let out = &out_buf;
                    for e in eps[..b * d].iter_mut() {
                        *e = noise_rng.normal() as f32;
                    }
                    for k in 0..b {
                        let row = &out[k * 2 * d..(k + 1) * 2 * d];
                        logp[k] = tanh_gaussian::sample(
                            &row[..d],
                            &row[d..],
                            &eps[k * d..(k + 1) * d],
                            &mut a_pi[k * d..(k + 1) * d],
                        );
                    }
                    concat_obs_action(&x, &a_pi, b, od, d, &mut qin);
                    ensure(&mut qa, b);
                    ensure(&mut qb, b);
                    {
                        let (c0, c1) = critics.split_at_mut(1);
                        let (c0, c1) = (&mut c0[0], &mut c1[0]);
                        qa[..b].copy_from_slice(qnet.forward(&c0.params, &qin, b, &mut c0.ws));
                        qb[..b].copy_from_slice(qnet.forward(&c1.params, &qin, b, &mut c1.ws));
                    }
                    ensure(&mut dqin, b * (od + d));
                    ensure(&mut scratch, critics[0].params.len());
                    ensure(&mut dout, b * 2 * d);
                    dout[..b * 2 * d].fill(0.0);
                    for (ci, c) in critics.iter_mut().enumerate() {
                        // Gradient flows through whichever critic is the minimum for each row.
                        for k in 0..b {
                            let pick = if qa[k] <= qb[k] { 0 } else { 1 };
                            dq[k] = if pick == ci { -1.0 / b as f32 } else { 0.0 };
                        }
                        scratch.fill(0.0);
                        qnet.backward(
                            &c.params,
                            &mut scratch,
                            &qin,
                            &dq,
                            &mut c.ws,
                            Some(&mut dqin),
                        );
                        for k in 0..b {
                            let da = &dqin[k * (od + d) + od..(k + 1) * (od + d)];
                            let row = &out[k * 2 * d..(k + 1) * 2 * d];
                            let (dm, dr) = dout[k * 2 * d..(k + 1) * 2 * d].split_at_mut(d);
                            let dlogp = if ci == 0 { alpha / b as f32 } else { 0.0 };
                            tanh_gaussian::backward(
                                &row[..d],
                                &row[d..],
                                &eps[k * d..(k + 1) * d],
                                da,
                                dlogp,
                                dm,
                                dr,
                            );
                        }
                    }
                    actor_grads.fill(0.0);
                    actor.backward(
                        &policy.params,
                        &mut actor_grads,
                        &x,
                        &dout,
                        &mut ws_actor,
                        None,
                    );
                    clip_grad_norm(&mut actor_grads, cfg.max_grad_norm);
                    actor_adam.step(&mut policy.params, &actor_grads, lr);
                    // Temperature: minimise −log α · (log π + target entropy).
                    let mean_lp = logp[..b].iter().map(|l| f64::from(*l)).sum::<f64>() / b as f64;
                    let g = -(mean_lp as f32 + target_entropy);
                    let mut la = [log_alpha];
                    alpha_adam.step(&mut la, &[g], lr);
                    log_alpha = la[0];
                    for c in critics.iter_mut() {
                        polyak(&mut c.target, &c.params, cfg.tau);
                    }
                }
                check_finite("SAC actor", &policy.params)?;
                check_finite("SAC critic", &critics[0].params)?;
            }
            let save = |p: &NetPolicy| {
                let mut w = StateWriter::new("sac", STATE_VERSION);
                p.save_training_state(&mut w);
                for c in &critics {
                    w.f32s(&c.params);
                    w.f32s(&c.target);
                    c.adam.save(&mut w);
                }
                actor_adam.save(&mut w);
                w.f32(log_alpha);
                alpha_adam.save(&mut w);
                w.rng(&rng);
                w.rng(&noise_rng);
                w.rng(&sample_rng);
                w.f32(credit);
                w.u64(env_steps);
                replay.save(&mut w);
                w.envs(&venv);
                Ok(w.finish())
            };
            if ctx.progress_resumable(env_steps, &mut policy, save)? == Control::Stop {
                break;
            }
        }
        ctx.finish(env_steps, &mut policy)?;
        venv.close()?;
        Ok(Box::new(policy))
    }
}

fn concat_obs_action(x: &[f32], a: &[f32], b: usize, od: usize, d: usize, out: &mut Vec<f32>) {
    ensure(out, b * (od + d));
    for k in 0..b {
        let o = &mut out[k * (od + d)..(k + 1) * (od + d)];
        o[..od].copy_from_slice(&x[k * od..(k + 1) * od]);
        o[od..].copy_from_slice(&a[k * d..(k + 1) * d]);
    }
}
