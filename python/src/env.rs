//! One environment of the registry driven from Python (the engine of `a2perf_rs.envs.A2PerfEnv`).
//!
//! Gymnasium conventions kept here so that single and vector environments agree exactly:
//! the spec's `max_episode_steps` truncates episodes; after `terminated` or `truncated` the
//! environment must be reset; an action that the current mask forbids either ends the episode
//! (`illegal_action="terminate"`, the default, so that every element of the action space can be
//! stepped as Gymnasium requires) or raises `ValueError` (`illegal_action="raise"`).

use std::collections::BTreeMap;
use std::sync::{Mutex, MutexGuard, OnceLock};

use a2perf_core::{Action, Env, EnvSpec, Observation, Registry, Space, Step, Value};
use numpy::{PyArray1, PyArrayDyn, PyArrayMethods};
use pyo3::exceptions::{PyRuntimeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyString, PyTuple};

use crate::convert::{ActionSpec, from_value, space_to_py, to_value};
use crate::errors::{env_error, guard, registry_error};

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

/// Builds environment `id` from Python keyword arguments; returns it with every parameter in
/// force (defaults included).
pub fn make_env(
    id: &str,
    kwargs: Option<&Bound<'_, PyDict>>,
) -> PyResult<(Box<dyn Env>, BTreeMap<String, Value>)> {
    let reg = registry();
    let mut params = BTreeMap::new();
    if let Some(kw) = kwargs {
        for (k, v) in kw.iter() {
            let key: String = k.extract()?;
            let value = to_value(&key, &v)?;
            params.insert(key, value);
        }
    }
    let kind_of = |key: &str| {
        reg.env(id).ok().and_then(|e| {
            e.params
                .iter()
                .find(|p| p.name == key)
                .map(|p| p.kind.clone())
        })
    };
    let resolved = reg
        .env_params(id, &params)
        .map_err(|e| registry_error(e, kind_of))?;
    let env = guard("building the environment", || {
        reg.make_env(id, &params)
            .map_err(|e| registry_error(e, kind_of))
    })?;
    Ok((env, resolved.values().clone()))
}

/// How an observation maps onto Python: one array (box space) or a dict of arrays.
pub struct ObsLayout {
    /// Dict keys (interned) or `None` for a box observation.
    pub keys: Option<Vec<Py<PyString>>>,
    /// Shape of each tensor, in the space's order.
    pub shapes: Vec<Vec<usize>>,
    /// Number of floats of each tensor.
    pub dims: Vec<usize>,
}

impl ObsLayout {
    /// The layout of `space`.
    pub fn of(py: Python<'_>, space: &Space) -> PyResult<Self> {
        let shape_of = |s: &Space| match s {
            Space::Box { shape, .. } => Ok(shape.clone()),
            other => Err(PyRuntimeError::new_err(format!(
                "observation space element {other:?} is not a box"
            ))),
        };
        let (keys, shapes) = match space {
            Space::Dict(items) => {
                let keys = items
                    .iter()
                    .map(|(k, _)| PyString::intern(py, k).unbind())
                    .collect();
                let shapes = items
                    .iter()
                    .map(|(_, s)| shape_of(s))
                    .collect::<PyResult<_>>()?;
                (Some(keys), shapes)
            }
            other => (None, vec![shape_of(other)?]),
        };
        let dims = shapes
            .iter()
            .map(|s: &Vec<usize>| s.iter().product())
            .collect();
        Ok(Self { keys, shapes, dims })
    }

    /// Checks that the environment wrote every tensor at its declared size.
    pub fn check(&self, obs: &Observation) -> PyResult<()> {
        if obs.tensors.len() != self.dims.len()
            || obs
                .tensors
                .iter()
                .zip(&self.dims)
                .any(|(t, d)| t.data.len() != *d)
        {
            return Err(PyRuntimeError::new_err(format!(
                "the environment returned an observation of {} tensors with sizes {:?}, its space \
                 declares {:?}",
                obs.tensors.len(),
                obs.tensors.iter().map(|t| t.data.len()).collect::<Vec<_>>(),
                self.dims
            )));
        }
        Ok(())
    }

    /// A new Python observation (fresh float32 arrays).
    pub fn to_py<'py>(&self, py: Python<'py>, obs: &Observation) -> PyResult<Bound<'py, PyAny>> {
        self.check(obs)?;
        let array = |i: usize| -> PyResult<Bound<'py, PyAny>> {
            // SAFETY: the array is created here with the tensor's size and filled completely
            // before anything else can see it.
            let arr = unsafe { PyArrayDyn::<f32>::new(py, self.shapes[i].as_slice(), false) };
            // SAFETY: fresh, contiguous and not shared (see above).
            let dst = unsafe { arr.as_slice_mut() }
                .map_err(|e| PyRuntimeError::new_err(e.to_string()))?;
            dst.copy_from_slice(&obs.tensors[i].data);
            Ok(arr.into_any())
        };
        match &self.keys {
            None => array(0),
            Some(keys) => {
                let d = PyDict::new(py);
                for (i, k) in keys.iter().enumerate() {
                    d.set_item(k.bind(py), array(i)?)?;
                }
                Ok(d.into_any())
            }
        }
    }

    /// Float32 buffers of shape `(n, *shape)` for `n` environments.
    pub fn buffers<'py>(&self, py: Python<'py>, n: usize) -> Vec<Bound<'py, PyArrayDyn<f32>>> {
        self.shapes
            .iter()
            .map(|s| {
                let mut dims = vec![n];
                dims.extend_from_slice(s);
                PyArrayDyn::zeros(py, dims, false)
            })
            .collect()
    }

    /// Python observation over buffers made by [`ObsLayout::buffers`].
    pub fn wrap<'py>(
        &self,
        py: Python<'py>,
        arrays: Vec<Bound<'py, PyAny>>,
    ) -> PyResult<Bound<'py, PyAny>> {
        match &self.keys {
            None => Ok(arrays
                .into_iter()
                .next()
                .unwrap_or_else(|| py.None().into_bound(py))),
            Some(keys) => {
                let d = PyDict::new(py);
                for (k, a) in keys.iter().zip(arrays) {
                    d.set_item(k.bind(py), a)?;
                }
                Ok(d.into_any())
            }
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
        if self.needs_reset {
            return Err(PyRuntimeError::new_err(
                "step() called before reset() or after the episode ended (terminated or \
                 truncated): call reset() first",
            ));
        }
        self.illegal = false;
        if let Action::Discrete(a) = action
            && let Some(mask) = &self.step.observation.action_mask
            && !mask.get(*a).copied().unwrap_or(false)
        {
            match self.policy {
                IllegalAction::Raise => {
                    return Err(PyValueError::new_err(format!(
                        "action {a} is masked out in this state (info[\"action_mask\"][{a}] == 0)"
                    )));
                }
                IllegalAction::Terminate(reward) => {
                    self.step.reward = reward;
                    self.step.terminated = true;
                    self.step.truncated = false;
                    self.step.info.clear();
                    self.illegal = true;
                    self.needs_reset = true;
                    return Ok(());
                }
            }
        }
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
    pub fn info<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let d = PyDict::new(py);
        for (k, v) in self.step.info.iter() {
            d.set_item(k, v)?;
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

/// A mask as an int8 array (Gymnasium's `Discrete.sample(mask=…)` type).
pub fn mask_to_py<'py>(py: Python<'py>, mask: &[bool]) -> Bound<'py, PyArray1<i8>> {
    let arr = PyArray1::<i8>::zeros(py, mask.len(), false);
    // SAFETY: the array was just created here and is not shared yet.
    if let Ok(s) = unsafe { arr.as_slice_mut() } {
        for (o, m) in s.iter_mut().zip(mask) {
            *o = i8::from(*m);
        }
    }
    arr
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
    core: Mutex<Option<EpisodeCore>>,
    layout: ObsLayout,
    action: ActionSpec,
    spec: EnvSpec,
    params: BTreeMap<String, Value>,
}

impl PyEnv {
    fn core(&self) -> PyResult<MutexGuard<'_, Option<EpisodeCore>>> {
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
            core: Mutex::new(Some(core)),
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
        let core = guard.as_mut().ok_or_else(closed)?;
        py.detach(|| core.reset(seed))?;
        let obs = self.layout.to_py(py, &core.step.observation)?;
        PyTuple::new(py, [obs, core.info(py)?.into_any()])
    }

    /// Applies `action`; returns `(observation, reward, terminated, truncated, info)`.
    fn step<'py>(
        &self,
        py: Python<'py>,
        action: &Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, PyTuple>> {
        let mut guard = self.core()?;
        let core = guard.as_mut().ok_or_else(closed)?;
        let mut a = match self.action {
            ActionSpec::Discrete(_) => Action::Discrete(0),
            ActionSpec::Box { .. } => Action::Continuous(Vec::new()),
        };
        self.action.parse(action, &mut a)?;
        py.detach(|| core.step(&a))?;
        let s = &core.step;
        PyTuple::new(
            py,
            [
                self.layout.to_py(py, &s.observation)?,
                s.reward.into_pyobject(py)?.into_any(),
                pyo3::types::PyBool::new(py, s.terminated)
                    .to_owned()
                    .into_any(),
                pyo3::types::PyBool::new(py, s.truncated)
                    .to_owned()
                    .into_any(),
                core.info(py)?.into_any(),
            ],
        )
    }

    /// The current action mask (int8, 1 = legal), or `None` when every action is legal.
    fn action_mask<'py>(&self, py: Python<'py>) -> PyResult<Option<Bound<'py, PyArray1<i8>>>> {
        let guard = self.core()?;
        let core = guard.as_ref().ok_or_else(closed)?;
        Ok(core
            .step
            .observation
            .action_mask
            .as_deref()
            .map(|m| mask_to_py(py, m)))
    }

    /// Releases the environment's resources (e.g. its Chromium browser). Closing twice is fine.
    fn close(&self, py: Python<'_>) -> PyResult<()> {
        let mut guard = self.core()?;
        if let Some(mut core) = guard.take() {
            py.detach(|| guard_close(&mut core))?;
        }
        Ok(())
    }

    /// Whether `close()` was called.
    #[getter]
    fn closed(&self) -> PyResult<bool> {
        Ok(self.core()?.is_none())
    }
}

/// `env.close()`, with the environment dropped afterwards whatever happens.
pub fn guard_close(core: &mut EpisodeCore) -> PyResult<()> {
    guard("close", || core.env.close().map_err(env_error))
}
