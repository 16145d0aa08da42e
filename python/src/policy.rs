//! Python callables as the benchmark's policies, so that the pipelines roll a Python agent out
//! exactly as they roll out a built-in one (same environments, seeds and per-call timer).
//!
//! A [`PyPolicy`] hands the callable each observation as the Gymnasium environment returns it (a
//! fresh float32 array, or a dict of them) and, when the callable takes a second argument, an
//! info dict holding `action_mask` (int8, 1 = legal) as the environment's `info` does. The
//! returned action is checked like `env.step`'s (type, shape, bounds, and the mask).
//!
//! A Python exception cannot travel through the pipeline's error types, so the policy keeps the
//! first one in an [`ErrorSlot`] and fails with a placeholder; [`pipeline_error`] puts the
//! exception back, its message prefixed with where the rollout failed (run, episode, step).

use std::path::Path;
use std::sync::{Arc, Mutex};

use a2perf_core::{
    ActMode, Action, Checkpoint, EnvError, EnvSpec, Observation, Policy, PolicyError, RunError,
};
use a2perf_pipeline::{LoadedRun, PipelineError, PolicySource, RegistryPolicies};
use pyo3::exceptions::{
    PyFileNotFoundError, PyKeyboardInterrupt, PyOSError, PyRuntimeError, PyValueError,
};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyTuple};

use crate::convert::ActionSpec;
use crate::env::{ObsLayout, mask_to_py};
use crate::errors::registry_error;

/// What went wrong in a Python policy.
pub enum PolicyFailure {
    /// The callable (or a policy loader) raised this exception.
    Raised(PyErr),
    /// The callable returned an action that `env.step` would refuse (the exception says why).
    BadAction(PyErr),
}

/// The first failure of the Python policies of one pipeline call.
pub type ErrorSlot = Arc<Mutex<Option<PolicyFailure>>>;

fn keep(slot: &ErrorSlot, failure: PolicyFailure) {
    if let Ok(mut s) = slot.lock()
        && s.is_none()
    {
        *s = Some(failure);
    }
}

/// A submission's `inference.py` bound to the policy its `load_policy` returned (`a2perf
/// submit`): `preprocess_observation(observation, **kwargs)` turns each observation into the
/// policy's input outside the inference timer, and `infer_once` — the only timed call — maps it
/// to an action, called as the original harness calls it (`infer_once(policy=…,
/// preprocessed_observation=…)`) or, for the template's `infer_once(model, observation)`,
/// positionally.
#[pyclass(module = "a2perf_rs._native", name = "SubmissionPolicy", frozen)]
pub struct SubmissionPolicy {
    policy: Py<PyAny>,
    preprocess: Py<PyAny>,
    infer_once: Py<PyAny>,
    keywords: bool,
    preprocess_info: bool,
    preprocess_kwargs: Py<PyDict>,
}

#[pymethods]
impl SubmissionPolicy {
    /// `keywords`: call `infer_once` with the original harness's keyword names;
    /// `preprocess_info`: also pass `info=` (the action mask) to `preprocess_observation`;
    /// `preprocess_kwargs`: further keywords it gets at every call (`time_step_spec`).
    #[new]
    #[pyo3(signature = (policy, preprocess_observation, infer_once, keywords, preprocess_info, preprocess_kwargs=None))]
    fn new(
        py: Python<'_>,
        policy: Py<PyAny>,
        preprocess_observation: Py<PyAny>,
        infer_once: Py<PyAny>,
        keywords: bool,
        preprocess_info: bool,
        preprocess_kwargs: Option<Py<PyDict>>,
    ) -> Self {
        Self {
            policy,
            preprocess: preprocess_observation,
            infer_once,
            keywords,
            preprocess_info,
            preprocess_kwargs: preprocess_kwargs.unwrap_or_else(|| PyDict::new(py).unbind()),
        }
    }
}

impl SubmissionPolicy {
    fn preprocess<'py>(
        &self,
        py: Python<'py>,
        observation: Bound<'py, PyAny>,
        info: impl FnOnce() -> PyResult<Bound<'py, PyDict>>,
    ) -> PyResult<Bound<'py, PyAny>> {
        let kwargs = self.preprocess_kwargs.bind(py).copy()?;
        if self.preprocess_info {
            kwargs.set_item(pyo3::intern!(py, "info"), info()?)?;
        }
        self.preprocess.bind(py).call((observation,), Some(&kwargs))
    }

    fn infer_once<'py>(
        &self,
        py: Python<'py>,
        preprocessed: Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, PyAny>> {
        let f = self.infer_once.bind(py);
        if self.keywords {
            let kwargs = PyDict::new(py);
            kwargs.set_item(pyo3::intern!(py, "policy"), self.policy.bind(py))?;
            kwargs.set_item(pyo3::intern!(py, "preprocessed_observation"), preprocessed)?;
            f.call((), Some(&kwargs))
        } else {
            f.call1((self.policy.bind(py), preprocessed))
        }
    }
}

/// How a [`PyPolicy`] calls the agent's code.
pub enum Calls {
    /// `callable(obs)`, or `callable(obs, info)` when `with_info`.
    Callable {
        /// The agent's callable.
        callable: Py<PyAny>,
        /// Whether it takes the info dict.
        with_info: bool,
    },
    /// A submission's `preprocess_observation` and `infer_once`.
    Submission(Py<SubmissionPolicy>),
}

impl Calls {
    /// A [`SubmissionPolicy`] as itself, any other object as a callable.
    pub fn of(policy: Bound<'_, PyAny>, with_info: bool) -> Self {
        match policy.cast_into::<SubmissionPolicy>() {
            Ok(s) => Self::Submission(s.unbind()),
            Err(e) => Self::Callable {
                callable: e.into_inner().unbind(),
                with_info,
            },
        }
    }

    fn clone_ref(&self, py: Python<'_>) -> Self {
        match self {
            Self::Callable {
                callable,
                with_info,
            } => Self::Callable {
                callable: callable.clone_ref(py),
                with_info: *with_info,
            },
            Self::Submission(s) => Self::Submission(s.clone_ref(py)),
        }
    }
}

/// A Python callable `obs -> action` (or `(obs, info) -> action`), or a submission's
/// `inference.py`, for one environment.
pub struct PyPolicy {
    calls: Calls,
    layout: ObsLayout,
    action: ActionSpec,
    errors: ErrorSlot,
    /// The input of the next call, made by `prepare` outside the inference timer: the
    /// callable's arguments, or the submission's preprocessed observation.
    prepared: Option<Py<PyAny>>,
}

impl PyPolicy {
    /// `calls` as the policy of an environment with `spec`; its failures go to `errors`.
    pub fn new(py: Python<'_>, calls: Calls, spec: &EnvSpec, errors: ErrorSlot) -> PyResult<Self> {
        Ok(Self {
            calls,
            layout: ObsLayout::of(py, &spec.observation_space)?,
            action: ActionSpec::of(&spec.action_space)?,
            errors,
            prepared: None,
        })
    }

    /// The input of a call for `obs`, fresh objects: the callable's arguments `(obs,)` or
    /// `(obs, info)`, or what the submission's `preprocess_observation` makes of `obs`.
    fn input<'py>(&self, py: Python<'py>, obs: &Observation) -> PyResult<Bound<'py, PyAny>> {
        let o = self.layout.to_py(py, obs)?;
        let info = || -> PyResult<Bound<'py, PyDict>> {
            let info = PyDict::new(py);
            if let Some(mask) = &obs.action_mask {
                info.set_item(pyo3::intern!(py, "action_mask"), mask_to_py(py, mask))?;
            }
            Ok(info)
        };
        match &self.calls {
            Calls::Callable {
                with_info: true, ..
            } => Ok(PyTuple::new(py, [o, info()?.into_any()])?.into_any()),
            Calls::Callable { .. } => Ok(PyTuple::new(py, [o])?.into_any()),
            Calls::Submission(s) => s.get().preprocess(py, o, info),
        }
    }

    fn call(&mut self, py: Python<'_>, obs: &Observation) -> Result<Action, PolicyFailure> {
        let input = match self.prepared.take() {
            Some(input) => input.into_bound(py),
            None => self.input(py, obs).map_err(PolicyFailure::Raised)?,
        };
        let returned = match &self.calls {
            Calls::Callable { callable, .. } => input
                .cast_into::<PyTuple>()
                .map_err(PyErr::from)
                .and_then(|args| callable.bind(py).call1(args)),
            Calls::Submission(s) => s.get().infer_once(py, input),
        }
        .map_err(PolicyFailure::Raised)?;
        let mut action = match self.action {
            ActionSpec::Discrete(_) => Action::Discrete(0),
            ActionSpec::Box { .. } => Action::Continuous(Vec::new()),
        };
        self.action
            .parse(&returned, &mut action)
            .map_err(PolicyFailure::BadAction)?;
        if let Action::Discrete(a) = action
            && let Some(mask) = &obs.action_mask
            && !mask.get(a).copied().unwrap_or(false)
        {
            return Err(PolicyFailure::BadAction(PyValueError::new_err(format!(
                "action {a} is masked out in this state (info[\"action_mask\"][{a}] == 0)"
            ))));
        }
        Ok(action)
    }
}

impl PyPolicy {
    fn failed(&self, failure: PolicyFailure) -> PolicyError {
        keep(&self.errors, failure);
        PolicyError::BadObservation("the Python policy failed (see the Python exception)".into())
    }
}

impl Policy for PyPolicy {
    fn act(&mut self, obs: &Observation, _mode: ActMode) -> Result<Action, PolicyError> {
        Python::attach(|py| self.call(py, obs)).map_err(|failure| self.failed(failure))
    }

    /// Converts the observation (and the mask) into numpy arrays before the timer starts, as
    /// the original harness's Gymnasium environment handed them over, and runs a submission's
    /// `preprocess_observation`, which the original did not time either: the time of `act` is
    /// the callable's (or `infer_once`'s), plus the call and the action check.
    fn prepare(&mut self, obs: &Observation) -> Result<(), PolicyError> {
        let input = Python::attach(|py| self.input(py, obs).map(Bound::unbind));
        match input {
            Ok(input) => {
                self.prepared = Some(input);
                Ok(())
            }
            Err(e) => Err(self.failed(PolicyFailure::Raised(e))),
        }
    }

    fn checkpoint(&self) -> Result<Checkpoint, PolicyError> {
        Err(PolicyError::BadCheckpoint(
            "a Python policy is saved by the agent's own code (TrainingRun.save_checkpoint)".into(),
        ))
    }
}

/// One Python callable (or submission) as every policy of a pipeline call (`a2perf_rs.infer`,
/// `generalize`).
pub struct CallablePolicies {
    calls: Calls,
    /// Failures of its policies.
    pub errors: ErrorSlot,
}

impl CallablePolicies {
    /// `policy`: a callable, called with the info dict when `with_info`, or a
    /// [`SubmissionPolicy`].
    pub fn new(py: Python<'_>, policy: Py<PyAny>, with_info: bool) -> Self {
        Self {
            calls: Calls::of(policy.into_bound(py), with_info),
            errors: ErrorSlot::default(),
        }
    }

    /// A policy for an environment with `spec`.
    pub fn for_spec(&self, py: Python<'_>, spec: &EnvSpec) -> PyResult<PyPolicy> {
        PyPolicy::new(py, self.calls.clone_ref(py), spec, self.errors.clone())
    }
}

impl PolicySource for CallablePolicies {
    fn policy(
        &mut self,
        run: &LoadedRun,
        _checkpoint: &Path,
        spec: &EnvSpec,
    ) -> a2perf_pipeline::Result<Box<dyn Policy>> {
        Python::attach(|py| self.for_spec(py, spec))
            .map(|p| Box::new(p) as Box<dyn Policy>)
            .map_err(|e| {
                keep(&self.errors, PolicyFailure::Raised(e));
                PipelineError::Invalid(format!("{}: the policy cannot be used", run.dir.display()))
            })
    }

    fn errors_are_fatal(&self) -> bool {
        true
    }
}

/// Checkpoints of external runs through a Python loader `path -> (policy, with_info)`; those of
/// built-in runs through the registry (`a2perf_rs.collect`).
pub struct LoaderPolicies<'r> {
    loader: Py<PyAny>,
    registry: &'r a2perf_core::Registry,
    /// Failures of the loader and its policies.
    pub errors: ErrorSlot,
}

impl<'r> LoaderPolicies<'r> {
    /// `loader(path)` must return `(callable, with_info)`.
    pub fn new(loader: Py<PyAny>, registry: &'r a2perf_core::Registry) -> Self {
        Self {
            loader,
            registry,
            errors: ErrorSlot::default(),
        }
    }
}

impl PolicySource for LoaderPolicies<'_> {
    fn policy(
        &mut self,
        run: &LoadedRun,
        checkpoint: &Path,
        spec: &EnvSpec,
    ) -> a2perf_pipeline::Result<Box<dyn Policy>> {
        if run.record.external.is_none() {
            return RegistryPolicies(self.registry).policy(run, checkpoint, spec);
        }
        let loaded = Python::attach(|py| -> PyResult<PyPolicy> {
            let pair = self
                .loader
                .bind(py)
                .call1((checkpoint.to_string_lossy().into_owned(),))?;
            let pair = pair.cast::<PyTuple>()?;
            let callable: Py<PyAny> = pair.get_item(0)?.unbind();
            let with_info: bool = pair.get_item(1)?.extract()?;
            let calls = Calls::Callable {
                callable,
                with_info,
            };
            PyPolicy::new(py, calls, spec, self.errors.clone())
        });
        loaded.map(|p| Box::new(p) as Box<dyn Policy>).map_err(|e| {
            keep(&self.errors, PolicyFailure::Raised(e));
            PipelineError::Invalid(format!("{}: load_policy failed", checkpoint.display()))
        })
    }

    fn errors_are_fatal(&self) -> bool {
        true
    }
}

/// `failure` again, as the same exception type with `prefix` in front of its message (and the
/// original as `__cause__` when it was raised by the user's code). `in_rollout`: the failure
/// happened in a policy call (rather than in loading a policy).
fn relocated(py: Python<'_>, prefix: &str, failure: PolicyFailure, in_rollout: bool) -> PyErr {
    let (err, raised) = match failure {
        PolicyFailure::Raised(e) => (e, true),
        PolicyFailure::BadAction(e) => (e, false),
    };
    let ty = err.get_type(py);
    let type_name = ty.name().map(|n| n.to_string()).unwrap_or_default();
    let text = match (raised, in_rollout) {
        (true, true) => format!("{prefix}the policy raised {type_name}: {}", err.value(py)),
        (true, false) => format!("{prefix}{type_name}: {}", err.value(py)),
        (false, _) => format!(
            "{prefix}the policy returned an invalid action: {}",
            err.value(py)
        ),
    };
    // The same type when it can be built from a message (every built-in exception can).
    let new = ty
        .call1((text.clone(),))
        .ok()
        .filter(|v| v.is_instance_of::<pyo3::exceptions::PyBaseException>())
        .map(PyErr::from_value)
        .unwrap_or_else(|| PyRuntimeError::new_err(text));
    if raised {
        new.set_cause(py, Some(err));
    }
    new
}

/// A pipeline error as a Python exception: a policy's own failure (kept in `errors`) comes back
/// as its exception type, named by run, episode and step; the rest map by kind (`ValueError`
/// for bad requests and files, `FileNotFoundError`/`OSError` for i/o, `TypeError` for
/// parameters, `RuntimeError` for failed rollouts, `RunLockedError` for a run directory another
/// trainer holds).
pub fn pipeline_error(e: PipelineError, errors: Option<&ErrorSlot>) -> PyErr {
    let failure = errors.and_then(|s| s.lock().ok().and_then(|mut f| f.take()));
    Python::attach(|py| {
        if let Some(failure) = failure {
            let (prefix, in_rollout) = match &e {
                PipelineError::Rollout {
                    run, episode, step, ..
                } => (
                    format!("{run}: episode {episode}, step {step} (counted from 0): "),
                    true,
                ),
                PipelineError::Run { run, .. } => (format!("{run}: "), true),
                other => (format!("{other}: "), false),
            };
            return relocated(py, &prefix, failure, in_rollout);
        }
        let msg = e.to_string();
        match e {
            PipelineError::Io { source, .. } if source.kind() == std::io::ErrorKind::NotFound => {
                PyFileNotFoundError::new_err(msg)
            }
            PipelineError::Io { .. } => PyOSError::new_err(msg),
            PipelineError::Registry(r) => registry_error(r, |_| None),
            PipelineError::Rollout {
                source: RunError::Env(EnvError::InvalidAction { .. }),
                ..
            } => PyValueError::new_err(msg),
            PipelineError::Rollout { .. } | PipelineError::Run { .. } => {
                PyRuntimeError::new_err(msg)
            }
            PipelineError::Cancelled => PyKeyboardInterrupt::new_err(msg),
            PipelineError::Locked(_) => crate::errors::RunLockedError::new_err(msg),
            PipelineError::Corrupt { .. } | PipelineError::Invalid(_) => PyValueError::new_err(msg),
        }
    })
}
