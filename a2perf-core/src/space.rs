//! Observation and action spaces, and the values that live in them.
//!
//! The vocabulary is Gymnasium's: `Discrete(n)` (optionally with an action mask carried by the
//! observation), `Box` (bounds and shape) and `Dict` (named sub-spaces). Observations are one or more
//! named `f32` tensors; integer data such as token ids is stored exactly in `f32` (all ids used by
//! the benchmark are below 2²⁴).

use serde::{Deserialize, Serialize};

use crate::rng::RngStream;

/// A space of observations or actions.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub enum Space {
    /// `n` discrete choices `0..n`. Which ones are legal at a given step is given by the
    /// observation's [`Observation::action_mask`].
    Discrete {
        /// Number of choices.
        n: usize,
    },
    /// A box of real vectors with per-element bounds (row-major `shape`).
    Box {
        /// Lower bounds, one per element (may be `-inf`).
        low: Vec<f32>,
        /// Upper bounds, one per element (may be `+inf`).
        high: Vec<f32>,
        /// Tensor shape; the product equals `low.len()`.
        shape: Vec<usize>,
    },
    /// Named sub-spaces, in a fixed order (a Gymnasium `Dict`).
    Dict(Vec<(String, Space)>),
}

impl Space {
    /// A box with the same bounds for every element.
    ///
    /// ```
    /// use a2perf_core::Space;
    /// let s = Space::uniform_box(&[2, 3], -1.0, 1.0);
    /// assert_eq!(s.flat_dim(), 6);
    /// ```
    pub fn uniform_box(shape: &[usize], low: f32, high: f32) -> Self {
        let n = shape.iter().product();
        Space::Box {
            low: vec![low; n],
            high: vec![high; n],
            shape: shape.to_vec(),
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
    /// legal. Unbounded box elements are drawn from a standard normal.
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
            Space::Box { low, high, .. } => Some(Action::Continuous(
                low.iter()
                    .zip(high)
                    .map(|(&l, &h)| {
                        if l.is_finite() && h.is_finite() {
                            rng.range(f64::from(l), f64::from(h)) as f32
                        } else {
                            rng.normal() as f32
                        }
                    })
                    .collect(),
            )),
            Space::Dict(_) => None,
        }
    }

    /// Whether `action` belongs to this space (ignoring masks).
    pub fn contains(&self, action: &Action) -> bool {
        match (self, action) {
            (Space::Discrete { n }, Action::Discrete(a)) => a < n,
            (Space::Box { low, high, .. }, Action::Continuous(v)) => {
                v.len() == low.len()
                    && v.iter()
                        .zip(low.iter().zip(high))
                        .all(|(x, (l, h))| x.is_finite() && x >= l && x <= h)
            }
            _ => false,
        }
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

/// A named `f32` tensor (row-major).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Tensor {
    /// Name, matching the [`Space::Dict`] key (or `"obs"` for a flat observation).
    pub name: String,
    /// Shape; its product equals `data.len()`.
    pub shape: Vec<usize>,
    /// Values.
    pub data: Vec<f32>,
}

impl Tensor {
    /// A zero tensor of the given shape.
    pub fn zeros(name: &str, shape: &[usize]) -> Self {
        Self {
            name: name.to_string(),
            shape: shape.to_vec(),
            data: vec![0.0; shape.iter().product()],
        }
    }
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
            tensors: vec![Tensor {
                name: "obs".into(),
                shape: vec![data.len()],
                data,
            }],
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

    /// All tensors concatenated in order (allocates; for simple MLP policies and tests).
    pub fn flat_values(&self) -> Vec<f32> {
        let mut out = Vec::with_capacity(self.tensors.iter().map(|t| t.data.len()).sum());
        self.write_flat(&mut out);
        out
    }

    /// Appends all tensors in order to `out` (no allocation when `out` has capacity).
    pub fn write_flat(&self, out: &mut Vec<f32>) {
        for t in &self.tensors {
            out.extend_from_slice(&t.data);
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
                if mine.name != t.name {
                    mine.name.clone_from(&t.name);
                }
                mine.shape.clone_from(&t.shape);
                mine.data.clone_from(&t.data);
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
}
