//! Policies: what a trained agent is (observations to actions) and how it is rebuilt from its
//! checkpoint.

use serde::{Deserialize, Serialize};

use crate::env::EnvSpec;
use crate::rng::RngStream;
use crate::space::{Action, Observation};

// The places these had before the training types were split out of this module (issue 35).
pub use crate::cancel::CancelToken;
pub use crate::checkpoint::Checkpoint;
pub use crate::curve::{CurvePoint, LearningCurve};
pub use crate::error::{PolicyError, RunError};

/// How a policy chooses actions.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum ActMode {
    /// Deterministic best action (evaluation, inference).
    Greedy,
    /// Sampled action (data collection, training).
    Explore,
}

/// A trained (or training) policy: maps observations to actions.
pub trait Policy: Send {
    /// Chooses an action for `obs`. `ActMode::Greedy` must be deterministic; `ActMode::Explore`
    /// may sample from the policy's own seeded stream.
    fn act(&mut self, obs: &Observation, mode: ActMode) -> Result<Action, PolicyError>;

    /// Called by the inference benchmark with the observation the next `act` call gets, before
    /// its timer starts: the place for work the original harness counted as the environment's,
    /// such as a policy living in another runtime converting the observation into that
    /// runtime's arrays (the original's environments returned them already converted). `act`
    /// must give the same action whether or not `prepare` was called. Default: nothing.
    ///
    /// ```
    /// use a2perf_core::{ActMode, Observation, Policy, RandomPolicy, Space};
    /// let mut p = RandomPolicy::new(Space::Discrete { n: 2 }, 0);
    /// let obs = Observation::flat(vec![0.0]);
    /// p.prepare(&obs).unwrap(); // a Rust policy has nothing to convert
    /// assert!(p.act(&obs, ActMode::Greedy).is_ok());
    /// ```
    fn prepare(&mut self, obs: &Observation) -> Result<(), PolicyError> {
        let _ = obs;
        Ok(())
    }

    /// Serialises the policy so that the algorithm's loader can rebuild it.
    fn checkpoint(&self) -> Result<Checkpoint, PolicyError>;

    /// A copy of this policy whose greedy actions are this policy's own, to play evaluation
    /// episodes beside it on another thread; `None` (the default) where there is none, such as
    /// a policy living in another runtime. Evaluation is then one episode after another.
    ///
    /// ```
    /// use a2perf_core::{Policy, RandomPolicy, Space};
    /// let p = RandomPolicy::new(Space::Discrete { n: 3 }, 0);
    /// assert!(p.fork().is_none());
    /// ```
    fn fork(&self) -> Option<Box<dyn Policy>> {
        None
    }
}

impl<P: Policy + ?Sized> Policy for Box<P> {
    fn act(&mut self, obs: &Observation, mode: ActMode) -> Result<Action, PolicyError> {
        (**self).act(obs, mode)
    }
    fn prepare(&mut self, obs: &Observation) -> Result<(), PolicyError> {
        (**self).prepare(obs)
    }
    fn checkpoint(&self) -> Result<Checkpoint, PolicyError> {
        (**self).checkpoint()
    }
    fn fork(&self) -> Option<Box<dyn Policy>> {
        (**self).fork()
    }
}

/// A policy that draws uniformly random legal actions (the benchmark's reference point).
///
/// ```
/// use a2perf_core::{ActMode, Observation, Policy, RandomPolicy, Space};
/// let mut p = RandomPolicy::new(Space::Discrete { n: 3 }, 0);
/// let mut obs = Observation::flat(vec![0.0]);
/// obs.action_mask = Some(vec![false, false, true]);
/// assert_eq!(p.act(&obs, ActMode::Explore).unwrap(), a2perf_core::Action::Discrete(2));
/// ```
#[derive(Clone, Debug)]
pub struct RandomPolicy {
    space: crate::space::Space,
    rng: RngStream,
}

impl RandomPolicy {
    /// A random policy over `space`, seeded by `seed`.
    pub fn new(space: crate::space::Space, seed: u64) -> Self {
        Self {
            space,
            rng: RngStream::new(seed, "random-policy"),
        }
    }
}

impl Policy for RandomPolicy {
    fn act(&mut self, obs: &Observation, _mode: ActMode) -> Result<Action, PolicyError> {
        self.space
            .sample(&mut self.rng, obs.action_mask.as_deref())
            .ok_or(PolicyError::NoLegalAction)
    }

    fn checkpoint(&self) -> Result<Checkpoint, PolicyError> {
        Ok(Checkpoint {
            algorithm: "random".into(),
            format_version: 1,
            payload: serde_json::to_vec(&self.space)
                .map_err(|e| PolicyError::BadCheckpoint(e.to_string()))?,
        })
    }
}

/// Rebuilds a policy from a checkpoint for an environment.
pub type PolicyLoader = fn(&Checkpoint, &EnvSpec) -> Result<Box<dyn Policy>, PolicyError>;
