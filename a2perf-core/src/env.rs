//! The environment contract, with Gymnasium semantics.

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

use crate::render::Frame;
use crate::space::{Action, Observation, Space};

/// Static description of an environment.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct EnvSpec {
    /// Registered id, e.g. `CircuitTraining-Ariane-v0`.
    pub id: String,
    /// Space of observations.
    pub observation_space: Space,
    /// Space of actions.
    pub action_space: Space,
    /// Episode limit after which `truncated` is set, if any.
    pub max_episode_steps: Option<usize>,
    /// Provenance that results must record: netlist or clip name and content hash, backend, …
    pub metadata: BTreeMap<String, String>,
}

/// Scalar diagnostics of one step (`info` in Gymnasium), reusable without allocation.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Info {
    entries: Vec<(String, f64)>,
}

impl Info {
    /// Removes all entries, keeping capacity.
    pub fn clear(&mut self) {
        self.entries.clear();
    }

    /// Sets `key` to `value`, replacing an existing entry of that name.
    pub fn set(&mut self, key: &str, value: f64) {
        if let Some(e) = self.entries.iter_mut().find(|(k, _)| k == key) {
            e.1 = value;
        } else {
            self.entries.push((key.to_string(), value));
        }
    }

    /// The value of `key`, if present.
    pub fn get(&self, key: &str) -> Option<f64> {
        self.entries.iter().find(|(k, _)| k == key).map(|(_, v)| *v)
    }

    /// All entries in insertion order.
    pub fn iter(&self) -> impl Iterator<Item = (&str, f64)> {
        self.entries.iter().map(|(k, v)| (k.as_str(), *v))
    }
}

/// Result of one environment step.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Step {
    /// Observation after the step.
    pub observation: Observation,
    /// Reward for the step.
    pub reward: f64,
    /// The episode reached a terminal state of the task.
    pub terminated: bool,
    /// The episode was cut short (time limit, interrupted backend).
    pub truncated: bool,
    /// Diagnostics.
    pub info: Info,
}

impl Step {
    /// `terminated || truncated`.
    pub fn done(&self) -> bool {
        self.terminated || self.truncated
    }
}

/// Errors raised by environments.
#[derive(Debug, thiserror::Error)]
pub enum EnvError {
    /// The action is not in the action space or is masked out.
    #[error("invalid action {action:?}: {reason}")]
    InvalidAction {
        /// The offending action.
        action: Action,
        /// Why it was refused.
        reason: String,
    },
    /// `step` was called before `reset` or after the episode ended.
    #[error("step called on an environment that needs reset")]
    NeedsReset,
    /// A parameter given to the environment is invalid.
    #[error("invalid parameter `{name}`: {reason}")]
    InvalidParameter {
        /// Parameter name.
        name: String,
        /// What is wrong with it.
        reason: String,
    },
    /// An input file (netlist, motion clip, design) could not be used.
    #[error("{path}: {reason}")]
    BadFile {
        /// The file.
        path: String,
        /// What is wrong with it (with line numbers where known).
        reason: String,
    },
    /// The backend (e.g. a browser) failed.
    #[error("backend failure: {0}")]
    Backend(String),
}

impl EnvError {
    /// The error of [`Env::render`] for a mode the environment does not draw: an
    /// [`EnvError::InvalidParameter`] named `render_mode` that lists the `supported` modes.
    ///
    /// ```
    /// use a2perf_core::EnvError;
    /// let e = EnvError::unsupported_render_mode("human", &["rgb_array", "svg"]);
    /// assert_eq!(
    ///     e.to_string(),
    ///     "invalid parameter `render_mode`: `human` is not supported (supported modes: \
    ///      rgb_array, svg)"
    /// );
    /// let e = EnvError::unsupported_render_mode("rgb_array", &[]);
    /// assert!(e.to_string().contains("no render modes"));
    /// ```
    pub fn unsupported_render_mode(mode: &str, supported: &[&str]) -> Self {
        let reason = if supported.is_empty() {
            format!("`{mode}` is not supported (this environment has no render modes)")
        } else {
            format!(
                "`{mode}` is not supported (supported modes: {})",
                supported.join(", ")
            )
        };
        Self::InvalidParameter {
            name: "render_mode".into(),
            reason,
        }
    }
}

/// A reinforcement-learning environment.
///
/// Implementors provide the allocation-free [`reset_into`](Env::reset_into) and
/// [`step_into`](Env::step_into); the Gymnasium-style [`reset`](Env::reset) and
/// [`step`](Env::step) are derived from them.
///
/// ```
/// use a2perf_core::{Action, Env, EnvError, EnvSpec, Observation, Space, Step};
///
/// /// Counts to three.
/// struct Counter { spec: EnvSpec, t: usize }
/// impl Env for Counter {
///     fn spec(&self) -> &EnvSpec { &self.spec }
///     fn reset_into(&mut self, _seed: Option<u64>, obs: &mut Observation) -> Result<(), EnvError> {
///         self.t = 0;
///         *obs = Observation::flat(vec![0.0]);
///         Ok(())
///     }
///     fn step_into(&mut self, _a: &Action, out: &mut Step) -> Result<(), EnvError> {
///         self.t += 1;
///         out.observation = Observation::flat(vec![self.t as f32]);
///         out.reward = 1.0;
///         out.terminated = self.t == 3;
///         out.truncated = false;
///         Ok(())
///     }
/// }
/// let spec = EnvSpec {
///     id: "Counter-v0".into(),
///     observation_space: Space::uniform_box(&[1], 0.0, 3.0),
///     action_space: Space::Discrete { n: 1 },
///     max_episode_steps: Some(10),
///     metadata: Default::default(),
/// };
/// let mut env = Counter { spec, t: 0 };
/// let obs = env.reset(Some(0)).unwrap();
/// assert_eq!(obs.flat_values(), vec![0.0]);
/// let step = env.step(&Action::Discrete(0)).unwrap();
/// assert_eq!(step.reward, 1.0);
/// ```
pub trait Env: Send {
    /// The environment's static description.
    fn spec(&self) -> &EnvSpec;

    /// Starts a new episode. With `Some(seed)` the episode's randomness is re-seeded from it;
    /// with `None` the environment continues its own stream. Writes the first observation into
    /// `obs`, reusing its buffers.
    ///
    /// The buffers' contents are not the environment's memory: every element of every tensor
    /// and of the action mask is overwritten, whatever `obs` held (an older observation, garbage
    /// or nothing). Callers rely on it — the Python bindings hand one step's buffers to numpy
    /// and pass recycled ones back — and `a2perf-pipeline`'s `env_buffer_contract` test checks
    /// it for every built-in environment.
    fn reset_into(&mut self, seed: Option<u64>, obs: &mut Observation) -> Result<(), EnvError>;

    /// Applies `action`, writing the outcome into `out` (its observation buffers are reused and
    /// wholly overwritten, as in [`reset_into`](Env::reset_into); its `info` should be cleared
    /// and refilled).
    fn step_into(&mut self, action: &Action, out: &mut Step) -> Result<(), EnvError>;

    /// Gymnasium `reset`: starts an episode and returns its first observation.
    fn reset(&mut self, seed: Option<u64>) -> Result<Observation, EnvError> {
        let mut obs = Observation::default();
        self.reset_into(seed, &mut obs)?;
        Ok(obs)
    }

    /// Gymnasium `step`.
    fn step(&mut self, action: &Action) -> Result<Step, EnvError> {
        let mut out = Step::default();
        self.step_into(action, &mut out)?;
        Ok(out)
    }

    /// Releases external resources (browser processes, servers). Called by pipelines at the end;
    /// implementations must also clean up on `Drop`.
    fn close(&mut self) -> Result<(), EnvError> {
        Ok(())
    }

    /// The modes [`render`](Env::render) accepts (Gymnasium's `metadata["render_modes"]`):
    /// `"rgb_array"` for [`Frame::Rgb`], others (`"svg"`, `"html"`) for [`Frame::Text`]. None by
    /// default.
    fn render_modes(&self) -> &'static [&'static str] {
        &[]
    }

    /// Draws the current state in `mode`, one of [`render_modes`](Env::render_modes). Computed
    /// only when called: environments do no rendering work in `step`.
    ///
    /// The default supports no mode and returns
    /// [`EnvError::unsupported_render_mode`]; implementations return it for modes they do not
    /// support too.
    ///
    /// ```
    /// use a2perf_core::{Action, Env, EnvError, EnvSpec, Observation, Space, Step};
    /// use a2perf_core::render::Frame;
    ///
    /// struct Dot { spec: EnvSpec, x: usize }
    /// impl Env for Dot {
    ///     fn spec(&self) -> &EnvSpec { &self.spec }
    ///     fn reset_into(&mut self, _: Option<u64>, obs: &mut Observation) -> Result<(), EnvError> {
    ///         self.x = 0;
    ///         *obs = Observation::flat(vec![0.0]);
    ///         Ok(())
    ///     }
    ///     fn step_into(&mut self, _: &Action, out: &mut Step) -> Result<(), EnvError> {
    ///         self.x += 1;
    ///         out.observation = Observation::flat(vec![self.x as f32]);
    ///         Ok(())
    ///     }
    ///     fn render_modes(&self) -> &'static [&'static str] { &["ansi"] }
    ///     fn render(&mut self, mode: &str) -> Result<Frame, EnvError> {
    ///         match mode {
    ///             "ansi" => Ok(Frame::Text(format!("{}*", " ".repeat(self.x)))),
    ///             other => Err(EnvError::unsupported_render_mode(other, self.render_modes())),
    ///         }
    ///     }
    /// }
    /// let spec = EnvSpec {
    ///     id: "Dot-v0".into(),
    ///     observation_space: Space::uniform_box(&[1], 0.0, 9.0),
    ///     action_space: Space::Discrete { n: 1 },
    ///     max_episode_steps: None,
    ///     metadata: Default::default(),
    /// };
    /// let mut env: Box<dyn Env> = Box::new(Dot { spec, x: 0 });
    /// env.reset(Some(0)).unwrap();
    /// env.step(&Action::Discrete(0)).unwrap();
    /// assert_eq!(env.render("ansi").unwrap(), Frame::Text(" *".into()));
    /// assert!(matches!(env.render("rgb_array"), Err(EnvError::InvalidParameter { .. })));
    /// ```
    fn render(&mut self, mode: &str) -> Result<Frame, EnvError> {
        Err(EnvError::unsupported_render_mode(mode, self.render_modes()))
    }
}

impl<E: Env + ?Sized> Env for Box<E> {
    fn spec(&self) -> &EnvSpec {
        (**self).spec()
    }
    fn reset_into(&mut self, seed: Option<u64>, obs: &mut Observation) -> Result<(), EnvError> {
        (**self).reset_into(seed, obs)
    }
    fn step_into(&mut self, action: &Action, out: &mut Step) -> Result<(), EnvError> {
        (**self).step_into(action, out)
    }
    fn close(&mut self) -> Result<(), EnvError> {
        (**self).close()
    }
    fn render_modes(&self) -> &'static [&'static str] {
        (**self).render_modes()
    }
    fn render(&mut self, mode: &str) -> Result<Frame, EnvError> {
        (**self).render(mode)
    }
}
