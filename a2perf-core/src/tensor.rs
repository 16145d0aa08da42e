//! Typed observation tensors: the element type of a [`Space::Box`](crate::Space::Box) and the
//! buffer that holds a tensor's values in that type.
//!
//! Values that are integers (token ids, node indices, flags) are stored as integers, so they are
//! exact at any magnitude and a Python user's embedding lookup takes them as they come; real-valued
//! features are `f32`. Networks that consume floats convert with
//! [`TensorData::write_f32_into`] / [`TensorData::extend_f32`].

use serde::{Deserialize, Serialize};

/// Element type of a box space and of the tensors that live in it (numpy's names in
/// [`DType::name`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum DType {
    /// 32-bit float (`float32`): real-valued features.
    F32,
    /// 32-bit signed integer (`int32`): ids, indices and flags, as the original environments.
    I32,
    /// 64-bit signed integer (`int64`).
    I64,
    /// 8-bit unsigned integer (`uint8`): images, compact flags.
    U8,
}

impl DType {
    /// Every element type, in declaration order.
    pub const ALL: [DType; 4] = [DType::F32, DType::I32, DType::I64, DType::U8];

    /// The numpy name (`float32`, `int32`, `int64`, `uint8`), also used in dataset schemas.
    ///
    /// ```
    /// use a2perf_core::DType;
    /// assert_eq!(DType::I32.name(), "int32");
    /// assert_eq!(DType::from_name("uint8"), Some(DType::U8));
    /// ```
    pub fn name(self) -> &'static str {
        match self {
            DType::F32 => "float32",
            DType::I32 => "int32",
            DType::I64 => "int64",
            DType::U8 => "uint8",
        }
    }

    /// The element type called `name` (numpy spelling), if any.
    pub fn from_name(name: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|d| d.name() == name)
    }

    /// Whether values of this type are integers.
    pub fn is_integer(self) -> bool {
        !matches!(self, DType::F32)
    }

    /// Size of one element in bytes.
    pub fn size(self) -> usize {
        match self {
            DType::F32 | DType::I32 => 4,
            DType::I64 => 8,
            DType::U8 => 1,
        }
    }

    /// The smallest and largest value of the type as `f64` (infinite for `F32`), the range that
    /// box bounds of this type are clamped to. `I64`'s ends are rounded to the nearest `f64`.
    pub fn range(self) -> (f64, f64) {
        match self {
            DType::F32 => (f64::NEG_INFINITY, f64::INFINITY),
            DType::I32 => (f64::from(i32::MIN), f64::from(i32::MAX)),
            DType::I64 => (i64::MIN as f64, i64::MAX as f64),
            DType::U8 => (0.0, 255.0),
        }
    }
}

/// `float32`: what every box was before spaces were typed, so a serialized box without a
/// `dtype` reads as one.
impl Default for DType {
    fn default() -> Self {
        DType::F32
    }
}

impl std::fmt::Display for DType {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// The values of a tensor, row-major, in the tensor's element type.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub enum TensorData {
    /// `float32` values.
    F32(Vec<f32>),
    /// `int32` values.
    I32(Vec<i32>),
    /// `int64` values.
    I64(Vec<i64>),
    /// `uint8` values.
    U8(Vec<u8>),
}

impl Default for TensorData {
    fn default() -> Self {
        TensorData::F32(Vec::new())
    }
}

macro_rules! typed_access {
    ($as:ident, $as_mut:ident, $variant:ident, $t:ty, $name:literal) => {
        #[doc = concat!("The values if the tensor is `", $name, "`.")]
        pub fn $as(&self) -> Option<&[$t]> {
            match self {
                TensorData::$variant(v) => Some(v),
                _ => None,
            }
        }

        #[doc = concat!("The values, mutable, if the tensor is `", $name, "`.")]
        pub fn $as_mut(&mut self) -> Option<&mut [$t]> {
            match self {
                TensorData::$variant(v) => Some(v),
                _ => None,
            }
        }
    };
}

impl TensorData {
    /// `n` zeros of element type `dtype`.
    pub fn zeros(dtype: DType, n: usize) -> Self {
        match dtype {
            DType::F32 => TensorData::F32(vec![0.0; n]),
            DType::I32 => TensorData::I32(vec![0; n]),
            DType::I64 => TensorData::I64(vec![0; n]),
            DType::U8 => TensorData::U8(vec![0; n]),
        }
    }

    /// The element type.
    pub fn dtype(&self) -> DType {
        match self {
            TensorData::F32(_) => DType::F32,
            TensorData::I32(_) => DType::I32,
            TensorData::I64(_) => DType::I64,
            TensorData::U8(_) => DType::U8,
        }
    }

    /// Number of values.
    pub fn len(&self) -> usize {
        match self {
            TensorData::F32(v) => v.len(),
            TensorData::I32(v) => v.len(),
            TensorData::I64(v) => v.len(),
            TensorData::U8(v) => v.len(),
        }
    }

    /// Whether there are no values.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    typed_access!(as_f32, as_f32_mut, F32, f32, "float32");
    typed_access!(as_i32, as_i32_mut, I32, i32, "int32");
    typed_access!(as_i64, as_i64_mut, I64, i64, "int64");
    typed_access!(as_u8, as_u8_mut, U8, u8, "uint8");

    /// Makes this `n` zeros of type `dtype`, reusing the buffer when the type is unchanged (no
    /// allocation once the capacity suffices).
    pub fn reset_zeroed(&mut self, dtype: DType, n: usize) {
        fn zero<T: Clone + Default>(v: &mut Vec<T>, n: usize) {
            v.clear();
            v.resize(n, T::default());
        }
        match (self, dtype) {
            (TensorData::F32(v), DType::F32) => zero(v, n),
            (TensorData::I32(v), DType::I32) => zero(v, n),
            (TensorData::I64(v), DType::I64) => zero(v, n),
            (TensorData::U8(v), DType::U8) => zero(v, n),
            (me, _) => *me = TensorData::zeros(dtype, n),
        }
    }

    /// Copies `other` into `self`, reusing the buffer when the types agree.
    pub fn copy_from(&mut self, other: &TensorData) {
        match (self, other) {
            (TensorData::F32(a), TensorData::F32(b)) => a.clone_from(b),
            (TensorData::I32(a), TensorData::I32(b)) => a.clone_from(b),
            (TensorData::I64(a), TensorData::I64(b)) => a.clone_from(b),
            (TensorData::U8(a), TensorData::U8(b)) => a.clone_from(b),
            (me, _) => *me = other.clone(),
        }
    }

    /// Value `i` as `f64` (exact for every type except `int64` beyond ±2⁵³), `None` out of range.
    pub fn get_f64(&self, i: usize) -> Option<f64> {
        match self {
            TensorData::F32(v) => v.get(i).map(|x| f64::from(*x)),
            TensorData::I32(v) => v.get(i).map(|x| f64::from(*x)),
            TensorData::I64(v) => v.get(i).map(|x| *x as f64),
            TensorData::U8(v) => v.get(i).map(|x| f64::from(*x)),
        }
    }

    /// Writes the values converted to `f32` into `out` (which must have [`len`](Self::len)
    /// elements), for layers that consume floats. Integers above 2²⁴ in magnitude round.
    ///
    /// ```
    /// use a2perf_core::TensorData;
    /// let ids = TensorData::I32(vec![3, 0, 7]);
    /// let mut x = [0.0f32; 3];
    /// ids.write_f32_into(&mut x);
    /// assert_eq!(x, [3.0, 0.0, 7.0]);
    /// ```
    pub fn write_f32_into(&self, out: &mut [f32]) {
        match self {
            TensorData::F32(v) => out.copy_from_slice(v),
            TensorData::I32(v) => out.iter_mut().zip(v).for_each(|(o, x)| *o = *x as f32),
            TensorData::I64(v) => out.iter_mut().zip(v).for_each(|(o, x)| *o = *x as f32),
            TensorData::U8(v) => out.iter_mut().zip(v).for_each(|(o, x)| *o = f32::from(*x)),
        }
    }

    /// Appends the values converted to `f32` to `out` (no allocation when `out` has capacity).
    pub fn extend_f32(&self, out: &mut Vec<f32>) {
        let at = out.len();
        out.resize(at + self.len(), 0.0);
        self.write_f32_into(&mut out[at..]);
    }

    /// The values converted to `f32` (allocates; see [`write_f32_into`](Self::write_f32_into)).
    pub fn to_f32_vec(&self) -> Vec<f32> {
        let mut out = Vec::with_capacity(self.len());
        self.extend_f32(&mut out);
        out
    }

    /// Feeds every value's exact bits (zero-extended to `u64`) to `eat`; used by observation
    /// hashes and dataset fingerprints, which add the element type themselves.
    pub fn for_each_bits(&self, mut eat: impl FnMut(u64)) {
        match self {
            TensorData::F32(v) => v.iter().for_each(|x| eat(u64::from(x.to_bits()))),
            TensorData::I32(v) => v.iter().for_each(|x| eat(u64::from(*x as u32))),
            TensorData::I64(v) => v.iter().for_each(|x| eat(*x as u64)),
            TensorData::U8(v) => v.iter().for_each(|x| eat(u64::from(*x))),
        }
    }
}

impl From<Vec<f32>> for TensorData {
    fn from(v: Vec<f32>) -> Self {
        TensorData::F32(v)
    }
}

impl From<Vec<i32>> for TensorData {
    fn from(v: Vec<i32>) -> Self {
        TensorData::I32(v)
    }
}

impl From<Vec<i64>> for TensorData {
    fn from(v: Vec<i64>) -> Self {
        TensorData::I64(v)
    }
}

impl From<Vec<u8>> for TensorData {
    fn from(v: Vec<u8>) -> Self {
        TensorData::U8(v)
    }
}

/// A named, typed tensor (row-major).
///
/// ```
/// use a2perf_core::{DType, Tensor};
/// let t = Tensor::new("current_node", &[1], vec![4i32]);
/// assert_eq!(t.dtype(), DType::I32);
/// assert_eq!(t.data.as_i32(), Some(&[4][..]));
/// assert_eq!(t.data.to_f32_vec(), vec![4.0]);
/// ```
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Tensor {
    /// Name, matching the [`Space::Dict`](crate::Space::Dict) key (or `"obs"` for a flat
    /// observation).
    pub name: String,
    /// Shape; its product equals `data.len()`.
    pub shape: Vec<usize>,
    /// Values, in the element type of the tensor's box.
    pub data: TensorData,
}

impl Tensor {
    /// A tensor of the given values (`Vec<f32>`, `Vec<i32>`, `Vec<i64>` or `Vec<u8>`).
    pub fn new(name: &str, shape: &[usize], data: impl Into<TensorData>) -> Self {
        Self {
            name: name.to_string(),
            shape: shape.to_vec(),
            data: data.into(),
        }
    }

    /// A `float32` zero tensor of the given shape.
    pub fn zeros(name: &str, shape: &[usize]) -> Self {
        Self::zeros_of(name, shape, DType::F32)
    }

    /// A zero tensor of the given shape and element type.
    pub fn zeros_of(name: &str, shape: &[usize], dtype: DType) -> Self {
        Self {
            name: name.to_string(),
            shape: shape.to_vec(),
            data: TensorData::zeros(dtype, shape.iter().product()),
        }
    }

    /// The element type.
    pub fn dtype(&self) -> DType {
        self.data.dtype()
    }

    /// Makes this a zero tensor called `name` of `shape` and `dtype`, reusing its buffers: no
    /// allocation when name, shape and type are unchanged (an environment's step).
    pub fn reset_zeroed(&mut self, name: &str, shape: &[usize], dtype: DType) {
        if self.name != name {
            self.name = name.to_string();
        }
        if self.shape != shape {
            self.shape = shape.to_vec();
        }
        self.data.reset_zeroed(dtype, shape.iter().product());
    }

    /// Copies `other` into `self`, reusing buffers where possible.
    pub fn copy_from(&mut self, other: &Tensor) {
        if self.name != other.name {
            self.name.clone_from(&other.name);
        }
        self.shape.clone_from(&other.shape);
        self.data.copy_from(&other.data);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn integers_beyond_f32_precision_stay_exact() {
        let big = (1 << 24) + 1;
        let t = Tensor::new("ids", &[2], vec![big, -big]);
        assert_eq!(t.data.as_i32(), Some(&[big, -big][..]));
        assert_eq!(t.data.get_f64(0), Some(f64::from(big)));
        // The float view rounds, which is why ids are not stored as floats.
        assert_ne!(t.data.to_f32_vec()[0] as i32, big);
    }

    #[test]
    fn reset_zeroed_changes_type_and_zeroes() {
        let mut t = Tensor::new("x", &[2], vec![1.5f32, 2.5]);
        t.reset_zeroed("y", &[3], DType::I32);
        assert_eq!(t, Tensor::new("y", &[3], vec![0i32; 3]));
        t.data.as_i32_mut().unwrap()[1] = 9;
        t.reset_zeroed("y", &[3], DType::I32);
        assert_eq!(t.data.as_i32(), Some(&[0, 0, 0][..]));
    }

    #[test]
    fn copy_from_and_bits_follow_the_type() {
        let mut a = Tensor::zeros("a", &[1]);
        let b = Tensor::new("b", &[1], vec![7u8]);
        a.copy_from(&b);
        assert_eq!(a, b);
        let bits = |t: &TensorData| {
            let mut v = Vec::new();
            t.for_each_bits(|x| v.push(x));
            v
        };
        assert_eq!(bits(&TensorData::I32(vec![-1])), vec![u64::from(u32::MAX)]);
        assert_eq!(
            bits(&TensorData::F32(vec![1.0])),
            vec![u64::from(1f32.to_bits())]
        );
    }

    #[test]
    fn dtype_names_round_trip_and_serialize_lowercase() {
        for d in DType::ALL {
            assert_eq!(DType::from_name(d.name()), Some(d));
        }
        assert_eq!(serde_json::to_string(&DType::I32).unwrap(), "\"i32\"");
    }
}
