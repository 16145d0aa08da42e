//! Stepping N environments in parallel over the machine's cores.
//!
//! Each environment is stepped by whichever thread is free, but every environment's randomness is
//! keyed by its index and episode number only, and results are stored by index, so trajectories do
//! not depend on thread timing.

use rayon::prelude::*;

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
}

impl Slot {
    fn next_seed(&mut self) -> u64 {
        let s = self.seeds.derive_index(self.episode).next_u64();
        self.episode += 1;
        s
    }
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
                let seed = slot.next_seed();
                slot.running_return = 0.0;
                slot.running_length = 0;
                out.step.reward = 0.0;
                out.step.terminated = false;
                out.step.truncated = false;
                out.step.info.clear();
                slot.env.reset_into(Some(seed), &mut out.step.observation)
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
                slot.env.step_into(action, &mut out.step)?;
                slot.running_return += out.step.reward;
                slot.running_length += 1;
                let limit = slot.env.spec().max_episode_steps.unwrap_or(usize::MAX);
                if !out.step.terminated && slot.running_length >= limit {
                    out.step.truncated = true;
                }
                if out.step.done() {
                    out.episode_return = slot.running_return;
                    out.episode_length = slot.running_length;
                    slot.running_return = 0.0;
                    slot.running_length = 0;
                    std::mem::swap(&mut out.final_observation, &mut out.step.observation);
                    let seed = slot.next_seed();
                    slot.env.reset_into(Some(seed), &mut out.step.observation)?;
                }
                Ok::<(), EnvError>(())
            })?;
        Ok(&self.outs)
    }

    /// Closes every environment.
    pub fn close(&mut self) -> Result<(), EnvError> {
        for s in &mut self.slots {
            s.env.close()?;
        }
        Ok(())
    }
}
