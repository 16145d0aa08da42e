//! Observations packed into contiguous per-tensor rows, the input format of every network.

use a2perf_core::{EnvSpec, Observation, PolicyError, Space};
use serde::{Deserialize, Serialize};

/// Names and shapes of an environment's observation tensors, plus the discrete action count when
/// actions may be masked.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ObsLayout {
    /// `(name, shape)` of each tensor, in observation-space order.
    pub tensors: Vec<(String, Vec<usize>)>,
    /// Number of discrete actions (mask width), `None` for continuous actions.
    pub num_actions: Option<usize>,
}

impl ObsLayout {
    /// The layout of `spec`'s observations. A `Box` observation is one tensor named `"obs"`.
    pub fn from_spec(spec: &EnvSpec) -> Result<Self, PolicyError> {
        let mut tensors = Vec::new();
        match &spec.observation_space {
            Space::Box { shape, .. } => tensors.push(("obs".to_string(), shape.clone())),
            Space::Dict(items) => {
                for (name, space) in items {
                    match space {
                        Space::Box { shape, .. } => tensors.push((name.clone(), shape.clone())),
                        Space::Discrete { .. } => tensors.push((name.clone(), vec![1])),
                        Space::Dict(_) => {
                            return Err(PolicyError::BadObservation(format!(
                                "nested dict observation `{name}` is not supported"
                            )));
                        }
                    }
                }
            }
            Space::Discrete { .. } => tensors.push(("obs".to_string(), vec![1])),
        }
        let num_actions = match spec.action_space {
            Space::Discrete { n } => Some(n),
            _ => None,
        };
        Ok(Self {
            tensors,
            num_actions,
        })
    }

    /// Index of the tensor called `name`.
    pub fn index(&self, name: &str) -> Option<usize> {
        self.tensors.iter().position(|(n, _)| n == name)
    }

    /// Flat size of tensor `i`.
    pub fn dim(&self, i: usize) -> usize {
        self.tensors[i].1.iter().product()
    }

    /// Sum of all tensors' flat sizes.
    pub fn total_dim(&self) -> usize {
        (0..self.tensors.len()).map(|i| self.dim(i)).sum()
    }
}

/// A batch of observations: for each tensor a `[rows, dim]` buffer, and a `[rows, n]` action mask
/// for discrete spaces (all `true` when the environment gives none).
///
/// Buffers only grow, so refilling a batch of the same size allocates nothing.
#[derive(Clone, Debug, Default)]
pub struct ObsBatch {
    dims: Vec<usize>,
    names: Vec<String>,
    data: Vec<Vec<f32>>,
    mask: Vec<bool>,
    mask_width: usize,
    len: usize,
}

impl ObsBatch {
    /// An empty batch for `layout`.
    pub fn new(layout: &ObsLayout) -> Self {
        let dims: Vec<usize> = (0..layout.tensors.len()).map(|i| layout.dim(i)).collect();
        Self {
            data: vec![Vec::new(); dims.len()],
            names: layout.tensors.iter().map(|(n, _)| n.clone()).collect(),
            dims,
            mask: Vec::new(),
            mask_width: layout.num_actions.unwrap_or(0),
            len: 0,
        }
    }

    /// Rows in use.
    pub fn len(&self) -> usize {
        self.len
    }

    /// Whether no rows are in use.
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// Sets the number of rows in use, growing buffers as needed (new rows are zero, masks legal).
    pub fn resize(&mut self, rows: usize) {
        for (d, dim) in self.data.iter_mut().zip(&self.dims) {
            if d.len() < rows * dim {
                d.resize(rows * dim, 0.0);
            }
        }
        if self.mask.len() < rows * self.mask_width {
            self.mask.resize(rows * self.mask_width, true);
        }
        self.len = rows;
    }

    /// Empties the batch (keeps capacity).
    pub fn clear(&mut self) {
        self.len = 0;
    }

    /// Appends `obs` as a new row.
    pub fn push(&mut self, obs: &Observation) -> Result<usize, PolicyError> {
        let row = self.len;
        self.resize(row + 1);
        self.write_row(row, obs)?;
        Ok(row)
    }

    /// Overwrites row `row` (which must be `< len`) with `obs`.
    pub fn write_row(&mut self, row: usize, obs: &Observation) -> Result<(), PolicyError> {
        let single = self.dims.len() == 1 && obs.tensors.len() == 1;
        for (i, name) in self.names.iter().enumerate() {
            let t = if single {
                &obs.tensors[0]
            } else {
                obs.tensor(name).ok_or_else(|| {
                    PolicyError::BadObservation(format!("missing tensor `{name}`"))
                })?
            };
            let dim = self.dims[i];
            if t.data.len() != dim {
                return Err(PolicyError::BadObservation(format!(
                    "tensor `{name}` has {} values, the policy expects {dim}",
                    t.data.len()
                )));
            }
            self.data[i][row * dim..(row + 1) * dim].copy_from_slice(&t.data);
        }
        let w = self.mask_width;
        if w > 0 {
            let m = &mut self.mask[row * w..(row + 1) * w];
            match &obs.action_mask {
                Some(src) if src.len() == w => m.copy_from_slice(src),
                Some(src) => {
                    return Err(PolicyError::BadObservation(format!(
                        "action mask has {} entries, the action space has {w}",
                        src.len()
                    )));
                }
                None => m.fill(true),
            }
        }
        Ok(())
    }

    /// Copies row `src_row` of `src` (same layout) into row `row` of `self`.
    pub fn copy_row(&mut self, row: usize, src: &ObsBatch, src_row: usize) {
        for (i, dim) in self.dims.iter().enumerate() {
            self.data[i][row * dim..(row + 1) * dim]
                .copy_from_slice(&src.data[i][src_row * dim..(src_row + 1) * dim]);
        }
        let w = self.mask_width;
        if w > 0 {
            self.mask[row * w..(row + 1) * w]
                .copy_from_slice(&src.mask[src_row * w..(src_row + 1) * w]);
        }
    }

    /// Makes `self` the rows `rows` of `src`, in that order.
    pub fn gather(&mut self, src: &ObsBatch, rows: &[usize]) {
        self.resize(rows.len());
        for (r, &s) in rows.iter().enumerate() {
            self.copy_row(r, src, s);
        }
    }

    /// All rows of tensor `i`, `[len, dim]`.
    pub fn tensor(&self, i: usize) -> &[f32] {
        &self.data[i][..self.len * self.dims[i]]
    }

    /// Row `row` of tensor `i`.
    pub fn tensor_row(&self, i: usize, row: usize) -> &[f32] {
        let d = self.dims[i];
        &self.data[i][row * d..(row + 1) * d]
    }

    /// Legal-action mask of row `row`, mutable (`None` for continuous action spaces).
    pub fn mask_mut(&mut self, row: usize) -> Option<&mut [bool]> {
        let w = self.mask_width;
        (w > 0).then(|| &mut self.mask[row * w..(row + 1) * w])
    }

    /// Row `row` of tensor `i`, mutable (for normalisation in place).
    pub fn row_mut(&mut self, i: usize, row: usize) -> &mut [f32] {
        let d = self.dims[i];
        &mut self.data[i][row * d..(row + 1) * d]
    }

    /// Flat size of tensor `i`.
    pub fn dim(&self, i: usize) -> usize {
        self.dims[i]
    }

    /// Number of tensors.
    pub fn num_tensors(&self) -> usize {
        self.dims.len()
    }

    /// Legal-action mask of row `row` (`None` for continuous action spaces).
    pub fn mask(&self, row: usize) -> Option<&[bool]> {
        let w = self.mask_width;
        (w > 0).then(|| &self.mask[row * w..(row + 1) * w])
    }

    /// Writes all tensors of every row, concatenated, into `out` (`[len, total_dim]`).
    pub fn concat_into(&self, out: &mut Vec<f32>) {
        let total: usize = self.dims.iter().sum();
        crate::nn::ensure(out, self.len * total);
        for r in 0..self.len {
            let mut at = r * total;
            for (i, d) in self.dims.iter().enumerate() {
                out[at..at + d].copy_from_slice(&self.data[i][r * d..(r + 1) * d]);
                at += d;
            }
        }
    }
}
