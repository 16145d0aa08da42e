//! Stepping N environments in parallel over the machine's cores.
//!
//! Each environment is stepped by whichever thread is free, but every environment's randomness is
//! keyed by its index and episode number only, and results are stored by index, so trajectories do
//! not depend on thread timing.
//!
//! Environments in mid-episode can be saved and restored for resumable training
//! ([`VecEnv::snapshot`], [`VecEnv::restore`]) by one general rule: an environment's state is its
//! current episode's reset seed plus the actions taken since that reset, and restoring replays
//! them. It is exact for environments whose episode is a function of its seed and actions (all
//! the simulated built-in ones); one that replays differently is detected (its observation hash
//! changes) and starts a new episode instead.

use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::env::{Env, EnvError, Step};
use crate::rng::RngStream;
use crate::space::{Action, Observation};

/// Outcome of one environment in a vectorised step.
#[derive(Clone, Debug, Default)]
pub struct VecStep {
    /// The step. When the episode ended, `step.observation` already holds the first observation of
    /// the next episode (auto-reset) and the terminal observation is in `final_observation`.
    pub step: Step,
    /// Observation that ended the episode (meaningful only when `step.done()`).
    pub final_observation: Observation,
    /// Return of the episode that just ended (meaningful only when `step.done()`).
    pub episode_return: f64,
    /// Length of the episode that just ended (meaningful only when `step.done()`).
    pub episode_length: usize,
}

struct Slot {
    env: Box<dyn Env>,
    episode: u64,
    running_return: f64,
    running_length: usize,
    seeds: RngStream,
    actions: ActionLog,
}

impl Slot {
    fn next_seed(&mut self) -> u64 {
        let s = self.seeds.derive_index(self.episode).next_u64();
        self.episode += 1;
        s
    }

    /// Starts the next episode: its seed, cleared counters and log.
    fn reset(&mut self, obs: &mut Observation) -> Result<(), EnvError> {
        let seed = self.next_seed();
        self.running_return = 0.0;
        self.running_length = 0;
        self.actions.clear();
        self.env.reset_into(Some(seed), obs)
    }

    /// Steps the environment, recording the action for [`VecEnv::snapshot`].
    fn step(&mut self, action: &Action, out: &mut Step) -> Result<(), EnvError> {
        self.env.step_into(action, out)?;
        self.actions.push(action);
        self.running_return += out.reward;
        self.running_length += 1;
        Ok(())
    }
}

/// The actions of the current episode, flat: recording allocates only while an episode is longer
/// than every one before it.
#[derive(Clone, Debug, Default)]
struct ActionLog {
    discrete: Vec<usize>,
    continuous: Vec<f32>,
    /// Per action: `None` for discrete, the vector's length for continuous.
    lens: Vec<Option<u32>>,
}

impl ActionLog {
    fn clear(&mut self) {
        self.discrete.clear();
        self.continuous.clear();
        self.lens.clear();
    }

    fn push(&mut self, action: &Action) {
        match action {
            Action::Discrete(a) => {
                self.discrete.push(*a);
                self.lens.push(None);
            }
            Action::Continuous(v) => {
                self.continuous.extend_from_slice(v);
                self.lens.push(Some(v.len() as u32));
            }
        }
    }

    fn to_actions(&self) -> Vec<Action> {
        let (mut d, mut c) = (self.discrete.iter(), 0usize);
        self.lens
            .iter()
            .map(|len| match len {
                None => Action::Discrete(d.next().copied().unwrap_or(0)),
                Some(n) => {
                    let n = *n as usize;
                    let v = self.continuous[c..c + n].to_vec();
                    c += n;
                    Action::Continuous(v)
                }
            })
            .collect()
    }
}

/// One environment of a [`VecEnvSnapshot`]: where it is in its current episode.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct EpisodeSnapshot {
    /// Episodes this environment has started (the current one is number `episodes − 1`, and its
    /// reset seed follows from that number).
    pub episodes: u64,
    /// Actions taken since the current episode's reset.
    pub actions: Vec<Action>,
    /// Bits of the return accumulated so far in the current episode.
    pub running_return_bits: u64,
    /// Hash of the current observation, checked after replay.
    pub observation_hash: u64,
}

/// Every environment of a [`VecEnv`] in mid-episode (see the module documentation).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct VecEnvSnapshot {
    /// One per environment, by index.
    pub envs: Vec<EpisodeSnapshot>,
}

/// FNV-1a over an observation's element types, shapes, values (exact bits in their own type) and
/// mask. A tensor's type is part of the hash, so an `int32` observation never matches a hash
/// taken when the same ids were `float32`.
pub fn observation_hash(obs: &Observation) -> u64 {
    let mut h = crate::hash::Fnv1a::new();
    let mut eat = |x: u64| h.write_u64(x);
    for t in &obs.tensors {
        eat(t.data.len() as u64);
        eat(t.dtype() as u64);
        for d in &t.shape {
            eat(*d as u64);
        }
        t.data.for_each_bits(&mut eat);
    }
    if let Some(m) = &obs.action_mask {
        eat(m.len() as u64);
        for legal in m {
            eat(u64::from(*legal));
        }
    }
    h.finish()
}

/// N environments stepped together, with automatic reset.
///
/// ```
/// # use a2perf_core::{Action, Env, EnvError, EnvSpec, Observation, Space, Step};
/// # struct Walk { spec: EnvSpec, x: f32 }
/// # impl Env for Walk {
/// #     fn spec(&self) -> &EnvSpec { &self.spec }
/// #     fn reset_into(&mut self, s: Option<u64>, obs: &mut Observation) -> Result<(), EnvError> {
/// #         self.x = s.unwrap_or(0) as f32 % 7.0; *obs = Observation::flat(vec![self.x]); Ok(()) }
/// #     fn step_into(&mut self, a: &Action, out: &mut Step) -> Result<(), EnvError> {
/// #         if let Action::Discrete(d) = a { self.x += *d as f32; }
/// #         out.observation = Observation::flat(vec![self.x]); out.reward = self.x as f64;
/// #         out.terminated = self.x > 20.0; out.truncated = false; Ok(()) }
/// # }
/// # let spec = EnvSpec { id: "W-v0".into(), observation_space: Space::uniform_box(&[1], 0.0, 99.0),
/// #     action_space: Space::Discrete { n: 3 }, max_episode_steps: None, metadata: Default::default() };
/// use a2perf_core::VecEnv;
/// let envs: Vec<Box<dyn Env>> = (0..4).map(|_| Box::new(Walk { spec: spec.clone(), x: 0.0 }) as Box<dyn Env>).collect();
/// let mut vec = VecEnv::new(envs, 42);
/// vec.reset_all().unwrap();
/// let actions = vec![Action::Discrete(2); 4];
/// let out = vec.step_all(&actions).unwrap();
/// assert_eq!(out.len(), 4);
/// ```
pub struct VecEnv {
    slots: Vec<Slot>,
    outs: Vec<VecStep>,
}

impl VecEnv {
    /// Wraps `envs`; episode seeds derive from `seed` and the environment index.
    pub fn new(envs: Vec<Box<dyn Env>>, seed: u64) -> Self {
        let base = RngStream::new(seed, "vec-env/reset");
        let slots: Vec<Slot> = envs
            .into_iter()
            .enumerate()
            .map(|(i, env)| Slot {
                env,
                episode: 0,
                running_return: 0.0,
                running_length: 0,
                seeds: base.derive_index(i as u64),
                actions: ActionLog::default(),
            })
            .collect();
        let outs = vec![VecStep::default(); slots.len()];
        Self { slots, outs }
    }

    /// Number of environments.
    pub fn len(&self) -> usize {
        self.slots.len()
    }

    /// Whether there are no environments.
    pub fn is_empty(&self) -> bool {
        self.slots.is_empty()
    }

    /// The environments' spec (all environments share it).
    pub fn spec(&self) -> Option<&crate::EnvSpec> {
        self.slots.first().map(|s| s.env.spec())
    }

    /// Resets every environment; the first observations are in `result[i].step.observation`.
    pub fn reset_all(&mut self) -> Result<&[VecStep], EnvError> {
        self.slots
            .par_iter_mut()
            .zip(self.outs.par_iter_mut())
            .try_for_each(|(slot, out)| {
                out.step.reward = 0.0;
                out.step.terminated = false;
                out.step.truncated = false;
                out.step.info.clear();
                slot.reset(&mut out.step.observation)
            })?;
        Ok(&self.outs)
    }

    /// Steps environment `i` with `actions[i]`, resetting those whose episode ended.
    pub fn step_all(&mut self, actions: &[Action]) -> Result<&[VecStep], EnvError> {
        if actions.len() != self.slots.len() {
            return Err(EnvError::InvalidParameter {
                name: "actions".into(),
                reason: format!(
                    "{} actions for {} environments",
                    actions.len(),
                    self.slots.len()
                ),
            });
        }
        self.slots
            .par_iter_mut()
            .zip(self.outs.par_iter_mut())
            .zip(actions.par_iter())
            .try_for_each(|((slot, out), action)| {
                slot.step(action, &mut out.step)?;
                let limit = slot.env.spec().max_episode_steps.unwrap_or(usize::MAX);
                if !out.step.terminated && slot.running_length >= limit {
                    out.step.truncated = true;
                }
                if out.step.done() {
                    out.episode_return = slot.running_return;
                    out.episode_length = slot.running_length;
                    std::mem::swap(&mut out.final_observation, &mut out.step.observation);
                    slot.reset(&mut out.step.observation)?;
                }
                Ok::<(), EnvError>(())
            })?;
        Ok(&self.outs)
    }

    /// Where every environment is in its current episode (see the module documentation).
    pub fn snapshot(&self) -> VecEnvSnapshot {
        VecEnvSnapshot {
            envs: self
                .slots
                .iter()
                .zip(&self.outs)
                .map(|(slot, out)| EpisodeSnapshot {
                    episodes: slot.episode,
                    actions: slot.actions.to_actions(),
                    running_return_bits: slot.running_return.to_bits(),
                    observation_hash: observation_hash(&out.step.observation),
                })
                .collect(),
        }
    }

    /// Puts every environment back where `snapshot` was taken: resets it with its current
    /// episode's seed and replays the recorded actions. Returns the current observations (as
    /// [`reset_all`](Self::reset_all) does) and the indices of environments whose replay did not
    /// reproduce the saved episode (an episode ended early, or the observation or return
    /// differs); those start their next episode instead, so training goes on but is no longer
    /// bit-identical to the uninterrupted run.
    ///
    /// A `VecEnv` built like the one the snapshot came from (same environments, same seed) must be
    /// used; a snapshot of another size is an error.
    pub fn restore(
        &mut self,
        snapshot: &VecEnvSnapshot,
    ) -> Result<(&[VecStep], Vec<usize>), EnvError> {
        if snapshot.envs.len() != self.slots.len() {
            return Err(EnvError::InvalidParameter {
                name: "snapshot".into(),
                reason: format!(
                    "{} environments saved, {} here",
                    snapshot.envs.len(),
                    self.slots.len()
                ),
            });
        }
        let replayed: Vec<bool> = self
            .slots
            .par_iter_mut()
            .zip(self.outs.par_iter_mut())
            .zip(snapshot.envs.par_iter())
            .map(|((slot, out), saved)| {
                slot.episode = saved.episodes.saturating_sub(1);
                slot.reset(&mut out.step.observation)?;
                let mut exact = saved.episodes > 0;
                for action in &saved.actions {
                    slot.step(action, &mut out.step)?;
                    if out.step.done() {
                        exact = false;
                        break;
                    }
                }
                exact = exact
                    && slot.running_return.to_bits() == saved.running_return_bits
                    && observation_hash(&out.step.observation) == saved.observation_hash;
                if !exact && saved.episodes > 0 {
                    slot.reset(&mut out.step.observation)?;
                }
                out.step.reward = 0.0;
                out.step.terminated = false;
                out.step.truncated = false;
                out.step.info.clear();
                Ok::<bool, EnvError>(exact || saved.episodes == 0)
            })
            .collect::<Result<_, _>>()?;
        let restarted = replayed
            .iter()
            .enumerate()
            .filter(|(_, ok)| !**ok)
            .map(|(i, _)| i)
            .collect();
        Ok((&self.outs, restarted))
    }

    /// Closes every environment.
    pub fn close(&mut self) -> Result<(), EnvError> {
        for s in &mut self.slots {
            s.env.close()?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::alloc_count::{CountingAllocator, count_allocations};

    #[global_allocator]
    static ALLOC: CountingAllocator = CountingAllocator;

    /// Recording the episode's actions (for snapshots) allocates only while an episode is longer
    /// than every one before it: stepping stays allocation-free in the steady state.
    #[test]
    fn recording_actions_allocates_nothing_once_warm() {
        let mut log = ActionLog::default();
        let continuous = Action::Continuous(vec![0.25; 12]);
        let episode = |log: &mut ActionLog| {
            log.clear();
            for k in 0..600 {
                log.push(&continuous);
                log.push(&Action::Discrete(k));
            }
        };
        episode(&mut log);
        let (n, ()) = count_allocations(|| {
            for _ in 0..3 {
                episode(&mut log);
            }
        });
        assert_eq!(n, 0);
        let actions = log.to_actions();
        assert_eq!(actions.len(), 1200);
        assert_eq!(
            (&actions[0], &actions[1199]),
            (&continuous, &Action::Discrete(599))
        );
    }
}
