//! Episode logs and their replay: the proof that a stated return came from a real episode.
//!
//! Environments are deterministic given their reset seed, so the seed and the actions of an
//! episode determine every reward in it. An [`EpisodeLog`] records them (and, for diagnosis, the
//! rewards as they were observed); [`replay`] steps a freshly made environment through the log
//! and recomputes the return with the same arithmetic as the rollout that produced it (rewards
//! summed in step order from `0.0`), so an honest log reproduces its return bit for bit. No
//! policy runs during a replay.
//!
//! ```
//! # use a2perf_core::{Action, Env, EnvError, EnvSpec, Observation, Space, Step};
//! use a2perf_core::replay::{EpisodeLog, replay};
//! # struct Counter { spec: EnvSpec, t: usize }
//! # impl Env for Counter {
//! #     fn spec(&self) -> &EnvSpec { &self.spec }
//! #     fn reset_into(&mut self, _s: Option<u64>, obs: &mut Observation) -> Result<(), EnvError> {
//! #         self.t = 0; *obs = Observation::flat(vec![0.0]); Ok(()) }
//! #     fn step_into(&mut self, a: &Action, out: &mut Step) -> Result<(), EnvError> {
//! #         self.t += 1;
//! #         out.reward = match a { Action::Discrete(k) => *k as f64, _ => 0.0 };
//! #         out.terminated = self.t == 3; out.truncated = false; Ok(()) }
//! # }
//! # let spec = EnvSpec { id: "C-v0".into(), observation_space: Space::uniform_box(&[1], 0.0, 9.0),
//! #     action_space: Space::Discrete { n: 4 }, max_episode_steps: None, metadata: Default::default() };
//! let mut env = Counter { spec, t: 0 };
//! let mut log = EpisodeLog::new(7);
//! for k in [1, 2, 3] {
//!     log.push(&Action::Discrete(k), k as f64).unwrap();
//! }
//! let replayed = replay(&mut env, &log).unwrap();
//! assert_eq!(replayed.episode_return, 6.0);
//! assert_eq!(replayed.length, 3);
//! assert!(replayed.first_difference(&log).is_none());
//! ```

use serde::{Deserialize, Serialize};

use crate::env::{Env, EnvError, Step};
use crate::space::Action;

/// The actions of one episode, stored compactly by kind.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ActionLog {
    /// Indices into a discrete action space.
    Discrete(Vec<usize>),
    /// Continuous actions of `dim` elements each, concatenated.
    Continuous {
        /// Elements per action.
        dim: usize,
        /// `len × dim` values.
        values: Vec<f32>,
    },
}

impl ActionLog {
    /// Number of actions.
    pub fn len(&self) -> usize {
        match self {
            ActionLog::Discrete(a) => a.len(),
            ActionLog::Continuous { dim, values } => values.len().checked_div(*dim).unwrap_or(0),
        }
    }

    /// Whether no action is logged.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The `i`-th action.
    pub fn get(&self, i: usize) -> Option<Action> {
        match self {
            ActionLog::Discrete(a) => a.get(i).map(|&k| Action::Discrete(k)),
            ActionLog::Continuous { dim, values } => values
                .get(i * dim..(i + 1) * dim)
                .map(|v| Action::Continuous(v.to_vec())),
        }
    }

    /// Writes the `i`-th action into `out`, reusing its buffer.
    fn write(&self, i: usize, out: &mut Action) -> bool {
        match (self, out) {
            (ActionLog::Discrete(a), Action::Discrete(k)) => match a.get(i) {
                Some(&v) => {
                    *k = v;
                    true
                }
                None => false,
            },
            (ActionLog::Continuous { dim, values }, Action::Continuous(v)) => {
                match values.get(i * dim..(i + 1) * dim) {
                    Some(src) => {
                        v.clear();
                        v.extend_from_slice(src);
                        true
                    }
                    None => false,
                }
            }
            _ => false,
        }
    }
}

/// Why an action could not be logged.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum LogError {
    /// A discrete action after continuous ones, or the reverse.
    #[error("action kind changed within an episode")]
    MixedKinds,
    /// A continuous action of another length than the episode's first.
    #[error("continuous action of {found} elements in an episode of {expected}")]
    Dimension {
        /// The episode's dimension.
        expected: usize,
        /// This action's.
        found: usize,
    },
}

/// One episode: its reset seed, its actions and the rewards observed when it ran.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct EpisodeLog {
    /// The seed given to `reset`.
    pub seed: u64,
    /// Every action, in order.
    pub actions: ActionLog,
    /// The reward after each action, as observed (diagnostic: replay recomputes them). A NaN
    /// reward is written as `null` (JSON has no NaN) and read back as NaN.
    #[serde(deserialize_with = "crate::results::vec_f64_or_nan")]
    pub rewards: Vec<f64>,
}

impl EpisodeLog {
    /// An empty log for an episode reset with `seed`.
    pub fn new(seed: u64) -> Self {
        Self {
            seed,
            actions: ActionLog::Discrete(Vec::new()),
            rewards: Vec::new(),
        }
    }

    /// Appends an action and the reward it earned.
    pub fn push(&mut self, action: &Action, reward: f64) -> Result<(), LogError> {
        let first = self.rewards.is_empty();
        match (&mut self.actions, action) {
            (ActionLog::Discrete(a), Action::Discrete(k)) => a.push(*k),
            (ActionLog::Continuous { dim, values }, Action::Continuous(v)) => {
                if v.len() != *dim {
                    return Err(LogError::Dimension {
                        expected: *dim,
                        found: v.len(),
                    });
                }
                values.extend_from_slice(v);
            }
            (log, Action::Continuous(v)) if first => {
                *log = ActionLog::Continuous {
                    dim: v.len(),
                    values: v.clone(),
                };
            }
            _ => return Err(LogError::MixedKinds),
        }
        self.rewards.push(reward);
        Ok(())
    }

    /// The return as recorded: the logged rewards summed in step order from `0.0`, as rollouts
    /// sum them.
    pub fn logged_return(&self) -> f64 {
        let mut ret = 0.0;
        for r in &self.rewards {
            ret += r;
        }
        ret
    }
}

/// What a replay recomputed.
#[derive(Clone, Debug, PartialEq)]
pub struct Replayed {
    /// Sum of the rewards, in step order from `0.0`.
    pub episode_return: f64,
    /// Steps taken.
    pub length: usize,
    /// Every reward.
    pub rewards: Vec<f64>,
}

/// The first step at which a replay disagrees with its log.
#[derive(Clone, Debug, PartialEq)]
pub struct Difference {
    /// Step index (from 0).
    pub step: usize,
    /// The logged reward (`None` when the log has no such step).
    pub expected: Option<f64>,
    /// The replayed reward (`None` when the replay ended before it).
    pub found: Option<f64>,
}

impl Replayed {
    /// The first step whose reward (compared bit for bit; any NaN matches any NaN, since a log
    /// read from JSON keeps no NaN's bits) or existence differs from the log.
    pub fn first_difference(&self, log: &EpisodeLog) -> Option<Difference> {
        let n = self.rewards.len().max(log.rewards.len());
        (0..n).find_map(|step| {
            let expected = log.rewards.get(step).copied();
            let found = self.rewards.get(step).copied();
            let same = matches!((expected, found),
                (Some(a), Some(b)) if a.to_bits() == b.to_bits() || (a.is_nan() && b.is_nan()));
            (!same).then_some(Difference {
                step,
                expected,
                found,
            })
        })
    }
}

/// Why a log could not be replayed.
#[derive(Debug, thiserror::Error)]
pub enum ReplayError {
    /// The environment refused a step or the reset.
    #[error("step {step} (counted from 0): {source}")]
    Env {
        /// The step (0 for the reset).
        step: usize,
        /// The environment's error.
        source: EnvError,
    },
    /// The episode ended before the log's last action.
    #[error("the episode ended after {ended} steps but the log has {logged} actions")]
    EndedEarly {
        /// Steps until the environment ended the episode.
        ended: usize,
        /// Actions in the log.
        logged: usize,
    },
    /// The log ran out while the episode was still going (and not at the spec's step limit).
    #[error("the log's {logged} actions end while the episode goes on")]
    Unfinished {
        /// Actions in the log.
        logged: usize,
    },
    /// The log's actions do not fit the environment's action kind.
    #[error("logged actions are {logged}, the environment's action space is {space}")]
    WrongKind {
        /// "discrete" or "continuous".
        logged: &'static str,
        /// The space, as text.
        space: String,
    },
}

/// Resets `env` with the log's seed and steps it through the logged actions, recomputing every
/// reward. The episode must end (terminated, truncated or at the spec's `max_episode_steps`)
/// exactly at the last logged action.
pub fn replay(env: &mut dyn Env, log: &EpisodeLog) -> Result<Replayed, ReplayError> {
    let limit = env.spec().max_episode_steps.unwrap_or(usize::MAX);
    let mut action = match &log.actions {
        ActionLog::Discrete(_) => Action::Discrete(0),
        ActionLog::Continuous { dim, .. } => Action::Continuous(vec![0.0; *dim]),
    };
    let discrete_space = matches!(env.spec().action_space, crate::Space::Discrete { .. });
    if discrete_space != matches!(action, Action::Discrete(_)) && !log.actions.is_empty() {
        return Err(ReplayError::WrongKind {
            logged: if discrete_space {
                "continuous"
            } else {
                "discrete"
            },
            space: format!("{:?}", env.spec().action_space),
        });
    }
    let logged = log.actions.len();
    let mut step = Step::default();
    env.reset_into(Some(log.seed), &mut step.observation)
        .map_err(|source| ReplayError::Env { step: 0, source })?;
    let mut rewards = Vec::with_capacity(logged);
    let mut ret = 0.0;
    for i in 0..logged {
        log.actions.write(i, &mut action);
        env.step_into(&action, &mut step)
            .map_err(|source| ReplayError::Env { step: i, source })?;
        ret += step.reward;
        rewards.push(step.reward);
        let done = step.terminated || step.truncated || i + 1 >= limit;
        if done && i + 1 < logged {
            return Err(ReplayError::EndedEarly {
                ended: i + 1,
                logged,
            });
        }
        if !done && i + 1 == logged {
            return Err(ReplayError::Unfinished { logged });
        }
    }
    if logged == 0 {
        return Err(ReplayError::Unfinished { logged });
    }
    Ok(Replayed {
        episode_return: ret,
        length: logged,
        rewards,
    })
}

/// An environment that logs every episode run through it: the reset seed, each action and its
/// reward. Rollout code is unchanged by it (it is just another [`Env`]), and recording costs a
/// push into a `Vec` per step, so a benchmark's timed rollouts can keep their proof.
///
/// ```
/// # use a2perf_core::{Action, Env, EnvError, EnvSpec, Observation, Space, Step};
/// use a2perf_core::replay::{Recorder, replay};
/// # struct Counter { spec: EnvSpec, t: usize }
/// # impl Env for Counter {
/// #     fn spec(&self) -> &EnvSpec { &self.spec }
/// #     fn reset_into(&mut self, _s: Option<u64>, obs: &mut Observation) -> Result<(), EnvError> {
/// #         self.t = 0; *obs = Observation::flat(vec![0.0]); Ok(()) }
/// #     fn step_into(&mut self, a: &Action, out: &mut Step) -> Result<(), EnvError> {
/// #         self.t += 1; out.reward = 0.5;
/// #         out.terminated = self.t == 2; out.truncated = false; Ok(()) }
/// # }
/// # let spec = EnvSpec { id: "C-v0".into(), observation_space: Space::uniform_box(&[1], 0.0, 9.0),
/// #     action_space: Space::Discrete { n: 2 }, max_episode_steps: None, metadata: Default::default() };
/// let mut env = Counter { spec, t: 0 };
/// let mut rec = Recorder::new(&mut env);
/// rec.reset(Some(5)).unwrap();
/// rec.step(&Action::Discrete(1)).unwrap();
/// rec.step(&Action::Discrete(0)).unwrap();
/// let logs = rec.into_logs();
/// assert_eq!(logs[0].seed, 5);
/// assert_eq!(logs[0].logged_return(), 1.0);
/// assert_eq!(replay(&mut env, &logs[0]).unwrap().episode_return, 1.0);
/// ```
pub struct Recorder<'a> {
    inner: &'a mut dyn Env,
    logs: Vec<EpisodeLog>,
}

impl<'a> Recorder<'a> {
    /// Wraps `inner`; nothing is logged until its first reset.
    pub fn new(inner: &'a mut dyn Env) -> Self {
        Self {
            inner,
            logs: Vec::new(),
        }
    }

    /// The episodes logged so far, one per reset, in order.
    pub fn logs(&self) -> &[EpisodeLog] {
        &self.logs
    }

    /// The logged episodes.
    pub fn into_logs(self) -> Vec<EpisodeLog> {
        self.logs
    }
}

impl Env for Recorder<'_> {
    fn spec(&self) -> &crate::EnvSpec {
        self.inner.spec()
    }

    /// A reset without a seed is logged with seed 0: benchmark rollouts always give one, and
    /// a replay of such an episode fails at its first step unless the environment ignores it.
    fn reset_into(
        &mut self,
        seed: Option<u64>,
        obs: &mut crate::Observation,
    ) -> Result<(), EnvError> {
        self.inner.reset_into(seed, obs)?;
        self.logs.push(EpisodeLog::new(seed.unwrap_or(0)));
        Ok(())
    }

    fn step_into(&mut self, action: &Action, out: &mut Step) -> Result<(), EnvError> {
        self.inner.step_into(action, out)?;
        let Some(log) = self.logs.last_mut() else {
            return Err(EnvError::Backend("stepped before the first reset".into()));
        };
        log.push(action, out.reward)
            .map_err(|e| EnvError::Backend(format!("cannot log the action: {e}")))
    }

    fn close(&mut self) -> Result<(), EnvError> {
        self.inner.close()
    }

    fn render_modes(&self) -> &'static [&'static str] {
        self.inner.render_modes()
    }

    fn render(&mut self, mode: &str) -> Result<crate::render::Frame, EnvError> {
        self.inner.render(mode)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{EnvSpec, Observation, Space};

    /// Reward = action + seed-dependent offset; ends after 4 steps.
    struct Toy {
        spec: EnvSpec,
        t: usize,
        offset: f64,
    }

    impl Env for Toy {
        fn spec(&self) -> &EnvSpec {
            &self.spec
        }
        fn reset_into(&mut self, s: Option<u64>, obs: &mut Observation) -> Result<(), EnvError> {
            self.t = 0;
            self.offset = s.unwrap_or(0) as f64 * 0.1;
            *obs = Observation::flat(vec![0.0]);
            Ok(())
        }
        fn step_into(&mut self, a: &Action, out: &mut Step) -> Result<(), EnvError> {
            self.t += 1;
            out.reward = match a {
                Action::Discrete(k) => *k as f64 + self.offset,
                Action::Continuous(v) => v.iter().map(|x| f64::from(*x)).sum(),
            };
            out.terminated = self.t == 4;
            out.truncated = false;
            Ok(())
        }
    }

    fn toy(action_space: Space) -> Toy {
        Toy {
            spec: EnvSpec {
                id: "Toy-v0".into(),
                observation_space: Space::uniform_box(&[1], -1.0, 1.0),
                action_space,
                max_episode_steps: None,
                metadata: Default::default(),
            },
            t: 0,
            offset: 0.0,
        }
    }

    fn honest(seed: u64, actions: &[usize]) -> EpisodeLog {
        let mut log = EpisodeLog::new(seed);
        for &k in actions {
            log.push(&Action::Discrete(k), k as f64 + seed as f64 * 0.1)
                .unwrap();
        }
        log
    }

    #[test]
    fn honest_log_replays_bit_for_bit() {
        let mut env = toy(Space::Discrete { n: 3 });
        let log = honest(3, &[0, 2, 1, 2]);
        let r = replay(&mut env, &log).unwrap();
        assert_eq!(r.episode_return.to_bits(), log.logged_return().to_bits());
        assert!(r.first_difference(&log).is_none());
    }

    #[test]
    fn changed_action_or_seed_is_found_at_its_step() {
        let mut env = toy(Space::Discrete { n: 3 });
        let mut log = honest(3, &[0, 2, 1, 2]);
        log.actions = ActionLog::Discrete(vec![0, 2, 0, 2]);
        let d = replay(&mut env, &log)
            .unwrap()
            .first_difference(&log)
            .unwrap();
        assert_eq!(d.step, 2);
        let mut log = honest(3, &[0, 2, 1, 2]);
        log.seed = 4;
        let d = replay(&mut env, &log)
            .unwrap()
            .first_difference(&log)
            .unwrap();
        assert_eq!(d.step, 0);
    }

    #[test]
    fn wrong_length_logs_fail() {
        let mut env = toy(Space::Discrete { n: 3 });
        let long = honest(0, &[0, 0, 0, 0, 0]);
        assert!(matches!(
            replay(&mut env, &long),
            Err(ReplayError::EndedEarly {
                ended: 4,
                logged: 5
            })
        ));
        let short = honest(0, &[0, 0]);
        assert!(matches!(
            replay(&mut env, &short),
            Err(ReplayError::Unfinished { logged: 2 })
        ));
        let mut env = toy(Space::uniform_box(&[2], -1.0, 1.0));
        assert!(matches!(
            replay(&mut env, &honest(0, &[0, 0, 0, 0])),
            Err(ReplayError::WrongKind { .. })
        ));
    }

    #[test]
    fn continuous_logs_round_trip_through_json_exactly() {
        let mut log = EpisodeLog::new(1);
        for i in 0..4 {
            let a = Action::Continuous(vec![0.1 * i as f32, -1.0 / 3.0, f32::MIN_POSITIVE]);
            log.push(&a, 0.0).unwrap();
        }
        assert!(matches!(
            log.push(&Action::Continuous(vec![0.0]), 0.0),
            Err(LogError::Dimension { .. })
        ));
        assert!(matches!(
            log.push(&Action::Discrete(0), 0.0),
            Err(LogError::MixedKinds)
        ));
        let json = serde_json::to_string(&log).unwrap();
        let back: EpisodeLog = serde_json::from_str(&json).unwrap();
        assert_eq!(back, log);
        assert_eq!(back.actions.len(), 4);
        assert_eq!(
            back.actions.get(3),
            Some(Action::Continuous(vec![
                0.1 * 3.0,
                -1.0 / 3.0,
                f32::MIN_POSITIVE
            ]))
        );
    }

    #[test]
    fn a_nan_reward_round_trips_through_json_and_replays() {
        // 0/0 is a negative NaN on x86; the log read back holds the positive default NaN.
        let zero = std::hint::black_box(0.0_f64);
        let mut log = EpisodeLog::new(0);
        log.push(&Action::Discrete(1), zero / zero).unwrap();
        log.push(&Action::Discrete(0), 0.5).unwrap();
        let json = serde_json::to_string(&log).unwrap();
        assert!(json.contains("[null,0.5]"), "{json}");
        let back: EpisodeLog = serde_json::from_str(&json).unwrap();
        assert!(back.rewards[0].is_nan());
        assert_eq!(back.rewards[1], 0.5);
        let replayed = Replayed {
            episode_return: f64::NAN,
            length: 2,
            rewards: log.rewards.clone(),
        };
        assert_eq!(replayed.first_difference(&back), None);
        let other = Replayed {
            rewards: vec![1.0, 0.5],
            ..replayed
        };
        assert_eq!(other.first_difference(&back).map(|d| d.step), Some(0));
    }
}
