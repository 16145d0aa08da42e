//! Conversions between Python objects and the benchmark's values, spaces and actions.

use std::collections::BTreeMap;

use a2perf_core::{Action, ParamKind, ParamSpec, Space, Value};
use numpy::{PyArray1, PyArrayDyn, PyArrayMethods, PyUntypedArrayMethods};
use pyo3::exceptions::{PyTypeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyBool, PyDict, PyFloat, PyInt, PyList, PyString, PyTuple};

/// A Python keyword argument as a configuration value. `bool` is tested before `int` (Python's
/// `bool` is an `int`); numpy scalars and `os.PathLike` paths are accepted.
pub fn to_value(name: &str, obj: &Bound<'_, PyAny>) -> PyResult<Value> {
    if obj.is_none() {
        return Ok(Value::Null);
    }
    if obj.is_instance_of::<PyBool>() {
        return Ok(Value::Bool(obj.extract()?));
    }
    if obj.is_instance_of::<PyInt>() {
        return obj.extract::<i64>().map(Value::Int).map_err(|_| {
            PyValueError::new_err(format!("parameter `{name}`: integer {obj} is out of range"))
        });
    }
    if obj.is_instance_of::<PyFloat>() {
        return Ok(Value::Float(obj.extract()?));
    }
    if obj.is_instance_of::<PyString>() {
        return Ok(Value::Str(obj.extract()?));
    }
    if let Ok(list) = obj.cast::<PyList>() {
        return list
            .iter()
            .map(|x| to_value(name, &x))
            .collect::<PyResult<_>>()
            .map(Value::List);
    }
    if let Ok(tuple) = obj.cast::<PyTuple>() {
        return tuple
            .iter()
            .map(|x| to_value(name, &x))
            .collect::<PyResult<_>>()
            .map(Value::List);
    }
    if let Ok(dict) = obj.cast::<PyDict>() {
        let mut map = BTreeMap::new();
        for (k, v) in dict.iter() {
            let key: String = k.extract().map_err(|_| {
                PyTypeError::new_err(format!("parameter `{name}`: map keys must be strings"))
            })?;
            map.insert(key, to_value(name, &v)?);
        }
        return Ok(Value::Map(map));
    }
    let py = obj.py();
    // `os.PathLike` (pathlib.Path): its file-system path.
    if obj.hasattr(pyo3::intern!(py, "__fspath__"))? {
        let path = obj.call_method0(pyo3::intern!(py, "__fspath__"))?;
        return to_value(name, &path);
    }
    // numpy scalars (np.int64, np.float32, np.bool_, np.str_): their Python value.
    if obj.hasattr(pyo3::intern!(py, "dtype"))? && obj.hasattr(pyo3::intern!(py, "item"))? {
        let ndim: usize = obj
            .getattr(pyo3::intern!(py, "ndim"))
            .and_then(|n| n.extract())
            .unwrap_or(1);
        if ndim == 0 {
            return to_value(name, &obj.call_method0(pyo3::intern!(py, "item"))?);
        }
        return to_value(name, &obj.call_method0(pyo3::intern!(py, "tolist"))?);
    }
    Err(PyTypeError::new_err(format!(
        "parameter `{name}`: unsupported type {}",
        obj.get_type().name()?
    )))
}

/// The Python type name of `obj`, for error messages (empty if it has none).
pub fn type_name_of(obj: &Bound<'_, PyAny>) -> String {
    obj.get_type()
        .name()
        .map(|n| n.to_string())
        .unwrap_or_default()
}

/// A configuration value as a Python object.
pub fn from_value<'py>(py: Python<'py>, v: &Value) -> PyResult<Bound<'py, PyAny>> {
    Ok(match v {
        Value::Null => py.None().into_bound(py),
        Value::Bool(b) => PyBool::new(py, *b).to_owned().into_any(),
        Value::Int(i) => i.into_pyobject(py)?.into_any(),
        Value::Float(f) => f.into_pyobject(py)?.into_any(),
        Value::Str(s) => PyString::new(py, s).into_any(),
        Value::List(items) => {
            let out = PyList::empty(py);
            for x in items {
                out.append(from_value(py, x)?)?;
            }
            out.into_any()
        }
        Value::Map(m) => {
            let out = PyDict::new(py);
            for (k, x) in m {
                out.set_item(k, from_value(py, x)?)?;
            }
            out.into_any()
        }
    })
}

/// `(name, kind, choices, default, doc)` of a parameter, for Python signatures and docs.
pub fn param_to_py<'py>(py: Python<'py>, p: &ParamSpec) -> PyResult<Bound<'py, PyTuple>> {
    let (kind, choices): (&str, Vec<&str>) = match &p.kind {
        ParamKind::Bool => ("bool", vec![]),
        ParamKind::Int => ("int", vec![]),
        ParamKind::Float => ("float", vec![]),
        ParamKind::Str => ("str", vec![]),
        ParamKind::Path => ("path", vec![]),
        ParamKind::Choice(c) => ("choice", c.to_vec()),
        ParamKind::FloatList => ("list[float]", vec![]),
        ParamKind::IntList => ("list[int]", vec![]),
    };
    PyTuple::new(
        py,
        [
            PyString::new(py, p.name).into_any(),
            PyString::new(py, kind).into_any(),
            PyList::new(py, choices)?.into_any(),
            from_value(py, &p.default)?,
            PyString::new(py, p.doc).into_any(),
        ],
    )
}

/// A space as nested tuples that `a2perf_rs.spaces` turns into `gymnasium.spaces`:
/// `("discrete", n)`, `("box", low, high, dtype)` (bounds as float64 arrays of the space's
/// shape, exact for every element type; `dtype` the numpy name, e.g. `"int32"`) or
/// `("dict", [(name, space), …])`.
pub fn space_to_py<'py>(py: Python<'py>, s: &Space) -> PyResult<Bound<'py, PyTuple>> {
    match s {
        Space::Discrete { n } => PyTuple::new(
            py,
            [
                PyString::new(py, "discrete").into_any(),
                n.into_pyobject(py)?.into_any(),
            ],
        ),
        Space::Box {
            low,
            high,
            shape,
            dtype,
        } => {
            let lo = PyArray1::from_slice(py, low).reshape(shape.clone())?;
            let hi = PyArray1::from_slice(py, high).reshape(shape.clone())?;
            PyTuple::new(
                py,
                [
                    PyString::new(py, "box").into_any(),
                    lo.into_any(),
                    hi.into_any(),
                    PyString::new(py, dtype.name()).into_any(),
                ],
            )
        }
        Space::Dict(items) => {
            let list = PyList::empty(py);
            for (name, sub) in items {
                list.append(PyTuple::new(
                    py,
                    [
                        PyString::new(py, name).into_any(),
                        space_to_py(py, sub)?.into_any(),
                    ],
                )?)?;
            }
            PyTuple::new(py, [PyString::new(py, "dict").into_any(), list.into_any()])
        }
    }
}

/// The action space of an environment, with what is needed to check actions quickly.
#[derive(Clone, Debug)]
pub enum ActionSpec {
    /// `Discrete(n)`.
    Discrete(usize),
    /// A float32 box.
    Box {
        /// Lower bounds.
        low: Vec<f32>,
        /// Upper bounds.
        high: Vec<f32>,
        /// Shape.
        shape: Vec<usize>,
    },
}

impl ActionSpec {
    /// The spec of a benchmark action space (dict action spaces do not occur).
    pub fn of(space: &Space) -> PyResult<Self> {
        match space {
            Space::Discrete { n } => Ok(Self::Discrete(*n)),
            // Actions are float32 (Action::Continuous); the bounds as the float32 they are.
            Space::Box {
                low, high, shape, ..
            } => Ok(Self::Box {
                low: low.iter().map(|x| *x as f32).collect(),
                high: high.iter().map(|x| *x as f32).collect(),
                shape: shape.clone(),
            }),
            Space::Dict(_) => Err(PyTypeError::new_err(
                "dict action spaces are not supported by the Python bindings",
            )),
        }
    }

    /// Checks a discrete action value.
    pub fn check_discrete(&self, a: i64) -> PyResult<usize> {
        let n = match self {
            Self::Discrete(n) => *n,
            Self::Box { .. } => return Err(PyTypeError::new_err("expected a box action")),
        };
        usize::try_from(a)
            .ok()
            .filter(|a| *a < n)
            .ok_or_else(|| PyValueError::new_err(format!("action {a} is outside Discrete({n})")))
    }

    /// Checks a continuous action (already float32) against shape and bounds; writes it into
    /// `out` (reusing its buffer).
    pub fn check_box(&self, values: &[f32], shape: &[usize], out: &mut Vec<f32>) -> PyResult<()> {
        let Self::Box {
            low,
            high,
            shape: want,
        } = self
        else {
            return Err(PyTypeError::new_err("expected a discrete action"));
        };
        if shape != want.as_slice() {
            return Err(PyValueError::new_err(format!(
                "action has shape {shape:?}, expected {want:?}"
            )));
        }
        for (i, ((v, l), h)) in values.iter().zip(low).zip(high).enumerate() {
            if !v.is_finite() {
                return Err(PyValueError::new_err(format!(
                    "action element {i} is {v}; actions must be finite"
                )));
            }
            if v < l || v > h {
                return Err(PyValueError::new_err(format!(
                    "action element {i} = {v} is outside the action space [{l}, {h}]"
                )));
            }
        }
        out.clear();
        out.extend_from_slice(values);
        Ok(())
    }

    /// Parses one action given from Python into `out` (reusing its buffer for box actions).
    ///
    /// Discrete: a Python or numpy integer (or 0-d integer array); `bool` and floats are refused.
    /// Box: any real array-like of the space's shape, converted to float32, finite, within bounds.
    pub fn parse(&self, obj: &Bound<'_, PyAny>, out: &mut Action) -> PyResult<()> {
        match self {
            Self::Discrete(_) => {
                if obj.is_instance_of::<PyBool>() {
                    return Err(PyTypeError::new_err("action must be an integer, not bool"));
                }
                if obj.is_instance_of::<PyFloat>() {
                    return Err(PyTypeError::new_err(format!(
                        "action must be an integer, not float {obj}"
                    )));
                }
                let a: i64 = obj.extract().map_err(|_| {
                    let ty = type_name_of(obj);
                    let shape = obj
                        .getattr("shape")
                        .map(|s| format!(" of shape {s}"))
                        .unwrap_or_default();
                    PyTypeError::new_err(format!("action must be one integer, got {ty}{shape}"))
                })?;
                *out = Action::Discrete(self.check_discrete(a)?);
                Ok(())
            }
            Self::Box { .. } => {
                let buf = match out {
                    Action::Continuous(v) => v,
                    other => {
                        *other = Action::Continuous(Vec::new());
                        let Action::Continuous(v) = other else {
                            unreachable!()
                        };
                        v
                    }
                };
                if let Ok(arr) = obj.cast::<PyArrayDyn<f32>>() {
                    let ro = arr.readonly();
                    let shape = ro.shape().to_vec();
                    return match ro.as_slice() {
                        Ok(s) => self.check_box(s, &shape, buf),
                        Err(_) => {
                            let v: Vec<f32> = ro.as_array().iter().copied().collect();
                            self.check_box(&v, &shape, buf)
                        }
                    };
                }
                let arr = as_float32_array(obj)?;
                let ro = arr.readonly();
                let shape = ro.shape().to_vec();
                let s = ro
                    .as_slice()
                    .map_err(|e| PyValueError::new_err(e.to_string()))?;
                self.check_box(s, &shape, buf)
            }
        }
    }
}

/// `numpy.ascontiguousarray(obj, dtype=float32)` for real numeric input; bool, complex, string
/// and object arrays are a `TypeError`.
pub fn as_float32_array<'py>(obj: &Bound<'py, PyAny>) -> PyResult<Bound<'py, PyArrayDyn<f32>>> {
    let py = obj.py();
    let np = py.import(pyo3::intern!(py, "numpy"))?;
    let arr = np
        .call_method1(pyo3::intern!(py, "asarray"), (obj,))
        .map_err(|e| PyTypeError::new_err(format!("action is not an array of numbers: {e}")))?;
    let kind: String = arr
        .getattr(pyo3::intern!(py, "dtype"))?
        .getattr(pyo3::intern!(py, "kind"))?
        .extract()?;
    if !matches!(kind.as_str(), "f" | "i" | "u") {
        let dtype = arr.getattr(pyo3::intern!(py, "dtype"))?;
        return Err(PyTypeError::new_err(format!(
            "action has dtype {dtype}; expected real numbers (float or integer)"
        )));
    }
    let out = np.call_method1(
        pyo3::intern!(py, "ascontiguousarray"),
        (arr, np.getattr(pyo3::intern!(py, "float32"))?),
    )?;
    Ok(out.cast_into::<PyArrayDyn<f32>>()?)
}
