//! Rust errors as Python exceptions that name the problem, and a guard that keeps Rust panics
//! from crossing into Python.

use std::panic::{AssertUnwindSafe, catch_unwind};
use std::path::Path;

use a2perf_core::{EnvError, ParamError, ParamKind, RegistryError};
use pyo3::exceptions::{PyFileNotFoundError, PyRuntimeError, PyTypeError, PyValueError};
use pyo3::{PyErr, create_exception};

create_exception!(
    _native,
    BackendError,
    PyRuntimeError,
    "An environment's backend (e.g. the Chromium browser) failed."
);

create_exception!(
    _native,
    RunLockedError,
    PyRuntimeError,
    "Another trainer (a process whose pid and host the message names) holds the run directory's \
     training lock: the run was left alone."
);

/// `EnvError` → `ValueError` for actions and parameters, `FileNotFoundError`/`ValueError` for
/// files, `BackendError` for a failed backend, `RuntimeError` for a call out of order.
pub fn env_error(e: EnvError) -> PyErr {
    let msg = e.to_string();
    match e {
        EnvError::InvalidAction { .. } | EnvError::InvalidParameter { .. } => {
            PyValueError::new_err(msg)
        }
        EnvError::BadFile { path, .. } => file_error(&path, msg),
        EnvError::Backend(_) => BackendError::new_err(msg),
        EnvError::NeedsReset => PyRuntimeError::new_err(format!(
            "{msg}: call reset() before step() and after an episode ends"
        )),
    }
}

/// A missing file is a `FileNotFoundError`; a file that exists but cannot be used a `ValueError`.
pub fn file_error(path: &str, msg: String) -> PyErr {
    if Path::new(path).exists() {
        PyValueError::new_err(msg)
    } else {
        PyFileNotFoundError::new_err(msg)
    }
}

/// Unknown, missing or mistyped parameters are `TypeError`s (as for a Python call); a value of the
/// right type that is not allowed (a choice not in its set) is a `ValueError`.
pub fn registry_error(e: RegistryError, kind_of: impl Fn(&str) -> Option<ParamKind>) -> PyErr {
    let msg = e.to_string();
    match e {
        RegistryError::UnknownEnv { .. } | RegistryError::UnknownAlgorithm { .. } => {
            PyValueError::new_err(msg)
        }
        RegistryError::Param { source, .. } => match source {
            ParamError::WrongType { key, .. }
                if matches!(kind_of(&key), Some(ParamKind::Choice(_))) =>
            {
                PyValueError::new_err(msg)
            }
            _ => PyTypeError::new_err(msg),
        },
        RegistryError::Env { id, source } => {
            let inner = env_error(source);
            // Keep the exception type, prefix the environment id.
            pyo3::Python::attach(|py| {
                let text = inner.value(py).to_string();
                let ty = inner.get_type(py);
                PyErr::from_type(ty, format!("{id}: {text}"))
            })
        }
        RegistryError::Algorithm { .. } => PyValueError::new_err(msg),
    }
}

/// Runs `f`, turning a Rust panic (a bug, never expected on any input) into a `RuntimeError` so
/// that it never reaches Python as a `PanicException`.
pub fn guard<T>(what: &str, f: impl FnOnce() -> Result<T, PyErr>) -> Result<T, PyErr> {
    match catch_unwind(AssertUnwindSafe(f)) {
        Ok(r) => r,
        Err(payload) => {
            let detail = payload
                .downcast_ref::<&str>()
                .map(|s| s.to_string())
                .or_else(|| payload.downcast_ref::<String>().cloned())
                .unwrap_or_else(|| "unknown panic".into());
            Err(PyRuntimeError::new_err(format!(
                "internal error in {what} (please report it): {detail}"
            )))
        }
    }
}
