//! Observations as numpy sees them: the layout of an observation space in arrays of each box's
//! element type, rows of the batched arrays of vector environments, and the buffers handed to
//! numpy without a copy (and recycled once Python lets them go).

use a2perf_core::{DType, Observation, Space, TensorData};
use numpy::{PyArrayDyn, PyArrayMethods, PyReadwriteArrayDyn, npyffi};
use pyo3::exceptions::PyRuntimeError;
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyString};

/// A numpy array of one observation tensor's element type.
pub enum ObsArray<'py> {
    /// `float32`.
    F32(Bound<'py, PyArrayDyn<f32>>),
    /// `int32`.
    I32(Bound<'py, PyArrayDyn<i32>>),
    /// `int64`.
    I64(Bound<'py, PyArrayDyn<i64>>),
    /// `uint8`.
    U8(Bound<'py, PyArrayDyn<u8>>),
}

/// Write access to an [`ObsArray`].
pub enum ObsArrayRw<'py> {
    /// `float32`.
    F32(PyReadwriteArrayDyn<'py, f32>),
    /// `int32`.
    I32(PyReadwriteArrayDyn<'py, i32>),
    /// `int64`.
    I64(PyReadwriteArrayDyn<'py, i64>),
    /// `uint8`.
    U8(PyReadwriteArrayDyn<'py, u8>),
}

/// Consecutive rows (one per environment) of an [`ObsArrayRw`].
pub enum ObsRows<'a> {
    /// `float32`.
    F32(std::slice::ChunksMut<'a, f32>),
    /// `int32`.
    I32(std::slice::ChunksMut<'a, i32>),
    /// `int64`.
    I64(std::slice::ChunksMut<'a, i64>),
    /// `uint8`.
    U8(std::slice::ChunksMut<'a, u8>),
}

/// One environment's row of an observation buffer.
pub enum ObsRow<'a> {
    /// `float32`.
    F32(&'a mut [f32]),
    /// `int32`.
    I32(&'a mut [i32]),
    /// `int64`.
    I64(&'a mut [i64]),
    /// `uint8`.
    U8(&'a mut [u8]),
}

impl<'py> ObsArray<'py> {
    /// Zeros of `dims` in `dtype`.
    pub fn zeros(py: Python<'py>, dims: Vec<usize>, dtype: DType) -> Self {
        match dtype {
            DType::F32 => Self::F32(PyArrayDyn::zeros(py, dims, false)),
            DType::I32 => Self::I32(PyArrayDyn::zeros(py, dims, false)),
            DType::I64 => Self::I64(PyArrayDyn::zeros(py, dims, false)),
            DType::U8 => Self::U8(PyArrayDyn::zeros(py, dims, false)),
        }
    }

    /// The array as a Python object.
    pub fn into_any(self) -> Bound<'py, PyAny> {
        match self {
            Self::F32(a) => a.into_any(),
            Self::I32(a) => a.into_any(),
            Self::I64(a) => a.into_any(),
            Self::U8(a) => a.into_any(),
        }
    }

    /// The array as an owned reference (to keep between calls).
    pub fn unbind(self) -> Py<PyAny> {
        self.into_any().unbind()
    }

    /// An array kept by [`unbind`](Self::unbind), as the `dtype` it was made with.
    pub fn bind(py: Python<'py>, array: &Py<PyAny>, dtype: DType) -> PyResult<Self> {
        let a = array.bind(py);
        Ok(match dtype {
            DType::F32 => Self::F32(a.cast::<PyArrayDyn<f32>>()?.clone()),
            DType::I32 => Self::I32(a.cast::<PyArrayDyn<i32>>()?.clone()),
            DType::I64 => Self::I64(a.cast::<PyArrayDyn<i64>>()?.clone()),
            DType::U8 => Self::U8(a.cast::<PyArrayDyn<u8>>()?.clone()),
        })
    }

    /// Write access (fails if the array is borrowed elsewhere).
    pub fn readwrite(&self) -> ObsArrayRw<'py> {
        match self {
            Self::F32(a) => ObsArrayRw::F32(a.readwrite()),
            Self::I32(a) => ObsArrayRw::I32(a.readwrite()),
            Self::I64(a) => ObsArrayRw::I64(a.readwrite()),
            Self::U8(a) => ObsArrayRw::U8(a.readwrite()),
        }
    }
}

impl ObsArrayRw<'_> {
    /// The rows of `dim` elements (at least 1, so that an empty tensor still yields rows).
    pub fn rows(&mut self, dim: usize) -> PyResult<ObsRows<'_>> {
        let d = dim.max(1);
        let slices = |e: numpy::AsSliceError| PyRuntimeError::new_err(e.to_string());
        Ok(match self {
            Self::F32(rw) => ObsRows::F32(rw.as_slice_mut().map_err(slices)?.chunks_mut(d)),
            Self::I32(rw) => ObsRows::I32(rw.as_slice_mut().map_err(slices)?.chunks_mut(d)),
            Self::I64(rw) => ObsRows::I64(rw.as_slice_mut().map_err(slices)?.chunks_mut(d)),
            Self::U8(rw) => ObsRows::U8(rw.as_slice_mut().map_err(slices)?.chunks_mut(d)),
        })
    }
}

impl<'a> Iterator for ObsRows<'a> {
    type Item = ObsRow<'a>;

    fn next(&mut self) -> Option<ObsRow<'a>> {
        match self {
            Self::F32(c) => c.next().map(ObsRow::F32),
            Self::I32(c) => c.next().map(ObsRow::I32),
            Self::I64(c) => c.next().map(ObsRow::I64),
            Self::U8(c) => c.next().map(ObsRow::U8),
        }
    }
}

impl ObsRow<'_> {
    /// Copies `data` (same element type and length, checked by [`ObsLayout::check`]) into the
    /// row.
    pub fn copy_from(&mut self, data: &TensorData) -> PyResult<()> {
        match (self, data) {
            (Self::F32(d), TensorData::F32(s)) if d.len() == s.len() => d.copy_from_slice(s),
            (Self::I32(d), TensorData::I32(s)) if d.len() == s.len() => d.copy_from_slice(s),
            (Self::I64(d), TensorData::I64(s)) if d.len() == s.len() => d.copy_from_slice(s),
            (Self::U8(d), TensorData::U8(s)) if d.len() == s.len() => d.copy_from_slice(s),
            _ => {
                return Err(PyRuntimeError::new_err(
                    "internal error: an observation tensor does not fit its buffer row",
                ));
            }
        }
        Ok(())
    }
}

/// A fresh numpy array of `shape` holding a copy of `data`, in the data's element type.
fn array_of<'py>(
    py: Python<'py>,
    shape: &[usize],
    data: &TensorData,
) -> PyResult<Bound<'py, PyAny>> {
    fn make<'py, T: numpy::Element + Copy>(
        py: Python<'py>,
        shape: &[usize],
        src: &[T],
    ) -> PyResult<Bound<'py, PyAny>> {
        // SAFETY: the array is created here with the tensor's size and filled completely
        // before anything else can see it.
        let arr = unsafe { PyArrayDyn::<T>::new(py, shape, false) };
        // SAFETY: fresh, contiguous and not shared (see above).
        let dst =
            unsafe { arr.as_slice_mut() }.map_err(|e| PyRuntimeError::new_err(e.to_string()))?;
        dst.copy_from_slice(src);
        Ok(arr.into_any())
    }
    match data {
        TensorData::F32(v) => make(py, shape, v),
        TensorData::I32(v) => make(py, shape, v),
        TensorData::I64(v) => make(py, shape, v),
        TensorData::U8(v) => make(py, shape, v),
    }
}

/// How an observation maps onto Python: one array (box space) or a dict of arrays, each of its
/// box's element type (`int32` ids, `float32` features).
pub struct ObsLayout {
    /// Dict keys (interned) or `None` for a box observation.
    pub keys: Option<Vec<Py<PyString>>>,
    /// Shape of each tensor, in the space's order.
    pub shapes: Vec<Vec<usize>>,
    /// Number of values of each tensor.
    pub dims: Vec<usize>,
    /// Element type of each tensor.
    pub dtypes: Vec<DType>,
    /// Each shape in numpy's integer type.
    pub npy_dims: Vec<Vec<npyffi::npy_intp>>,
}

impl ObsLayout {
    /// The layout of `space`.
    pub fn of(py: Python<'_>, space: &Space) -> PyResult<Self> {
        let box_of = |s: &Space| match s {
            Space::Box { shape, dtype, .. } => Ok((shape.clone(), *dtype)),
            other => Err(PyRuntimeError::new_err(format!(
                "observation space element {other:?} is not a box"
            ))),
        };
        let (keys, boxes): (_, Vec<(Vec<usize>, DType)>) = match space {
            Space::Dict(items) => {
                let keys = items
                    .iter()
                    .map(|(k, _)| PyString::intern(py, k).unbind())
                    .collect();
                let boxes = items
                    .iter()
                    .map(|(_, s)| box_of(s))
                    .collect::<PyResult<_>>()?;
                (Some(keys), boxes)
            }
            other => (None, vec![box_of(other)?]),
        };
        let (shapes, dtypes): (Vec<Vec<usize>>, Vec<DType>) = boxes.into_iter().unzip();
        let dims = shapes
            .iter()
            .map(|s: &Vec<usize>| s.iter().product())
            .collect();
        let npy_dims = shapes
            .iter()
            .map(|s: &Vec<usize>| {
                s.iter()
                    .map(|&d| npyffi::npy_intp::try_from(d))
                    .collect::<Result<Vec<_>, _>>()
            })
            .collect::<Result<_, _>>()
            .map_err(|_| PyRuntimeError::new_err("observation dimension too large for numpy"))?;
        Ok(Self {
            keys,
            shapes,
            dims,
            dtypes,
            npy_dims,
        })
    }

    /// Checks that the environment wrote every tensor at its declared size and element type.
    pub fn check(&self, obs: &Observation) -> PyResult<()> {
        if obs.tensors.len() != self.dims.len()
            || obs
                .tensors
                .iter()
                .zip(self.dims.iter().zip(&self.dtypes))
                .any(|(t, (d, ty))| t.data.len() != *d || t.dtype() != *ty)
        {
            return Err(PyRuntimeError::new_err(format!(
                "the environment returned an observation of {} tensors with sizes and types \
                 {:?}, its space declares {:?}",
                obs.tensors.len(),
                obs.tensors
                    .iter()
                    .map(|t| (t.data.len(), t.dtype().name()))
                    .collect::<Vec<_>>(),
                self.dims
                    .iter()
                    .zip(&self.dtypes)
                    .map(|(d, t)| (*d, t.name()))
                    .collect::<Vec<_>>()
            )));
        }
        Ok(())
    }

    /// A new Python observation (fresh arrays of the tensors' element types).
    pub fn to_py<'py>(&self, py: Python<'py>, obs: &Observation) -> PyResult<Bound<'py, PyAny>> {
        self.check(obs)?;
        let array = |i: usize| array_of(py, &self.shapes[i], &obs.tensors[i].data);
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

    /// Zeroed buffers of shape `(n, *shape)` for `n` environments, in the tensors' types.
    pub fn buffers<'py>(&self, py: Python<'py>, n: usize) -> Vec<ObsArray<'py>> {
        self.shapes
            .iter()
            .zip(&self.dtypes)
            .map(|(s, t)| {
                let mut dims = vec![n];
                dims.extend_from_slice(s);
                ObsArray::zeros(py, dims, *t)
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

/// Owns the memory of one observation array handed to Python without a copy: the array's numpy
/// `base`. Not constructible from Python.
#[pyclass(module = "a2perf_rs._native", name = "ObservationBuffer")]
pub struct ObsBuffer {
    data: TensorData,
}

/// A C-contiguous, writeable array of shape `dims` and element type `T` over `data`, kept alive
/// by `owner` (its numpy `base`): what `PyArray::borrow_from_array` does, without building an
/// ndarray view and its strides first (a measurable share of a web step from Python).
///
/// # Safety
/// `data` points to the product of `dims` values of type `T`, owned by `owner` and neither freed
/// nor moved while `owner` is referenced by anything else than its creator.
unsafe fn array_over<'py, T: numpy::Element>(
    py: Python<'py>,
    dims: &[npyffi::npy_intp],
    data: *const T,
    owner: Bound<'py, PyAny>,
) -> PyResult<Bound<'py, PyAny>> {
    use numpy::PyArrayDescrMethods;
    let nd = std::ffi::c_int::try_from(dims.len())
        .map_err(|_| PyRuntimeError::new_err("too many dimensions"))?;
    // SAFETY: numpy's C API as `PyArray::borrow_from_array` uses it, with NULL strides (C order)
    // and the dims and data of the caller's contract.
    let array = unsafe {
        npyffi::PY_ARRAY_API.PyArray_NewFromDescr(
            py,
            npyffi::get_type_object(py, npyffi::NpyTypes::PyArray_Type),
            T::get_dtype(py).into_dtype_ptr(),
            nd,
            dims.as_ptr().cast_mut(),
            std::ptr::null_mut(),
            data.cast_mut().cast(),
            npyffi::NPY_ARRAY_WRITEABLE,
            std::ptr::null_mut(),
        )
    };
    if array.is_null() {
        return Err(PyErr::fetch(py));
    }
    // SAFETY: `array` is a new reference we own; `PyArray_SetBaseObject` steals the reference to
    // `owner` whatever it returns.
    unsafe {
        let array = Bound::from_owned_ptr(py, array);
        if npyffi::PY_ARRAY_API.PyArray_SetBaseObject(py, array.as_ptr().cast(), owner.into_ptr())
            < 0
        {
            return Err(PyErr::fetch(py));
        }
        Ok(array)
    }
}

/// Hands an environment's observation buffers to numpy without copying them, and recycles the
/// buffers of observations Python has released.
///
/// After a step, each tensor's buffer (of its element type) moves into an [`ObsBuffer`] that becomes the `base` of the
/// returned numpy array (no copy). Before the next step the environment needs buffers again: a
/// set whose every `ObsBuffer` is referenced by this recycler alone (reference count 1: no array,
/// view or memoryview can reach it) is lent back, still holding an older observation. That is
/// sound because every environment overwrites its whole observation (the contract of
/// [`a2perf_core::Env::reset_into`], tested for every built-in id); when no set is free (Python
/// keeps its observations), fresh zeroed buffers are allocated. At most [`ObsRecycler::SETS`] sets
/// are tracked; older ones are forgotten and live as long as Python keeps them.
#[derive(Default)]
pub struct ObsRecycler {
    /// Sets handed to Python, oldest first.
    sets: Vec<Vec<Py<ObsBuffer>>>,
    /// The emptied `ObsBuffer`s of the set lent for the current call (refilled by `hand_out`).
    spare: Option<Vec<Py<ObsBuffer>>>,
}

impl ObsRecycler {
    /// How many handed-out sets are tracked for reuse.
    pub const SETS: usize = 4;

    /// Gives `obs` buffers of the sizes `layout` declares, taken from a set Python has released
    /// when there is one. An observation whose tensors already hold their data (or that the
    /// environment has not built yet) is left alone.
    pub fn lend(&mut self, py: Python<'_>, layout: &ObsLayout, obs: &mut Observation) {
        let holds =
            |t: &a2perf_core::Tensor, d: usize, ty: DType| t.data.len() == d && t.dtype() == ty;
        if obs.tensors.len() != layout.dims.len()
            || obs
                .tensors
                .iter()
                .zip(layout.dims.iter().zip(&layout.dtypes))
                .all(|(t, (d, ty))| holds(t, *d, *ty))
        {
            return;
        }
        // SAFETY: reading the reference count of a live object while attached to the
        // interpreter (`py`).
        let only_here = |b: &Py<ObsBuffer>| unsafe { pyo3::ffi::Py_REFCNT(b.as_ptr()) } == 1;
        let free = self.sets.iter().position(|set| set.iter().all(only_here));
        match free {
            Some(i) => {
                let set = self.sets.remove(i);
                for (t, b) in obs.tensors.iter_mut().zip(&set) {
                    t.data = std::mem::take(&mut b.bind(py).borrow_mut().data);
                }
                self.spare = Some(set);
            }
            None => {
                for (t, (d, ty)) in obs
                    .tensors
                    .iter_mut()
                    .zip(layout.dims.iter().zip(&layout.dtypes))
                {
                    if !holds(t, *d, *ty) {
                        t.data = TensorData::zeros(*ty, *d);
                    }
                }
            }
        }
    }

    /// The Python observation over `obs`'s buffers, which move out of `obs` (no copy).
    pub fn hand_out<'py>(
        &mut self,
        py: Python<'py>,
        layout: &ObsLayout,
        obs: &mut Observation,
    ) -> PyResult<Bound<'py, PyAny>> {
        layout.check(obs)?;
        let set = match self.spare.take() {
            Some(set) => set,
            None => (0..layout.dims.len())
                .map(|_| {
                    Py::new(
                        py,
                        ObsBuffer {
                            data: TensorData::default(),
                        },
                    )
                })
                .collect::<PyResult<_>>()?,
        };
        let mut arrays = Vec::with_capacity(set.len());
        for ((t, b), dims) in obs.tensors.iter_mut().zip(&set).zip(&layout.npy_dims) {
            let owner = b.bind(py);
            let mut buf = owner.borrow_mut();
            buf.data = std::mem::take(&mut t.data);
            let base = owner.clone().into_any();
            // SAFETY: `check` above: the buffer holds the product of `dims` values of its type.
            // `owner` owns the memory and becomes the array's base; the `Vec` is neither moved
            // out nor reallocated while any object other than this recycler references `owner`
            // (`lend` takes it back only at reference count 1).
            let array = unsafe {
                match &buf.data {
                    TensorData::F32(v) => array_over(py, dims, v.as_ptr(), base)?,
                    TensorData::I32(v) => array_over(py, dims, v.as_ptr(), base)?,
                    TensorData::I64(v) => array_over(py, dims, v.as_ptr(), base)?,
                    TensorData::U8(v) => array_over(py, dims, v.as_ptr(), base)?,
                }
            };
            drop(buf);
            arrays.push(array);
        }
        self.sets.push(set);
        if self.sets.len() > Self::SETS {
            self.sets.remove(0);
        }
        layout.wrap(py, arrays)
    }
}

/// A copy of an observation: a dict of arrays or one array.
pub(crate) fn copy_obs<'py>(obs: &Bound<'py, PyAny>) -> PyResult<Bound<'py, PyAny>> {
    let py = obs.py();
    let copy = pyo3::intern!(py, "copy");
    match obs.cast::<PyDict>() {
        Ok(d) => {
            let out = PyDict::new(py);
            for (k, v) in d.iter() {
                out.set_item(k, v.call_method0(copy)?)?;
            }
            Ok(out.into_any())
        }
        Err(_) => obs.call_method0(copy),
    }
}
