//! Observation and action spaces, and the values that live in them.
//!
//! The vocabulary is Gymnasium's: `Discrete(n)` (optionally with an action mask carried by the
//! observation), `Box` (bounds, shape and element type) and `Dict` (named sub-spaces).
//! Observations are one or more named [`Tensor`]s, each in its box's [`DType`]: token ids, node
//! indices and flags are `int32` as in the original environments, real-valued features `float32`.

use serde::{Deserialize, Serialize};

use crate::rng::RngStream;
pub use crate::tensor::{DType, Tensor, TensorData};

/// A space of observations or actions.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub enum Space {
    /// `n` discrete choices `0..n`. Which ones are legal at a given step is given by the
    /// observation's [`Observation::action_mask`].
    Discrete {
        /// Number of choices.
        n: usize,
    },
    /// A box of tensors with per-element bounds (row-major `shape`) and an element type.
    ///
    /// Bounds are `f64`: that holds every `float32`, `int32` and `uint8` value exactly (and
    /// `int64` values up to ±2⁵³), so one bound type serves every element type and integer bounds
    /// are never rounded, as they would be in `f32` beyond 2²⁴.
    Box {
        /// Lower bounds, one per element (may be `-inf` for `float32`).
        low: Vec<f64>,
        /// Upper bounds, one per element (may be `+inf` for `float32`).
        high: Vec<f64>,
        /// Tensor shape; the product equals `low.len()`.
        shape: Vec<usize>,
        /// Element type of the values (`float32` when a serialized box, written before spaces
        /// were typed, has none).
        #[serde(default)]
        dtype: DType,
    },
    /// Named sub-spaces, in a fixed order (a Gymnasium `Dict`).
    Dict(Vec<(String, Space)>),
}

impl Space {
    /// A `float32` box with the same bounds for every element.
    ///
    /// ```
    /// use a2perf_core::{DType, Space};
    /// let s = Space::uniform_box(&[2, 3], -1.0, 1.0);
    /// assert_eq!(s.flat_dim(), 6);
    /// assert_eq!(s.dtype(), Some(DType::F32));
    /// ```
    pub fn uniform_box(shape: &[usize], low: f32, high: f32) -> Self {
        Self::uniform_box_of(shape, DType::F32, f64::from(low), f64::from(high))
    }

    /// A box of element type `dtype` with the same bounds for every element.
    ///
    /// ```
    /// use a2perf_core::{DType, Space, Tensor};
    /// let ids = Space::uniform_box_of(&[3], DType::I32, 0.0, 14_999.0);
    /// assert!(ids.contains_tensor(&Tensor::new("t", &[3], vec![0i32, 7, 14_999])));
    /// assert!(!ids.contains_tensor(&Tensor::new("t", &[3], vec![0.0f32, 7.0, 1.0])));
    /// ```
    pub fn uniform_box_of(shape: &[usize], dtype: DType, low: f64, high: f64) -> Self {
        let n = shape.iter().product();
        Space::Box {
            low: vec![low; n],
            high: vec![high; n],
            shape: shape.to_vec(),
            dtype,
        }
    }

    /// The element type of a box, `None` for other spaces.
    pub fn dtype(&self) -> Option<DType> {
        match self {
            Space::Box { dtype, .. } => Some(*dtype),
            _ => None,
        }
    }

    /// Number of scalars in a value of this space (1 for discrete, the sum for dicts).
    pub fn flat_dim(&self) -> usize {
        match self {
            Space::Discrete { .. } => 1,
            Space::Box { low, .. } => low.len(),
            Space::Dict(items) => items.iter().map(|(_, s)| s.flat_dim()).sum(),
        }
    }

    /// Draws a uniformly random action from this space.
    ///
    /// For discrete spaces only legal choices (per `mask`) are drawn; `None` when no choice is
    /// legal. Unbounded `float32` box elements are drawn from a standard normal; integer boxes
    /// give whole numbers drawn uniformly between the bounds (inclusive; an unbounded side is
    /// clamped to the type's range).
    pub fn sample(&self, rng: &mut RngStream, mask: Option<&[bool]>) -> Option<Action> {
        match self {
            Space::Discrete { n } => match mask {
                None => (*n > 0).then(|| Action::Discrete(rng.index(*n))),
                Some(mask) => {
                    let legal = mask.iter().take(*n).filter(|m| **m).count();
                    if legal == 0 {
                        return None;
                    }
                    let pick = rng.index(legal);
                    mask.iter()
                        .take(*n)
                        .enumerate()
                        .filter(|(_, m)| **m)
                        .nth(pick)
                        .map(|(i, _)| Action::Discrete(i))
                }
            },
            Space::Box {
                low, high, dtype, ..
            } => Some(Action::Continuous(
                low.iter()
                    .zip(high)
                    .map(|(&l, &h)| draw(*dtype, l, h, rng) as f32)
                    .collect(),
            )),
            Space::Dict(_) => None,
        }
    }

    /// Draws a tensor called `name` from a box, in the box's element type, element by element as
    /// [`sample`](Space::sample) (integers exact at any magnitude); `None` for other spaces.
    ///
    /// ```
    /// use a2perf_core::{DType, RngStream, Space};
    /// let ids = Space::uniform_box_of(&[2, 3], DType::I32, 1.0, 9.0);
    /// let t = ids.sample_tensor("ids", &mut RngStream::new(0, "doc")).unwrap();
    /// assert!(ids.contains_tensor(&t));
    /// ```
    pub fn sample_tensor(&self, name: &str, rng: &mut RngStream) -> Option<Tensor> {
        let Space::Box {
            low,
            high,
            shape,
            dtype,
        } = self
        else {
            return None;
        };
        let values = low.iter().zip(high).map(|(&l, &h)| draw(*dtype, l, h, rng));
        let data = match dtype {
            DType::F32 => TensorData::F32(values.map(|x| x as f32).collect()),
            DType::I32 => TensorData::I32(values.map(|x| x as i32).collect()),
            DType::I64 => TensorData::I64(values.map(|x| x as i64).collect()),
            DType::U8 => TensorData::U8(values.map(|x| x as u8).collect()),
        };
        Some(Tensor {
            name: name.to_string(),
            shape: shape.clone(),
            data,
        })
    }

    /// Whether `action` belongs to this space (ignoring masks). For an integer box the values
    /// must be whole numbers.
    pub fn contains(&self, action: &Action) -> bool {
        match (self, action) {
            (Space::Discrete { n }, Action::Discrete(a)) => a < n,
            (
                Space::Box {
                    low, high, dtype, ..
                },
                Action::Continuous(v),
            ) => {
                v.len() == low.len()
                    && v.iter().zip(low.iter().zip(high)).all(|(x, (l, h))| {
                        let x = f64::from(*x);
                        x.is_finite()
                            && x >= *l
                            && x <= *h
                            && (!dtype.is_integer() || x.fract() == 0.0)
                    })
            }
            _ => false,
        }
    }

    /// Whether `tensor` belongs to this box: same element type, shape and number of values, every
    /// value within its bounds (and no NaN). `false` for non-box spaces.
    pub fn contains_tensor(&self, tensor: &Tensor) -> bool {
        let Space::Box {
            low,
            high,
            shape,
            dtype,
        } = self
        else {
            return false;
        };
        tensor.dtype() == *dtype
            && tensor.shape == *shape
            && tensor.data.len() == low.len()
            && (0..low.len()).all(|i| {
                tensor
                    .data
                    .get_f64(i)
                    .is_some_and(|x| x >= low[i] && x <= high[i])
            })
    }

    /// Whether `obs` belongs to this space: for a box its single tensor, for a dict one tensor
    /// per entry, in order and with the entry's name, each in its box ([`contains_tensor`]).
    ///
    /// [`contains_tensor`]: Space::contains_tensor
    pub fn contains_observation(&self, obs: &Observation) -> bool {
        match self {
            Space::Box { .. } => obs.tensors.len() == 1 && self.contains_tensor(&obs.tensors[0]),
            Space::Dict(items) => {
                obs.tensors.len() == items.len()
                    && items
                        .iter()
                        .zip(&obs.tensors)
                        .all(|((name, space), t)| *name == t.name && space.contains_tensor(t))
            }
            Space::Discrete { .. } => false,
        }
    }
}

/// One element of a box of type `dtype` with bounds `low..=high`: for integer types a whole
/// number, each with the same probability (unbounded sides clamped to the type's range); for
/// floats uniform within finite bounds, standard normal otherwise.
fn draw(dtype: DType, low: f64, high: f64, rng: &mut RngStream) -> f64 {
    if dtype.is_integer() {
        let (min, max) = dtype.range();
        let (lo, hi) = (low.max(min).ceil(), high.min(max).floor());
        if hi <= lo {
            return lo;
        }
        let k = rng.range(0.0, hi - lo + 1.0).floor().min(hi - lo);
        lo + k
    } else if low.is_finite() && high.is_finite() {
        rng.range(low, high)
    } else {
        rng.normal()
    }
}

/// An action: a discrete choice or a continuous vector.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub enum Action {
    /// Index into a [`Space::Discrete`].
    Discrete(usize),
    /// Element of a [`Space::Box`].
    Continuous(Vec<f32>),
}

/// One observation: named tensors plus, for discrete action spaces with illegal actions, the mask
/// of legal actions (`true` = legal).
///
/// Environments write observations in place (see [`crate::Env::step_into`]), reusing the buffers,
/// so stepping allocates nothing.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Observation {
    /// The tensors, in the order of the observation space.
    pub tensors: Vec<Tensor>,
    /// Legal-action mask for discrete action spaces, `None` when every action is legal.
    pub action_mask: Option<Vec<bool>>,
}

impl Observation {
    /// A flat observation with one tensor named `"obs"`.
    ///
    /// ```
    /// use a2perf_core::Observation;
    /// let o = Observation::flat(vec![1.0, 2.0]);
    /// assert_eq!(o.flat_values(), vec![1.0, 2.0]);
    /// ```
    pub fn flat(data: Vec<f32>) -> Self {
        Self {
            tensors: vec![Tensor::new("obs", &[data.len()], data)],
            action_mask: None,
        }
    }

    /// The tensor called `name`, if any.
    pub fn tensor(&self, name: &str) -> Option<&Tensor> {
        self.tensors.iter().find(|t| t.name == name)
    }

    /// Mutable access to the tensor called `name`, if any.
    pub fn tensor_mut(&mut self, name: &str) -> Option<&mut Tensor> {
        self.tensors.iter_mut().find(|t| t.name == name)
    }

    /// All tensors concatenated in order, converted to `f32` (allocates; for simple MLP
    /// policies and tests).
    pub fn flat_values(&self) -> Vec<f32> {
        let mut out = Vec::with_capacity(self.tensors.iter().map(|t| t.data.len()).sum());
        self.write_flat(&mut out);
        out
    }

    /// Appends all tensors in order to `out`, converted to `f32` (no allocation when `out` has
    /// capacity).
    pub fn write_flat(&self, out: &mut Vec<f32>) {
        for t in &self.tensors {
            t.data.extend_f32(out);
        }
    }

    /// Whether discrete action `a` is legal under the mask (always true without a mask).
    pub fn is_legal(&self, a: usize) -> bool {
        self.action_mask
            .as_ref()
            .is_none_or(|m| m.get(a).copied().unwrap_or(false))
    }

    /// Copies `other` into `self`, reusing buffers where shapes allow.
    pub fn copy_from(&mut self, other: &Observation) {
        self.tensors.truncate(other.tensors.len());
        for (i, t) in other.tensors.iter().enumerate() {
            if let Some(mine) = self.tensors.get_mut(i) {
                mine.copy_from(t);
            } else {
                self.tensors.push(t.clone());
            }
        }
        match (&mut self.action_mask, &other.action_mask) {
            (Some(m), Some(o)) => m.clone_from(o),
            (mine, o) => mine.clone_from(o),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn masked_sampling_only_returns_legal_actions() {
        let space = Space::Discrete { n: 5 };
        let mask = [false, true, false, true, false];
        let mut rng = RngStream::new(0, "t");
        for _ in 0..100 {
            let Some(Action::Discrete(a)) = space.sample(&mut rng, Some(&mask)) else {
                panic!("expected a discrete action");
            };
            assert!(mask[a]);
        }
        assert_eq!(space.sample(&mut rng, Some(&[false; 5])), None);
    }

    #[test]
    fn box_sampling_is_within_bounds() {
        let space = Space::uniform_box(&[3], -2.0, 0.5);
        let mut rng = RngStream::new(0, "t");
        for _ in 0..100 {
            let a = space.sample(&mut rng, None).unwrap();
            assert!(space.contains(&a));
        }
    }

    #[test]
    fn copy_from_reproduces_the_source() {
        let mut a = Observation::flat(vec![1.0; 3]);
        let mut b = Observation::flat(vec![2.0; 5]);
        b.action_mask = Some(vec![true, false]);
        a.copy_from(&b);
        assert_eq!(a, b);
    }

    #[test]
    fn integer_boxes_sample_and_contain_whole_numbers() {
        let space = Space::uniform_box_of(&[4], DType::I32, 0.0, 3.0);
        let mut rng = RngStream::new(0, "t");
        let mut seen = [false; 4];
        for _ in 0..200 {
            let a = space.sample(&mut rng, None).unwrap();
            assert!(space.contains(&a));
            let Action::Continuous(v) = a else {
                panic!("expected a vector");
            };
            for x in v {
                seen[x as usize] = true;
            }
        }
        assert_eq!(seen, [true; 4], "both bounds are reachable");
        assert!(!space.contains(&Action::Continuous(vec![0.5, 1.0, 2.0, 3.0])));
        assert!(!space.contains(&Action::Continuous(vec![4.0, 1.0, 2.0, 3.0])));
    }

    #[test]
    fn contains_tensor_checks_type_shape_and_bounds() {
        let space = Space::uniform_box_of(&[2], DType::I32, 0.0, f64::from(i32::MAX));
        assert!(space.contains_tensor(&Tensor::new("x", &[2], vec![0, i32::MAX])));
        assert!(!space.contains_tensor(&Tensor::new("x", &[2], vec![-1, 0])));
        assert!(!space.contains_tensor(&Tensor::new("x", &[1, 2], vec![0, 0])));
        assert!(!space.contains_tensor(&Tensor::new("x", &[2], vec![0i64, 0])));
        let floats = Space::uniform_box(&[1], 0.0, f32::INFINITY);
        assert!(floats.contains_tensor(&Tensor::new("x", &[1], vec![1e30f32])));
        assert!(!floats.contains_tensor(&Tensor::new("x", &[1], vec![f32::NAN])));
        let dict = Space::Dict(vec![("a".into(), floats), ("b".into(), space)]);
        let obs = Observation {
            tensors: vec![
                Tensor::new("a", &[1], vec![2.0f32]),
                Tensor::new("b", &[2], vec![1, 2]),
            ],
            action_mask: None,
        };
        assert!(dict.contains_observation(&obs));
    }

    #[test]
    fn serialized_boxes_state_their_dtype() {
        let json =
            serde_json::to_string(&Space::uniform_box_of(&[1], DType::I32, 0.0, 9.0)).unwrap();
        assert!(json.contains("\"dtype\":\"i32\""), "{json}");
        // A box written before spaces were typed was a float box.
        let old = r#"{"Box":{"low":[0.0],"high":[1.0],"shape":[1]}}"#;
        assert_eq!(
            serde_json::from_str::<Space>(old).unwrap(),
            Space::uniform_box(&[1], 0.0, 1.0)
        );
    }
}
