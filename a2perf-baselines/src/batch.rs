//! Observations packed into contiguous per-tensor rows, the input format of every network.
//!
//! Each tensor keeps its kind of values: `float32` tensors are `f32` rows (what float-consuming
//! layers read, and what observation normalisation shifts), integer tensors (`int32`, and `uint8`
//! widened) are exact `i32` rows, which embedding lookups read directly.

use a2perf_core::copy::copy_slice;
use a2perf_core::{DType, EnvSpec, Observation, PolicyError, Space, TensorData};
use serde::{Deserialize, Serialize};

/// Names, shapes and element types of an environment's observation tensors, plus the discrete
/// action count when actions may be masked.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ObsLayout {
    /// `(name, shape)` of each tensor, in observation-space order.
    pub tensors: Vec<(String, Vec<usize>)>,
    /// Element type of each tensor (empty in layouts saved before observations were typed: then
    /// every tensor is `float32`).
    #[serde(default)]
    pub dtypes: Vec<DType>,
    /// Number of discrete actions (mask width), `None` for continuous actions.
    pub num_actions: Option<usize>,
}

impl ObsLayout {
    /// The layout of `spec`'s observations. A `Box` observation is one tensor named `"obs"`.
    /// `int64` tensors are refused: the baselines' integer rows are `i32`.
    pub fn from_spec(spec: &EnvSpec) -> Result<Self, PolicyError> {
        let mut tensors = Vec::new();
        let mut dtypes = Vec::new();
        let mut push = |name: &str, shape: Vec<usize>, dtype: DType| {
            if dtype == DType::I64 {
                return Err(PolicyError::BadObservation(format!(
                    "tensor `{name}` is int64; the baselines take float32, int32 and uint8 \
                     observations"
                )));
            }
            tensors.push((name.to_string(), shape));
            dtypes.push(dtype);
            Ok(())
        };
        match &spec.observation_space {
            Space::Box { shape, dtype, .. } => push("obs", shape.clone(), *dtype)?,
            Space::Dict(items) => {
                for (name, space) in items {
                    match space {
                        Space::Box { shape, dtype, .. } => push(name, shape.clone(), *dtype)?,
                        Space::Discrete { .. } => push(name, vec![1], DType::I32)?,
                        Space::Dict(_) => {
                            return Err(PolicyError::BadObservation(format!(
                                "nested dict observation `{name}` is not supported"
                            )));
                        }
                    }
                }
            }
            Space::Discrete { .. } => push("obs", vec![1], DType::I32)?,
        }
        let num_actions = match spec.action_space {
            Space::Discrete { n } => Some(n),
            _ => None,
        };
        Ok(Self {
            tensors,
            dtypes,
            num_actions,
        })
    }

    /// A layout of `float32` tensors.
    ///
    /// ```
    /// use a2perf_baselines::ObsLayout;
    /// let l = ObsLayout::floats(vec![("obs".into(), vec![2])], Some(3));
    /// assert_eq!(l.total_dim(), 2);
    /// ```
    pub fn floats(tensors: Vec<(String, Vec<usize>)>, num_actions: Option<usize>) -> Self {
        Self {
            dtypes: vec![DType::F32; tensors.len()],
            tensors,
            num_actions,
        }
    }

    /// Element type of tensor `i` (`float32` for layouts saved before observations were typed).
    pub fn dtype(&self, i: usize) -> DType {
        self.dtypes.get(i).copied().unwrap_or(DType::F32)
    }

    /// Whether tensor `i` holds integers (kept exact as `i32` rows in an [`ObsBatch`]).
    pub fn is_integer(&self, i: usize) -> bool {
        self.dtype(i).is_integer()
    }

    /// Whether `other` has the same tensor names, shapes and action count. Element types are not
    /// compared: the networks read the same numbers whether ids are stored as floats or integers,
    /// so a network saved before observations were typed runs on typed ones.
    pub fn same_shapes(&self, other: &ObsLayout) -> bool {
        self.tensors == other.tensors && self.num_actions == other.num_actions
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

/// Rows of one tensor: `f32` for float tensors, exact `i32` for integer ones.
#[derive(Clone, Debug)]
enum Rows {
    F32(Vec<f32>),
    I32(Vec<i32>),
}

impl Rows {
    fn len(&self) -> usize {
        match self {
            Rows::F32(v) => v.len(),
            Rows::I32(v) => v.len(),
        }
    }

    fn grow(&mut self, n: usize) {
        match self {
            Rows::F32(v) => v.resize(n, 0.0),
            Rows::I32(v) => v.resize(n, 0),
        }
    }

    /// Copies `src[from..from + n]` to `self[at..at + n]` (same kinds, by construction).
    fn copy_range(&mut self, at: usize, src: &Rows, from: usize, n: usize) {
        match (self, src) {
            (Rows::F32(d), Rows::F32(s)) => copy_slice(&mut d[at..at + n], &s[from..from + n]),
            (Rows::I32(d), Rows::I32(s)) => copy_slice(&mut d[at..at + n], &s[from..from + n]),
            _ => {}
        }
    }
}

/// Row `row`'s entry of a per-row watermark list (growing it with "not known", `u32::MAX`).
fn mark(marks: &mut Vec<u32>, row: usize) -> &mut u32 {
    if marks.len() <= row {
        marks.resize(row + 1, u32::MAX);
    }
    &mut marks[row]
}

/// Writes the first `n` places of `row` by `fill` and `blank` after them, clearing only up to
/// `known` (where the last such write of this row ended its values, `u32::MAX` when not known;
/// the places after it still hold `blank`); then records `n` there.
fn fill_trimmed<T: Copy>(
    row: &mut [T],
    n: usize,
    blank: T,
    known: &mut u32,
    fill: impl FnOnce(&mut [T]),
) {
    let n = n.min(row.len());
    let clear_to = (*known as usize).min(row.len()).max(n);
    fill(&mut row[..n]);
    row[n..clear_to].fill(blank);
    *known = n as u32;
}

/// A batch of observations: for each tensor a `[rows, dim]` buffer (`f32` or exact `i32`, see the
/// module documentation), and a `[rows, n]` action mask for discrete spaces (all `true` when the
/// environment gives none).
///
/// Buffers only grow, so refilling a batch of the same size allocates nothing.
#[derive(Clone, Debug, Default)]
pub struct ObsBatch {
    dims: Vec<usize>,
    /// Values stored per row of each tensor: its `dims` entry, or 0 for a tensor left out by
    /// [`keep_tensors`](ObsBatch::keep_tensors).
    widths: Vec<usize>,
    names: Vec<String>,
    data: Vec<Rows>,
    mask: Vec<bool>,
    mask_width: usize,
    len: usize,
    /// Per tensor, per row: the values from this index on are zero, as the last
    /// [`write_trimmed`](Self::write_trimmed) left them (`u32::MAX`: not known; any other
    /// write forgets it).
    zero_from: Vec<Vec<u32>>,
    /// Per row: the mask's actions from this index on are illegal, as the last
    /// [`write_mask_trimmed`](Self::write_mask_trimmed) left them (`u32::MAX`: not known).
    illegal_from: Vec<u32>,
}

impl ObsBatch {
    /// An empty batch for `layout`.
    pub fn new(layout: &ObsLayout) -> Self {
        let dims: Vec<usize> = (0..layout.tensors.len()).map(|i| layout.dim(i)).collect();
        Self {
            data: (0..dims.len())
                .map(|i| {
                    if layout.is_integer(i) {
                        Rows::I32(Vec::new())
                    } else {
                        Rows::F32(Vec::new())
                    }
                })
                .collect(),
            names: layout.tensors.iter().map(|(n, _)| n.clone()).collect(),
            widths: dims.clone(),
            dims,
            mask: Vec::new(),
            mask_width: layout.num_actions.unwrap_or(0),
            len: 0,
            zero_from: Vec::new(),
            illegal_from: Vec::new(),
        }
    }

    /// Keeps the values of tensors `keep` only (indices into the layout): every other tensor
    /// is still checked on [`write_row`](Self::write_row) but neither stored nor copied, and
    /// reads as empty. For the batches a network fills and reads many times when it reads few
    /// of the tensors: the circuit network reads two of eleven, and the others (the netlist's
    /// graph, the same in every row) are most of an observation's values.
    ///
    /// ```
    /// use a2perf_baselines::batch::{ObsBatch, ObsLayout};
    ///
    /// let layout = ObsLayout::floats(vec![("a".into(), vec![2]), ("b".into(), vec![3])], None);
    /// let mut batch = ObsBatch::new(&layout);
    /// batch.keep_tensors(&[1]);
    /// batch.resize(4);
    /// assert!(batch.tensor(0).is_empty());
    /// assert_eq!(batch.tensor(1).len(), 4 * 3);
    /// assert_eq!(batch.dim(0), 2);
    /// ```
    pub fn keep_tensors(&mut self, keep: &[usize]) {
        for (i, (w, d)) in self.widths.iter_mut().zip(&self.dims).enumerate() {
            *w = if keep.contains(&i) { *d } else { 0 };
        }
        // The rows' places move with the widths.
        self.zero_from.clear();
    }

    /// Forgets what [`write_trimmed`](Self::write_trimmed) knew of row `row`'s zeros (tensor
    /// `i`, or every tensor).
    fn forget_zeros(&mut self, i: Option<usize>, row: usize) {
        for (t, z) in self.zero_from.iter_mut().enumerate() {
            if i.is_none_or(|i| i == t)
                && let Some(z) = z.get_mut(row)
            {
                *z = u32::MAX;
            }
        }
    }

    /// Writes row `row` of tensor `i` as `nz` leading values, written by `floats` (a float
    /// tensor) or `ints` (an integer one) into the row's first `nz` places, followed by zeros.
    /// Only the places the last such write of this row did not leave zero are cleared, so a
    /// row that is mostly trailing zeros (a web page's empty element slots) costs what its
    /// values do. Nothing is written for a tensor left out by
    /// [`keep_tensors`](Self::keep_tensors).
    ///
    /// ```
    /// use a2perf_baselines::batch::{ObsBatch, ObsLayout};
    ///
    /// let layout = ObsLayout::floats(vec![("x".into(), vec![4])], None);
    /// let mut batch = ObsBatch::new(&layout);
    /// batch.resize(1);
    /// batch.write_trimmed(0, 0, 3, |d| d.copy_from_slice(&[1.0, 2.0, 3.0]), |_| {});
    /// batch.write_trimmed(0, 0, 1, |d| d[0] = 5.0, |_| {});
    /// assert_eq!(batch.tensor_row(0, 0), [5.0, 0.0, 0.0, 0.0]);
    /// batch.row_mut(0, 0).fill(7.0);
    /// batch.write_trimmed(0, 0, 2, |d| d.copy_from_slice(&[1.0, 2.0]), |_| {});
    /// assert_eq!(batch.tensor_row(0, 0), [1.0, 2.0, 0.0, 0.0]);
    /// ```
    pub fn write_trimmed(
        &mut self,
        i: usize,
        row: usize,
        nz: usize,
        floats: impl FnOnce(&mut [f32]),
        ints: impl FnOnce(&mut [i32]),
    ) {
        let d = self.widths[i];
        if d == 0 {
            return;
        }
        if self.zero_from.len() != self.dims.len() {
            self.zero_from = vec![Vec::new(); self.dims.len()];
        }
        let known = mark(&mut self.zero_from[i], row);
        match &mut self.data[i] {
            Rows::F32(v) => fill_trimmed(&mut v[row * d..(row + 1) * d], nz, 0.0, known, floats),
            Rows::I32(v) => fill_trimmed(&mut v[row * d..(row + 1) * d], nz, 0, known, ints),
        }
    }

    /// Forgets what [`write_mask_trimmed`](Self::write_mask_trimmed) knew of row `row`'s mask.
    fn forget_illegal(&mut self, row: usize) {
        if let Some(k) = self.illegal_from.get_mut(row) {
            *k = u32::MAX;
        }
    }

    /// Writes row `row`'s action mask as `n` leading flags, written by `fill` into the mask's
    /// first `n` places, followed by illegal actions; only the places the last such write of
    /// this row did not leave illegal are cleared (a web page's mask has 12,500 actions, its
    /// legal ones all among the first few hundred). Nothing happens without a mask.
    ///
    /// ```
    /// use a2perf_baselines::batch::{ObsBatch, ObsLayout};
    ///
    /// let layout = ObsLayout::floats(vec![("x".into(), vec![1])], Some(5));
    /// let mut batch = ObsBatch::new(&layout);
    /// batch.resize(1);
    /// batch.write_mask_trimmed(0, 2, |m| m.copy_from_slice(&[false, true]));
    /// assert_eq!(batch.mask(0), Some(&[false, true, false, false, false][..]));
    /// assert_eq!(batch.legal_end(0), 2);
    /// ```
    pub fn write_mask_trimmed(&mut self, row: usize, n: usize, fill: impl FnOnce(&mut [bool])) {
        let w = self.mask_width;
        if w == 0 {
            return;
        }
        let known = mark(&mut self.illegal_from, row);
        fill_trimmed(
            &mut self.mask[row * w..(row + 1) * w],
            n,
            false,
            known,
            fill,
        );
    }

    /// An index from which every action of row `row`'s mask is known illegal: where the last
    /// [`write_mask_trimmed`](Self::write_mask_trimmed) of the row ended them, else the mask's
    /// width (0 without a mask). A masked argmax over the actions before it picks what it picks
    /// over all of them.
    pub fn legal_end(&self, row: usize) -> usize {
        let w = self.mask_width;
        self.illegal_from
            .get(row)
            .map_or(w, |&k| (k as usize).min(w))
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
        for (d, dim) in self.data.iter_mut().zip(&self.widths) {
            if d.len() < rows * dim {
                d.grow(rows * dim);
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

    /// Overwrites row `row` (which must be `< len`) with `obs`. A float tensor must be `float32`;
    /// an integer tensor `int32` or `uint8`.
    pub fn write_row(&mut self, row: usize, obs: &Observation) -> Result<(), PolicyError> {
        self.forget_zeros(None, row);
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
            let width = self.widths[i];
            let at = row * width..(row + 1) * width;
            let s = ..width;
            match (&mut self.data[i], &t.data) {
                (Rows::F32(d), TensorData::F32(v)) => copy_slice(&mut d[at], &v[s]),
                (Rows::I32(d), TensorData::I32(v)) => copy_slice(&mut d[at], &v[s]),
                (Rows::I32(d), TensorData::U8(v)) => d[at]
                    .iter_mut()
                    .zip(&v[s])
                    .for_each(|(d, v)| *d = i32::from(*v)),
                (rows, data) => {
                    let expected = match rows {
                        Rows::F32(_) => "float32",
                        Rows::I32(_) => "int32",
                    };
                    return Err(PolicyError::BadObservation(format!(
                        "tensor `{name}` is {}, the policy expects {expected}",
                        data.dtype()
                    )));
                }
            }
        }
        let w = self.mask_width;
        if w > 0 {
            self.forget_illegal(row);
            let m = &mut self.mask[row * w..(row + 1) * w];
            match &obs.action_mask {
                Some(src) if src.len() == w => copy_slice(m, src),
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

    /// Copies row `src_row` of `src` (same layout, keeping at least the tensors `self` keeps)
    /// into row `row` of `self`.
    pub fn copy_row(&mut self, row: usize, src: &ObsBatch, src_row: usize) {
        self.forget_zeros(None, row);
        for (i, (dim, from)) in self.widths.iter().zip(&src.widths).enumerate() {
            self.data[i].copy_range(row * dim, &src.data[i], src_row * from, *dim);
        }
        let w = self.mask_width;
        if w > 0 {
            self.forget_illegal(row);
            copy_slice(
                &mut self.mask[row * w..(row + 1) * w],
                &src.mask[src_row * w..(src_row + 1) * w],
            );
        }
    }

    /// Makes `self` the rows `rows` of `src`, in that order.
    pub fn gather(&mut self, src: &ObsBatch, rows: &[usize]) {
        self.resize(rows.len());
        for (r, &s) in rows.iter().enumerate() {
            self.copy_row(r, src, s);
        }
    }

    /// Whether tensor `i` holds integers (read with [`ints`](Self::ints)).
    pub fn is_integer(&self, i: usize) -> bool {
        matches!(self.data[i], Rows::I32(_))
    }

    /// All rows of float tensor `i`, `[len, dim]` (empty for an integer tensor).
    pub fn tensor(&self, i: usize) -> &[f32] {
        match &self.data[i] {
            Rows::F32(v) => &v[..self.len * self.widths[i]],
            Rows::I32(_) => &[],
        }
    }

    /// All rows of integer tensor `i`, `[len, dim]`, exact (empty for a float tensor).
    pub fn ints(&self, i: usize) -> &[i32] {
        match &self.data[i] {
            Rows::I32(v) => &v[..self.len * self.widths[i]],
            Rows::F32(_) => &[],
        }
    }

    /// Row `row` of float tensor `i` (empty for an integer tensor).
    pub fn tensor_row(&self, i: usize, row: usize) -> &[f32] {
        let d = self.widths[i];
        match &self.data[i] {
            Rows::F32(v) => &v[row * d..(row + 1) * d],
            Rows::I32(_) => &[],
        }
    }

    /// Row `row` of integer tensor `i` (empty for a float tensor).
    pub fn int_row(&self, i: usize, row: usize) -> &[i32] {
        let d = self.widths[i];
        match &self.data[i] {
            Rows::I32(v) => &v[row * d..(row + 1) * d],
            Rows::F32(_) => &[],
        }
    }

    /// Legal-action mask of row `row`, mutable (`None` for continuous action spaces).
    pub fn mask_mut(&mut self, row: usize) -> Option<&mut [bool]> {
        self.forget_illegal(row);
        let w = self.mask_width;
        (w > 0).then(|| &mut self.mask[row * w..(row + 1) * w])
    }

    /// Row `row` of float tensor `i`, mutable (for normalisation in place; empty for an integer
    /// tensor).
    pub fn row_mut(&mut self, i: usize, row: usize) -> &mut [f32] {
        self.forget_zeros(Some(i), row);
        let d = self.widths[i];
        match &mut self.data[i] {
            Rows::F32(v) => &mut v[row * d..(row + 1) * d],
            Rows::I32(_) => &mut [],
        }
    }

    /// Row `row` of integer tensor `i`, mutable (empty for a float tensor).
    pub fn int_row_mut(&mut self, i: usize, row: usize) -> &mut [i32] {
        self.forget_zeros(Some(i), row);
        let d = self.widths[i];
        match &mut self.data[i] {
            Rows::I32(v) => &mut v[row * d..(row + 1) * d],
            Rows::F32(_) => &mut [],
        }
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

    /// Writes all tensors of every row, concatenated and converted to `f32`, into `out`
    /// (`[len, total_dim]`): the input of flat MLPs.
    pub fn concat_into(&self, out: &mut Vec<f32>) {
        debug_assert_eq!(self.widths, self.dims, "a flat network reads every tensor");
        let total: usize = self.dims.iter().sum();
        crate::nn::ensure(out, self.len * total);
        for r in 0..self.len {
            let mut at = r * total;
            for (i, d) in self.dims.iter().enumerate() {
                let dst = &mut out[at..at + d];
                match &self.data[i] {
                    Rows::F32(v) => dst.copy_from_slice(&v[r * d..(r + 1) * d]),
                    Rows::I32(v) => dst
                        .iter_mut()
                        .zip(&v[r * d..(r + 1) * d])
                        .for_each(|(o, x)| *o = *x as f32),
                }
                at += d;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use a2perf_core::Tensor;

    fn layout() -> ObsLayout {
        ObsLayout {
            tensors: vec![("ids".into(), vec![2]), ("x".into(), vec![1])],
            dtypes: vec![DType::I32, DType::F32],
            num_actions: None,
        }
    }

    #[test]
    fn integer_rows_are_exact_and_floats_convert_for_flat_networks() {
        let big = (1 << 24) + 1;
        let mut b = ObsBatch::new(&layout());
        let obs = Observation {
            tensors: vec![
                Tensor::new("ids", &[2], vec![big, 3]),
                Tensor::new("x", &[1], vec![0.5f32]),
            ],
            action_mask: None,
        };
        b.push(&obs).unwrap();
        assert!(b.is_integer(0) && !b.is_integer(1));
        assert_eq!(b.ints(0), &[big, 3]);
        assert_eq!(b.tensor(1), &[0.5]);
        assert!(b.tensor(0).is_empty() && b.ints(1).is_empty());
        let mut x = Vec::new();
        b.concat_into(&mut x);
        assert_eq!(x, vec![big as f32, 3.0, 0.5]);
        // uint8 tensors widen into the integer rows.
        let small = Observation {
            tensors: vec![
                Tensor::new("ids", &[2], vec![7u8, 255]),
                Tensor::new("x", &[1], vec![1.0f32]),
            ],
            action_mask: None,
        };
        b.write_row(0, &small).unwrap();
        assert_eq!(b.ints(0), &[7, 255]);
    }

    #[test]
    fn a_batch_keeping_some_tensors_still_checks_the_others() {
        let obs = |ids: Vec<i32>| Observation {
            tensors: vec![
                Tensor::new("ids", &[ids.len()], ids),
                Tensor::new("x", &[1], vec![0.5f32]),
            ],
            action_mask: None,
        };
        let mut full = ObsBatch::new(&layout());
        let mut kept = ObsBatch::new(&layout());
        kept.keep_tensors(&[1]);
        for b in [&mut full, &mut kept] {
            b.push(&obs(vec![4, 5])).unwrap();
            b.push(&obs(vec![6, 7])).unwrap();
        }
        assert_eq!(full.ints(0), &[4, 5, 6, 7]);
        assert!(kept.ints(0).is_empty() && kept.int_row(0, 1).is_empty());
        assert_eq!(
            (kept.tensor(1), kept.tensor_row(1, 1)),
            (&[0.5, 0.5][..], &[0.5][..])
        );
        assert_eq!(kept.dim(0), 2);
        // A tensor it does not keep is still checked: bad input is refused, not dropped.
        let err = kept.push(&obs(vec![1, 2, 3])).unwrap_err().to_string();
        assert!(err.contains("`ids` has 3 values"), "{err}");
        // Rows copied in from a batch that keeps everything.
        let mut copy = ObsBatch::new(&layout());
        copy.keep_tensors(&[1]);
        copy.gather(&full, &[1, 0]);
        assert_eq!(copy.tensor(1), &[0.5, 0.5]);
        assert!(copy.ints(0).is_empty());
    }

    #[test]
    fn a_tensor_of_the_wrong_type_is_refused_by_name() {
        let mut b = ObsBatch::new(&layout());
        let floats = Observation {
            tensors: vec![
                Tensor::new("ids", &[2], vec![1.0f32, 2.0]),
                Tensor::new("x", &[1], vec![0.5f32]),
            ],
            action_mask: None,
        };
        let err = b.push(&floats).unwrap_err().to_string();
        assert!(
            err.contains("`ids` is float32") && err.contains("int32"),
            "{err}"
        );
    }

    #[test]
    fn layouts_from_specs_carry_dtypes_and_refuse_int64() {
        let spec = |dtype| EnvSpec {
            id: "T-v0".into(),
            observation_space: Space::Dict(vec![
                ("a".into(), Space::uniform_box(&[1], 0.0, 1.0)),
                ("b".into(), Space::uniform_box_of(&[2], dtype, 0.0, 9.0)),
            ]),
            action_space: Space::Discrete { n: 2 },
            max_episode_steps: None,
            metadata: Default::default(),
        };
        let l = ObsLayout::from_spec(&spec(DType::I32)).unwrap();
        assert_eq!(l.dtypes, vec![DType::F32, DType::I32]);
        assert!(l.same_shapes(&ObsLayout::floats(l.tensors.clone(), Some(2))));
        let err = ObsLayout::from_spec(&spec(DType::I64))
            .unwrap_err()
            .to_string();
        assert!(err.contains("`b` is int64"), "{err}");
    }
}
