//! Small neural networks on faer: layers, MLPs, embeddings, distributions and the optimiser.
//!
//! Every network is a *structure* (layer sizes and offsets into a flat parameter vector) plus
//! explicit *workspaces* holding activations. Parameters and gradients are plain `Vec<f32>`s,
//! which makes the optimiser, gradient clipping, Polyak averaging and checkpoints one loop each,
//! and lets one structure run with several parameter vectors (online and target networks).
//!
//! Activations are row-major `[batch, features]`. Workspaces grow to the largest batch seen and
//! are reused afterwards, so forward and backward passes allocate nothing in the steady state.

pub mod dist;
pub mod embed;
pub mod norm;
pub mod optim;
pub mod tanh;

use a2perf_core::RngStream;
use faer::{Accum, MatMut, MatRef, Par};
use serde::{Deserialize, Serialize};

/// `dst = lhs·rhs` ([`Accum::Replace`]) or `dst += lhs·rhs` ([`Accum::Add`]) on this thread:
/// faer's GEMM, then [`clear_upper_simd`], as its kernels return with the upper halves of the
/// 256-bit registers in use. Every network here multiplies through it.
pub(crate) fn gemm(dst: MatMut<'_, f32>, accum: Accum, lhs: MatRef<'_, f32>, rhs: MatRef<'_, f32>) {
    faer::linalg::matmul::matmul(dst, accum, lhs, rhs, 1.0f32, Par::Seq);
    clear_upper_simd();
}

/// Marks the upper halves of the 256-bit registers unused (`vzeroupper`) when the CPU has AVX;
/// does nothing elsewhere. Values are untouched. Scalar float code compiled for baseline
/// x86-64 (legacy SSE encoding) that calls a VEX-encoded libm routine (`expf`, `logf`) while
/// those halves are in use pays a state transition at each call and return on CPUs that save
/// and restore them: measured here, a masked softmax over 12,500 logits right after a faer
/// GEMM ran about 10× slower than after `vzeroupper`.
///
/// ```
/// a2perf_baselines::nn::clear_upper_simd();
/// ```
#[inline]
pub fn clear_upper_simd() {
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx") {
        // SAFETY: the CPU has AVX (checked just above), all `zero_upper` needs.
        unsafe { zero_upper() }
    }
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx")]
fn zero_upper() {
    std::arch::x86_64::_mm256_zeroupper();
}

/// Grows `buf` to at least `len` elements (never shrinks, so steady state allocates nothing).
pub(crate) fn ensure(buf: &mut Vec<f32>, len: usize) {
    if buf.len() < len {
        buf.resize(len, 0.0);
    }
}

/// Hands out consecutive ranges of a flat parameter vector.
#[derive(Clone, Debug, Default)]
pub struct ParamAlloc {
    next: usize,
}

impl ParamAlloc {
    /// An empty allocator.
    pub fn new() -> Self {
        Self::default()
    }
    /// Reserves `n` parameters and returns their offset.
    pub fn take(&mut self, n: usize) -> usize {
        let at = self.next;
        self.next += n;
        at
    }
    /// Total parameters reserved so far.
    pub fn len(&self) -> usize {
        self.next
    }
    /// Whether nothing was reserved.
    pub fn is_empty(&self) -> bool {
        self.next == 0
    }
}

/// A fully connected layer `y = x Wᵀ + b`, with `W` stored row-major `[out, in]` followed by `b`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Linear {
    /// Input features.
    pub inp: usize,
    /// Output features.
    pub out: usize,
    /// Offset of `W` in the parameter vector (`b` follows it).
    pub offset: usize,
}

impl Linear {
    /// A layer whose parameters are reserved from `alloc`.
    pub fn new(alloc: &mut ParamAlloc, inp: usize, out: usize) -> Self {
        let offset = alloc.take(inp * out + out);
        Self { inp, out, offset }
    }

    pub(crate) fn w_range(&self) -> std::ops::Range<usize> {
        self.offset..self.offset + self.inp * self.out
    }

    pub(crate) fn b_range(&self) -> std::ops::Range<usize> {
        let s = self.offset + self.inp * self.out;
        s..s + self.out
    }

    /// Uniform `±gain·√(3/in)` weights (variance `gain²/in`, LeCun-style) and zero biases.
    pub fn init(&self, params: &mut [f32], rng: &mut RngStream, gain: f32) {
        let k = gain * (3.0 / self.inp.max(1) as f32).sqrt();
        for w in &mut params[self.w_range()] {
            *w = (rng.uniform_f32() * 2.0 - 1.0) * k;
        }
        params[self.b_range()].fill(0.0);
    }

    /// `y[b, out] = x[b, in] Wᵀ + bias` for the first `batch` rows.
    pub fn forward(&self, params: &[f32], x: &[f32], batch: usize, y: &mut [f32]) {
        let bias = &params[self.b_range()];
        let y = &mut y[..batch * self.out];
        if batch == 0 {
            return;
        }
        // Every row starts as the bias: the first row copied, then the filled rows doubled
        // (a copy per row is a `memmove` call per row, and the circuit network's per-cell
        // layer has batch × cells rows of 50).
        y[..self.out].copy_from_slice(bias);
        let mut filled = self.out;
        while filled < y.len() {
            let n = filled.min(y.len() - filled);
            y.copy_within(..n, filled);
            filled += n;
        }
        let xm = MatRef::from_row_major_slice(&x[..batch * self.inp], batch, self.inp);
        let wm = MatRef::from_row_major_slice(&params[self.w_range()], self.out, self.inp);
        let ym = MatMut::from_row_major_slice_mut(y, batch, self.out);
        gemm(ym, Accum::Add, xm, wm.transpose());
    }

    /// Accumulates `dW += dyᵀ x`, `db += Σ dy` into `grads`, and writes `dx = dy W` when asked.
    pub fn backward(
        &self,
        params: &[f32],
        grads: &mut [f32],
        x: &[f32],
        dy: &[f32],
        batch: usize,
        dx: Option<&mut [f32]>,
    ) {
        self.backward_at(params, grads, 0, x, dy, batch, dx);
    }

    /// [`backward`](Self::backward) into a part of the gradient vector: `grads[0]` is the
    /// gradient of parameter `base`.
    #[allow(clippy::too_many_arguments)] // backward's arguments and the part's offset
    fn backward_at(
        &self,
        params: &[f32],
        grads: &mut [f32],
        base: usize,
        x: &[f32],
        dy: &[f32],
        batch: usize,
        dx: Option<&mut [f32]>,
    ) {
        if batch == 0 {
            return;
        }
        let shift = |r: std::ops::Range<usize>| r.start - base..r.end - base;
        let dy = &dy[..batch * self.out];
        let dym = MatRef::from_row_major_slice(dy, batch, self.out);
        let xm = MatRef::from_row_major_slice(&x[..batch * self.inp], batch, self.inp);
        {
            let gw = MatMut::from_row_major_slice_mut(
                &mut grads[shift(self.w_range())],
                self.out,
                self.inp,
            );
            gemm(gw, Accum::Add, dym.transpose(), xm);
        }
        let gb = &mut grads[shift(self.b_range())];
        for row in dy.chunks_exact(self.out) {
            for (g, d) in gb.iter_mut().zip(row) {
                *g += d;
            }
        }
        if let Some(dx) = dx {
            self.backward_input(params, dy, batch, dx);
        }
    }

    /// Writes the input gradient `dx = dy W` alone, the same values as
    /// [`backward`](Self::backward)'s, without the parameter gradients: for a caller that
    /// needs the gradient with respect to the input only (SAC's actor, through its critics).
    pub fn backward_input(&self, params: &[f32], dy: &[f32], batch: usize, dx: &mut [f32]) {
        self.backward_input_cols(params, dy, batch, 0..self.inp, dx);
    }

    /// The input gradient's columns `cols` alone, `dx[b, cols.len()] = dy W[:, cols]`: the
    /// same values as those columns of [`backward_input`](Self::backward_input)'s (each is a
    /// sum over the layer's outputs in the same order), at `cols.len() / inp` of the work.
    ///
    /// ```
    /// use a2perf_baselines::nn::{Linear, ParamAlloc};
    /// let mut alloc = ParamAlloc::new();
    /// let layer = Linear::new(&mut alloc, 4, 3);
    /// let params: Vec<f32> = (0..alloc.len()).map(|i| (i as f32 * 0.61).cos()).collect();
    /// let dy = [0.3, -1.0, 0.5, 2.0, 0.25, -0.75];
    /// let mut dx = [0.0; 8];
    /// layer.backward_input(&params, &dy, 2, &mut dx);
    /// let mut part = [0.0; 4];
    /// layer.backward_input_cols(&params, &dy, 2, 1..3, &mut part);
    /// assert_eq!(part, [dx[1], dx[2], dx[5], dx[6]]);
    /// ```
    pub fn backward_input_cols(
        &self,
        params: &[f32],
        dy: &[f32],
        batch: usize,
        cols: std::ops::Range<usize>,
        dx: &mut [f32],
    ) {
        if batch == 0 {
            return;
        }
        let n = cols.len();
        let dym = MatRef::from_row_major_slice(&dy[..batch * self.out], batch, self.out);
        let wm = MatRef::from_row_major_slice(&params[self.w_range()], self.out, self.inp)
            .subcols(cols.start, n);
        let dxm = MatMut::from_row_major_slice_mut(&mut dx[..batch * n], batch, n);
        gemm(dxm, Accum::Replace, dym, wm);
    }
}

/// Hidden-layer nonlinearity.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum Activation {
    /// `max(0, x)`.
    Relu,
    /// `tanh(x)`.
    Tanh,
}

impl Activation {
    /// Applies the nonlinearity in place.
    pub fn apply(self, v: &mut [f32]) {
        match self {
            Activation::Relu => v.iter_mut().for_each(|x| *x = x.max(0.0)),
            Activation::Tanh => tanh::tanh_in_place(v),
        }
    }

    /// Multiplies `d` by the derivative, expressed through the activation's *output* `y`.
    pub fn backward(self, y: &[f32], d: &mut [f32]) {
        match self {
            // A select, not a conditional store: the loop vectorizes, where the branch on a
            // sign that is random from element to element mispredicted about half the time
            // (it cost SAC's learning about as much as the layer's GEMM).
            Activation::Relu => {
                for (d, y) in d.iter_mut().zip(y) {
                    *d = if *y <= 0.0 { 0.0 } else { *d };
                }
            }
            Activation::Tanh => {
                for (d, y) in d.iter_mut().zip(y) {
                    *d *= 1.0 - y * y;
                }
            }
        }
    }
}

/// A multi-layer perceptron: linear layers with a nonlinearity between them (none after the last).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Mlp {
    /// The layers, input first.
    pub layers: Vec<Linear>,
    /// Nonlinearity after every layer but the last.
    pub activation: Activation,
    /// Also apply the nonlinearity after the last layer (for encoders feeding other layers).
    #[serde(default)]
    pub activate_last: bool,
}

/// Activations of one [`Mlp`] pass (reused between calls).
#[derive(Clone, Debug, Default)]
pub struct MlpWs {
    outs: Vec<Vec<f32>>,
    d_a: Vec<f32>,
    d_b: Vec<f32>,
    batch: usize,
}

impl Mlp {
    /// An MLP `sizes[0] → sizes[1] → … → sizes[last]`.
    ///
    /// ```
    /// use a2perf_baselines::nn::{Activation, Mlp, MlpWs, ParamAlloc};
    /// use a2perf_core::RngStream;
    /// let mut alloc = ParamAlloc::new();
    /// let mlp = Mlp::new(&mut alloc, &[3, 8, 2], Activation::Relu);
    /// let mut params = vec![0.0; alloc.len()];
    /// mlp.init(&mut params, &mut RngStream::new(0, "init"), 1.0);
    /// let mut ws = MlpWs::default();
    /// let y = mlp.forward(&params, &[0.1, 0.2, 0.3, 1.0, 0.0, -1.0], 2, &mut ws);
    /// assert_eq!(y.len(), 4);
    /// ```
    pub fn new(alloc: &mut ParamAlloc, sizes: &[usize], activation: Activation) -> Self {
        let layers = sizes
            .windows(2)
            .map(|w| Linear::new(alloc, w[0], w[1]))
            .collect();
        Self {
            layers,
            activation,
            activate_last: false,
        }
    }

    /// Like [`new`](Self::new) but with the nonlinearity applied to the output too.
    pub fn encoder(alloc: &mut ParamAlloc, sizes: &[usize], activation: Activation) -> Self {
        Self {
            activate_last: true,
            ..Self::new(alloc, sizes, activation)
        }
    }

    /// Input features.
    pub fn inp(&self) -> usize {
        self.layers.first().map_or(0, |l| l.inp)
    }

    /// Output features.
    pub fn out(&self) -> usize {
        self.layers.last().map_or(0, |l| l.out)
    }

    /// Initialises hidden layers with gain √2 (ReLU) or 1 (tanh) and the last with `last_gain`.
    pub fn init(&self, params: &mut [f32], rng: &mut RngStream, last_gain: f32) {
        let hidden_gain = match self.activation {
            Activation::Relu => std::f32::consts::SQRT_2,
            Activation::Tanh => 1.0,
        };
        let n = self.layers.len();
        for (i, l) in self.layers.iter().enumerate() {
            l.init(
                params,
                rng,
                if i + 1 == n { last_gain } else { hidden_gain },
            );
        }
    }

    /// Forward pass over `batch` rows of `x`; returns the output `[batch, out]`.
    pub fn forward<'w>(
        &self,
        params: &[f32],
        x: &[f32],
        batch: usize,
        ws: &'w mut MlpWs,
    ) -> &'w [f32] {
        self.forward_with_first(params, batch, ws, |first, out| {
            first.forward(params, x, batch, out)
        })
    }

    /// Forward pass whose first layer is computed by `first(layer, out)`, which writes the
    /// layer's pre-activation `[batch, layers[0].out]` into `out`; the nonlinearity and the other
    /// layers run as in [`forward`](Self::forward). For callers that compute the first layer
    /// more cheaply than from an explicit input (the web network's projected embeddings).
    ///
    /// ```
    /// use a2perf_baselines::nn::{Activation, Mlp, MlpWs, ParamAlloc};
    /// use a2perf_core::RngStream;
    /// let mut alloc = ParamAlloc::new();
    /// let mlp = Mlp::new(&mut alloc, &[3, 8, 2], Activation::Relu);
    /// let mut params = vec![0.0; alloc.len()];
    /// mlp.init(&mut params, &mut RngStream::new(0, "init"), 1.0);
    /// let x = [0.1, 0.2, 0.3];
    /// let y = mlp.forward(&params, &x, 1, &mut MlpWs::default()).to_vec();
    /// let mut ws = MlpWs::default();
    /// let z = mlp.forward_with_first(&params, 1, &mut ws, |l, out| l.forward(&params, &x, 1, out));
    /// assert_eq!(y, z);
    /// ```
    pub fn forward_with_first<'w>(
        &self,
        params: &[f32],
        batch: usize,
        ws: &'w mut MlpWs,
        first: impl FnOnce(&Linear, &mut [f32]),
    ) -> &'w [f32] {
        if ws.outs.len() != self.layers.len() {
            ws.outs = vec![Vec::new(); self.layers.len()];
        }
        ws.batch = batch;
        let n = self.layers.len();
        let mut first = Some(first);
        for i in 0..n {
            let layer = &self.layers[i];
            let (before, rest) = ws.outs.split_at_mut(i);
            let out = &mut rest[0];
            ensure(out, batch * layer.out);
            match first.take() {
                Some(f) => f(layer, &mut out[..batch * layer.out]),
                None => layer.forward(params, &before[i - 1], batch, out),
            }
            if i + 1 < n || self.activate_last {
                self.activation.apply(&mut out[..batch * layer.out]);
            }
        }
        ws.outs.last().map_or(&[][..], |o| &o[..batch * self.out()])
    }

    /// Keeps the rows `rows` (ascending, each below the last pass's batch) of the last forward
    /// pass in `ws` and drops the others, as if that pass had run on those rows alone: a
    /// backward pass then costs what the kept rows need. Each row's activations depend on its
    /// own input only, so the kept ones are bit for bit those of a pass over the kept rows.
    ///
    /// ```
    /// use a2perf_baselines::nn::{Activation, Mlp, MlpWs, ParamAlloc};
    /// let mut alloc = ParamAlloc::new();
    /// let mlp = Mlp::new(&mut alloc, &[2, 3, 1], Activation::Relu);
    /// let params: Vec<f32> = (0..alloc.len()).map(|i| (i as f32 * 0.37).sin()).collect();
    /// let x = [0.5, -1.0, 2.0, 0.25, -0.5, 1.5];
    /// let mut ws = MlpWs::default();
    /// mlp.forward(&params, &x, 3, &mut ws);
    /// let all = mlp.output(&ws).to_vec();
    /// mlp.keep_rows(&mut ws, &[0, 2]);
    /// assert_eq!(mlp.output(&ws), [all[0], all[2]]);
    /// let (mut dx, mut dx_all) = ([0.0; 4], [0.0; 6]);
    /// mlp.backward_input(&params, &[1.0, 1.0], &mut ws, &mut dx);
    /// mlp.forward(&params, &x, 3, &mut ws);
    /// mlp.backward_input(&params, &[1.0, 0.0, 1.0], &mut ws, &mut dx_all);
    /// assert_eq!(dx, [dx_all[0], dx_all[1], dx_all[4], dx_all[5]]);
    /// ```
    ///
    /// # Panics
    ///
    /// If `rows` does not ascend or names a row at or past the last pass's batch.
    pub fn keep_rows(&self, ws: &mut MlpWs, rows: &[usize]) {
        assert!(
            rows.windows(2).all(|w| w[0] < w[1]) && rows.last().is_none_or(|&r| r < ws.batch),
            "Mlp::keep_rows: rows must ascend and lie below the batch ({})",
            ws.batch
        );
        for (out, layer) in ws.outs.iter_mut().zip(&self.layers) {
            let w = layer.out;
            for (j, &r) in rows.iter().enumerate() {
                if j != r {
                    out.copy_within(r * w..(r + 1) * w, j * w);
                }
            }
        }
        ws.batch = rows.len();
    }

    /// The output of the last [`forward`](Self::forward).
    pub fn output<'w>(&self, ws: &'w MlpWs) -> &'w [f32] {
        ws.outs
            .last()
            .map_or(&[][..], |o| &o[..ws.batch * self.out()])
    }

    /// Backward pass for the last forward over `x`: accumulates parameter gradients and writes the
    /// input gradient into `dx` when asked.
    pub fn backward(
        &self,
        params: &[f32],
        grads: &mut [f32],
        x: &[f32],
        dout: &[f32],
        ws: &mut MlpWs,
        dx: Option<&mut [f32]>,
    ) {
        self.backward_into(params, grads, 0, x, dout, ws, dx);
    }

    /// The span of the parameter vector this MLP's layers occupy (empty for no layers).
    ///
    /// ```
    /// use a2perf_baselines::nn::{Activation, Mlp, ParamAlloc};
    /// let mut alloc = ParamAlloc::new();
    /// let first = Mlp::new(&mut alloc, &[3, 4, 2], Activation::Tanh);
    /// let second = Mlp::new(&mut alloc, &[3, 1], Activation::Tanh);
    /// assert_eq!(first.param_range(), 0..(3 * 4 + 4) + (4 * 2 + 2));
    /// assert_eq!(second.param_range(), 26..30);
    /// ```
    pub fn param_range(&self) -> std::ops::Range<usize> {
        let start = self.layers.iter().map(|l| l.offset).min().unwrap_or(0);
        let end = self
            .layers
            .iter()
            .map(|l| l.b_range().end)
            .max()
            .unwrap_or(start);
        start..end
    }

    /// [`backward`](Self::backward) with the gradients written into `grads`, the part of the
    /// gradient vector over [`param_range`](Self::param_range) alone: so that two networks
    /// whose parameters do not overlap can run their backward passes at the same time, each
    /// into its own part. The values are those [`backward`](Self::backward) accumulates.
    ///
    /// ```
    /// use a2perf_baselines::nn::{Activation, Mlp, MlpWs, ParamAlloc};
    /// let mut alloc = ParamAlloc::new();
    /// let _before = alloc.take(5);
    /// let mlp = Mlp::new(&mut alloc, &[3, 4, 2], Activation::Tanh);
    /// let params: Vec<f32> = (0..alloc.len()).map(|i| (i as f32 * 0.37).sin()).collect();
    /// let (x, dout) = ([0.5, -1.0, 2.0], [1.0, -0.5]);
    /// let mut ws = MlpWs::default();
    /// mlp.forward(&params, &x, 1, &mut ws);
    /// let mut grads = vec![0.0; params.len()];
    /// mlp.backward(&params, &mut grads, &x, &dout, &mut ws, None);
    /// let mut part = vec![0.0; mlp.param_range().len()];
    /// mlp.backward_local(&params, &mut part, &x, &dout, &mut ws, None);
    /// assert_eq!(part, grads[mlp.param_range()]);
    /// ```
    pub fn backward_local(
        &self,
        params: &[f32],
        grads: &mut [f32],
        x: &[f32],
        dout: &[f32],
        ws: &mut MlpWs,
        dx: Option<&mut [f32]>,
    ) {
        self.backward_into(params, grads, self.param_range().start, x, dout, ws, dx);
    }

    /// The backward pass into a gradient part starting at parameter `base`.
    #[allow(clippy::too_many_arguments)] // backward's arguments and the part's offset
    fn backward_into(
        &self,
        params: &[f32],
        grads: &mut [f32],
        base: usize,
        x: &[f32],
        dout: &[f32],
        ws: &mut MlpWs,
        dx: Option<&mut [f32]>,
    ) {
        let batch = ws.batch;
        let Some(first) = self.layers.first() else {
            return;
        };
        let d = self.backward_layers(params, Some((&mut *grads, base)), dout, ws);
        first.backward_at(params, grads, base, x, d, batch, dx);
    }

    /// Backward pass through every layer but the first: accumulates those layers' parameter
    /// gradients and returns the gradient of the first layer's pre-activation
    /// `[batch, layers[0].out]`, for a caller that computed the first layer itself
    /// ([`forward_with_first`](Self::forward_with_first)).
    pub fn backward_to_first<'w>(
        &self,
        params: &[f32],
        grads: &mut [f32],
        dout: &[f32],
        ws: &'w mut MlpWs,
    ) -> &'w [f32] {
        self.backward_layers(params, Some((grads, 0)), dout, ws)
    }

    /// The input gradient `dx` `[batch, inp]` of the last forward alone, the same values as
    /// [`backward`](Self::backward) writes, without any parameter gradient (half the
    /// multiplications of a backward pass).
    ///
    /// ```
    /// use a2perf_baselines::nn::{Activation, Mlp, MlpWs, ParamAlloc};
    /// let mut alloc = ParamAlloc::new();
    /// let mlp = Mlp::new(&mut alloc, &[3, 4, 2], Activation::Tanh);
    /// let params: Vec<f32> = (0..alloc.len()).map(|i| (i as f32 * 0.37).sin()).collect();
    /// let (x, dout) = ([0.5, -1.0, 2.0], [1.0, -0.5]);
    /// let mut ws = MlpWs::default();
    /// mlp.forward(&params, &x, 1, &mut ws);
    /// let (mut grads, mut dx) = (vec![0.0; params.len()], [0.0; 3]);
    /// mlp.backward(&params, &mut grads, &x, &dout, &mut ws, Some(&mut dx));
    /// let mut dx_alone = [0.0; 3];
    /// mlp.backward_input(&params, &dout, &mut ws, &mut dx_alone);
    /// assert_eq!(dx, dx_alone);
    /// ```
    pub fn backward_input(&self, params: &[f32], dout: &[f32], ws: &mut MlpWs, dx: &mut [f32]) {
        let inp = self.layers.first().map_or(0, |l| l.inp);
        self.backward_input_cols(params, dout, ws, 0..inp, dx);
    }

    /// The input gradient's columns `cols` alone (`dx` `[batch, cols.len()]`), the same values
    /// as those columns of [`backward_input`](Self::backward_input)'s: for a caller that needs
    /// the gradient with respect to part of the input (SAC's actor: a critic's action columns).
    ///
    /// ```
    /// use a2perf_baselines::nn::{Activation, Mlp, MlpWs, ParamAlloc};
    /// let mut alloc = ParamAlloc::new();
    /// let mlp = Mlp::new(&mut alloc, &[3, 4, 1], Activation::Relu);
    /// let params: Vec<f32> = (0..alloc.len()).map(|i| (i as f32 * 0.37).sin()).collect();
    /// let mut ws = MlpWs::default();
    /// mlp.forward(&params, &[0.5, -1.0, 2.0], 1, &mut ws);
    /// let mut dx = [0.0; 3];
    /// mlp.backward_input(&params, &[1.0], &mut ws, &mut dx);
    /// let mut last = [0.0; 1];
    /// mlp.backward_input_cols(&params, &[1.0], &mut ws, 2..3, &mut last);
    /// assert_eq!(last[0], dx[2]);
    /// ```
    pub fn backward_input_cols(
        &self,
        params: &[f32],
        dout: &[f32],
        ws: &mut MlpWs,
        cols: std::ops::Range<usize>,
        dx: &mut [f32],
    ) {
        let batch = ws.batch;
        let Some(first) = self.layers.first() else {
            return;
        };
        let d = self.backward_layers(params, None, dout, ws);
        first.backward_input_cols(params, d, batch, cols, dx);
    }

    /// [`backward_to_first`](Self::backward_to_first), accumulating parameter gradients only
    /// when `grads` is given (with the parameter its first element belongs to).
    fn backward_layers<'w>(
        &self,
        params: &[f32],
        mut grads: Option<(&mut [f32], usize)>,
        dout: &[f32],
        ws: &'w mut MlpWs,
    ) -> &'w [f32] {
        let batch = ws.batch;
        let n = self.layers.len();
        let MlpWs { outs, d_a, d_b, .. } = ws;
        ensure(d_a, batch * self.out());
        d_a[..batch * self.out()].copy_from_slice(&dout[..batch * self.out()]);
        if self.activate_last
            && let Some(last) = outs.last()
        {
            self.activation
                .backward(&last[..batch * self.out()], &mut d_a[..batch * self.out()]);
        }
        for i in (1..n).rev() {
            let layer = &self.layers[i];
            ensure(d_b, batch * layer.inp);
            match grads.as_mut() {
                Some((g, base)) => {
                    layer.backward_at(params, g, *base, &outs[i - 1], d_a, batch, Some(d_b))
                }
                None => layer.backward_input(params, d_a, batch, d_b),
            }
            self.activation.backward(
                &outs[i - 1][..batch * layer.inp],
                &mut d_b[..batch * layer.inp],
            );
            std::mem::swap(d_a, d_b);
        }
        let inp = self.layers.first().map_or(0, |l| l.out);
        &d_a[..batch * inp]
    }
}

/// Global L2 norm of `grads`.
pub fn grad_norm(grads: &[f32]) -> f32 {
    grads
        .iter()
        .map(|g| f64::from(*g) * f64::from(*g))
        .sum::<f64>()
        .sqrt() as f32
}

/// Scales `grads` so that their global norm is at most `max_norm` (no-op when `max_norm <= 0`).
/// Returns the norm before clipping.
///
/// ```
/// let mut g = vec![3.0, 4.0];
/// assert_eq!(a2perf_baselines::nn::clip_grad_norm(&mut g, 1.0), 5.0);
/// assert!((g[0] - 0.6).abs() < 1e-6);
/// ```
pub fn clip_grad_norm(grads: &mut [f32], max_norm: f32) -> f32 {
    let norm = grad_norm(grads);
    if max_norm > 0.0 && norm > max_norm {
        let s = max_norm / (norm + 1e-6);
        grads.iter_mut().for_each(|g| *g *= s);
    }
    norm
}

/// `target ← (1−τ)·target + τ·online` (Polyak averaging of target networks).
pub fn polyak(target: &mut [f32], online: &[f32], tau: f32) {
    for (t, o) in target.iter_mut().zip(online) {
        *t += tau * (o - *t);
    }
}
