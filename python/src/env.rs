//! One environment of the registry driven from Python (the engine of `a2perf_rs.envs.A2PerfEnv`).
//!
//! Gymnasium conventions kept here so that single and vector environments agree exactly:
//! the spec's `max_episode_steps` truncates episodes; after `terminated` or `truncated` the
//! environment must be reset; an action that the current mask forbids either ends the episode
//! (`illegal_action="terminate"`, the default, so that every element of the action space can be
//! stepped as Gymnasium requires) or raises `ValueError` (`illegal_action="raise"`).

use std::collections::BTreeMap;
use std::sync::{Mutex, MutexGuard, OnceLock};

use a2perf_core::render::Frame;
use a2perf_core::{Action, Env, EnvSpec, Registry, Step, Value};
use numpy::{PyArray1, PyArrayMethods};
use pyo3::exceptions::{PyRuntimeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyString, PyTuple};

use crate::convert::{ActionSpec, from_value, space_to_py, to_value};
use crate::errors::{env_error, guard, registry_error};
use crate::observation::copy_obs;
// The conversions' old paths (they lived here until issue 35).
pub use crate::observation::{
    ObsArray, ObsArrayRw, ObsBuffer, ObsLayout, ObsRecycler, ObsRow, ObsRows,
};

/// Every built-in environment and algorithm, built once.
pub fn registry() -> &'static Registry {
    static REGISTRY: OnceLock<Registry> = OnceLock::new();
    REGISTRY.get_or_init(a2perf_pipeline::registry::full_registry)
}

/// What to do with an action that the current action mask forbids.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum IllegalAction {
    /// `ValueError`.
    Raise,
    /// The action is not applied; the episode terminates with this reward and
    /// `info["illegal_action"] = True`.
    Terminate(f64),
}

impl IllegalAction {
    /// Parses the Python keyword arguments. The default reward is the environment's own
    /// `infeasible_reward` where it has one (circuit: the reward of a placement that cannot be
    /// completed), else −1 (MiniWoB's reward of a failed episode).
    pub fn parse(
        mode: &str,
        reward: Option<f64>,
        params: &BTreeMap<String, Value>,
    ) -> PyResult<Self> {
        match mode {
            "raise" => Ok(Self::Raise),
            "terminate" => {
                let r = reward
                    .or_else(|| params.get("infeasible_reward").and_then(Value::as_f64))
                    .unwrap_or(-1.0);
                if !r.is_finite() {
                    return Err(PyValueError::new_err(format!(
                        "illegal_action_reward must be finite, got {r}"
                    )));
                }
                Ok(Self::Terminate(r))
            }
            other => {
                let hint = a2perf_core::did_you_mean(other, ["raise", "terminate"])
                    .map(|h| format!(" (did you mean `{h}`?)"))
                    .unwrap_or_default();
                Err(PyValueError::new_err(format!(
                    "illegal_action must be `terminate` or `raise`, got `{other}`{hint}"
                )))
            }
        }
    }
}

/// Python keyword arguments as environment parameters (typed, not yet checked against an id).
pub fn env_kwargs(kwargs: Option<&Bound<'_, PyDict>>) -> PyResult<BTreeMap<String, Value>> {
    let mut params = BTreeMap::new();
    if let Some(kw) = kwargs {
        for (k, v) in kw.iter() {
            let key: String = k.extract()?;
            let value = to_value(&key, &v)?;
            params.insert(key, value);
        }
    }
    Ok(params)
}

/// The declared kind of parameter `key` of environment `id` (for [`registry_error`]).
pub fn param_kind(id: &str, key: &str) -> Option<a2perf_core::ParamKind> {
    registry().env(id).ok().and_then(|e| {
        e.params
            .iter()
            .find(|p| p.name == key)
            .map(|p| p.kind.clone())
    })
}

/// Builds environment `id` from Python keyword arguments; returns it with every parameter in
/// force (defaults included).
pub fn make_env(
    id: &str,
    kwargs: Option<&Bound<'_, PyDict>>,
) -> PyResult<(Box<dyn Env>, BTreeMap<String, Value>)> {
    build_env(id, &env_kwargs(kwargs)?)
}

/// Builds environment `id` from typed parameters (no Python needed: callable on any thread);
/// returns it with every parameter in force (defaults included).
pub fn build_env(
    id: &str,
    params: &BTreeMap<String, Value>,
) -> PyResult<(Box<dyn Env>, BTreeMap<String, Value>)> {
    let reg = registry();
    let kind_of = |key: &str| param_kind(id, key);
    let resolved = reg
        .env_params(id, params)
        .map_err(|e| registry_error(e, kind_of))?;
    let env = guard("building the environment", || {
        reg.make_env(id, params)
            .map_err(|e| registry_error(e, kind_of))
    })?;
    Ok((env, resolved.values().clone()))
}

/// Why a step is refused with an error (see [`EpisodeCore::refusal`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Refusal {
    /// Before the first reset, or after the episode ended.
    NeedsReset,
    /// The mask forbids this action and the policy is [`IllegalAction::Raise`].
    Masked(usize),
}

impl Refusal {
    /// The Python exception, its message prefixed with `context` (e.g. `"environment 1: "`).
    pub fn into_err(self, context: &str) -> PyErr {
        match self {
            Self::NeedsReset => PyRuntimeError::new_err(format!(
                "{context}step() called before reset() or after the episode ended (terminated \
                 or truncated): call reset() first"
            )),
            Self::Masked(a) => PyValueError::new_err(format!(
                "{context}action {a} is masked out in this state (info[\"action_mask\"][{a}] == 0)"
            )),
        }
    }
}

/// One environment with the episode bookkeeping shared by single and vector environments.
pub struct EpisodeCore {
    /// The environment.
    pub env: Box<dyn Env>,
    /// Its last step (the observation buffers are reused).
    pub step: Step,
    /// Steps taken in the current episode.
    pub elapsed: usize,
    /// Truncation limit.
    pub limit: Option<usize>,
    /// The episode ended (or never started): `step` is refused.
    pub needs_reset: bool,
    /// The last step was an illegal (masked-out) action.
    pub illegal: bool,
    /// Illegal-action policy.
    pub policy: IllegalAction,
    /// Where resets without a seed take theirs from (`None`: the environment's own stream).
    pub episode_seeds: Option<EpisodeSeeds>,
}

/// The reset seeds of a training run's environment (`a2perf_rs.TrainingRun.make_env` /
/// `make_vec`): episode `k` of environment `index` gets
/// [`a2perf_pipeline::external::episode_seed`]`(run_seed, index, k)`, as the built-in algorithms'
/// environments do.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct EpisodeSeeds {
    /// The run's seed.
    pub run_seed: u64,
    /// The environment's index.
    pub index: usize,
    /// Episodes started so far from this stream.
    pub episode: u64,
}

impl EpisodeSeeds {
    /// The seed of the next episode.
    fn next_seed(&mut self) -> u64 {
        let s = a2perf_pipeline::external::episode_seed(self.run_seed, self.index, self.episode);
        self.episode += 1;
        s
    }
}

impl EpisodeCore {
    /// Wraps `env`.
    pub fn new(env: Box<dyn Env>, policy: IllegalAction) -> Self {
        let limit = env.spec().max_episode_steps;
        Self {
            env,
            step: Step::default(),
            elapsed: 0,
            limit,
            needs_reset: true,
            illegal: false,
            policy,
            episode_seeds: None,
        }
    }

    /// Resets without a seed draw theirs from environment `index`'s stream of the run with
    /// `run_seed` (see [`EpisodeSeeds`]).
    pub fn with_episode_seeds(mut self, run_seed: u64, index: usize) -> Self {
        self.episode_seeds = Some(EpisodeSeeds {
            run_seed,
            index,
            episode: 0,
        });
        self
    }

    /// Starts an episode (`None`: the next seed of the episode-seed stream when there is one,
    /// else the environment continues its own random stream).
    pub fn reset(&mut self, seed: Option<u64>) -> PyResult<()> {
        let seed = seed.or_else(|| self.episode_seeds.as_mut().map(EpisodeSeeds::next_seed));
        self.needs_reset = true;
        self.illegal = false;
        self.step.reward = 0.0;
        self.step.terminated = false;
        self.step.truncated = false;
        self.step.info.clear();
        guard("reset", || {
            self.env
                .reset_into(seed, &mut self.step.observation)
                .map_err(env_error)
        })?;
        self.elapsed = 0;
        self.needs_reset = false;
        Ok(())
    }

    /// One step; the outcome is in `self.step`.
    pub fn step(&mut self, action: &Action) -> PyResult<()> {
        if self.admit(action)? {
            self.step_env(action)?;
        }
        Ok(())
    }

    /// The checks before a step: refuses a step that needs a reset, and handles an action the
    /// mask forbids (an error, or the terminated outcome in `self.step`). `Ok(true)`: the
    /// environment must now be stepped with [`EpisodeCore::step_env`].
    pub fn admit(&mut self, action: &Action) -> PyResult<bool> {
        if let Some(refusal) = self.refusal(action) {
            return Err(refusal.into_err(""));
        }
        self.illegal = false;
        if let (Some(_), IllegalAction::Terminate(reward)) = (self.masked_out(action), self.policy)
        {
            self.step.reward = reward;
            self.step.terminated = true;
            self.step.truncated = false;
            self.step.info.clear();
            self.illegal = true;
            self.needs_reset = true;
            return Ok(false);
        }
        Ok(true)
    }

    /// Why [`EpisodeCore::admit`] would refuse `action` with an error, changing nothing: the
    /// episode needs a reset, or the mask forbids the action under [`IllegalAction::Raise`]. A
    /// vector environment asks every environment first, so that a refused batch steps none.
    pub fn refusal(&self, action: &Action) -> Option<Refusal> {
        if self.needs_reset {
            return Some(Refusal::NeedsReset);
        }
        match (self.masked_out(action), self.policy) {
            (Some(a), IllegalAction::Raise) => Some(Refusal::Masked(a)),
            _ => None,
        }
    }

    /// The discrete action `action` when the current mask forbids it.
    fn masked_out(&self, action: &Action) -> Option<usize> {
        match (action, &self.step.observation.action_mask) {
            (Action::Discrete(a), Some(mask)) if !mask.get(*a).copied().unwrap_or(false) => {
                Some(*a)
            }
            _ => None,
        }
    }

    /// Steps the environment with an action [`EpisodeCore::admit`] accepted.
    pub fn step_env(&mut self, action: &Action) -> PyResult<()> {
        // An error leaves the environment in an unknown state: it must be reset.
        self.needs_reset = true;
        guard("step", || {
            self.env
                .step_into(action, &mut self.step)
                .map_err(env_error)
        })?;
        self.elapsed += 1;
        if !self.step.terminated && self.limit.is_some_and(|l| self.elapsed >= l) {
            self.step.truncated = true;
        }
        self.needs_reset = self.step.done();
        Ok(())
    }

    /// The info dict of the last reset/step: the environment's scalar diagnostics,
    /// `action_mask` (int8, 1 = legal) when the observation carries one, and
    /// `illegal_action = True` after a masked-out action.
    pub fn info<'py>(&self, py: Python<'py>, keys: &mut InfoKeys) -> PyResult<Bound<'py, PyDict>> {
        let d = PyDict::new(py);
        for (k, v) in self.step.info.iter() {
            d.set_item(keys.get(py, k), v)?;
        }
        if let Some(mask) = &self.step.observation.action_mask {
            d.set_item(pyo3::intern!(py, "action_mask"), mask_to_py(py, mask))?;
        }
        if self.illegal {
            d.set_item(pyo3::intern!(py, "illegal_action"), true)?;
        }
        Ok(d)
    }
}

/// The Python strings of an environment's info keys, made once (an environment reports the
/// same few keys at every step; a new string per key and step would be hashed every time).
#[derive(Default)]
pub struct InfoKeys(Vec<(String, Py<PyString>)>);

impl InfoKeys {
    /// The Python string `key`.
    pub fn get<'py>(&mut self, py: Python<'py>, key: &str) -> Bound<'py, PyString> {
        if let Some((_, s)) = self.0.iter().find(|(k, _)| k == key) {
            return s.bind(py).clone();
        }
        let s = PyString::new(py, key);
        self.0.push((key.to_string(), s.clone().unbind()));
        s
    }
}

/// A mask as an int8 array (Gymnasium's `Discrete.sample(mask=…)` type).
pub fn mask_to_py<'py>(py: Python<'py>, mask: &[bool]) -> Bound<'py, PyArray1<i8>> {
    // SAFETY: `bool` has the size and alignment of `i8` and only the values 0 and 1.
    let bytes = unsafe { std::slice::from_raw_parts(mask.as_ptr().cast::<i8>(), mask.len()) };
    PyArray1::from_slice(py, bytes)
}

/// The spec as a Python dict.
pub fn spec_to_py<'py>(
    py: Python<'py>,
    spec: &EnvSpec,
    params: &BTreeMap<String, Value>,
) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("id", &spec.id)?;
    d.set_item(
        "observation_space",
        space_to_py(py, &spec.observation_space)?,
    )?;
    d.set_item("action_space", space_to_py(py, &spec.action_space)?)?;
    d.set_item("max_episode_steps", spec.max_episode_steps)?;
    let meta = PyDict::new(py);
    for (k, v) in &spec.metadata {
        meta.set_item(k, v)?;
    }
    d.set_item("metadata", meta)?;
    let p = PyDict::new(py);
    for (k, v) in params {
        p.set_item(k, from_value(py, v)?)?;
    }
    d.set_item("params", p)?;
    Ok(d)
}

/// A registered environment driven from Python: `a2perf_rs._native.Env(env_id, params)`.
#[pyclass(module = "a2perf_rs._native", name = "Env")]
pub struct PyEnv {
    core: Mutex<Option<Single>>,
    layout: ObsLayout,
    action: ActionSpec,
    spec: EnvSpec,
    params: BTreeMap<String, Value>,
}

/// The state behind a [`PyEnv`].
struct Single {
    core: EpisodeCore,
    /// Moves observations to numpy without copies.
    recycler: ObsRecycler,
    /// The last observation returned (an illegal action returns a copy of it: the environment
    /// does not step, and its buffers now belong to that observation).
    last_obs: Option<Py<PyAny>>,
    /// Its info keys as Python strings.
    keys: InfoKeys,
}

impl Single {
    /// Runs `work` (a reset or an admitted step) with the GIL released, writing into recycled
    /// buffers, and returns its observation, handed to numpy without a copy.
    fn advance<'py>(
        &mut self,
        py: Python<'py>,
        layout: &ObsLayout,
        work: impl FnOnce(&mut EpisodeCore) -> PyResult<()> + Send,
    ) -> PyResult<Bound<'py, PyAny>> {
        // Dropped first: the last observation's buffers are free once the caller dropped it too.
        self.last_obs = None;
        self.recycler
            .lend(py, layout, &mut self.core.step.observation);
        let core = &mut self.core;
        py.detach(|| work(core))?;
        let obs = self
            .recycler
            .hand_out(py, layout, &mut self.core.step.observation)?;
        self.last_obs = Some(obs.clone().unbind());
        Ok(obs)
    }
}

impl PyEnv {
    fn core(&self) -> PyResult<MutexGuard<'_, Option<Single>>> {
        self.core.lock().map_err(|_| {
            PyRuntimeError::new_err("the environment is unusable after an earlier failure")
        })
    }
}

fn closed() -> PyErr {
    PyRuntimeError::new_err("the environment is closed")
}

#[pymethods]
impl PyEnv {
    /// Builds `env_id` with `params` (the registry's typed parameters).
    /// `episode_seeds=(run_seed, index)` seeds every reset without a seed from a training run's
    /// stream (see [`EpisodeSeeds`]).
    #[new]
    #[pyo3(signature = (env_id, params=None, illegal_action="terminate", illegal_action_reward=None, episode_seeds=None))]
    fn new(
        py: Python<'_>,
        env_id: &str,
        params: Option<&Bound<'_, PyDict>>,
        illegal_action: &str,
        illegal_action_reward: Option<f64>,
        episode_seeds: Option<(u64, usize)>,
    ) -> PyResult<Self> {
        let (env, resolved) = make_env(env_id, params)?;
        let policy = IllegalAction::parse(illegal_action, illegal_action_reward, &resolved)?;
        let spec = env.spec().clone();
        let mut core = EpisodeCore::new(env, policy);
        if let Some((run_seed, index)) = episode_seeds {
            core = core.with_episode_seeds(run_seed, index);
        }
        Ok(Self {
            layout: ObsLayout::of(py, &spec.observation_space)?,
            action: ActionSpec::of(&spec.action_space)?,
            core: Mutex::new(Some(Single {
                core,
                recycler: ObsRecycler::default(),
                last_obs: None,
                keys: InfoKeys::default(),
            })),
            spec,
            params: resolved,
        })
    }

    /// `{"id", "observation_space", "action_space", "max_episode_steps", "metadata", "params"}`.
    fn spec<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        spec_to_py(py, &self.spec, &self.params)
    }

    /// Starts an episode; returns `(observation, info)`.
    #[pyo3(signature = (seed=None))]
    fn reset<'py>(&self, py: Python<'py>, seed: Option<u64>) -> PyResult<Bound<'py, PyTuple>> {
        let mut guard = self.core()?;
        let st = guard.as_mut().ok_or_else(closed)?;
        let obs = st.advance(py, &self.layout, |core| core.reset(seed))?;
        PyTuple::new(py, [obs, st.core.info(py, &mut st.keys)?.into_any()])
    }

    /// Applies `action`; returns `(observation, reward, terminated, truncated, info)`.
    fn step<'py>(
        &self,
        py: Python<'py>,
        action: &Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, PyTuple>> {
        let mut guard = self.core()?;
        let st = guard.as_mut().ok_or_else(closed)?;
        let mut a = match self.action {
            ActionSpec::Discrete(_) => Action::Discrete(0),
            ActionSpec::Box { .. } => Action::Continuous(Vec::new()),
        };
        self.action.parse(action, &mut a)?;
        let obs = if st.core.admit(&a)? {
            st.advance(py, &self.layout, |core| core.step_env(&a))?
        } else {
            // Illegal action: the state, hence the observation, is unchanged.
            let last = st
                .last_obs
                .as_ref()
                .ok_or_else(|| PyRuntimeError::new_err("no observation to repeat"))?;
            copy_obs(last.bind(py))?
        };
        let s = &st.core.step;
        PyTuple::new(
            py,
            [
                obs,
                s.reward.into_pyobject(py)?.into_any(),
                pyo3::types::PyBool::new(py, s.terminated)
                    .to_owned()
                    .into_any(),
                pyo3::types::PyBool::new(py, s.truncated)
                    .to_owned()
                    .into_any(),
                st.core.info(py, &mut st.keys)?.into_any(),
            ],
        )
    }

    /// The current action mask (int8, 1 = legal), or `None` when every action is legal.
    fn action_mask<'py>(&self, py: Python<'py>) -> PyResult<Option<Bound<'py, PyArray1<i8>>>> {
        let guard = self.core()?;
        let st = guard.as_ref().ok_or_else(closed)?;
        Ok(st
            .core
            .step
            .observation
            .action_mask
            .as_deref()
            .map(|m| mask_to_py(py, m)))
    }

    /// Releases the environment's resources (e.g. its Chromium browser). Closing twice is fine.
    fn close(&self, py: Python<'_>) -> PyResult<()> {
        let mut guard = self.core()?;
        if let Some(mut st) = guard.take() {
            py.detach(|| guard_close(&mut st.core))?;
        }
        Ok(())
    }

    /// Whether `close()` was called.
    #[getter]
    fn closed(&self) -> PyResult<bool> {
        Ok(self.core()?.is_none())
    }

    /// The modes `render` accepts (Gymnasium's `metadata["render_modes"]`).
    fn render_modes(&self) -> PyResult<Vec<&'static str>> {
        let lock = self.core()?;
        let st = lock.as_ref().ok_or_else(closed)?;
        Ok(st.core.env.render_modes().to_vec())
    }

    /// Draws the current state in `mode`, one of `render_modes()`: a C-contiguous uint8 array
    /// `(height, width, 3)` for `"rgb_array"`, a `str` for the text modes (`"svg"`, `"html"`).
    /// Any other mode raises `ValueError` naming the supported ones.
    fn render<'py>(&self, py: Python<'py>, mode: &str) -> PyResult<Bound<'py, PyAny>> {
        let mut lock = self.core()?;
        let st = lock.as_mut().ok_or_else(closed)?;
        let env = &mut st.core.env;
        let frame = py.detach(|| render_env(env.as_mut(), mode))?;
        frame_to_py(py, frame)
    }
}

/// `env.render(mode)` with a panic turned into an error.
pub fn render_env(env: &mut dyn Env, mode: &str) -> PyResult<Frame> {
    guard("render", || env.render(mode).map_err(env_error))
}

/// A frame as Python gets it: a C-contiguous uint8 array `(height, width, 3)` or a `str`.
pub fn frame_to_py(py: Python<'_>, frame: Frame) -> PyResult<Bound<'_, PyAny>> {
    match frame {
        Frame::Rgb {
            height,
            width,
            data,
        } => Ok(PyArray1::from_vec(py, data)
            .reshape([height, width, 3])?
            .into_any()),
        Frame::Text(text) => Ok(PyString::new(py, &text).into_any()),
    }
}

/// `env.close()`, with the environment dropped afterwards whatever happens.
pub fn guard_close(core: &mut EpisodeCore) -> PyResult<()> {
    guard("close", || core.env.close().map_err(env_error))
}
