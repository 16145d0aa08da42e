//! N environments stepped together in Rust threads with the GIL released (the engine of
//! `a2perf_rs.vector.A2PerfVectorEnv`).
//!
//! Observations, rewards, flags and masks are written straight into numpy arrays (fresh ones each
//! call with `copy=True`, the vector env's own buffers with `copy=False`);
//! the environments are split into one contiguous chunk per thread (the caller's and the vector
//! environment's own workers, an [`a2perf_core::crew::Crew`]: `min(N, cores)` threads in all),
//! each environment built on and always stepped by the same thread. Semantics are Gymnasium
//! 1.x's: `reset(seed=s)` seeds environment `i` with `s + i` (as `SyncVectorEnv` does), later
//! resets continue each environment's own stream, and the autoreset mode is next-step (default)
//! or same-step. So N single environments reset with seeds `s + i` and stepped with the same
//! actions produce the same trajectories, which the tests check.

use std::sync::{Mutex, MutexGuard, PoisonError};

use a2perf_core::crew::Crew;
use a2perf_core::{Action, Observation};
use numpy::{
    PyArray1, PyArray2, PyArrayMethods, PyReadonlyArray1, PyReadonlyArray2, PyUntypedArrayMethods,
};
use pyo3::exceptions::{PyRuntimeError, PyTypeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyTuple};

use crate::convert::{ActionSpec, type_name_of};
use crate::env::{
    EpisodeCore, IllegalAction, ObsArray, ObsLayout, ObsRow, ObsRows, build_env, env_kwargs,
    frame_to_py, guard_close, render_env, spec_to_py,
};
use crate::errors::guard;

/// Gymnasium's autoreset modes that are supported.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Autoreset {
    /// The step after an episode ends resets that environment (its action is ignored).
    NextStep,
    /// An environment whose episode ends is reset in the same step; the last observation and
    /// info go to `info["final_obs"]`, `info["final_info"]`.
    SameStep,
}

struct Slot {
    core: EpisodeCore,
    /// Next-step mode: this environment is reset at the next `step`.
    pending_reset: bool,
    /// Same-step mode: the episode ended in this step; its last observation and info.
    ended: bool,
    final_obs: Observation,
    final_info: a2perf_core::Info,
    final_illegal: bool,
}

/// Where one environment writes its outcome.
struct SlotOut<'a> {
    obs: Vec<ObsRow<'a>>,
    reward: &'a mut f64,
    terminated: &'a mut bool,
    truncated: &'a mut bool,
    mask: Option<&'a mut [i8]>,
}

/// The arrays one call writes its outcome into and returns.
struct Arrays<'py> {
    obs: Vec<ObsArray<'py>>,
    rewards: Bound<'py, PyArray1<f64>>,
    terminated: Bound<'py, PyArray1<bool>>,
    truncated: Bound<'py, PyArray1<bool>>,
    /// `(N, actions)` for discrete action spaces.
    masks: Option<Bound<'py, PyArray2<i8>>>,
}

impl<'py> Arrays<'py> {
    /// Zeroed arrays for `n` environments (every element is written by each call).
    fn new(py: Python<'py>, layout: &ObsLayout, n: usize, action: &ActionSpec) -> Self {
        Self {
            obs: layout.buffers(py, n),
            rewards: PyArray1::zeros(py, n, false),
            terminated: PyArray1::zeros(py, n, false),
            truncated: PyArray1::zeros(py, n, false),
            masks: match action {
                ActionSpec::Discrete(k) => Some(PyArray2::zeros(py, [n, *k], false)),
                ActionSpec::Box { .. } => None,
            },
        }
    }

    fn unbind(self) -> Buffers {
        Buffers {
            obs: self.obs.into_iter().map(ObsArray::unbind).collect(),
            rewards: self.rewards.unbind(),
            terminated: self.terminated.unbind(),
            truncated: self.truncated.unbind(),
            masks: self.masks.map(Bound::unbind),
        }
    }
}

/// `copy=False`: the vector env's own [`Arrays`], overwritten by every call.
struct Buffers {
    /// Arrays of the layout's element types (see [`ObsArray::bind`]).
    obs: Vec<Py<PyAny>>,
    rewards: Py<PyArray1<f64>>,
    terminated: Py<PyArray1<bool>>,
    truncated: Py<PyArray1<bool>>,
    masks: Option<Py<PyArray2<i8>>>,
}

impl Buffers {
    fn bind<'py>(&self, py: Python<'py>, layout: &ObsLayout) -> PyResult<Arrays<'py>> {
        Ok(Arrays {
            obs: self
                .obs
                .iter()
                .zip(&layout.dtypes)
                .map(|(b, t)| ObsArray::bind(py, b, *t))
                .collect::<PyResult<_>>()?,
            rewards: self.rewards.bind(py).clone(),
            terminated: self.terminated.bind(py).clone(),
            truncated: self.truncated.bind(py).clone(),
            masks: self.masks.as_ref().map(|m| m.bind(py).clone()),
        })
    }
}

struct State {
    slots: Vec<Slot>,
    /// The threads beside the caller's; `None` for one environment or one core.
    workers: Option<Crew>,
    actions: Vec<Action>,
    /// `None` with `copy=True`: each call writes into fresh arrays, which it hands over.
    bufs: Option<Buffers>,
    closed: bool,
}

/// N environments of one id: `a2perf_rs._native.VecEnv(env_id, num_envs, params, …)`.
#[pyclass(module = "a2perf_rs._native", name = "VecEnv")]
pub struct PyVecEnv {
    state: Mutex<State>,
    layout: ObsLayout,
    action: ActionSpec,
    spec: a2perf_core::EnvSpec,
    params: std::collections::BTreeMap<String, a2perf_core::Value>,
    autoreset: Autoreset,
}

fn write_obs(layout: &ObsLayout, obs: &Observation, out: &mut SlotOut<'_>) -> PyResult<()> {
    layout.check(obs)?;
    for (dst, t) in out.obs.iter_mut().zip(&obs.tensors) {
        dst.copy_from(&t.data)?;
    }
    Ok(())
}

fn write_slot(layout: &ObsLayout, slot: &Slot, out: &mut SlotOut<'_>) -> PyResult<()> {
    let s = &slot.core.step;
    write_obs(layout, &s.observation, out)?;
    *out.reward = s.reward;
    *out.terminated = s.terminated;
    *out.truncated = s.truncated;
    if let Some(dst) = out.mask.as_deref_mut() {
        match &s.observation.action_mask {
            Some(m) if m.len() == dst.len() => {
                for (o, v) in dst.iter_mut().zip(m) {
                    *o = i8::from(*v);
                }
            }
            Some(m) => {
                return Err(PyRuntimeError::new_err(format!(
                    "the environment returned an action mask of {} entries for {} actions",
                    m.len(),
                    dst.len()
                )));
            }
            None => dst.fill(1),
        }
    }
    Ok(())
}

/// Runs `one` over `slots` (environments `first..`) in order, stopping at the first error.
fn run_chunk<F>(first: usize, slots: &mut [Slot], outs: &mut [SlotOut<'_>], one: &F) -> PyResult<()>
where
    F: Fn(usize, &mut Slot, &mut SlotOut<'_>) -> PyResult<()>,
{
    slots
        .iter_mut()
        .zip(outs.iter_mut())
        .enumerate()
        .try_for_each(|(i, (slot, out))| one(first + i, slot, out))
}

/// How many threads step `n` environments with `crew` (the caller's and its workers'): one
/// per environment at most.
fn threads(crew: Option<&Crew>, n: usize) -> usize {
    crew.map_or(1, |c| c.workers() + 1).min(n)
}

/// The environments that thread `k` of `parts` steps: a contiguous chunk, the chunks' sizes
/// differing by one at most. Thread 0 is the caller, thread `k ≥ 1` worker `k` of the crew.
fn chunk(n: usize, parts: usize, k: usize) -> std::ops::Range<usize> {
    k * n / parts..(k + 1) * n / parts
}

/// Builds environment `i` as `build(i)` for `i < n`, each on the thread that will step it
/// ([`chunk`]), the threads at once (a browser-backed environment starts its browser in
/// parallel); an environment's memory so comes from that thread's allocator and is first
/// touched by its core. Returns the error of the lowest-numbered environment that failed.
fn build_on_threads<T: Send>(
    py: Python<'_>,
    crew: Option<&Crew>,
    n: usize,
    build: impl Fn(usize) -> PyResult<T> + Sync,
) -> PyResult<Vec<T>> {
    let built: Vec<Mutex<Option<PyResult<T>>>> = (0..n).map(|_| Mutex::new(None)).collect();
    let parts = threads(crew, n);
    let job = |k: usize| {
        if k < parts {
            for i in chunk(n, parts, k) {
                let b = build(i);
                *built[i].lock().unwrap_or_else(PoisonError::into_inner) = Some(b);
            }
        }
    };
    let finished = py.detach(|| match crew {
        Some(c) => c.run(&job),
        None => {
            job(0);
            true
        }
    });
    if !finished {
        return Err(PyRuntimeError::new_err(
            "a worker thread panicked while building the environments",
        ));
    }
    built
        .into_iter()
        .map(|b| {
            b.into_inner()
                .unwrap_or_else(PoisonError::into_inner)
                .unwrap_or_else(|| {
                    Err(PyRuntimeError::new_err(
                        "internal error: an environment was not built",
                    ))
                })
        })
        .collect()
}

/// Adds the scalar diagnostics of `n` environments' infos (`info(i)`, `None`: environment `i`
/// has none) to the vector info dict `d` in Gymnasium's layout: each key a float64 array over the
/// environments (0 where absent), `_key` a boolean array saying which have it.
fn put_scalar_infos<'a>(
    d: &Bound<'_, PyDict>,
    n: usize,
    info: impl Fn(usize) -> Option<&'a a2perf_core::Info>,
) -> PyResult<()> {
    let py = d.py();
    let mut keys: Vec<&str> = Vec::new();
    for k in (0..n)
        .filter_map(&info)
        .flat_map(|inf| inf.iter().map(|(k, _)| k))
    {
        if !keys.contains(&k) {
            keys.push(k);
        }
    }
    for k in keys {
        let mut values = vec![0.0f64; n];
        let mut has = vec![false; n];
        for i in 0..n {
            if let Some(v) = info(i).and_then(|inf| inf.get(k)) {
                values[i] = v;
                has[i] = true;
            }
        }
        d.set_item(k, PyArray1::from_slice(py, &values))?;
        d.set_item(format!("_{k}"), PyArray1::from_slice(py, &has))?;
    }
    Ok(())
}

/// Runs `one` over the slots split into contiguous chunks, one per thread ([`chunk`]): the
/// calling thread takes the first chunk and worker `k` of `crew` always chunk `k`. An
/// environment so stays on one thread from step to step (its state stays in that core's cache)
/// and the caller works instead of waiting. Returns the error of the lowest-numbered failing
/// environment's chunk.
fn run_pinned<F>(crew: &Crew, slots: &mut [Slot], outs: &mut [SlotOut<'_>], one: &F) -> PyResult<()>
where
    F: Fn(usize, &mut Slot, &mut SlotOut<'_>) -> PyResult<()> + Sync,
{
    let n = slots.len();
    let parts = threads(Some(crew), n);
    let mut chunks = Vec::with_capacity(parts);
    let (mut slots, mut outs) = (slots, outs);
    for k in 0..parts {
        let range = chunk(n, parts, k);
        let (s, s_rest) = std::mem::take(&mut slots).split_at_mut(range.len());
        let (o, o_rest) = std::mem::take(&mut outs).split_at_mut(range.len());
        chunks.push(Mutex::new((range.start, s, o, Ok(()))));
        (slots, outs) = (s_rest, o_rest);
    }
    let finished = crew.run(&|k| {
        if let Some(chunk) = chunks.get(k) {
            let mut c = chunk.lock().unwrap_or_else(PoisonError::into_inner);
            let (first, s, o, result) = &mut *c;
            *result = run_chunk(*first, s, o, one);
        }
    });
    if !finished {
        return Err(PyRuntimeError::new_err(
            "a worker thread of the vector environment panicked; reset the environments",
        ));
    }
    chunks
        .into_iter()
        .try_for_each(|c| c.into_inner().unwrap_or_else(PoisonError::into_inner).3)
}

/// The worker threads of `n` environments: one fewer than the threads that step them,
/// `min(n, available cores)`; `None` when that is one thread (the caller's).
fn worker_crew(n: usize) -> PyResult<Option<Crew>> {
    let cores = std::thread::available_parallelism().map_or(1, std::num::NonZeroUsize::get);
    let threads = n.min(cores);
    if threads <= 1 {
        return Ok(None);
    }
    Crew::new(threads - 1, "a2perf-vec")
        .map(Some)
        .map_err(|e| PyRuntimeError::new_err(format!("cannot start the worker threads: {e}")))
}

impl PyVecEnv {
    fn state(&self) -> PyResult<MutexGuard<'_, State>> {
        let st = self.state.lock().map_err(|_| {
            PyRuntimeError::new_err("the vector environment is unusable after an earlier failure")
        })?;
        if st.closed {
            return Err(PyRuntimeError::new_err("the vector environment is closed"));
        }
        Ok(st)
    }

    /// Runs `work` on every slot in parallel (GIL released), then writes the outcomes into the
    /// buffers; returns `(obs, rewards, terminated, truncated, infos)`.
    fn run<'py>(
        &self,
        py: Python<'py>,
        st: &mut State,
        work: impl Fn(usize, &mut Slot, &Action) -> PyResult<()> + Sync,
    ) -> PyResult<Bound<'py, PyTuple>> {
        let n = st.slots.len();
        // A vector env inherited through fork(): its worker threads stayed in the parent, so
        // start this process's own (the crew alone would run every part on this thread).
        if st.workers.as_ref().is_some_and(Crew::forked) {
            st.workers = worker_crew(n)?;
        }
        let Arrays {
            obs: obs_bufs,
            rewards,
            terminated,
            truncated,
            masks,
        } = match &st.bufs {
            Some(bufs) => bufs.bind(py, &self.layout)?,
            None => Arrays::new(py, &self.layout, n, &self.action),
        };
        {
            let mut obs_rw: Vec<_> = obs_bufs.iter().map(|b| b.readwrite()).collect();
            let mut rew_rw = rewards.readwrite();
            let mut term_rw = terminated.readwrite();
            let mut trunc_rw = truncated.readwrite();
            let mut mask_rw = masks.as_ref().map(|m| m.readwrite());
            let slices = |e: numpy::AsSliceError| PyRuntimeError::new_err(e.to_string());
            let mut obs_rows: Vec<ObsRows<'_>> = obs_rw
                .iter_mut()
                .zip(&self.layout.dims)
                .map(|(rw, d)| rw.rows(*d))
                .collect::<PyResult<_>>()?;
            let mut mask_rows = match mask_rw.as_mut() {
                Some(rw) => {
                    let n_actions = rw.shape()[1].max(1);
                    Some(rw.as_slice_mut().map_err(slices)?.chunks_mut(n_actions))
                }
                None => None,
            };
            let mut outs: Vec<SlotOut<'_>> = rew_rw
                .as_slice_mut()
                .map_err(slices)?
                .iter_mut()
                .zip(term_rw.as_slice_mut().map_err(slices)?.iter_mut())
                .zip(trunc_rw.as_slice_mut().map_err(slices)?.iter_mut())
                .map(|((reward, terminated), truncated)| SlotOut {
                    obs: obs_rows.iter_mut().filter_map(Iterator::next).collect(),
                    reward,
                    terminated,
                    truncated,
                    mask: mask_rows.as_mut().and_then(Iterator::next),
                })
                .collect();
            if outs.len() != n || outs.iter().any(|o| o.obs.len() != self.layout.dims.len()) {
                return Err(PyRuntimeError::new_err(
                    "internal error: buffer layout mismatch",
                ));
            }
            let layout = &self.layout;
            let actions = &st.actions;
            let one = |i: usize, slot: &mut Slot, out: &mut SlotOut<'_>| {
                work(i, slot, &actions[i])?;
                write_slot(layout, slot, out)
            };
            // A panic on this thread becomes an error, as a worker's does (see `run_pinned`).
            py.detach(|| {
                guard("the vector step", || match &st.workers {
                    // No thread hand-off for a single environment.
                    None => run_chunk(0, &mut st.slots, &mut outs, &one),
                    Some(pool) => run_pinned(pool, &mut st.slots, &mut outs, &one),
                })
            })?;
        }
        let obs = self
            .layout
            .wrap(py, obs_bufs.into_iter().map(ObsArray::into_any).collect())?;
        let infos = self.infos(py, st, masks.map(Bound::into_any))?;
        PyTuple::new(
            py,
            [
                obs,
                rewards.into_any(),
                terminated.into_any(),
                truncated.into_any(),
                infos.into_any(),
            ],
        )
    }

    /// Gymnasium's vector info dict: each key maps to an array over environments and `_key` to a
    /// boolean array saying which environments have it.
    fn infos<'py>(
        &self,
        py: Python<'py>,
        st: &State,
        masks: Option<Bound<'py, PyAny>>,
    ) -> PyResult<Bound<'py, PyDict>> {
        let n = st.slots.len();
        let d = PyDict::new(py);
        put_scalar_infos(&d, n, |i| Some(&st.slots[i].core.step.info))?;
        if let Some(m) = masks {
            d.set_item(pyo3::intern!(py, "action_mask"), m)?;
            d.set_item("_action_mask", PyArray1::from_slice(py, &vec![true; n]))?;
        }
        // Same-step mode: an ended environment's illegal action is reported in `final_info`,
        // its info here being the new episode's (as Gymnasium's `SyncVectorEnv` does).
        let illegal: Vec<bool> = st.slots.iter().map(|s| s.core.illegal).collect();
        if illegal.iter().any(|b| *b) {
            d.set_item("illegal_action", PyArray1::from_slice(py, &illegal))?;
            d.set_item("_illegal_action", PyArray1::from_slice(py, &illegal))?;
        }
        if self.autoreset == Autoreset::SameStep && st.slots.iter().any(|s| s.ended) {
            let ended: Vec<bool> = st.slots.iter().map(|s| s.ended).collect();
            let final_obs = py
                .import("numpy")?
                .call_method1("full", (n, py.None(), "object"))?;
            for (i, s) in st.slots.iter().enumerate() {
                if s.ended {
                    final_obs.set_item(i, self.layout.to_py(py, &s.final_obs)?)?;
                }
            }
            d.set_item("final_obs", final_obs)?;
            d.set_item("_final_obs", PyArray1::from_slice(py, &ended))?;
            d.set_item("final_info", self.final_infos(py, st)?)?;
            d.set_item("_final_info", PyArray1::from_slice(py, &ended))?;
        }
        Ok(d)
    }

    /// Same-step mode's `final_info`: the ended environments' last infos as one vector info dict
    /// (each key an array over environments, `_key` saying which have it), built as Gymnasium's
    /// `SyncVectorEnv` builds it from single environments' infos: scalar diagnostics (float64),
    /// `action_mask` (int8 rows of the final observations' masks) and `illegal_action`.
    fn final_infos<'py>(&self, py: Python<'py>, st: &State) -> PyResult<Bound<'py, PyDict>> {
        let n = st.slots.len();
        let d = PyDict::new(py);
        put_scalar_infos(&d, n, |i| {
            let s = &st.slots[i];
            s.ended.then_some(&s.final_info)
        })?;
        if let ActionSpec::Discrete(k) = self.action {
            let masks = PyArray2::<i8>::zeros(py, [n, k], false);
            let mut has = vec![false; n];
            {
                let mut rw = masks.readwrite();
                let mut rows = rw.as_array_mut();
                for (i, s) in st.slots.iter().enumerate() {
                    if let Some(mask) = s.final_obs.action_mask.as_ref().filter(|_| s.ended) {
                        for (out, legal) in rows.row_mut(i).iter_mut().zip(mask) {
                            *out = i8::from(*legal);
                        }
                        has[i] = true;
                    }
                }
            }
            if has.iter().any(|h| *h) {
                d.set_item("action_mask", masks)?;
                d.set_item("_action_mask", PyArray1::from_slice(py, &has))?;
            }
        }
        let illegal: Vec<bool> = st
            .slots
            .iter()
            .map(|s| s.ended && s.final_illegal)
            .collect();
        if illegal.iter().any(|b| *b) {
            d.set_item("illegal_action", PyArray1::from_slice(py, &illegal))?;
            d.set_item("_illegal_action", PyArray1::from_slice(py, &illegal))?;
        }
        Ok(d)
    }

    /// Parses the batch of actions into `st.actions`.
    fn parse_actions(&self, st: &mut State, actions: &Bound<'_, PyAny>) -> PyResult<()> {
        let n = st.slots.len();
        match &self.action {
            ActionSpec::Discrete(_) => {
                let arr: PyReadonlyArray1<'_, i64> = actions.extract().map_err(|_| {
                    PyTypeError::new_err(format!(
                        "actions must be an int64 array of shape ({n},) (a2perf_rs converts \
                         integer arrays); got {}",
                        type_name_of(actions)
                    ))
                })?;
                if arr.len() != n {
                    return Err(PyValueError::new_err(format!(
                        "actions have shape {:?}, expected ({n},)",
                        arr.shape()
                    )));
                }
                for (i, (a, out)) in arr.as_array().iter().zip(&mut st.actions).enumerate() {
                    let a = self
                        .action
                        .check_discrete(*a)
                        .map_err(|e| PyValueError::new_err(format!("environment {i}: {e}")))?;
                    *out = Action::Discrete(a);
                }
            }
            ActionSpec::Box { shape, .. } => {
                let arr: PyReadonlyArray2<'_, f32> = actions.extract().map_err(|_| {
                    PyTypeError::new_err(format!(
                        "actions must be a float32 array of shape ({n}, {}); got {}",
                        shape
                            .iter()
                            .map(|d| d.to_string())
                            .collect::<Vec<_>>()
                            .join(", "),
                        type_name_of(actions)
                    ))
                })?;
                let view = arr.as_array();
                if view.nrows() != n {
                    return Err(PyValueError::new_err(format!(
                        "actions have shape {:?}, expected ({n}, …)",
                        arr.shape()
                    )));
                }
                for (i, (row, out)) in view.rows().into_iter().zip(&mut st.actions).enumerate() {
                    let v: Vec<f32> = row.iter().copied().collect();
                    if !matches!(out, Action::Continuous(_)) {
                        *out = Action::Continuous(Vec::new());
                    }
                    if let Action::Continuous(buf) = out {
                        self.action
                            .check_box(&v, &[v.len()], buf)
                            .map_err(|e| PyValueError::new_err(format!("environment {i}: {e}")))?;
                    }
                }
            }
        }
        Ok(())
    }
}

#[pymethods]
impl PyVecEnv {
    /// `num_envs` environments `env_id` with `params`. `episode_seeds=run_seed` seeds every
    /// reset without a seed (autoresets included) of environment `i` from stream `i` of a
    /// training run (see [`crate::env::EpisodeSeeds`]).
    #[new]
    #[pyo3(signature = (env_id, num_envs, params=None, autoreset_mode="next_step", copy=true, illegal_action="terminate", illegal_action_reward=None, episode_seeds=None))]
    #[allow(clippy::too_many_arguments)]
    fn new(
        py: Python<'_>,
        env_id: &str,
        num_envs: usize,
        params: Option<&Bound<'_, PyDict>>,
        autoreset_mode: &str,
        copy: bool,
        illegal_action: &str,
        illegal_action_reward: Option<f64>,
        episode_seeds: Option<u64>,
    ) -> PyResult<Self> {
        if num_envs == 0 {
            return Err(PyValueError::new_err("num_envs must be at least 1"));
        }
        let autoreset = match autoreset_mode {
            "next_step" | "NextStep" => Autoreset::NextStep,
            "same_step" | "SameStep" => Autoreset::SameStep,
            other => {
                return Err(PyValueError::new_err(format!(
                    "autoreset_mode `{other}` is not supported: use next_step or same_step"
                )));
            }
        };
        let kwargs = env_kwargs(params)?;
        let workers = worker_crew(num_envs)?;
        let built = build_on_threads(py, workers.as_ref(), num_envs, |i| {
            let (env, resolved) = build_env(env_id, &kwargs)?;
            let policy = IllegalAction::parse(illegal_action, illegal_action_reward, &resolved)?;
            let mut core = EpisodeCore::new(env, policy);
            if let Some(run_seed) = episode_seeds {
                core = core.with_episode_seeds(run_seed, i);
            }
            let slot = Slot {
                core,
                pending_reset: false,
                ended: false,
                final_obs: Observation::default(),
                final_info: Default::default(),
                final_illegal: false,
            };
            Ok((slot, resolved))
        })?;
        let (slots, resolved): (Vec<Slot>, Vec<_>) = built.into_iter().unzip();
        // Every copy has the same spec and parameters: environment 0's stand for all.
        let (Some(first), Some(params)) = (slots.first(), resolved.into_iter().next()) else {
            return Err(PyValueError::new_err("num_envs must be at least 1"));
        };
        let spec = first.core.env.spec().clone();
        let layout = ObsLayout::of(py, &spec.observation_space)?;
        let action = ActionSpec::of(&spec.action_space)?;
        let bufs = (!copy).then(|| Arrays::new(py, &layout, num_envs, &action).unbind());
        let actions = match action {
            ActionSpec::Discrete(_) => vec![Action::Discrete(0); num_envs],
            ActionSpec::Box { .. } => vec![Action::Continuous(Vec::new()); num_envs],
        };
        Ok(Self {
            state: Mutex::new(State {
                slots,
                actions,
                bufs,
                closed: false,
                workers,
            }),
            layout,
            action,
            spec,
            params,
            autoreset,
        })
    }

    /// Number of environments.
    #[getter]
    fn num_envs(&self) -> PyResult<usize> {
        Ok(self.state()?.slots.len())
    }

    /// The spec of the environments (as `Env.spec()`).
    fn spec<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        spec_to_py(py, &self.spec, &self.params)
    }

    /// Resets every environment (`seeds[i]` for environment `i`, `None` = continue its own
    /// stream); returns `(obs, infos)`.
    fn reset<'py>(
        &self,
        py: Python<'py>,
        seeds: Vec<Option<u64>>,
    ) -> PyResult<Bound<'py, PyTuple>> {
        let mut st = self.state()?;
        if seeds.len() != st.slots.len() {
            return Err(PyValueError::new_err(format!(
                "{} seeds for {} environments",
                seeds.len(),
                st.slots.len()
            )));
        }
        let out = self.run(py, &mut st, |i, slot, _| {
            slot.pending_reset = false;
            slot.ended = false;
            slot.core.reset(seeds[i])
        })?;
        let obs = out.get_item(0)?;
        let infos = out.get_item(4)?;
        PyTuple::new(py, [obs, infos])
    }

    /// Steps environment `i` with `actions[i]`; returns `(obs, rewards, terminated, truncated,
    /// infos)`. `actions`: int64 `(N,)` for discrete spaces, float32 `(N, dim)` for boxes.
    fn step<'py>(
        &self,
        py: Python<'py>,
        actions: &Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, PyTuple>> {
        let mut st = self.state()?;
        self.parse_actions(&mut st, actions)?;
        // All or nothing: a step that one environment refuses steps none of them, so that the
        // environments stay in step with each other (and with the caller's view of them).
        for (i, (slot, action)) in st.slots.iter().zip(&st.actions).enumerate() {
            if let Some(refusal) = (!slot.pending_reset)
                .then(|| slot.core.refusal(action))
                .flatten()
            {
                return Err(refusal.into_err(&format!("environment {i}: ")));
            }
        }
        let mode = self.autoreset;
        self.run(py, &mut st, |_, slot, action| {
            slot.ended = false;
            if slot.pending_reset {
                slot.pending_reset = false;
                return slot.core.reset(None);
            }
            slot.core.step(action)?;
            if slot.core.step.done() {
                match mode {
                    Autoreset::NextStep => slot.pending_reset = true,
                    Autoreset::SameStep => {
                        slot.ended = true;
                        slot.final_obs.copy_from(&slot.core.step.observation);
                        slot.final_info.clone_from(&slot.core.step.info);
                        slot.final_illegal = slot.core.illegal;
                        let (reward, terminated, truncated) = (
                            slot.core.step.reward,
                            slot.core.step.terminated,
                            slot.core.step.truncated,
                        );
                        slot.core.reset(None)?;
                        // The step's reward and flags are reported with the new observation.
                        slot.core.step.reward = reward;
                        slot.core.step.terminated = terminated;
                        slot.core.step.truncated = truncated;
                    }
                }
            }
            Ok(())
        })
    }

    /// Closes every environment (releasing e.g. their Chromium browsers). Closing twice is fine.
    fn close(&self, py: Python<'_>) -> PyResult<()> {
        let mut st = self
            .state
            .lock()
            .map_err(|_| PyRuntimeError::new_err("the vector environment is unusable"))?;
        if st.closed {
            return Ok(());
        }
        st.closed = true;
        let slots = std::mem::take(&mut st.slots);
        py.detach(|| {
            let mut first_err = None;
            for mut s in slots {
                if let Err(e) = guard_close(&mut s.core) {
                    first_err.get_or_insert(e);
                }
            }
            first_err.map_or(Ok(()), Err)
        })
    }

    /// The modes `render` accepts (every environment's: they share an id).
    fn render_modes(&self) -> PyResult<Vec<&'static str>> {
        let st = self.state()?;
        Ok(st
            .slots
            .first()
            .map(|s| s.core.env.render_modes().to_vec())
            .unwrap_or_default())
    }

    /// Every environment's frame in `mode` (as `Env.render`), in order.
    fn render<'py>(&self, py: Python<'py>, mode: &str) -> PyResult<Vec<Bound<'py, PyAny>>> {
        let mut st = self.state()?;
        let slots = &mut st.slots;
        let frames = py.detach(|| {
            slots
                .iter_mut()
                .map(|s| render_env(s.core.env.as_mut(), mode))
                .collect::<PyResult<Vec<_>>>()
        })?;
        frames.into_iter().map(|f| frame_to_py(py, f)).collect()
    }

    /// Whether `close()` was called.
    #[getter]
    fn closed(&self) -> PyResult<bool> {
        Ok(self
            .state
            .lock()
            .map_err(|_| PyRuntimeError::new_err("the vector environment is unusable"))?
            .closed)
    }
}
