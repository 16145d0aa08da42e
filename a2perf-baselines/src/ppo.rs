//! Proximal Policy Optimisation (clipped surrogate), as the paper's `PPOClipAgent`.
//!
//! Rollouts of `num_steps` steps from `num_envs` parallel environments, generalised advantage
//! estimation, then `num_epochs` passes of shuffled minibatches. Observations are normalised by
//! running statistics (frozen into the policy), rewards are scaled by the running std of the
//! discounted return, and time-limit truncations bootstrap from the value of the final
//! observation. Discrete actions use a masked categorical, continuous actions a diagonal Gaussian
//! with a state-independent log-std (separate actor and value MLPs, as TF-Agents).

use a2perf_core::{
    Action, Algorithm, Control, ParamKind, ParamSpec, Params, Policy, RunError, TrainingContext,
    Value,
};

use crate::batch::{ObsBatch, ObsLayout};
use crate::common::*;
use crate::model::NetOptions;
use crate::nn::dist::{gaussian, masked};
use crate::nn::norm::RewardScaler;
use crate::nn::optim::{Adam, LrSchedule};
use crate::nn::{MlpWs, clip_grad_norm, ensure};
use crate::policy::{Head, NetPolicy, ObsNorm};
use crate::resume::{StateReader, StateWriter, resume_err};

/// Version of PPO's resumable training state (2: observations are typed, so the
/// observation hashes and the stored observations of version 1 no longer apply).
const STATE_VERSION: u32 = 2;

/// PPO hyperparameters (see [`Ppo::params`] for documentation and defaults).
#[derive(Clone, Debug, PartialEq)]
pub struct PpoConfig {
    /// Learning rate schedule.
    pub lr: LrSchedule,
    /// Steps per environment per rollout.
    pub num_steps: usize,
    /// Passes over each rollout.
    pub num_epochs: usize,
    /// Minibatch size.
    pub minibatch_size: usize,
    /// Discount.
    pub gamma: f32,
    /// GAE λ.
    pub gae_lambda: f32,
    /// Ratio clipping ε.
    pub clip_ratio: f32,
    /// Value loss weight.
    pub value_coef: f32,
    /// Entropy bonus weight.
    pub entropy_coef: f32,
    /// Global gradient-norm clip (0 = none).
    pub max_grad_norm: f32,
    /// Normalise observations.
    pub normalize_observations: bool,
    /// Scale rewards.
    pub normalize_rewards: bool,
    /// Initial log-std of the Gaussian policy.
    pub init_log_std: f32,
    /// Whether the log-std is trained (false: fixed at `init_log_std`, as motion_imitation's
    /// PPO with its constant std of 0.125).
    pub learn_log_std: bool,
    /// Networks.
    pub net: NetOptions,
}

/// The PPO algorithm.
#[derive(Clone, Debug)]
pub struct Ppo {
    /// Hyperparameters.
    pub config: PpoConfig,
}

impl Ppo {
    /// Documented hyperparameters with their defaults (the paper's `PPOClipAgent` settings:
    /// clip 0.2, value coefficient 0.5, entropy 1e-2, 4 epochs, minibatch 64, Adam ε 1e-5,
    /// observation and reward normalisation; learning rates differ per domain in the configs).
    pub fn params() -> Vec<ParamSpec> {
        let mut v = vec![
            ParamSpec::new(
                "learning_rate",
                ParamKind::Float,
                Value::Float(3e-4),
                "Adam learning rate (Adam eps is 1e-5)",
            ),
            ParamSpec::new(
                "num_steps",
                ParamKind::Int,
                Value::Int(128),
                "rollout length per environment between updates",
            ),
            ParamSpec::new(
                "num_epochs",
                ParamKind::Int,
                Value::Int(4),
                "passes over each rollout (paper: 4)",
            ),
            ParamSpec::new(
                "minibatch_size",
                ParamKind::Int,
                Value::Int(64),
                "minibatch size (paper: 64)",
            ),
            ParamSpec::new(
                "gamma",
                ParamKind::Float,
                Value::Float(0.99),
                "discount (paper circuit: 1.0)",
            ),
            ParamSpec::new(
                "gae_lambda",
                ParamKind::Float,
                Value::Float(0.95),
                "GAE lambda (1.0 = Monte-Carlo returns, the paper's circuit `use_gae=False`)",
            ),
            ParamSpec::new(
                "clip_ratio",
                ParamKind::Float,
                Value::Float(0.2),
                "importance-ratio clipping (paper: 0.2)",
            ),
            ParamSpec::new(
                "value_coef",
                ParamKind::Float,
                Value::Float(0.5),
                "value loss coefficient (paper: 0.5)",
            ),
            ParamSpec::new(
                "entropy_coef",
                ParamKind::Float,
                Value::Float(0.01),
                "entropy bonus (paper: 1e-2)",
            ),
            ParamSpec::new(
                "max_grad_norm",
                ParamKind::Float,
                Value::Float(1.0),
                "global gradient-norm clipping, 0 = off (paper circuit: 1.0)",
            ),
            ParamSpec::new(
                "normalize_observations",
                ParamKind::Bool,
                Value::Bool(true),
                "running observation normalisation (paper: true)",
            ),
            ParamSpec::new(
                "normalize_rewards",
                ParamKind::Bool,
                Value::Bool(true),
                "reward scaling by the return's running std (paper: true)",
            ),
            ParamSpec::new(
                "init_log_std",
                ParamKind::Float,
                Value::Float(-0.5),
                "initial log standard deviation of the Gaussian policy (continuous actions)",
            ),
            ParamSpec::new(
                "learn_log_std",
                ParamKind::Bool,
                Value::Bool(true),
                "train the Gaussian's log-std (false: keep it at init_log_std, as motion_imitation's fixed std 0.125)",
            ),
        ];
        v.extend(schedule_specs());
        v.extend(net_specs(&[64, 64]));
        v
    }

    /// Builds PPO from resolved hyperparameters.
    pub fn from_params(p: &Params) -> Result<Self, RunError> {
        let lr = positive_f32(p, "learning_rate")?;
        Ok(Self {
            config: PpoConfig {
                lr: schedule(p, lr)?,
                num_steps: positive_usize(p, "num_steps")?,
                num_epochs: positive_usize(p, "num_epochs")?,
                minibatch_size: positive_usize(p, "minibatch_size")?,
                gamma: unit_f32(p, "gamma")?,
                gae_lambda: unit_f32(p, "gae_lambda")?,
                clip_ratio: positive_f32(p, "clip_ratio")?,
                value_coef: nonneg_f32(p, "value_coef")?,
                entropy_coef: nonneg_f32(p, "entropy_coef")?,
                max_grad_norm: nonneg_f32(p, "max_grad_norm")?,
                normalize_observations: p.bool("normalize_observations").map_err(hp)?,
                normalize_rewards: p.bool("normalize_rewards").map_err(hp)?,
                init_log_std: p.f64("init_log_std").map_err(hp)? as f32,
                learn_log_std: p.bool("learn_log_std").map_err(hp)?,
                net: net_options(p)?,
            },
        })
    }
}

/// Rollout storage and scratch space.
struct Rollout {
    obs: ObsBatch,
    act_d: Vec<usize>,
    act_c: Vec<f32>,
    logp: Vec<f32>,
    values: Vec<f32>,
    rewards: Vec<f32>,
    ended: Vec<bool>,
    adv: Vec<f32>,
    ret: Vec<f32>,
}

/// Per-row value and (for continuous heads) mean, from one forward pass.
struct Forward {
    x: Vec<f32>,
    actor: MlpWs,
    critic: MlpWs,
    logp: Vec<f32>,
}

impl Forward {
    /// Forward over all rows of `batch`; returns nothing, results read from the nets/workspaces.
    fn run(&mut self, policy: &mut NetPolicy, batch: &ObsBatch) {
        match &mut policy.head {
            Head::Discrete(net) => net.forward(&policy.params, batch),
            Head::Gaussian(g) => {
                batch.concat_into(&mut self.x);
                g.actor
                    .forward(&policy.params, &self.x, batch.len(), &mut self.actor);
                if let Some(c) = &g.critic {
                    c.forward(&policy.params, &self.x, batch.len(), &mut self.critic);
                }
            }
            Head::Squashed(_) => {}
        }
    }

    fn value(&self, policy: &NetPolicy, row: usize) -> f32 {
        match &policy.head {
            Head::Discrete(net) => net.values()[row],
            Head::Gaussian(g) => g
                .critic
                .as_ref()
                .map_or(0.0, |c| c.output(&self.critic)[row]),
            Head::Squashed(_) => 0.0,
        }
    }
}

impl Algorithm for Ppo {
    fn name(&self) -> &str {
        "ppo"
    }

    /// Resumable: the state saved at every checkpoint interval holds the policy (parameters,
    /// observation statistics), Adam, the reward scaler, both random streams, the minibatch
    /// order, the step count and every environment's current episode. A resume point is taken
    /// after an update, when the rollout buffer holds nothing that is still needed.
    fn train(&mut self, ctx: &mut TrainingContext<'_>) -> Result<Box<dyn Policy>, RunError> {
        let cfg = self.config.clone();
        let resume = ctx.take_resume_state();
        let (mut venv, spec) = make_vec_env(ctx)?;
        let n_env = venv.len();
        let layout = ObsLayout::from_spec(&spec)?;
        let head = head_for(&spec, &layout, &cfg.net, true)?;
        let mut init_rng = ctx.rng("ppo/init");
        let params = match &head {
            Head::Discrete(net) => net.init_params(&mut init_rng),
            Head::Gaussian(g) => g.init_params(&mut init_rng, cfg.init_log_std),
            Head::Squashed(_) => return Err(RunError::Unsupported("squashed head".into())),
        };
        let obs_norm = if cfg.normalize_observations {
            ObsNorm::for_head(&head, &layout)
        } else {
            None
        };
        let mut policy = NetPolicy::new("ppo", &spec, head, params, obs_norm, ctx.seed())?;
        let act_dim = match &policy.head {
            Head::Gaussian(g) => g.act_dim,
            _ => 0,
        };
        let n_actions = layout.num_actions.unwrap_or(0);
        let mut rng = ctx.rng("ppo/actions");
        let mut mb_rng = ctx.rng("ppo/minibatch");
        let mut adam = Adam::new(policy.params.len());
        let mut grads = vec![0.0f32; policy.params.len()];
        let mut scaler = RewardScaler::new(n_env, f64::from(cfg.gamma));
        let rows = cfg.num_steps * n_env;
        let mut ro = Rollout {
            obs: ObsBatch::new(&layout),
            act_d: vec![0; rows],
            act_c: vec![0.0; rows * act_dim],
            logp: vec![0.0; rows],
            values: vec![0.0; rows],
            rewards: vec![0.0; rows],
            ended: vec![false; rows],
            adv: vec![0.0; rows],
            ret: vec![0.0; rows],
        };
        ro.obs.resize(rows);
        let mut now = ObsBatch::new(&layout);
        let mut raw = ObsBatch::new(&layout);
        let mut finals = ObsBatch::new(&layout);
        let mut final_rows: Vec<usize> = Vec::new();
        let mut mb = ObsBatch::new(&layout);
        let mut fw = Forward {
            x: Vec::new(),
            actor: MlpWs::default(),
            critic: MlpWs::default(),
            logp: Vec::new(),
        };
        let mut actions: Vec<Action> = vec![Action::Discrete(0); n_env];
        let mut noise = vec![0.0f32; act_dim];
        let mut order: Vec<usize> = (0..rows).collect();
        let mut dlogits: Vec<f32> = Vec::new();
        let mut dvalues: Vec<f32> = Vec::new();
        let mut dmean: Vec<f32> = Vec::new();
        let mut next_adv = vec![0.0f32; n_env];
        let mut next_val = vec![0.0f32; n_env];
        let mut dlog_std = vec![0.0f32; act_dim];
        let total = ctx.settings().total_env_steps.max(1);
        let mut env_steps: u64 = 0;

        // Current observations (raw) of every environment.
        raw.resize(n_env);
        match &resume {
            Some(bytes) => {
                let mut r = StateReader::new(bytes, "ppo", STATE_VERSION)?;
                policy.load_training_state(&mut r)?;
                adam.load("policy", &mut r)?;
                scaler.load(&mut r)?;
                rng = r.rng()?;
                mb_rng = r.rng()?;
                let saved_order = r.usizes()?;
                if saved_order.len() != rows {
                    return Err(resume_err(format!(
                        "rollout of {} rows saved, this configuration has {rows}",
                        saved_order.len()
                    )));
                }
                order = saved_order;
                env_steps = r.u64()?;
                for (i, out) in r.envs(&mut venv, &mut |m| ctx.warn(m))?.iter().enumerate() {
                    raw.write_row(i, &out.step.observation)?;
                }
                r.finish()?;
            }
            None => {
                for (i, out) in venv.reset_all()?.iter().enumerate() {
                    raw.write_row(i, &out.step.observation)?;
                }
            }
        }
        loop {
            for t in 0..cfg.num_steps {
                if let Some(n) = &mut policy.obs_norm {
                    n.update(&raw, n_env);
                }
                now.resize(n_env);
                for i in 0..n_env {
                    now.copy_row(i, &raw, i);
                    if let Some(n) = &policy.obs_norm {
                        n.apply(&mut now, i);
                    }
                    ro.obs.copy_row(t * n_env + i, &now, i);
                }
                fw.run(&mut policy, &now);
                #[allow(clippy::needless_range_loop)] // i indexes several parallel buffers
                for i in 0..n_env {
                    let row = t * n_env + i;
                    ro.values[row] = fw.value(&policy, i);
                    match &policy.head {
                        Head::Discrete(net) => {
                            let logits = &net.logits()[i * n_actions..(i + 1) * n_actions];
                            ensure(&mut fw.logp, n_actions);
                            let lp = &mut fw.logp[..n_actions];
                            if !masked::log_softmax(logits, now.mask(i), lp) {
                                return Err(RunError::Policy(
                                    a2perf_core::PolicyError::NoLegalAction,
                                ));
                            }
                            let a = masked::sample(lp, &mut rng)
                                .ok_or(RunError::Policy(a2perf_core::PolicyError::NoLegalAction))?;
                            ro.act_d[row] = a;
                            ro.logp[row] = lp[a];
                            actions[i] = Action::Discrete(a);
                        }
                        Head::Gaussian(g) => {
                            let mean = &g.actor.output(&fw.actor)[i * act_dim..(i + 1) * act_dim];
                            let log_std = &policy.params[g.log_std..g.log_std + act_dim];
                            for (k, z) in noise.iter_mut().enumerate() {
                                *z = mean[k] + log_std[k].exp() * rng.normal() as f32;
                            }
                            ro.act_c[row * act_dim..(row + 1) * act_dim].copy_from_slice(&noise);
                            ro.logp[row] = gaussian::log_prob(mean, log_std, &noise);
                            actions[i] = clip_action(&policy.action_space, &noise, &mut actions[i]);
                        }
                        Head::Squashed(_) => {}
                    }
                }
                let outs = venv.step_all(&actions)?;
                finals.clear();
                final_rows.clear();
                for (i, out) in outs.iter().enumerate() {
                    let row = t * n_env + i;
                    let done = out.step.done();
                    let r = if cfg.normalize_rewards {
                        scaler.scale(i, out.step.reward, done)
                    } else {
                        out.step.reward
                    };
                    ro.rewards[row] = r as f32;
                    ro.ended[row] = done;
                    if out.step.truncated && !out.step.terminated {
                        let fr = finals.push(&out.final_observation)?;
                        if let Some(n) = &policy.obs_norm {
                            n.apply(&mut finals, fr);
                        }
                        final_rows.push(row);
                    }
                    raw.write_row(i, &out.step.observation)?;
                }
                if !finals.is_empty() {
                    fw.run(&mut policy, &finals);
                    for (k, &row) in final_rows.iter().enumerate() {
                        ro.rewards[row] += cfg.gamma * fw.value(&policy, k);
                    }
                }
                env_steps += n_env as u64;
            }
            // Bootstrap values of the current observations.
            now.resize(n_env);
            for i in 0..n_env {
                now.copy_row(i, &raw, i);
                if let Some(n) = &policy.obs_norm {
                    n.apply(&mut now, i);
                }
            }
            fw.run(&mut policy, &now);
            next_adv.fill(0.0);
            for (i, v) in next_val.iter_mut().enumerate() {
                *v = fw.value(&policy, i);
            }
            for t in (0..cfg.num_steps).rev() {
                for i in 0..n_env {
                    let row = t * n_env + i;
                    let nonterminal = if ro.ended[row] { 0.0 } else { 1.0 };
                    let delta =
                        ro.rewards[row] + cfg.gamma * next_val[i] * nonterminal - ro.values[row];
                    let a = delta + cfg.gamma * cfg.gae_lambda * nonterminal * next_adv[i];
                    ro.adv[row] = a;
                    ro.ret[row] = a + ro.values[row];
                    next_adv[i] = a;
                    next_val[i] = ro.values[row];
                }
            }
            // Optimisation.
            let lr = cfg.lr.at(env_steps as f64 / total as f64);
            let mbs = cfg.minibatch_size.min(rows);
            for _ in 0..cfg.num_epochs {
                mb_rng.shuffle(&mut order);
                for chunk in order.chunks(mbs) {
                    mb.gather(&ro.obs, chunk);
                    fw.run(&mut policy, &mb);
                    let bsz = chunk.len();
                    let (mut amean, mut astd) = (0.0f64, 0.0f64);
                    for &r in chunk {
                        amean += f64::from(ro.adv[r]);
                    }
                    amean /= bsz as f64;
                    for &r in chunk {
                        astd += (f64::from(ro.adv[r]) - amean).powi(2);
                    }
                    astd = (astd / bsz as f64).sqrt();
                    let inv_b = 1.0 / bsz as f32;
                    grads.fill(0.0);
                    ensure(&mut dvalues, bsz);
                    for (k, &r) in chunk.iter().enumerate() {
                        let v = fw.value(&policy, k);
                        dvalues[k] = 2.0 * cfg.value_coef * (v - ro.ret[r]) * inv_b;
                    }
                    let adv_of = |r: usize| {
                        if bsz > 1 {
                            ((f64::from(ro.adv[r]) - amean) / (astd + 1e-8)) as f32
                        } else {
                            ro.adv[r]
                        }
                    };
                    let clip = cfg.clip_ratio;
                    // ∂L/∂logπ(a) of the clipped surrogate −min(ρA, clip(ρ)A).
                    let surrogate = |logp_new: f32, logp_old: f32, a: f32| {
                        let ratio = (logp_new - logp_old).exp();
                        let active =
                            (a > 0.0 && ratio < 1.0 + clip) || (a < 0.0 && ratio > 1.0 - clip);
                        if active { -a * ratio } else { 0.0 }
                    };
                    match &mut policy.head {
                        Head::Discrete(net) => {
                            ensure(&mut dlogits, bsz * n_actions);
                            dlogits[..bsz * n_actions].fill(0.0);
                            ensure(&mut fw.logp, n_actions);
                            for (k, &r) in chunk.iter().enumerate() {
                                let logits = &net.logits()[k * n_actions..(k + 1) * n_actions];
                                let lp = &mut fw.logp[..n_actions];
                                masked::log_softmax(logits, mb.mask(k), lp);
                                let a = ro.act_d[r];
                                let g = surrogate(lp[a], ro.logp[r], adv_of(r));
                                let dl = &mut dlogits[k * n_actions..(k + 1) * n_actions];
                                masked::grad_logp(lp, a, g * inv_b, dl);
                                masked::grad_entropy(lp, -cfg.entropy_coef * inv_b, dl);
                            }
                            net.backward(&policy.params, &mut grads, &mb, &dlogits, Some(&dvalues));
                        }
                        Head::Gaussian(g) => {
                            ensure(&mut dmean, bsz * act_dim);
                            let log_std = &policy.params[g.log_std..g.log_std + act_dim];
                            let means = g.actor.output(&fw.actor);
                            dlog_std.fill(0.0);
                            for (k, &r) in chunk.iter().enumerate() {
                                let mean = &means[k * act_dim..(k + 1) * act_dim];
                                let a = &ro.act_c[r * act_dim..(r + 1) * act_dim];
                                let lp = gaussian::log_prob(mean, log_std, a);
                                let gcoef = surrogate(lp, ro.logp[r], adv_of(r)) * inv_b;
                                let dm = &mut dmean[k * act_dim..(k + 1) * act_dim];
                                dm.fill(0.0);
                                gaussian::grad_log_prob(mean, log_std, a, gcoef, dm, &mut dlog_std);
                            }
                            for d in &mut dlog_std {
                                *d -= cfg.entropy_coef;
                            }
                            g.actor.backward(
                                &policy.params,
                                &mut grads,
                                &fw.x,
                                &dmean,
                                &mut fw.actor,
                                None,
                            );
                            if let Some(c) = &g.critic {
                                c.backward(
                                    &policy.params,
                                    &mut grads,
                                    &fw.x,
                                    &dvalues,
                                    &mut fw.critic,
                                    None,
                                );
                            }
                            if cfg.learn_log_std {
                                for (k, d) in dlog_std.iter().enumerate() {
                                    grads[g.log_std + k] += d;
                                }
                            }
                        }
                        Head::Squashed(_) => {}
                    }
                    clip_grad_norm(&mut grads, cfg.max_grad_norm);
                    adam.step(&mut policy.params, &grads, lr);
                }
            }
            check_finite("PPO parameters", &policy.params)?;
            let save = |p: &NetPolicy| {
                let mut w = StateWriter::new("ppo", STATE_VERSION);
                p.save_training_state(&mut w);
                adam.save(&mut w);
                scaler.save(&mut w);
                w.rng(&rng);
                w.rng(&mb_rng);
                w.usizes(&order);
                w.u64(env_steps);
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

/// Clips a continuous action to the space's bounds, reusing `slot`'s buffer.
pub(crate) fn clip_action(space: &a2perf_core::Space, a: &[f32], slot: &mut Action) -> Action {
    let mut v = match std::mem::replace(slot, Action::Discrete(0)) {
        Action::Continuous(v) => v,
        Action::Discrete(_) => Vec::with_capacity(a.len()),
    };
    v.clear();
    match space {
        a2perf_core::Space::Box { low, high, .. } => {
            v.extend(
                a.iter()
                    .zip(low.iter().zip(high))
                    .map(|(x, (l, h))| x.clamp(*l as f32, *h as f32)),
            );
        }
        _ => v.extend_from_slice(a),
    }
    Action::Continuous(v)
}
