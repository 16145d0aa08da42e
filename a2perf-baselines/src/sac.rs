//! Soft Actor-Critic (Haarnoja et al.) with twin Q networks, Polyak-averaged targets
//! (τ = 0.005) and automatic entropy tuning (target entropy −|A|), as the paper's TF-Agents
//! `SacAgent`. Actions are a tanh-squashed Gaussian mapped affinely onto the box bounds.

use a2perf_core::{
    Action, Algorithm, EnvSpec, ParamKind, ParamSpec, Params, Policy, RngStream, RunError, Space,
    TrainingContext, Value, VecEnv,
};

use rayon::prelude::*;

use crate::batch::{ObsBatch, ObsLayout};
use a2perf_core::{TimePart, TimeSplit};

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
    /// Output gradient of the current pass (one per row).
    dq: Vec<f32>,
    /// Action gradient of the actor's pass (`[rows, action]`).
    dqin: Vec<f32>,
    /// The rows of the actor's pass on which this critic is the minimum.
    rows: Vec<usize>,
}

impl Critic {
    /// One regression step on targets `y` at the inputs `qin`: forward, squared-error gradient,
    /// backward, clipping and Adam.
    fn regress(&mut self, qnet: &Mlp, qin: &[f32], y: &[f32], b: usize, max_norm: f32, lr: f32) {
        ensure(&mut self.dq, b);
        let q = qnet.forward(&self.params, qin, b, &mut self.ws);
        for k in 0..b {
            self.dq[k] = 2.0 * (q[k] - y[k]) / b as f32;
        }
        self.grads.fill(0.0);
        qnet.backward(
            &self.params,
            &mut self.grads,
            qin,
            &self.dq,
            &mut self.ws,
            None,
        );
        clip_grad_norm(&mut self.grads, max_norm);
        self.adam.step(&mut self.params, &self.grads, lr);
    }
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
        let resume = ctx.take_resume_state();
        let (venv, spec) = make_vec_env(ctx)?;
        let (policy, run) = SacRun::new(self.config.clone(), venv, &spec, ctx)?;
        drive(run, policy, resume, ctx)
    }
}

/// The bounds of a box action space, which SAC's squashed actions are mapped onto.
fn squash_bounds(space: &Space) -> Result<(Vec<f32>, Vec<f32>), RunError> {
    match space {
        Space::Box { low, high, .. } => {
            if low.iter().chain(high).any(|x| !x.is_finite()) {
                return Err(RunError::Unsupported(
                    "SAC needs finite action bounds to squash into".into(),
                ));
            }
            Ok((
                low.iter().map(|x| *x as f32).collect(),
                high.iter().map(|x| *x as f32).collect(),
            ))
        }
        _ => Err(RunError::Unsupported("SAC needs a box action space".into())),
    }
}

/// Everything a SAC run updates besides the actor (the policy): the environments, the critics,
/// the optimisers, the temperature, the replay, the random streams and the workspaces of the
/// steps below.
struct SacRun {
    cfg: SacConfig,
    venv: VecEnv,
    n_env: usize,
    /// Action dimensions.
    d: usize,
    /// Flattened observation dimensions.
    od: usize,
    low: Vec<f32>,
    high: Vec<f32>,
    actor: Mlp,
    qnet: Mlp,
    critics: Vec<Critic>,
    actor_adam: Adam,
    actor_grads: Vec<f32>,
    log_alpha: f32,
    alpha_adam: Adam,
    target_entropy: f32,
    replay: ReplayBuffer,
    sample: ReplaySample,
    idx: Vec<usize>,
    rng: RngStream,
    noise_rng: RngStream,
    sample_rng: RngStream,
    /// Every environment's current observation, raw (as the replay stores them).
    cur: ObsBatch,
    /// `cur` normalised for acting.
    cur_n: ObsBatch,
    actions: Vec<Action>,
    /// The actions in [−1, 1] (before mapping onto the bounds), as the replay stores them.
    a_norm: Vec<f32>,
    ws_actor: MlpWs,
    /// The actor's pass over the next observations (the critics' targets).
    ws_next: MlpWs,
    x: Vec<f32>,
    xn: Vec<f32>,
    qin: Vec<f32>,
    eps: Vec<f32>,
    a_pi: Vec<f32>,
    logp: Vec<f32>,
    y: Vec<f32>,
    dout: Vec<f32>,
    /// A zero action gradient (`[action]`), for the rows a critic is not the minimum on.
    zero_da: Vec<f32>,
    total: u64,
    env_steps: u64,
    /// Gradient updates earned and not yet made (`updates_per_step` per environment step).
    credit: f32,
}

impl SacRun {
    /// The untrained actor (as the policy) and critics for `spec`'s environments.
    fn new(
        cfg: SacConfig,
        venv: VecEnv,
        spec: &EnvSpec,
        ctx: &TrainingContext<'_>,
    ) -> Result<(NetPolicy, Self), RunError> {
        let n_env = venv.len();
        let (low, high) = squash_bounds(&spec.action_space)?;
        let d = low.len();
        let layout = ObsLayout::from_spec(spec)?;
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
        let critics: Vec<Critic> = (0..2)
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
                    dq: Vec::new(),
                    dqin: Vec::new(),
                    rows: Vec::new(),
                }
            })
            .collect();
        let actor = arch.actor.clone();
        let mut policy = NetPolicy::new(
            "sac",
            spec,
            Head::Squashed(arch),
            actor_params,
            None,
            ctx.seed(),
        )?;
        policy.action_limit = cfg.action_limit;
        if cfg.normalize_observations {
            policy.obs_norm = ObsNorm::for_head(&policy.head, &layout);
        }
        let mut cur = ObsBatch::new(&layout);
        cur.resize(n_env);
        let run = Self {
            n_env,
            d,
            od,
            low,
            high,
            actor,
            qnet,
            critics,
            actor_adam: Adam::new(policy.params.len()),
            actor_grads: vec![0.0; policy.params.len()],
            log_alpha: cfg.init_alpha.ln(),
            alpha_adam: Adam::new(1),
            target_entropy: -(d as f32),
            replay: ReplayBuffer::new(&layout, cfg.replay_capacity, d),
            sample: ReplaySample::new(&layout),
            idx: Vec::new(),
            rng: ctx.rng("sac/explore"),
            noise_rng: ctx.rng("sac/update-noise"),
            sample_rng: ctx.rng("sac/replay"),
            cur,
            cur_n: ObsBatch::new(&layout),
            actions: vec![Action::Continuous(vec![0.0; d]); n_env],
            a_norm: vec![0.0; n_env * d],
            ws_actor: MlpWs::default(),
            ws_next: MlpWs::default(),
            x: Vec::new(),
            xn: Vec::new(),
            qin: Vec::new(),
            eps: Vec::new(),
            a_pi: Vec::new(),
            logp: Vec::new(),
            y: Vec::new(),
            dout: Vec::new(),
            zero_da: vec![0.0; d],
            total: ctx.settings().total_env_steps.max(1),
            env_steps: 0,
            credit: 0.0,
            venv,
            cfg,
        };
        Ok((policy, run))
    }

    /// Updates the observation statistics and picks every environment's action: uniformly
    /// random before `learning_starts`, then sampled from the squashed Gaussian.
    fn choose_actions(&mut self, policy: &mut NetPolicy) {
        let (n_env, d) = (self.n_env, self.d);
        if let Some(n) = &mut policy.obs_norm {
            n.update(&self.cur, n_env);
        }
        if (self.env_steps as usize) < self.cfg.learning_starts {
            for v in self.a_norm.iter_mut() {
                *v = self.rng.range(-1.0, 1.0) as f32;
            }
        } else {
            match &policy.obs_norm {
                Some(n) => {
                    self.cur_n.resize(n_env);
                    for i in 0..n_env {
                        self.cur_n.copy_row(i, &self.cur, i);
                        n.apply(&mut self.cur_n, i);
                    }
                    self.cur_n.concat_into(&mut self.x);
                }
                None => self.cur.concat_into(&mut self.x),
            }
            let out = self
                .actor
                .forward(&policy.params, &self.x, n_env, &mut self.ws_actor);
            ensure(&mut self.eps, d);
            for i in 0..n_env {
                for e in self.eps[..d].iter_mut() {
                    *e = self.rng.normal() as f32;
                }
                let row = &out[i * 2 * d..(i + 1) * 2 * d];
                tanh_gaussian::sample(
                    &row[..d],
                    &row[d..],
                    &self.eps[..d],
                    &mut self.a_norm[i * d..(i + 1) * d],
                );
            }
        }
        for (i, slot) in self.actions.iter_mut().enumerate() {
            if let Action::Continuous(v) = slot {
                #[allow(clippy::needless_range_loop)] // k indexes several parallel buffers
                for k in 0..d {
                    v[k] = squash_to_bounds(
                        self.a_norm[i * d + k],
                        self.low[k],
                        self.high[k],
                        self.cfg.action_limit,
                    );
                }
            }
        }
    }

    /// Steps every environment with the chosen actions, storing the transitions.
    fn step_envs(&mut self) -> Result<(), RunError> {
        let outs = self.venv.step_all(&self.actions)?;
        let d = self.d;
        push_transitions(
            &mut self.replay,
            &mut self.cur,
            outs,
            |_| 0,
            &self.a_norm,
            d,
        )?;
        self.env_steps += self.n_env as u64;
        Ok(())
    }

    /// The gradient updates earned by the last step, once learning has started.
    fn learn(&mut self, policy: &mut NetPolicy) -> Result<(), RunError> {
        if self.replay.is_empty() || (self.env_steps as usize) < self.cfg.learning_starts {
            return Ok(());
        }
        self.credit += self.cfg.updates_per_step * self.n_env as f32;
        let lr = self.cfg.lr.at(self.env_steps as f64 / self.total as f64);
        while self.credit >= 1.0 {
            self.credit -= 1.0;
            self.update(policy, lr);
        }
        check_finite("SAC actor", &policy.params)?;
        check_finite("SAC critic", &self.critics[0].params)
    }

    /// One update on a replay minibatch: critics, actor, temperature, then the targets.
    fn update(&mut self, policy: &mut NetPolicy, lr: f32) {
        self.replay.sample(
            self.cfg.batch_size,
            &mut self.sample_rng,
            &mut self.idx,
            &mut self.sample,
        );
        let b = self.sample.obs.len();
        if let Some(n) = &policy.obs_norm {
            for r in 0..b {
                n.apply(&mut self.sample.obs, r);
                n.apply(&mut self.sample.next, r);
            }
        }
        let alpha = self.log_alpha.exp();
        self.sample.obs.concat_into(&mut self.x);
        self.sample.next.concat_into(&mut self.xn);
        // The actor's two passes (next observations for the targets, observations for its own
        // step) read only its parameters, which change at the end: both now, side by side.
        let (actor, params) = (&self.actor, &policy.params);
        let (ws_next, ws_actor) = (&mut self.ws_next, &mut self.ws_actor);
        let (xn, x) = (&self.xn, &self.x);
        rayon::join(
            || actor.forward(params, xn, b, ws_next),
            || actor.forward(params, x, b, ws_actor),
        );
        self.critic_targets(b, alpha);
        self.critic_step(b, lr);
        self.actor_step(policy, b, alpha, lr);
        // Temperature: minimise −log α · (log π + target entropy).
        let mean_lp = self.logp[..b].iter().map(|l| f64::from(*l)).sum::<f64>() / b as f64;
        let g = -(mean_lp as f32 + self.target_entropy);
        let mut la = [self.log_alpha];
        self.alpha_adam.step(&mut la, &[g], lr);
        self.log_alpha = la[0];
        for c in self.critics.iter_mut() {
            polyak(&mut c.target, &c.params, self.cfg.tau);
        }
    }

    /// `y` = r + γ(1−done)(min Q'(s', a') − α log π(a'|s')), with a' sampled from the actor.
    /// The actor's pass over the next observations is in `ws_next`.
    fn critic_targets(&mut self, b: usize, alpha: f32) {
        let (d, od) = (self.d, self.od);
        let out = self.actor.output(&self.ws_next);
        ensure(&mut self.eps, b * d);
        ensure(&mut self.a_pi, b * d);
        ensure(&mut self.logp, b);
        sample_squashed(
            out,
            b,
            d,
            &mut self.noise_rng,
            &mut self.eps,
            &mut self.a_pi,
            &mut self.logp,
        );
        concat_obs_action(&self.xn, &self.a_pi, b, od, d, &mut self.qin);
        ensure(&mut self.y, b);
        let (qnet, qin) = (&self.qnet, &self.qin);
        self.critics.par_iter_mut().for_each(|c| {
            qnet.forward(&c.target, qin, b, &mut c.ws_t);
        });
        let q1 = qnet.output(&self.critics[0].ws_t);
        let q2 = qnet.output(&self.critics[1].ws_t);
        for k in 0..b {
            let boot = if self.sample.terminated[k] {
                0.0
            } else {
                q1[k].min(q2[k]) - alpha * self.logp[k]
            };
            self.y[k] = self.sample.rewards[k] + self.cfg.gamma * boot;
        }
    }

    /// Both critics regress on `y` at the stored actions, side by side (each step is the
    /// critic's own).
    fn critic_step(&mut self, b: usize, lr: f32) {
        concat_obs_action(
            &self.x,
            &self.sample.act_c,
            b,
            self.od,
            self.d,
            &mut self.qin,
        );
        let (qnet, qin, y) = (&self.qnet, &self.qin, &self.y);
        let max_norm = self.cfg.max_grad_norm;
        self.critics
            .par_iter_mut()
            .for_each(|c| c.regress(qnet, qin, y, b, max_norm, lr));
    }

    /// The actor minimises α log π(a|s) − min Q(s, a), with a reparameterised; leaves the
    /// log-probabilities of its actions in `logp` for the temperature.
    fn actor_step(&mut self, policy: &mut NetPolicy, b: usize, alpha: f32, lr: f32) {
        let (d, od) = (self.d, self.od);
        let out = self.actor.output(&self.ws_actor);
        sample_squashed(
            out,
            b,
            d,
            &mut self.noise_rng,
            &mut self.eps,
            &mut self.a_pi,
            &mut self.logp,
        );
        concat_obs_action(&self.x, &self.a_pi, b, od, d, &mut self.qin);
        let (qnet, qin) = (&self.qnet, &self.qin);
        self.critics.par_iter_mut().for_each(|c| {
            qnet.forward(&c.params, qin, b, &mut c.ws);
        });
        ensure(&mut self.dout, b * 2 * d);
        self.dout[..b * 2 * d].fill(0.0);
        {
            // Gradient flows through whichever critic is the minimum for each row: each critic
            // keeps its rows (the rest would carry a zero gradient through it).
            let (c0, c1) = self.critics.split_at_mut(1);
            let (c0, c1) = (&mut c0[0], &mut c1[0]);
            c0.rows.clear();
            c1.rows.clear();
            let (qa, qb) = (qnet.output(&c0.ws), qnet.output(&c1.ws));
            for k in 0..b {
                if qa[k] <= qb[k] {
                    c0.rows.push(k);
                } else {
                    c1.rows.push(k);
                }
            }
        }
        // The actor needs each critic's gradient with respect to the action columns of its
        // input only, on the rows where it is the minimum: no parameter gradients, no
        // observation columns. The two side by side, each into its own buffer.
        self.critics.par_iter_mut().for_each(|c| {
            let n = c.rows.len();
            ensure(&mut c.dq, n);
            c.dq[..n].fill(-1.0 / b as f32);
            ensure(&mut c.dqin, n * d);
            qnet.keep_rows(&mut c.ws, &c.rows);
            qnet.backward_input_cols(&c.params, &c.dq[..n], &mut c.ws, od..od + d, &mut c.dqin);
        });
        // Then their contributions, critic 0's first, as when one thread did it all (a row
        // the critic is not the minimum on contributes a zero action gradient).
        for (ci, c) in self.critics.iter().enumerate() {
            let mut kept = c.rows.iter().enumerate().peekable();
            for k in 0..b {
                let da = match kept.next_if(|(_, r)| **r == k) {
                    Some((j, _)) => &c.dqin[j * d..(j + 1) * d],
                    None => &self.zero_da[..d],
                };
                let row = &out[k * 2 * d..(k + 1) * 2 * d];
                let (dm, dr) = self.dout[k * 2 * d..(k + 1) * 2 * d].split_at_mut(d);
                let dlogp = if ci == 0 { alpha / b as f32 } else { 0.0 };
                tanh_gaussian::backward(
                    &row[..d],
                    &row[d..],
                    &self.eps[k * d..(k + 1) * d],
                    da,
                    dlogp,
                    dm,
                    dr,
                );
            }
        }
        self.actor_grads.fill(0.0);
        self.actor.backward(
            &policy.params,
            &mut self.actor_grads,
            &self.x,
            &self.dout,
            &mut self.ws_actor,
            None,
        );
        clip_grad_norm(&mut self.actor_grads, self.cfg.max_grad_norm);
        self.actor_adam
            .step(&mut policy.params, &self.actor_grads, lr);
    }
}

/// Reparameterised actions of the `b` actor rows `out` (`[mean | raw log-std]` each): fresh
/// noise from `rng` into `eps`, the squashed actions into `a_pi`, their log-probabilities into
/// `logp`.
fn sample_squashed(
    out: &[f32],
    b: usize,
    d: usize,
    rng: &mut RngStream,
    eps: &mut [f32],
    a_pi: &mut [f32],
    logp: &mut [f32],
) {
    for e in eps[..b * d].iter_mut() {
        *e = rng.normal() as f32;
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
}

fn concat_obs_action(x: &[f32], a: &[f32], b: usize, od: usize, d: usize, out: &mut Vec<f32>) {
    ensure(out, b * (od + d));
    for k in 0..b {
        let o = &mut out[k * (od + d)..(k + 1) * (od + d)];
        o[..od].copy_from_slice(&x[k * od..(k + 1) * od]);
        o[od..].copy_from_slice(&a[k * d..(k + 1) * d]);
    }
}

impl OnlineRun for SacRun {
    fn restore(
        &mut self,
        bytes: &[u8],
        policy: &mut NetPolicy,
        ctx: &mut TrainingContext<'_>,
    ) -> Result<(), RunError> {
        let mut r = StateReader::new(bytes, "sac", STATE_VERSION)?;
        policy.load_training_state(&mut r)?;
        for (k, c) in self.critics.iter_mut().enumerate() {
            r.f32s_into(&format!("critic {k} parameters"), &mut c.params)?;
            r.f32s_into(&format!("critic {k} target"), &mut c.target)?;
            c.adam.load(&format!("critic {k}"), &mut r)?;
        }
        self.actor_adam.load("actor", &mut r)?;
        self.log_alpha = r.f32()?;
        self.alpha_adam.load("temperature", &mut r)?;
        self.rng = r.rng()?;
        self.noise_rng = r.rng()?;
        self.sample_rng = r.rng()?;
        self.credit = r.f32()?;
        self.env_steps = r.u64()?;
        self.replay.load(&mut r)?;
        write_observations(&mut self.cur, r.envs(&mut self.venv, &mut |m| ctx.warn(m))?)?;
        r.finish()
    }

    fn reset(&mut self) -> Result<(), RunError> {
        write_observations(&mut self.cur, self.venv.reset_all()?)
    }

    fn iterate(&mut self, policy: &mut NetPolicy, split: &mut TimeSplit) -> Result<(), RunError> {
        // On a thread of rayon's pool, so that the environments' steps and the two critics'
        // passes side by side hand work to the other thread through its queue, without a
        // wake-up and a heap block per hand-off.
        rayon::scope(|_| {
            split.time(TimePart::Act, || self.choose_actions(policy));
            split.time(TimePart::Env, || self.step_envs())?;
            split.time(TimePart::Learn, || self.learn(policy))
        })
    }

    fn env_steps(&self) -> u64 {
        self.env_steps
    }

    fn save_state(&self, policy: &NetPolicy) -> Vec<u8> {
        let mut w = StateWriter::new("sac", STATE_VERSION);
        policy.save_training_state(&mut w);
        for c in &self.critics {
            w.f32s(&c.params);
            w.f32s(&c.target);
            c.adam.save(&mut w);
        }
        self.actor_adam.save(&mut w);
        w.f32(self.log_alpha);
        self.alpha_adam.save(&mut w);
        w.rng(&self.rng);
        w.rng(&self.noise_rng);
        w.rng(&self.sample_rng);
        w.f32(self.credit);
        w.u64(self.env_steps);
        self.replay.save(&mut w);
        w.envs(&self.venv);
        w.finish()
    }

    fn close(&mut self) -> Result<(), RunError> {
        Ok(self.venv.close()?)
    }
}
