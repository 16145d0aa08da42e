//! Proximal Policy Optimisation (clipped surrogate), as the paper's `PPOClipAgent`.
//!
//! Rollouts of `num_steps` steps from `num_envs` parallel environments, generalised advantage
//! estimation, then `num_epochs` passes of shuffled minibatches. Observations are normalised by
//! running statistics (frozen into the policy), rewards are scaled by the running std of the
//! discounted return, and time-limit truncations bootstrap from the value of the final
//! observation. Discrete actions use a masked categorical, continuous actions a diagonal Gaussian
//! with a state-independent log-std (separate actor and value MLPs, as TF-Agents).

use a2perf_core::{
    Action, Algorithm, EnvSpec, ParamKind, ParamSpec, Params, Policy, RngStream, RunError,
    TrainingContext, Value, VecEnv,
};

use crate::batch::{ObsBatch, ObsLayout};
use a2perf_core::{TimePart, TimeSplit};

use crate::common::*;
use crate::model::{DiscreteNet, GaussianArch, NetOptions};
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
        self.run_as(policy, batch, false);
    }

    /// [`run`](Self::run), with a discrete network's logits over its scored actions only
    /// when `scored` (see [`DiscreteNet::forward_scored`]).
    fn run_as(&mut self, policy: &mut NetPolicy, batch: &ObsBatch, scored: bool) {
        match &mut policy.head {
            Head::Discrete(net) if scored => net.forward_scored(&policy.params, batch),
            Head::Discrete(net) => net.forward(&policy.params, batch),
            Head::Gaussian(g) => {
                batch.concat_into(&mut self.x);
                g.forward_both(
                    &policy.params,
                    &self.x,
                    batch.len(),
                    &mut self.actor,
                    &mut self.critic,
                );
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
        let resume = ctx.take_resume_state();
        let (venv, spec) = make_vec_env(ctx)?;
        let layout = ObsLayout::from_spec(&spec)?;
        let policy = self.initial_policy(ctx, &spec, &layout)?;
        let run = PpoRun::new(self.config.clone(), venv, &layout, &policy, ctx);
        drive(run, policy, resume, ctx)
    }
}

impl Ppo {
    /// The untrained policy: its network for `spec`, fresh parameters and, when configured,
    /// empty observation statistics.
    fn initial_policy(
        &self,
        ctx: &TrainingContext<'_>,
        spec: &EnvSpec,
        layout: &ObsLayout,
    ) -> Result<NetPolicy, RunError> {
        let cfg = &self.config;
        let head = head_for(spec, layout, &cfg.net, true)?;
        let params = initial_params(&head, &mut ctx.rng("ppo/init"), cfg.init_log_std)?;
        let obs_norm = if cfg.normalize_observations {
            ObsNorm::for_head(&head, layout)
        } else {
            None
        };
        Ok(NetPolicy::new(
            "ppo",
            spec,
            head,
            params,
            obs_norm,
            ctx.seed(),
        )?)
    }
}

/// Everything a PPO run updates besides the policy: the environments, the optimiser, the
/// reward scaler, the random streams, the rollout and the workspaces of the steps below.
struct PpoRun {
    cfg: PpoConfig,
    venv: VecEnv,
    n_env: usize,
    /// Rows of a rollout: `num_steps × n_env`, step-major.
    rows: usize,
    act_dim: usize,
    n_actions: usize,
    rng: RngStream,
    mb_rng: RngStream,
    adam: Adam,
    grads: Vec<f32>,
    scaler: RewardScaler,
    ro: Rollout,
    /// Every environment's current observation, raw.
    raw: ObsBatch,
    /// `raw` normalised.
    now: ObsBatch,
    /// Final observations of the episodes truncated at this step, normalised, and their rows.
    finals: ObsBatch,
    final_rows: Vec<usize>,
    mb: ObsBatch,
    fw: Forward,
    actions: Vec<Action>,
    noise: Vec<f32>,
    /// The rollout's rows in minibatch order (shuffled at every epoch).
    order: Vec<usize>,
    dlogits: Vec<f32>,
    /// The network's scored actions (see [`DiscreteNet::scored_actions_into`]) and one
    /// row's mask over them.
    scored: Vec<usize>,
    scored_mask: Vec<bool>,
    dvalues: Vec<f32>,
    dmean: Vec<f32>,
    dlog_std: Vec<f32>,
    next_adv: Vec<f32>,
    next_val: Vec<f32>,
    total: u64,
    env_steps: u64,
}

impl PpoRun {
    fn new(
        cfg: PpoConfig,
        venv: VecEnv,
        layout: &ObsLayout,
        policy: &NetPolicy,
        ctx: &TrainingContext<'_>,
    ) -> Self {
        let n_env = venv.len();
        let act_dim = match &policy.head {
            Head::Gaussian(g) => g.act_dim,
            _ => 0,
        };
        let rows = cfg.num_steps * n_env;
        // Observation batches hold only what the network reads (the circuit network: 2 of 11
        // tensors); normalisation statistics, when kept, see every tensor.
        let keep = match &policy.head {
            Head::Discrete(net) if policy.obs_norm.is_none() => net.inputs(),
            _ => None,
        };
        let batch = || {
            let mut b = ObsBatch::new(layout);
            if let Some(keep) = &keep {
                b.keep_tensors(keep);
            }
            b
        };
        let mut ro = Rollout {
            obs: batch(),
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
        let mut raw = batch();
        raw.resize(n_env);
        Self {
            venv,
            n_env,
            rows,
            act_dim,
            n_actions: layout.num_actions.unwrap_or(0),
            rng: ctx.rng("ppo/actions"),
            mb_rng: ctx.rng("ppo/minibatch"),
            adam: Adam::new(policy.params.len()),
            grads: vec![0.0; policy.params.len()],
            scaler: RewardScaler::new(n_env, f64::from(cfg.gamma)),
            ro,
            raw,
            now: batch(),
            finals: batch(),
            final_rows: Vec::new(),
            mb: batch(),
            fw: Forward {
                x: Vec::new(),
                actor: MlpWs::default(),
                critic: MlpWs::default(),
                logp: Vec::new(),
            },
            actions: vec![Action::Discrete(0); n_env],
            noise: vec![0.0; act_dim],
            order: (0..rows).collect(),
            dlogits: Vec::new(),
            scored: Vec::new(),
            scored_mask: Vec::new(),
            dvalues: Vec::new(),
            dmean: Vec::new(),
            dlog_std: vec![0.0; act_dim],
            next_adv: vec![0.0; n_env],
            next_val: vec![0.0; n_env],
            total: ctx.settings().total_env_steps.max(1),
            env_steps: 0,
            cfg,
        }
    }

    /// `num_steps` steps of every environment into the rollout. Rewards are scaled when
    /// configured; a truncated (not terminated) episode's reward takes the discounted value of
    /// its final observation.
    fn collect_rollout(
        &mut self,
        policy: &mut NetPolicy,
        split: &mut TimeSplit,
    ) -> Result<(), RunError> {
        let n_env = self.n_env;
        for t in 0..self.cfg.num_steps {
            split.time(TimePart::Act, || self.choose_actions(policy, t))?;
            let outs = split.time(TimePart::Env, || self.venv.step_all(&self.actions))?;
            self.finals.clear();
            self.final_rows.clear();
            for (i, out) in outs.iter().enumerate() {
                let row = t * n_env + i;
                let done = out.step.done();
                let r = if self.cfg.normalize_rewards {
                    self.scaler.scale(i, out.step.reward, done)
                } else {
                    out.step.reward
                };
                self.ro.rewards[row] = r as f32;
                self.ro.ended[row] = done;
                if out.step.truncated && !out.step.terminated {
                    let fr = self.finals.push(&out.final_observation)?;
                    if let Some(n) = &policy.obs_norm {
                        n.apply(&mut self.finals, fr);
                    }
                    self.final_rows.push(row);
                }
                self.raw.write_row(i, &out.step.observation)?;
            }
            if !self.finals.is_empty() {
                self.fw.run(policy, &self.finals);
                for (k, &row) in self.final_rows.iter().enumerate() {
                    self.ro.rewards[row] += self.cfg.gamma * self.fw.value(policy, k);
                }
            }
            self.env_steps += n_env as u64;
        }
        Ok(())
    }

    /// Rollout step `t`: updates the observation statistics, then records every environment's
    /// normalised observation, value, sampled action and its log-probability.
    fn choose_actions(&mut self, policy: &mut NetPolicy, t: usize) -> Result<(), RunError> {
        let (n_env, n_actions, act_dim) = (self.n_env, self.n_actions, self.act_dim);
        if let Some(n) = &mut policy.obs_norm {
            n.update(&self.raw, n_env);
        }
        self.normalise_current(policy);
        for i in 0..n_env {
            self.ro.obs.copy_row(t * n_env + i, &self.now, i);
        }
        self.fw.run(policy, &self.now);
        #[allow(clippy::needless_range_loop)] // i indexes several parallel buffers
        for i in 0..n_env {
            let row = t * n_env + i;
            self.ro.values[row] = self.fw.value(policy, i);
            match &policy.head {
                Head::Discrete(net) => {
                    let logits = &net.logits()[i * n_actions..(i + 1) * n_actions];
                    ensure(&mut self.fw.logp, n_actions);
                    let lp = &mut self.fw.logp[..n_actions];
                    if !masked::log_softmax(logits, self.now.mask(i), lp) {
                        return Err(RunError::Policy(a2perf_core::PolicyError::NoLegalAction));
                    }
                    let a = masked::sample(lp, &mut self.rng)
                        .ok_or(RunError::Policy(a2perf_core::PolicyError::NoLegalAction))?;
                    self.ro.act_d[row] = a;
                    self.ro.logp[row] = lp[a];
                    self.actions[i] = Action::Discrete(a);
                }
                Head::Gaussian(g) => {
                    let mean = &g.actor.output(&self.fw.actor)[i * act_dim..(i + 1) * act_dim];
                    let log_std = &policy.params[g.log_std..g.log_std + act_dim];
                    for (k, z) in self.noise.iter_mut().enumerate() {
                        *z = mean[k] + log_std[k].exp() * self.rng.normal() as f32;
                    }
                    self.ro.act_c[row * act_dim..(row + 1) * act_dim].copy_from_slice(&self.noise);
                    self.ro.logp[row] = gaussian::log_prob(mean, log_std, &self.noise);
                    self.actions[i] =
                        clip_action(&policy.action_space, &self.noise, &mut self.actions[i]);
                }
                Head::Squashed(_) => {}
            }
        }
        Ok(())
    }

    /// `now` = every environment's current observation, normalised.
    fn normalise_current(&mut self, policy: &NetPolicy) {
        self.now.resize(self.n_env);
        for i in 0..self.n_env {
            self.now.copy_row(i, &self.raw, i);
            if let Some(n) = &policy.obs_norm {
                n.apply(&mut self.now, i);
            }
        }
    }

    /// Generalised advantage estimation over the rollout, bootstrapped from the values of the
    /// current observations; returns are advantages plus values.
    fn compute_advantages(&mut self, policy: &mut NetPolicy) {
        let n_env = self.n_env;
        self.normalise_current(policy);
        self.fw.run(policy, &self.now);
        self.next_adv.fill(0.0);
        for (i, v) in self.next_val.iter_mut().enumerate() {
            *v = self.fw.value(policy, i);
        }
        let (cfg, ro) = (&self.cfg, &mut self.ro);
        for t in (0..cfg.num_steps).rev() {
            for i in 0..n_env {
                let row = t * n_env + i;
                let nonterminal = if ro.ended[row] { 0.0 } else { 1.0 };
                let delta =
                    ro.rewards[row] + cfg.gamma * self.next_val[i] * nonterminal - ro.values[row];
                let a = delta + cfg.gamma * cfg.gae_lambda * nonterminal * self.next_adv[i];
                ro.adv[row] = a;
                ro.ret[row] = a + ro.values[row];
                self.next_adv[i] = a;
                self.next_val[i] = ro.values[row];
            }
        }
    }

    /// `num_epochs` passes over the rollout in shuffled minibatches.
    fn optimise(&mut self, policy: &mut NetPolicy) {
        let lr = self.cfg.lr.at(self.env_steps as f64 / self.total as f64);
        let mbs = self.cfg.minibatch_size.min(self.rows);
        // Out of `self` while its chunks are read, so that each step can borrow `self`.
        let mut order = std::mem::take(&mut self.order);
        for _ in 0..self.cfg.num_epochs {
            self.mb_rng.shuffle(&mut order);
            for chunk in order.chunks(mbs) {
                self.minibatch_step(policy, chunk, lr);
            }
        }
        self.order = order;
    }

    /// One gradient step on the rollout rows `chunk`: clipped surrogate, entropy bonus and
    /// value regression.
    fn minibatch_step(&mut self, policy: &mut NetPolicy, chunk: &[usize], lr: f32) {
        self.mb.gather(&self.ro.obs, chunk);
        self.fw.run_as(policy, &self.mb, true);
        let bsz = chunk.len();
        let adv = AdvantageNorm::of(&self.ro.adv, chunk);
        let inv_b = 1.0 / bsz as f32;
        self.grads.fill(0.0);
        ensure(&mut self.dvalues, bsz);
        for (k, &r) in chunk.iter().enumerate() {
            let v = self.fw.value(policy, k);
            self.dvalues[k] = 2.0 * self.cfg.value_coef * (v - self.ro.ret[r]) * inv_b;
        }
        match &mut policy.head {
            Head::Discrete(net) => self.discrete_gradient(net, &policy.params, chunk, &adv),
            Head::Gaussian(g) => self.gaussian_gradient(g, &policy.params, chunk, &adv),
            Head::Squashed(_) => {}
        }
        clip_grad_norm(&mut self.grads, self.cfg.max_grad_norm);
        self.adam.step(&mut policy.params, &self.grads, lr);
    }

    /// The gradient of a masked categorical policy and its value head (in `grads`), with the
    /// minibatch's value gradients in `dvalues`.
    ///
    /// The logits are the network's scored ones (the minibatch's forward is
    /// [`DiscreteNet::forward_scored`]: on A2Perf's padded circuit canvas the grid's cells).
    /// That is exact: the other actions are never legal, and every sum over the legal actions
    /// (softmax, entropy) runs in the same order over the same values.
    fn discrete_gradient(
        &mut self,
        net: &mut DiscreteNet,
        params: &[f32],
        chunk: &[usize],
        adv: &AdvantageNorm,
    ) {
        let (m, bsz) = (net.logit_width(), chunk.len());
        let some = net.scored_actions_into(&mut self.scored);
        let inv_b = 1.0 / bsz as f32;
        ensure(&mut self.dlogits, bsz * m);
        self.dlogits[..bsz * m].fill(0.0);
        ensure(&mut self.fw.logp, m);
        for (k, &r) in chunk.iter().enumerate() {
            let logits = &net.logits()[k * m..(k + 1) * m];
            let lp = &mut self.fw.logp[..m];
            let (mask, a) = match (some, self.mb.mask(k)) {
                (false, mask) => (mask, Some(self.ro.act_d[r])),
                (true, full) => {
                    self.scored_mask.clear();
                    if let Some(full) = full {
                        self.scored_mask
                            .extend(self.scored.iter().map(|&a| full[a]));
                    }
                    let col = self.scored.binary_search(&self.ro.act_d[r]).ok();
                    (full.map(|_| self.scored_mask.as_slice()), col)
                }
            };
            masked::log_softmax(logits, mask, lp);
            let dl = &mut self.dlogits[k * m..(k + 1) * m];
            // An action outside the scored ones is never legal, so never sampled: were it in
            // the rollout, its surrogate would have no gradient to give the scored logits.
            if let Some(a) = a {
                let g = surrogate_grad(
                    lp[a],
                    self.ro.logp[r],
                    adv.apply(self.ro.adv[r]),
                    self.cfg.clip_ratio,
                );
                masked::grad_logp(lp, a, g * inv_b, dl);
            }
            masked::grad_entropy(lp, -self.cfg.entropy_coef * inv_b, dl);
        }
        net.backward(
            params,
            &mut self.grads,
            &self.mb,
            &self.dlogits,
            Some(&self.dvalues),
        );
    }

    /// The gradient of a diagonal Gaussian policy (mean network, log-std when learned) and
    /// its value network (in `grads`).
    fn gaussian_gradient(
        &mut self,
        g: &GaussianArch,
        params: &[f32],
        chunk: &[usize],
        adv: &AdvantageNorm,
    ) {
        let (act_dim, bsz) = (self.act_dim, chunk.len());
        let inv_b = 1.0 / bsz as f32;
        ensure(&mut self.dmean, bsz * act_dim);
        let log_std = &params[g.log_std..g.log_std + act_dim];
        let means = g.actor.output(&self.fw.actor);
        self.dlog_std.fill(0.0);
        for (k, &r) in chunk.iter().enumerate() {
            let mean = &means[k * act_dim..(k + 1) * act_dim];
            let a = &self.ro.act_c[r * act_dim..(r + 1) * act_dim];
            let lp = gaussian::log_prob(mean, log_std, a);
            let gcoef = surrogate_grad(
                lp,
                self.ro.logp[r],
                adv.apply(self.ro.adv[r]),
                self.cfg.clip_ratio,
            ) * inv_b;
            let dm = &mut self.dmean[k * act_dim..(k + 1) * act_dim];
            dm.fill(0.0);
            gaussian::grad_log_prob(mean, log_std, a, gcoef, dm, &mut self.dlog_std);
        }
        for d in &mut self.dlog_std {
            *d -= self.cfg.entropy_coef;
        }
        g.backward_both(
            params,
            &mut self.grads,
            &self.fw.x,
            &self.dmean,
            &self.dvalues,
            &mut self.fw.actor,
            &mut self.fw.critic,
        );
        if self.cfg.learn_log_std {
            for (k, d) in self.dlog_std.iter().enumerate() {
                self.grads[g.log_std + k] += d;
            }
        }
    }
}

/// A minibatch's advantage statistics, to normalise its advantages (a single row is left as
/// it is).
struct AdvantageNorm {
    mean: f64,
    std: f64,
    rows: usize,
}

impl AdvantageNorm {
    fn of(adv: &[f32], chunk: &[usize]) -> Self {
        let rows = chunk.len();
        let (mut mean, mut std) = (0.0f64, 0.0f64);
        for &r in chunk {
            mean += f64::from(adv[r]);
        }
        mean /= rows as f64;
        for &r in chunk {
            std += (f64::from(adv[r]) - mean).powi(2);
        }
        std = (std / rows as f64).sqrt();
        Self { mean, std, rows }
    }

    fn apply(&self, a: f32) -> f32 {
        if self.rows > 1 {
            ((f64::from(a) - self.mean) / (self.std + 1e-8)) as f32
        } else {
            a
        }
    }
}

/// ∂L/∂logπ(a) of the clipped surrogate −min(ρA, clip(ρ)A), with ρ = π(a)/π_old(a).
fn surrogate_grad(logp_new: f32, logp_old: f32, a: f32, clip: f32) -> f32 {
    let ratio = (logp_new - logp_old).exp();
    let active = (a > 0.0 && ratio < 1.0 + clip) || (a < 0.0 && ratio > 1.0 - clip);
    if active { -a * ratio } else { 0.0 }
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

impl OnlineRun for PpoRun {
    fn restore(
        &mut self,
        bytes: &[u8],
        policy: &mut NetPolicy,
        ctx: &mut TrainingContext<'_>,
    ) -> Result<(), RunError> {
        let mut r = StateReader::new(bytes, "ppo", STATE_VERSION)?;
        policy.load_training_state(&mut r)?;
        self.adam.load("policy", &mut r)?;
        self.scaler.load(&mut r)?;
        self.rng = r.rng()?;
        self.mb_rng = r.rng()?;
        let saved_order = r.usizes()?;
        if saved_order.len() != self.rows {
            return Err(resume_err(format!(
                "rollout of {} rows saved, this configuration has {}",
                saved_order.len(),
                self.rows
            )));
        }
        self.order = saved_order;
        self.env_steps = r.u64()?;
        write_observations(&mut self.raw, r.envs(&mut self.venv, &mut |m| ctx.warn(m))?)?;
        r.finish()
    }

    fn reset(&mut self) -> Result<(), RunError> {
        write_observations(&mut self.raw, self.venv.reset_all()?)
    }

    fn iterate(&mut self, policy: &mut NetPolicy, split: &mut TimeSplit) -> Result<(), RunError> {
        // On a thread of rayon's pool, so that the environments' steps and the actor's and
        // critic's passes side by side (`GaussianArch::forward_both`) hand work to the other
        // thread through its queue, without a wake-up and a heap block per hand-off.
        rayon::scope(|_| {
            self.collect_rollout(policy, split)?;
            split.time(TimePart::Learn, || {
                self.compute_advantages(policy);
                self.optimise(policy);
            });
            check_finite("PPO parameters", &policy.params)
        })
    }

    fn env_steps(&self) -> u64 {
        self.env_steps
    }

    fn save_state(&self, policy: &NetPolicy) -> Vec<u8> {
        let mut w = StateWriter::new("ppo", STATE_VERSION);
        policy.save_training_state(&mut w);
        self.adam.save(&mut w);
        self.scaler.save(&mut w);
        w.rng(&self.rng);
        w.rng(&self.mb_rng);
        w.usizes(&self.order);
        w.u64(self.env_steps);
        w.envs(&self.venv);
        w.finish()
    }

    fn close(&mut self) -> Result<(), RunError> {
        Ok(self.venv.close()?)
    }
}
