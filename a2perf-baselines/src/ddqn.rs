//! Double DQN (van Hasselt et al.), as the paper's TF-Agents `DdqnAgent`: the online network picks
//! the next action (masked argmax), the target network evaluates it; squared TD loss; ε-greedy
//! exploration over legal actions; uniform replay of configurable capacity.

use a2perf_core::{
    Action, Algorithm, Control, ParamKind, ParamSpec, Params, Policy, PolicyError, RunError, Space,
    TrainingContext, Value,
};

use crate::batch::{ObsBatch, ObsLayout};
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
        let cfg = self.config.clone();
        let resume = ctx.take_resume_state();
        let (mut venv, spec) = make_vec_env(ctx)?;
        let n_env = venv.len();
        if !matches!(spec.action_space, Space::Discrete { .. }) {
            return Err(RunError::Unsupported(
                "DDQN needs a discrete action space".into(),
            ));
        }
        let layout = ObsLayout::from_spec(&spec)?;
        let net = DiscreteNet::for_spec(&spec, &layout, &cfg.net, false)?;
        let params = net.init_params(&mut ctx.rng("ddqn/init"));
        let mut target_params = params.clone();
        let mut target_net = net.clone();
        let mut policy =
            NetPolicy::new("ddqn", &spec, Head::Discrete(net), params, None, ctx.seed())?;
        policy.explore_epsilon = cfg.epsilon_greedy;
        let n = layout.num_actions.unwrap_or(0);
        let mut replay = ReplayBuffer::new(&layout, cfg.replay_capacity, 0);
        let mut sample = ReplaySample::new(&layout);
        let mut idx = Vec::new();
        let mut rng = ctx.rng("ddqn/explore");
        let mut sample_rng = ctx.rng("ddqn/replay");
        let mut adam = Adam::new(policy.params.len());
        let mut grads = vec![0.0f32; policy.params.len()];
        let mut cur = ObsBatch::new(&layout);
        let mut actions = vec![Action::Discrete(0); n_env];
        let mut next_best: Vec<usize> = Vec::new();
        let mut targets: Vec<f32> = Vec::new();
        let mut dq: Vec<f32> = Vec::new();
        let total = ctx.settings().total_env_steps.max(1);
        let mut env_steps = 0u64;
        let mut update_credit = 0.0f32;
        let mut updates = 0usize;

        cur.resize(n_env);
        match &resume {
            Some(bytes) => {
                let mut r = StateReader::new(bytes, "ddqn", STATE_VERSION)?;
                policy.load_training_state(&mut r)?;
                r.f32s_into("target parameters", &mut target_params)?;
                adam.load("policy", &mut r)?;
                rng = r.rng()?;
                sample_rng = r.rng()?;
                update_credit = r.f32()?;
                updates = r.usize()?;
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
            let progress = env_steps as f64 / total as f64;
            let eps = if cfg.epsilon_decay_fraction > 0.0 {
                let f = (progress / f64::from(cfg.epsilon_decay_fraction)).min(1.0) as f32;
                cfg.epsilon_start + f * (cfg.epsilon_greedy - cfg.epsilon_start)
            } else {
                cfg.epsilon_greedy
            };
            if let Head::Discrete(net) = &mut policy.head {
                net.forward(&policy.params, &cur);
                for (i, slot) in actions.iter_mut().enumerate() {
                    let mask = cur.mask(i);
                    let a = if rng.uniform() < f64::from(eps) {
                        spec.action_space.sample(&mut rng, mask)
                    } else {
                        masked::argmax(&net.logits()[i * n..(i + 1) * n], mask)
                            .map(Action::Discrete)
                    };
                    *slot = a.ok_or(RunError::Policy(PolicyError::NoLegalAction))?;
                }
            }
            let outs = venv.step_all(&actions)?;
            for (i, out) in outs.iter().enumerate() {
                let next = if out.step.done() {
                    &out.final_observation
                } else {
                    &out.step.observation
                };
                let a = match actions[i] {
                    Action::Discrete(a) => a,
                    Action::Continuous(_) => 0,
                };
                replay.push(
                    i,
                    &cur,
                    i,
                    next,
                    a,
                    &[],
                    out.step.reward as f32,
                    out.step.terminated,
                )?;
            }
            for (i, out) in outs.iter().enumerate() {
                cur.write_row(i, &out.step.observation)?;
            }
            env_steps += n_env as u64;

            if replay.len() >= cfg.learning_starts.max(1) {
                update_credit += cfg.updates_per_step * n_env as f32;
                let lr = cfg.lr.at(env_steps as f64 / total as f64);
                while update_credit >= 1.0 {
                    update_credit -= 1.0;
                    let Head::Discrete(net) = &mut policy.head else {
                        break;
                    };
                    replay.sample(cfg.batch_size, &mut sample_rng, &mut idx, &mut sample);
                    let b = sample.obs.len();
                    // Double-Q target: online argmax, target evaluation.
                    net.forward(&policy.params, &sample.next);
                    next_best.clear();
                    for k in 0..b {
                        next_best.push(
                            masked::argmax(&net.logits()[k * n..(k + 1) * n], sample.next.mask(k))
                                .unwrap_or(usize::MAX),
                        );
                    }
                    target_net.forward(&target_params, &sample.next);
                    targets.clear();
                    for (k, &best) in next_best.iter().enumerate() {
                        let boot = if sample.terminated[k] || best == usize::MAX {
                            0.0
                        } else {
                            target_net.logits()[k * n + best]
                        };
                        targets.push(sample.rewards[k] + cfg.gamma * boot);
                    }
                    net.forward(&policy.params, &sample.obs);
                    ensure(&mut dq, b * n);
                    dq[..b * n].fill(0.0);
                    for k in 0..b {
                        let a = sample.act_d[k];
                        let err = net.logits()[k * n + a] - targets[k];
                        let g = if cfg.huber {
                            err.clamp(-1.0, 1.0)
                        } else {
                            2.0 * err
                        };
                        dq[k * n + a] = g / b as f32;
                    }
                    grads.fill(0.0);
                    net.backward(&policy.params, &mut grads, &sample.obs, &dq, None);
                    clip_grad_norm(&mut grads, cfg.max_grad_norm);
                    adam.step(&mut policy.params, &grads, lr);
                    updates += 1;
                    if updates.is_multiple_of(cfg.target_update_period) {
                        polyak(&mut target_params, &policy.params, cfg.target_tau);
                    }
                }
                check_finite("DDQN parameters", &policy.params)?;
            }
            let save = |p: &NetPolicy| {
                let mut w = StateWriter::new("ddqn", STATE_VERSION);
                p.save_training_state(&mut w);
                w.f32s(&target_params);
                adam.save(&mut w);
                w.rng(&rng);
                w.rng(&sample_rng);
                w.f32(update_credit);
                w.usize(updates);
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
