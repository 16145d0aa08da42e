//! Running episodes.

use serde::{Deserialize, Serialize};

use crate::env::{Env, Step};
use crate::error::RunError;
use crate::policy::Policy;
use crate::space::{Action, Observation};

/// The old path of [`ActMode`], kept for users of `a2perf_core::rollout::ActMode`.
pub use crate::policy::ActMode;

/// One recorded step of an episode.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Transition {
    /// Observation the action was chosen from.
    pub observation: Observation,
    /// Action taken.
    pub action: Action,
    /// Reward received.
    pub reward: f64,
    /// Terminal state reached.
    pub terminated: bool,
    /// Episode cut short.
    pub truncated: bool,
}

/// Outcome of one episode.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Episode {
    /// Sum of rewards.
    pub episode_return: f64,
    /// Number of steps.
    pub length: usize,
    /// Ended in a terminal state.
    pub terminated: bool,
    /// Ended by truncation (time limit or interruption).
    pub truncated: bool,
    /// The steps, when recording was requested (empty otherwise).
    pub transitions: Vec<Transition>,
    /// The final observation (only when recording).
    pub final_observation: Option<Observation>,
}

/// Runs one episode of `policy` in `env`, reset with `seed`.
///
/// The episode is truncated at the spec's `max_episode_steps` if the environment does not do so
/// itself.
///
/// ```
/// # use a2perf_core::{Action, Env, EnvError, EnvSpec, Observation, Space, Step};
/// # struct Counter { spec: EnvSpec, t: usize }
/// # impl Env for Counter {
/// #     fn spec(&self) -> &EnvSpec { &self.spec }
/// #     fn reset_into(&mut self, _s: Option<u64>, obs: &mut Observation) -> Result<(), EnvError> {
/// #         self.t = 0; *obs = Observation::flat(vec![0.0]); Ok(()) }
/// #     fn step_into(&mut self, _a: &Action, out: &mut Step) -> Result<(), EnvError> {
/// #         self.t += 1; out.reward = 1.0; out.terminated = false; out.truncated = false;
/// #         out.observation = Observation::flat(vec![self.t as f32]); Ok(()) }
/// # }
/// # let spec = EnvSpec { id: "C-v0".into(), observation_space: Space::uniform_box(&[1], 0.0, 9.0),
/// #     action_space: Space::Discrete { n: 2 }, max_episode_steps: Some(4), metadata: Default::default() };
/// use a2perf_core::{rollout, ActMode, RandomPolicy};
/// let mut env = Counter { spec: spec.clone(), t: 0 };
/// let mut policy = RandomPolicy::new(spec.action_space.clone(), 0);
/// let ep = rollout(&mut env, &mut policy, 1, ActMode::Greedy, true).unwrap();
/// assert_eq!(ep.length, 4);
/// assert!(ep.truncated);
/// assert_eq!(ep.episode_return, 4.0);
/// ```
pub fn rollout(
    env: &mut dyn Env,
    policy: &mut dyn Policy,
    seed: u64,
    mode: ActMode,
    record: bool,
) -> Result<Episode, RunError> {
    let limit = env.spec().max_episode_steps.unwrap_or(usize::MAX);
    let mut step = Step::default();
    env.reset_into(Some(seed), &mut step.observation)?;
    let mut episode = Episode {
        episode_return: 0.0,
        length: 0,
        terminated: false,
        truncated: false,
        transitions: Vec::new(),
        final_observation: None,
    };
    loop {
        let action = policy.act(&step.observation, mode)?;
        let before = record.then(|| step.observation.clone());
        env.step_into(&action, &mut step)?;
        episode.episode_return += step.reward;
        episode.length += 1;
        let truncated = step.truncated || (!step.terminated && episode.length >= limit);
        if let Some(observation) = before {
            episode.transitions.push(Transition {
                observation,
                action,
                reward: step.reward,
                terminated: step.terminated,
                truncated,
            });
        }
        if step.terminated || truncated {
            episode.terminated = step.terminated;
            episode.truncated = truncated;
            if record {
                episode.final_observation = Some(step.observation.clone());
            }
            return Ok(episode);
        }
    }
}
