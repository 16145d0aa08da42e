//! Token embeddings with masked mean pooling.

use a2perf_core::RngStream;
use serde::{Deserialize, Serialize};

use super::ParamAlloc;

/// An embedding table `[vocab, dim]`, looked up with `int32` token ids. Token id 0 is padding and never contributes; ids at or above
/// `vocab` share the last row (an out-of-vocabulary bucket), so unseen ids cannot index out of
/// bounds.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Embedding {
    /// Vocabulary size (rows).
    pub vocab: usize,
    /// Embedding width.
    pub dim: usize,
    /// Offset of the table in the parameter vector.
    pub offset: usize,
}

impl Embedding {
    /// A table whose parameters are reserved from `alloc`.
    pub fn new(alloc: &mut ParamAlloc, vocab: usize, dim: usize) -> Self {
        let vocab = vocab.max(2);
        let offset = alloc.take(vocab * dim);
        Self { vocab, dim, offset }
    }

    /// Small normal initialisation (σ = 1/√dim).
    pub fn init(&self, params: &mut [f32], rng: &mut RngStream) {
        let s = 1.0 / (self.dim as f64).sqrt();
        for p in &mut params[self.offset..self.offset + self.vocab * self.dim] {
            *p = (rng.normal() * s) as f32;
        }
    }

    /// The table row of `token`, or `None` for padding.
    pub(crate) fn row(&self, token: i32) -> Option<usize> {
        // Padding (0) and negative ids do not contribute.
        let id = usize::try_from(token).ok().filter(|&id| id > 0)?;
        Some(id.min(self.vocab - 1))
    }

    /// For each group of `len` tokens in `tokens`, writes the mean embedding of its non-padding
    /// tokens into `out[group, dim]` (zeros for an all-padding group).
    ///
    /// ```
    /// use a2perf_baselines::nn::{ParamAlloc, embed::Embedding};
    /// let mut alloc = ParamAlloc::new();
    /// let e = Embedding::new(&mut alloc, 3, 2);
    /// let params = vec![0.0, 0.0, 1.0, 2.0, 3.0, 4.0];
    /// let mut out = vec![0.0; 4];
    /// e.pool(&params, &[1, 2, 0, 0], 2, &mut out);
    /// assert_eq!(out, vec![2.0, 3.0, 0.0, 0.0]);
    /// ```
    pub fn pool(&self, params: &[f32], tokens: &[i32], len: usize, out: &mut [f32]) {
        let table = &params[self.offset..self.offset + self.vocab * self.dim];
        for (group, o) in tokens.chunks_exact(len).zip(out.chunks_exact_mut(self.dim)) {
            o.fill(0.0);
            let mut count = 0usize;
            for &t in group {
                if let Some(r) = self.row(t) {
                    count += 1;
                    for (o, w) in o.iter_mut().zip(&table[r * self.dim..(r + 1) * self.dim]) {
                        *o += w;
                    }
                }
            }
            if count > 1 {
                let inv = 1.0 / count as f32;
                o.iter_mut().for_each(|x| *x *= inv);
            }
        }
    }

    /// Accumulates the table gradient of [`pool`](Self::pool) given `dout[group, dim]`.
    pub fn pool_backward(&self, grads: &mut [f32], tokens: &[i32], len: usize, dout: &[f32]) {
        let table = &mut grads[self.offset..self.offset + self.vocab * self.dim];
        for (group, d) in tokens.chunks_exact(len).zip(dout.chunks_exact(self.dim)) {
            let count = group.iter().filter(|t| self.row(**t).is_some()).count();
            if count == 0 {
                continue;
            }
            let inv = 1.0 / count as f32;
            for &t in group {
                if let Some(r) = self.row(t) {
                    for (g, d) in table[r * self.dim..(r + 1) * self.dim].iter_mut().zip(d) {
                        *g += d * inv;
                    }
                }
            }
        }
    }
}
