//! Double DQN (van Hasselt et al.), as the paper's TF-Agents `DdqnAgent`: the online network picks
//! the next action (masked argmax), the target network evaluates it; squared TD loss; ε-greedy
//! exploration over legal actions; uniform replay of configurable capacity.

use a2perf_core::{
    Action, Algorithm, EnvSpec, ParamKind, ParamSpec, Params, Policy, PolicyError, RngStream,
    RunError, Space, TrainingContext, Value, VecEnv,
};

use crate::batch::{ObsBatch, ObsLayout};
use a2perf_core::{TimePart, TimeSplit};

use crate::common::*;
use crate::model::{DiscreteNet, NetOptions};
use crate::nn::dist::masked;
use crate::nn::optim::{Adam, LrSchedule};
use crate::nn::{clip_grad_norm, ensure, polyak};
use crate::policy::{Head, NetPolicy};
use crate::replay::{ReplayBuffer, ReplaySample};
use crate::resume::{StateReader, StateWriter};

/// Version of DDQN's resumable training state (2: observations are typed, so the
/// observation hashes and the stored observations of version 1 no longer apply).
const STATE_VERSION: u32 = 2;

/// DDQN hyperparameters (see [`Ddqn::params`]).
#[derive(Clone, Debug, PartialEq)]
pub struct DdqnConfig {
    /// Learning rate schedule.
    pub lr: LrSchedule,
    /// Minibatch size.
    pub batch_size: usize,
    /// Replay capacity (transitions).
    pub replay_capacity: usize,
    /// Discount.
    pub gamma: f32,
    /// Initial ε.
    pub epsilon_start: f32,
    /// Final ε (paper: 0.3).
    pub epsilon_greedy: f32,
    /// Fraction of the budget over which ε decays linearly.
    pub epsilon_decay_fraction: f32,
    /// Transitions collected before learning starts.
    pub learning_starts: usize,
    /// Gradient updates per environment step.
    pub updates_per_step: f32,
    /// Target network update: Polyak τ per update (1 = hard copy).
    pub target_tau: f32,
    /// Updates between target updates.
    pub target_update_period: usize,
    /// Huber instead of squared TD loss.
    pub huber: bool,
    /// Gradient-norm clip.
    pub max_grad_norm: f32,
    /// Networks.
    pub net: NetOptions,
}

/// The DDQN algorithm.
#[derive(Clone, Debug)]
pub struct Ddqn {
    /// Hyperparameters.
    pub config: DdqnConfig,
}

impl Ddqn {
    /// Documented hyperparameters (paper: batch 256, lr 4e-5, ε-greedy 0.3, squared loss; the
    /// paper's replay of 1e7 transitions is not a sensible in-memory default, see `replay_capacity`).
    pub fn params() -> Vec<ParamSpec> {
        let mut v = vec![
            ParamSpec::new(
                "learning_rate",
                ParamKind::Float,
                Value::Float(4e-5),
                "Adam learning rate (paper: 4e-5)",
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
                Value::Int(100_000),
                "replay buffer capacity in transitions (paper: 1e7 with Reverb; each observation is stored once, in its narrowest exact type, see `replay`)",
            ),
            ParamSpec::new("gamma", ParamKind::Float, Value::Float(0.99), "discount"),
            ParamSpec::new(
                "epsilon_start",
                ParamKind::Float,
                Value::Float(1.0),
                "initial exploration rate",
            ),
            ParamSpec::new(
                "epsilon_greedy",
                ParamKind::Float,
                Value::Float(0.3),
                "final exploration rate (paper: 0.3, constant)",
            ),
            ParamSpec::new(
                "epsilon_decay_fraction",
                ParamKind::Float,
                Value::Float(0.1),
                "fraction of the budget over which epsilon decays linearly (0 = constant epsilon_greedy)",
            ),
            ParamSpec::new(
                "learning_starts",
                ParamKind::Int,
                Value::Int(1000),
                "transitions collected before the first update",
            ),
            ParamSpec::new(
                "updates_per_step",
                ParamKind::Float,
                Value::Float(0.25),
                "gradient updates per environment step",
            ),
            ParamSpec::new(
                "target_tau",
                ParamKind::Float,
                Value::Float(1.0),
                "target update: Polyak coefficient (1 = hard copy)",
            ),
            ParamSpec::new(
                "target_update_period",
                ParamKind::Int,
                Value::Int(250),
                "gradient updates between target updates",
            ),
            ParamSpec::new(
                "td_loss",
                ParamKind::Choice(&["squared", "huber"]),
                Value::Str("squared".into()),
                "TD loss (paper: squared)",
            ),
            ParamSpec::new(
                "max_grad_norm",
                ParamKind::Float,
                Value::Float(10.0),
                "global gradient-norm clipping, 0 = off",
            ),
        ];
        v.extend(schedule_specs());
        v.extend(net_specs(&[64, 64]));
        v
    }

    /// Builds DDQN from resolved hyperparameters.
    pub fn from_params(p: &Params) -> Result<Self, RunError> {
        let lr = positive_f32(p, "learning_rate")?;
        Ok(Self {
            config: DdqnConfig {
                lr: schedule(p, lr)?,
                batch_size: positive_usize(p, "batch_size")?,
                replay_capacity: positive_usize(p, "replay_capacity")?,
                gamma: unit_f32(p, "gamma")?,
                epsilon_start: unit_f32(p, "epsilon_start")?,
                epsilon_greedy: unit_f32(p, "epsilon_greedy")?,
                epsilon_decay_fraction: unit_f32(p, "epsilon_decay_fraction")?,
                learning_starts: p.usize("learning_starts").map_err(hp)?,
                updates_per_step: nonneg_f32(p, "updates_per_step")?,
                target_tau: unit_f32(p, "target_tau")?,
                target_update_period: positive_usize(p, "target_update_period")?,
                huber: p.str("td_loss").map_err(hp)? == "huber",
                max_grad_norm: nonneg_f32(p, "max_grad_norm")?,
                net: net_options(p)?,
            },
        })
    }
}

impl Algorithm for Ddqn {
    fn name(&self) -> &str {
        "ddqn"
    }

    /// Resumable: the state saved at every checkpoint interval holds the online and target
    /// parameters, Adam, both random streams, the update counters, the whole replay buffer and
    /// every environment's current episode.
    fn train(&mut self, ctx: &mut TrainingContext<'_>) -> Result<Box<dyn Policy>, RunError> {
        let resume = ctx.take_resume_state();
        let (venv, spec) = make_vec_env(ctx)?;
        let (policy, run) = DdqnRun::new(self.config.clone(), venv, &spec, ctx)?;
        drive(run, policy, resume, ctx)
    }
}

/// Everything a DDQN run updates besides the online network (the policy): the environments,
/// the target network, the optimiser, the replay, the random streams, the counters and the
/// workspaces of the steps below.
struct DdqnRun {
    cfg: DdqnConfig,
    venv: VecEnv,
    n_env: usize,
    action_space: Space,
    /// Number of actions.
    n: usize,
    target_net: DiscreteNet,
    target_params: Vec<f32>,
    adam: Adam,
    grads: Vec<f32>,
    replay: ReplayBuffer,
    sample: ReplaySample,
    idx: Vec<usize>,
    rng: RngStream,
    sample_rng: RngStream,
    /// Every environment's current observation.
    cur: ObsBatch,
    actions: Vec<Action>,
    next_best: Vec<usize>,
    targets: Vec<f32>,
    dq: Vec<f32>,
    /// The network's scored actions (see [`DiscreteNet::scored_actions_into`]).
    scored: Vec<usize>,
    /// Per sample, the logit column of its action (`None`: not scored).
    cols: Vec<Option<usize>>,
    total: u64,
    env_steps: u64,
    /// Gradient updates earned and not yet made (`updates_per_step` per environment step).
    update_credit: f32,
    updates: usize,
}

impl DdqnRun {
    /// The untrained online network (as the policy), its target copy and the rest of the run.
    fn new(
        cfg: DdqnConfig,
        venv: VecEnv,
        spec: &EnvSpec,
        ctx: &TrainingContext<'_>,
    ) -> Result<(NetPolicy, Self), RunError> {
        let n_env = venv.len();
        if !matches!(spec.action_space, Space::Discrete { .. }) {
            return Err(RunError::Unsupported(
                "DDQN needs a discrete action space".into(),
            ));
        }
        let layout = ObsLayout::from_spec(spec)?;
        let net = DiscreteNet::for_spec(spec, &layout, &cfg.net, false)?;
        let params = net.init_params(&mut ctx.rng("ddqn/init"));
        let target_params = params.clone();
        let target_net = net.clone();
        // Minibatches hold only what the networks read (the circuit network: 2 of 11 tensors).
        let mut sample = ReplaySample::new(&layout);
        if let Some(keep) = net.inputs() {
            sample.obs.keep_tensors(&keep);
            sample.next.keep_tensors(&keep);
        }
        let mut policy =
            NetPolicy::new("ddqn", spec, Head::Discrete(net), params, None, ctx.seed())?;
        policy.explore_epsilon = cfg.epsilon_greedy;
        let mut cur = ObsBatch::new(&layout);
        cur.resize(n_env);
        let run = Self {
            n_env,
            action_space: spec.action_space.clone(),
            n: layout.num_actions.unwrap_or(0),
            target_net,
            target_params,
            adam: Adam::new(policy.params.len()),
            grads: vec![0.0; policy.params.len()],
            replay: ReplayBuffer::new(&layout, cfg.replay_capacity, 0),
            sample,
            idx: Vec::new(),
            rng: ctx.rng("ddqn/explore"),
            sample_rng: ctx.rng("ddqn/replay"),
            cur,
            actions: vec![Action::Discrete(0); n_env],
            next_best: Vec::new(),
            targets: Vec::new(),
            dq: Vec::new(),
            scored: Vec::new(),
            cols: Vec::new(),
            total: ctx.settings().total_env_steps.max(1),
            env_steps: 0,
            update_credit: 0.0,
            updates: 0,
            venv,
            cfg,
        };
        Ok((policy, run))
    }

    /// ε-greedy actions over the legal ones, ε decaying linearly from `epsilon_start` to
    /// `epsilon_greedy` over the first `epsilon_decay_fraction` of the budget.
    fn choose_actions(&mut self, policy: &mut NetPolicy) -> Result<(), RunError> {
        let cfg = &self.cfg;
        let progress = self.env_steps as f64 / self.total as f64;
        let eps = if cfg.epsilon_decay_fraction > 0.0 {
            let f = (progress / f64::from(cfg.epsilon_decay_fraction)).min(1.0) as f32;
            cfg.epsilon_start + f * (cfg.epsilon_greedy - cfg.epsilon_start)
        } else {
            cfg.epsilon_greedy
        };
        let n = self.n;
        if let Head::Discrete(net) = &mut policy.head {
            net.forward(&policy.params, &self.cur);
            for (i, slot) in self.actions.iter_mut().enumerate() {
                let mask = self.cur.mask(i);
                let a = if self.rng.uniform() < f64::from(eps) {
                    self.action_space.sample(&mut self.rng, mask)
                } else {
                    masked::argmax(&net.logits()[i * n..(i + 1) * n], mask).map(Action::Discrete)
                };
                *slot = a.ok_or(RunError::Policy(PolicyError::NoLegalAction))?;
            }
        }
        Ok(())
    }

    /// Steps every environment with the chosen actions, storing the transitions.
    fn step_envs(&mut self) -> Result<(), RunError> {
        let outs = self.venv.step_all(&self.actions)?;
        let actions = &self.actions;
        let act_d = |i: usize| match actions[i] {
            Action::Discrete(a) => a,
            Action::Continuous(_) => 0,
        };
        push_transitions(&mut self.replay, &mut self.cur, outs, act_d, &[], 0)?;
        self.env_steps += self.n_env as u64;
        Ok(())
    }

    /// The gradient updates earned by the last step, once the replay holds `learning_starts`
    /// transitions.
    fn learn(&mut self, policy: &mut NetPolicy) -> Result<(), RunError> {
        if self.replay.len() < self.cfg.learning_starts.max(1) {
            return Ok(());
        }
        self.update_credit += self.cfg.updates_per_step * self.n_env as f32;
        let lr = self.cfg.lr.at(self.env_steps as f64 / self.total as f64);
        while self.update_credit >= 1.0 {
            self.update_credit -= 1.0;
            let Head::Discrete(net) = &mut policy.head else {
                break;
            };
            self.update(net, &mut policy.params, lr);
        }
        check_finite("DDQN parameters", &policy.params)
    }

    /// One update on a replay minibatch: the double-Q targets (online argmax, target
    /// evaluation), the TD loss's gradient step and, every `target_update_period` updates,
    /// the target network's.
    ///
    /// It reads the networks' scored logits only ([`DiscreteNet::forward_scored`]: on A2Perf's
    /// padded circuit canvas, the grid's cells, not the 128·128 actions) and the next
    /// observations' masks only, at the scored actions alone. That is exact: the scored
    /// actions keep the actions' order, the others are never legal, so the masked argmax (ties
    /// to the lowest action), the target values and the gradients are the same as over every
    /// action. The two passes over
    /// the next observations feed no backward pass, so they keep no activations
    /// ([`DiscreteNet::infer_scored`]), the same values.
    fn update(&mut self, net: &mut DiscreteNet, params: &mut [f32], lr: f32) {
        let cfg = &self.cfg;
        let sample = &mut self.sample;
        let some = net.scored_actions_into(&mut self.scored);
        let scored = some.then_some(self.scored.as_slice());
        let (rng, idx) = (&mut self.sample_rng, &mut self.idx);
        match scored {
            None => self
                .replay
                .sample_next_masks(cfg.batch_size, rng, idx, sample),
            Some(actions) => self
                .replay
                .sample_legal_at(cfg.batch_size, rng, idx, sample, actions),
        }
        let b = sample.obs.len();
        net.infer_scored(params, &sample.next);
        let m = net.logit_width();
        self.next_best.clear();
        for k in 0..b {
            let row = &net.logits()[k * m..(k + 1) * m];
            let best = match scored {
                // Every action from `legal_end` on is illegal (the replay's mask read knows
                // where a page's legal actions end): the argmax over the actions before it.
                None => {
                    let end = sample.next.legal_end(k).min(m);
                    match sample.next.mask(k) {
                        Some(mask) => masked::argmax(&row[..end], Some(&mask[..end])),
                        None => masked::argmax(row, None),
                    }
                }
                // Column `j` is legal as its action is (`argmax_at` over the whole mask).
                Some(_) => masked::argmax(row, Some(&sample.next_legal[k * m..(k + 1) * m])),
            };
            self.next_best.push(best.unwrap_or(usize::MAX));
        }
        self.target_net
            .infer_scored(&self.target_params, &sample.next);
        self.targets.clear();
        for (k, &best) in self.next_best.iter().enumerate() {
            let boot = if sample.terminated[k] || best == usize::MAX {
                0.0
            } else {
                self.target_net.logits()[k * m + best]
            };
            self.targets.push(sample.rewards[k] + cfg.gamma * boot);
        }
        net.forward_scored(params, &sample.obs);
        // An action outside the scored ones (never legal, so never taken) would have a `−∞`
        // Q-value whose gradient no parameter receives: it gets none here either.
        self.cols.clear();
        self.cols
            .extend(sample.act_d[..b].iter().map(|&a| match scored {
                None => Some(a),
                Some(actions) => actions.binary_search(&a).ok(),
            }));
        // `dq` is all zeros between updates (each update clears the entries it set), which
        // spares a [B, m] fill per update: m is 12,500 for web navigation.
        ensure(&mut self.dq, b * m);
        for (k, col) in self.cols.iter().enumerate() {
            let Some(j) = *col else { continue };
            let err = net.logits()[k * m + j] - self.targets[k];
            let g = if cfg.huber {
                err.clamp(-1.0, 1.0)
            } else {
                2.0 * err
            };
            self.dq[k * m + j] = g / b as f32;
        }
        self.grads.fill(0.0);
        net.backward(params, &mut self.grads, &sample.obs, &self.dq, None);
        for (k, col) in self.cols.iter().enumerate() {
            if let Some(j) = *col {
                self.dq[k * m + j] = 0.0;
            }
        }
        clip_grad_norm(&mut self.grads, cfg.max_grad_norm);
        self.adam.step(params, &self.grads, lr);
        self.updates += 1;
        if self.updates.is_multiple_of(cfg.target_update_period) {
            polyak(&mut self.target_params, params, cfg.target_tau);
        }
    }
}

impl OnlineRun for DdqnRun {
    fn restore(
        &mut self,
        bytes: &[u8],
        policy: &mut NetPolicy,
        ctx: &mut TrainingContext<'_>,
    ) -> Result<(), RunError> {
        let mut r = StateReader::new(bytes, "ddqn", STATE_VERSION)?;
        policy.load_training_state(&mut r)?;
        r.f32s_into("target parameters", &mut self.target_params)?;
        self.adam.load("policy", &mut r)?;
        self.rng = r.rng()?;
        self.sample_rng = r.rng()?;
        self.update_credit = r.f32()?;
        self.updates = r.usize()?;
        self.env_steps = r.u64()?;
        self.replay.load(&mut r)?;
        write_observations(&mut self.cur, r.envs(&mut self.venv, &mut |m| ctx.warn(m))?)?;
        r.finish()
    }

    fn reset(&mut self) -> Result<(), RunError> {
        write_observations(&mut self.cur, self.venv.reset_all()?)
    }

    fn iterate(&mut self, policy: &mut NetPolicy, split: &mut TimeSplit) -> Result<(), RunError> {
        split.time(TimePart::Act, || self.choose_actions(policy))?;
        split.time(TimePart::Env, || self.step_envs())?;
        split.time(TimePart::Learn, || self.learn(policy))
    }

    fn env_steps(&self) -> u64 {
        self.env_steps
    }

    fn save_state(&self, policy: &NetPolicy) -> Vec<u8> {
        let mut w = StateWriter::new("ddqn", STATE_VERSION);
        policy.save_training_state(&mut w);
        w.f32s(&self.target_params);
        self.adam.save(&mut w);
        w.rng(&self.rng);
        w.rng(&self.sample_rng);
        w.f32(self.update_credit);
        w.usize(self.updates);
        w.u64(self.env_steps);
        self.replay.save(&mut w);
        w.envs(&self.venv);
        w.finish()
    }

    fn close(&mut self) -> Result<(), RunError> {
        Ok(self.venv.close()?)
    }
}
