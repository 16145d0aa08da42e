//! The web navigation DOM–profile network (see the table in [`super`]).
//!
//! Its cost at learning batch sizes is the first layer of the element and field MLPs: an
//! element row is `[5 mean-pooled attribute embeddings ++ 8 DOM features]` (508 wide at the
//! paper's sizes) and a batch of 256 pages holds thousands of active elements. That layer is
//! linear after a mean, so for every token slot `s` with weight block `W_s` the pooled product
//! equals the mean of the rows of `P_s = E W_sᵀ` (`[vocab, latent]`, one small GEMM per slot):
//! the *projected* path ([`WebPath::Projected`]) gathers those rows instead of multiplying every
//! element row, and its backward scatters the gradient into `dP_s` and forms `dW_s = dP_sᵀ E`
//! and `dE += dP_s W_s`. It is exact in real arithmetic, not bit for bit. The *direct* path
//! (pool, then the layer as written) is the reference, and is cheaper when there are few rows
//! (acting on a handful of environments), so each forward picks the path with fewer
//! floating-point operations, from shapes and active counts only, which keeps runs
//! deterministic. Parameters, their layout and checkpoints are the same on both paths.
//!
//! Scores and type terms are computed on the active rows only: an inactive element or field
//! has a zero encoding, so its logits are the other side's type term alone.

use a2perf_core::EnvSpec;
use faer::{Accum, MatMut, MatRef};
use serde::{Deserialize, Serialize};

use super::{DiscreteArch, NetOptions, Ws};
use crate::batch::{ObsBatch, ObsLayout};
use crate::nn::embed::Embedding;
use crate::nn::{Activation, Linear, Mlp, MlpWs, ParamAlloc, ensure, gemm};

/// Web navigation DOM–profile network (see the module table).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct WebArch {
    /// Tensor indices: profile_keys, profile_values, profile_mask, dom_tokens, dom_features, dom_mask.
    idx: [usize; 6],
    fields: usize,
    elements: usize,
    tokens: usize,
    attrs: usize,
    dom_feats: usize,
    pub(super) embed: Embedding,
    pub(super) field_mlp: Mlp,
    pub(super) elem_mlp: Mlp,
    pub(super) type_e: Linear,
    pub(super) type_f: Linear,
    pub(super) value: Option<Mlp>,
}

impl WebArch {
    /// The observation tensors the network reads (indices into its layout).
    pub(super) fn inputs(&self) -> Vec<usize> {
        self.idx.to_vec()
    }
}

/// How the web network computes the first layer of its element and field MLPs (see the module
/// documentation). Both paths give the same values up to float rounding.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum WebPath {
    /// Whichever needs fewer floating-point operations for the batch (the default).
    #[default]
    Auto,
    /// Pool the token embeddings, then apply the layer (the reference).
    Direct,
    /// Project the embedding table through the layer's weights, then pool the projections.
    Projected,
}

/// The web network's activations and scratch (reused between calls).
#[derive(Clone, Debug, Default)]
pub(super) struct WebWs {
    pub(super) path: WebPath,
    /// Active `(row, field)` and `(row, element)` pairs, row-major.
    active_f: Vec<(usize, usize)>,
    active_e: Vec<(usize, usize)>,
    /// Where each batch row's pairs start in `active_f` / `active_e` (`B + 1` entries).
    row_f: Vec<usize>,
    row_e: Vec<usize>,
    /// Whether the last forward projected the field and the element first layer.
    projected: [bool; 2],
    /// Direct-path MLP inputs, fields and elements.
    fin: Vec<f32>,
    ein: Vec<f32>,
    /// Projected tables of the field and the element MLP.
    proj: [Projection; 2],
    /// Gradients of a projected table (backward scratch).
    dtab: Vec<f32>,
    /// Type terms of the active fields / elements `[n, 2]`, and their gradients.
    tf: Vec<f32>,
    te: Vec<f32>,
    dtf: Vec<f32>,
    dte: Vec<f32>,
    /// One row's field type terms over all field slots `[F, 2]` (and their gradients).
    tf_row: Vec<f32>,
    /// One row's scores `[active fields, active elements]` (and their gradients).
    s: Vec<f32>,
    /// Value-head input `[B, 2L]`.
    vx: Vec<f32>,
    /// Encoding gradients of the active fields / elements `[n, L]`.
    dfe: Vec<f32>,
    dee: Vec<f32>,
    dtmp: Vec<f32>,
    /// Direct-path input gradients.
    dx: Vec<f32>,
}

impl WebPath {
    fn projects(self, g: &Groups<'_>, embed: &Embedding, latent: usize) -> bool {
        match self {
            WebPath::Direct => false,
            WebPath::Projected => true,
            WebPath::Auto => projected_pays(g, embed, latent),
        }
    }
}

/// Whether the projected first layer needs fewer floating-point operations than the direct one
/// (forward; the backward passes scale the same way: two GEMMs of the same shapes each). Direct:
/// pooling `rows · slots · tokens · d` plus the layer's GEMM `2 · rows · in · l`. Projected: the
/// tables `2 · slots · vocab · d · l` plus gathering `rows · slots · tokens · l` and the dense
/// features. Shapes and active counts only, so the choice is deterministic.
fn projected_pays(g: &Groups<'_>, embed: &Embedding, l: usize) -> bool {
    let (rows, slots, t, d) = (g.rows(), g.slots(), g.t, embed.dim);
    let direct = rows * (2 * (slots * d + g.dense_w) * l + slots * t * d);
    let projected = 2 * slots * embed.vocab * d * l + rows * (slots * t + 2 * g.dense_w) * l;
    projected < direct
}

/// The active rows of one MLP's input: per row, `slots` groups of `t` token ids (each
/// mean-pooled through the embedding) followed by `dense_w` dense features.
struct Groups<'a> {
    active: &'a [(usize, usize)],
    /// Items (fields or elements) per batch row.
    width: usize,
    /// Token tensors; each holds `slots_per_source` groups per item.
    sources: &'a [&'a [i32]],
    slots_per_source: usize,
    t: usize,
    dense: &'a [f32],
    dense_w: usize,
}

impl<'a> Groups<'a> {
    fn rows(&self) -> usize {
        self.active.len()
    }

    fn slots(&self) -> usize {
        self.sources.len() * self.slots_per_source
    }

    fn item(&self, i: usize) -> usize {
        let (r, k) = self.active[i];
        r * self.width + k
    }

    /// Row `i`'s token groups, in slot order.
    fn slot_tokens(&self, i: usize) -> impl Iterator<Item = &'a [i32]> + use<'a> {
        let (item, t) = (self.item(i), self.t);
        let n = self.slots_per_source * t;
        self.sources
            .iter()
            .flat_map(move |src| src[item * n..(item + 1) * n].chunks_exact(t))
    }

    fn dense(&self, i: usize) -> &'a [f32] {
        let at = self.item(i) * self.dense_w;
        &self.dense[at..at + self.dense_w]
    }
}

/// `1 / count` of a token group's non-padding tokens (ids above 0, as [`Embedding`] counts
/// them), or `None` for an all-padding group (which contributes nothing).
fn inv_count(tokens: &[i32]) -> Option<f32> {
    let count = tokens.iter().filter(|&&t| t > 0).count();
    (count > 0).then(|| 1.0 / count as f32)
}

/// The projected tables of one MLP's first layer, `P_s = E W_sᵀ` for every slot
/// (`[slots, vocab, l]`) followed by the dense features' weights transposed (`[dense, l]`),
/// and the parameters they were built from. A forward pass with bit-identical parameters (the
/// DDQN target network between its updates, the online network's second forward of an update)
/// reuses them instead of repeating the GEMMs; the result is the same either way.
#[derive(Clone, Debug, Default)]
struct Projection {
    tab: Vec<f32>,
    key: Vec<f32>,
}

impl Projection {
    fn update(&mut self, embed: &Embedding, layer: &Linear, g: &Groups<'_>, params: &[f32]) {
        let (v, d, l, inp) = (embed.vocab, embed.dim, layer.out, layer.inp);
        let slots = g.slots();
        let table = &params[embed.offset..embed.offset + v * d];
        let weights = &params[layer.w_range()];
        let bits = |a: &[f32], b: &[f32]| a.iter().zip(b).all(|(x, y)| x.to_bits() == y.to_bits());
        let (kt, kw) = self.key.split_at(self.key.len().min(table.len()));
        let tab_len = (slots * v + g.dense_w) * l;
        if self.key.len() == table.len() + weights.len()
            && self.tab.len() >= tab_len
            && bits(kt, table)
            && bits(kw, weights)
        {
            return;
        }
        self.key.clear();
        self.key.extend_from_slice(table);
        self.key.extend_from_slice(weights);
        ensure(&mut self.tab, tab_len);
        let e = MatRef::from_row_major_slice(table, v, d);
        let w = MatRef::from_row_major_slice(weights, l, inp);
        let (p, dense) = self.tab[..tab_len].split_at_mut(slots * v * l);
        for (s, p) in p.chunks_exact_mut(v * l).enumerate() {
            let p = MatMut::from_row_major_slice_mut(p, v, l);
            let ws = w.submatrix(0, s * d, l, d);
            gemm(p, Accum::Replace, e, ws.transpose());
        }
        let base = slots * d;
        for (k, row) in dense.chunks_exact_mut(l).enumerate() {
            for (j, x) in row.iter_mut().enumerate() {
                *x = weights[j * inp + base + k];
            }
        }
    }
}

/// The first layer's pre-activation `out` `[rows, l]` from the projected tables.
fn projected_forward(
    embed: &Embedding,
    layer: &Linear,
    g: &Groups<'_>,
    params: &[f32],
    tab: &[f32],
    out: &mut [f32],
) {
    let (v, l) = (embed.vocab, layer.out);
    let (p, dense_t) = tab.split_at(g.slots() * v * l);
    let bias = &params[layer.b_range()];
    for (i, o) in out.chunks_exact_mut(l).take(g.rows()).enumerate() {
        let x = g.dense(i);
        if x.is_empty() {
            o.copy_from_slice(bias);
        } else {
            // bias_j + Σ_k w_jk x_k with each sum in k order from -0.0 (as `Iterator::sum`),
            // vectorized over j through the transposed weights.
            o.fill(-0.0);
            for (x, wt) in x.iter().zip(dense_t.chunks_exact(l)) {
                for (o, w) in o.iter_mut().zip(wt) {
                    *o += w * x;
                }
            }
            for (o, b) in o.iter_mut().zip(bias) {
                *o += b;
            }
        }
        for (toks, p) in g.slot_tokens(i).zip(p.chunks_exact(v * l)) {
            let Some(inv) = inv_count(toks) else {
                continue;
            };
            for r in toks.iter().filter_map(|t| embed.row(*t)) {
                for (o, x) in o.iter_mut().zip(&p[r * l..(r + 1) * l]) {
                    *o += x * inv;
                }
            }
        }
    }
}

/// Backward of [`projected_forward`] given the pre-activation gradient `dh` `[rows, l]`:
/// accumulates the layer's and the embedding table's gradients (`dtab` is scratch for `dP`).
fn projected_backward(
    embed: &Embedding,
    layer: &Linear,
    g: &Groups<'_>,
    params: &[f32],
    grads: &mut [f32],
    dtab: &mut Vec<f32>,
    dh: &[f32],
) {
    let (v, d, l, inp) = (embed.vocab, embed.dim, layer.out, layer.inp);
    let slots = g.slots();
    let base = slots * d;
    ensure(dtab, slots * v * l);
    let dp = &mut dtab[..slots * v * l];
    dp.fill(0.0);
    {
        let gw = &mut grads[layer.w_range()];
        for (i, dy) in dh.chunks_exact(l).take(g.rows()).enumerate() {
            let x = g.dense(i);
            if !x.is_empty() {
                for (j, gy) in dy.iter().enumerate() {
                    let gr = &mut gw[j * inp + base..j * inp + base + x.len()];
                    for (a, b) in gr.iter_mut().zip(x) {
                        *a += gy * b;
                    }
                }
            }
            for (toks, p) in g.slot_tokens(i).zip(dp.chunks_exact_mut(v * l)) {
                let Some(inv) = inv_count(toks) else {
                    continue;
                };
                for r in toks.iter().filter_map(|t| embed.row(*t)) {
                    for (a, y) in p[r * l..(r + 1) * l].iter_mut().zip(dy) {
                        *a += y * inv;
                    }
                }
            }
        }
    }
    let gb = &mut grads[layer.b_range()];
    for dy in dh.chunks_exact(l).take(g.rows()) {
        for (a, y) in gb.iter_mut().zip(dy) {
            *a += y;
        }
    }
    let e_range = embed.offset..embed.offset + v * d;
    let e = MatRef::from_row_major_slice(&params[e_range.clone()], v, d);
    let w = MatRef::from_row_major_slice(&params[layer.w_range()], l, inp);
    for s in 0..slots {
        let dps = MatRef::from_row_major_slice(&dp[s * v * l..(s + 1) * v * l], v, l);
        let gw = MatMut::from_row_major_slice_mut(&mut grads[layer.w_range()], l, inp);
        let gws = gw.submatrix_mut(0, s * d, l, d);
        gemm(gws, Accum::Add, dps.transpose(), e);
        let ge = MatMut::from_row_major_slice_mut(&mut grads[e_range.clone()], v, d);
        gemm(ge, Accum::Add, dps, w.submatrix(0, s * d, l, d));
    }
}

/// Runs `mlp` over the rows of `g` by the chosen path; returns its output `[rows, out]`.
#[allow(clippy::too_many_arguments)]
fn encode<'w>(
    embed: &Embedding,
    mlp: &Mlp,
    g: &Groups<'_>,
    projected: bool,
    params: &[f32],
    x: &mut Vec<f32>,
    proj: &mut Projection,
    ws: &'w mut MlpWs,
) -> &'w [f32] {
    let rows = g.rows();
    if projected {
        proj.update(embed, &mlp.layers[0], g, params);
        let tab = &proj.tab[..];
        return mlp.forward_with_first(params, rows, ws, |layer, out| {
            projected_forward(embed, layer, g, params, tab, out)
        });
    }
    let (d, inp) = (embed.dim, mlp.inp());
    let base = g.slots() * d;
    ensure(x, rows * inp);
    for (i, o) in x.chunks_exact_mut(inp).take(rows).enumerate() {
        for (toks, o) in g.slot_tokens(i).zip(o.chunks_exact_mut(d)) {
            embed.pool(params, toks, g.t, o);
        }
        o[base..].copy_from_slice(g.dense(i));
    }
    mlp.forward(params, x, rows, ws)
}

/// Backward of [`encode`] given the output gradient `dout` `[rows, out]`.
#[allow(clippy::too_many_arguments)]
fn encode_backward(
    embed: &Embedding,
    mlp: &Mlp,
    g: &Groups<'_>,
    projected: bool,
    params: &[f32],
    grads: &mut [f32],
    dout: &[f32],
    x: &[f32],
    dtab: &mut Vec<f32>,
    dx: &mut Vec<f32>,
    ws: &mut MlpWs,
) {
    let rows = g.rows();
    if projected {
        let dh = mlp.backward_to_first(params, grads, dout, ws);
        projected_backward(embed, &mlp.layers[0], g, params, grads, dtab, dh);
        return;
    }
    let (d, inp) = (embed.dim, mlp.inp());
    ensure(dx, rows * inp);
    mlp.backward(params, grads, x, dout, ws, Some(&mut dx[..rows * inp]));
    for (i, dxi) in dx.chunks_exact(inp).take(rows).enumerate() {
        for (toks, dxs) in g.slot_tokens(i).zip(dxi.chunks_exact(d)) {
            embed.pool_backward(grads, toks, g.t, dxs);
        }
    }
}

pub(super) fn web_arch(
    spec: &EnvSpec,
    layout: &ObsLayout,
    opts: &NetOptions,
    n: usize,
    with_value: bool,
    alloc: &mut ParamAlloc,
) -> Option<DiscreteArch> {
    let names = [
        "profile_keys",
        "profile_values",
        "profile_mask",
        "dom_tokens",
        "dom_features",
        "dom_mask",
    ];
    let mut idx = [0; 6];
    for (i, name) in names.iter().enumerate() {
        idx[i] = layout.index(name)?;
    }
    if !web_dtypes_fit(layout, &idx) {
        return None;
    }
    let shape = |i: usize| &layout.tensors[idx[i]].1;
    let (pk, dt, df) = (shape(0), shape(3), shape(4));
    if pk.len() != 2 || dt.len() != 3 || df.len() != 2 {
        return None;
    }
    let (fields, tokens) = (pk[0], pk[1]);
    let (elements, attrs) = (dt[0], dt[1]);
    if dt[2] != tokens
        || shape(1) != pk
        || layout.dim(idx[2]) != fields
        || layout.dim(idx[5]) != elements
        || df[0] != elements
        || n != elements * fields * 2
    {
        return None;
    }
    let vocab = spec
        .metadata
        .get("vocab_size")
        .and_then(|v| v.parse::<usize>().ok())
        .unwrap_or(500);
    let (d, l) = (opts.embedding_dim, opts.latent_dim);
    let embed = Embedding::new(alloc, vocab, d);
    let field_mlp = Mlp::new(alloc, &[2 * d, l, l], Activation::Relu);
    let elem_mlp = Mlp::new(alloc, &[attrs * d + df[1], l, l], Activation::Relu);
    let type_e = Linear::new(alloc, l, 2);
    let type_f = Linear::new(alloc, l, 2);
    let value = with_value.then(|| Mlp::new(alloc, &[2 * l, l, 1], Activation::Relu));
    Some(DiscreteArch::Web(WebArch {
        idx,
        fields,
        elements,
        tokens,
        attrs,
        dom_feats: df[1],
        embed,
        field_mlp,
        elem_mlp,
        type_e,
        type_f,
        value,
    }))
}

/// Whether the web network can read `layout`: token tensors (keys, values, DOM tokens) are
/// integers, which the embedding looks up as they are, and masks and DOM features are floats.
fn web_dtypes_fit(layout: &ObsLayout, idx: &[usize; 6]) -> bool {
    idx.iter()
        .enumerate()
        .all(|(k, &i)| layout.is_integer(i) == matches!(k, 0 | 1 | 3))
}

impl WebArch {
    /// Whether this network can read `layout`'s element types ([`web_dtypes_fit`]).
    pub(super) fn dtypes_fit(&self, layout: &ObsLayout) -> bool {
        web_dtypes_fit(layout, &self.idx)
    }

    /// The field and element inputs of `batch`, given its active `(row, field)` and
    /// `(row, element)` pairs.
    fn groups<'a>(
        &self,
        batch: &'a ObsBatch,
        active: [&'a [(usize, usize)]; 2],
        field_src: &'a [&'a [i32]; 2],
        elem_src: &'a [&'a [i32]; 1],
    ) -> (Groups<'a>, Groups<'a>) {
        let fields = Groups {
            active: active[0],
            width: self.fields,
            sources: field_src,
            slots_per_source: 1,
            t: self.tokens,
            dense: &[],
            dense_w: 0,
        };
        let elements = Groups {
            active: active[1],
            width: self.elements,
            sources: elem_src,
            slots_per_source: self.attrs,
            t: self.tokens,
            dense: batch.tensor(self.idx[4]),
            dense_w: self.dom_feats,
        };
        (fields, elements)
    }
}

/// Collects the active `(row, item)` pairs of `mask` `[B, width]` and each row's start.
fn collect_active(
    mask: &[f32],
    b: usize,
    width: usize,
    active: &mut Vec<(usize, usize)>,
    starts: &mut Vec<usize>,
) {
    active.clear();
    starts.clear();
    for r in 0..b {
        starts.push(active.len());
        for k in 0..width {
            if mask[r * width + k] > 0.5 {
                active.push((r, k));
            }
        }
    }
    starts.push(active.len());
}

pub(super) fn web_forward(w: &WebArch, params: &[f32], batch: &ObsBatch, ws: &mut Ws) {
    let b = batch.len();
    let (nf, ne) = (w.fields, w.elements);
    let l = w.field_mlp.out();
    let n = ne * nf * 2;
    {
        let web = &mut ws.web;
        collect_active(
            batch.tensor(w.idx[2]),
            b,
            nf,
            &mut web.active_f,
            &mut web.row_f,
        );
        collect_active(
            batch.tensor(w.idx[5]),
            b,
            ne,
            &mut web.active_e,
            &mut web.row_e,
        );
    }
    let field_src = [batch.ints(w.idx[0]), batch.ints(w.idx[1])];
    let elem_src = [batch.ints(w.idx[3])];
    let Ws {
        logits,
        values,
        a,
        b: wb,
        c,
        web,
        ..
    } = ws;
    let mut fin = std::mem::take(&mut web.fin);
    let mut ein = std::mem::take(&mut web.ein);
    let [mut proj_f, mut proj_e] = std::mem::take(&mut web.proj);
    let active = [&web.active_f[..], &web.active_e[..]];
    let (fg, eg) = w.groups(batch, active, &field_src, &elem_src);
    let pf = web.path.projects(&fg, &w.embed, l);
    let pe = web.path.projects(&eg, &w.embed, l);
    let fe = encode(
        &w.embed,
        &w.field_mlp,
        &fg,
        pf,
        params,
        &mut fin,
        &mut proj_f,
        a,
    );
    let ee = encode(
        &w.embed,
        &w.elem_mlp,
        &eg,
        pe,
        params,
        &mut ein,
        &mut proj_e,
        wb,
    );
    let (caf, cae) = (fg.rows(), eg.rows());
    web.projected = [pf, pe];
    web.fin = fin;
    web.ein = ein;
    web.proj = [proj_f, proj_e];
    let WebWs {
        active_f,
        active_e,
        row_f,
        row_e,
        tf,
        te,
        tf_row,
        s,
        vx,
        ..
    } = web;
    ensure(tf, caf * 2);
    w.type_f.forward(params, fe, caf, tf);
    ensure(te, cae * 2);
    w.type_e.forward(params, ee, cae, te);
    ensure(tf_row, nf * 2);
    ensure(s, nf * ne);
    for r in 0..b {
        let (f0, f1, e0, e1) = (row_f[r], row_f[r + 1], row_e[r], row_e[r + 1]);
        let (nfr, ner) = (f1 - f0, e1 - e0);
        // Every element's logits start as the field type terms (an inactive element's stay so).
        let tr = &mut tf_row[..nf * 2];
        tr.fill(0.0);
        for (i, &(_, f)) in active_f[f0..f1].iter().enumerate() {
            tr[f * 2..f * 2 + 2].copy_from_slice(&tf[(f0 + i) * 2..(f0 + i) * 2 + 2]);
        }
        let lg = &mut logits[r * n..(r + 1) * n];
        // Doubling copies: a few large moves instead of one small copy per element.
        lg[..nf * 2].copy_from_slice(tr);
        let mut filled = nf * 2;
        while filled < n {
            let m = filled.min(n - filled);
            lg.copy_within(..m, filled);
            filled += m;
        }
        if ner == 0 {
            continue;
        }
        // Scores of the active pairs, [active fields, active elements].
        if nfr > 0 {
            let fm = MatRef::from_row_major_slice(&fe[f0 * l..f1 * l], nfr, l);
            let em = MatRef::from_row_major_slice(&ee[e0 * l..e1 * l], ner, l);
            let sm = MatMut::from_row_major_slice_mut(&mut s[..nfr * ner], nfr, ner);
            gemm(sm, Accum::Replace, fm, em.transpose());
        }
        for (j, &(_, e)) in active_e[e0..e1].iter().enumerate() {
            let tej = &te[(e0 + j) * 2..(e0 + j) * 2 + 2];
            let row = &mut lg[e * nf * 2..(e + 1) * nf * 2];
            for pair in row.chunks_exact_mut(2) {
                pair[0] += tej[0];
                pair[1] += tej[1];
            }
            for (i, &(_, f)) in active_f[f0..f1].iter().enumerate() {
                let sc = s[i * ner + j];
                row[f * 2] += sc;
                row[f * 2 + 1] += sc;
            }
        }
    }
    if let Some(v) = &w.value {
        // Mean element and mean field encodings per row, [B, 2L].
        ensure(vx, b * 2 * l);
        for r in 0..b {
            let out = &mut vx[r * 2 * l..(r + 1) * 2 * l];
            let (oe, of) = out.split_at_mut(l);
            mean_rows(&ee[row_e[r] * l..row_e[r + 1] * l], l, oe);
            mean_rows(&fe[row_f[r] * l..row_f[r + 1] * l], l, of);
        }
        let y = v.forward(params, vx, b, c);
        values[..b].copy_from_slice(y);
    }
}

/// The mean of the `l`-wide rows of `x` into `out` (zeros when there are none).
fn mean_rows(x: &[f32], l: usize, out: &mut [f32]) {
    out.fill(0.0);
    for row in x.chunks_exact(l) {
        for (o, v) in out.iter_mut().zip(row) {
            *o += v;
        }
    }
    let c = (x.len() / l).max(1) as f32;
    out.iter_mut().for_each(|o| *o /= c);
}

pub(super) fn web_backward(
    w: &WebArch,
    params: &[f32],
    grads: &mut [f32],
    batch: &ObsBatch,
    ws: &mut Ws,
    dlogits: &[f32],
    dvalues: Option<&[f32]>,
) {
    let b = ws.batch;
    let (nf, ne) = (w.fields, w.elements);
    let l = w.field_mlp.out();
    let n = ne * nf * 2;
    let field_src = [batch.ints(w.idx[0]), batch.ints(w.idx[1])];
    let elem_src = [batch.ints(w.idx[3])];
    let Ws {
        a, b: wb, c, web, ..
    } = ws;
    let mut dtab = std::mem::take(&mut web.dtab);
    let mut dx = std::mem::take(&mut web.dx);
    let mut dfe = std::mem::take(&mut web.dfe);
    let mut dee = std::mem::take(&mut web.dee);
    let mut dtmp = std::mem::take(&mut web.dtmp);
    let [pf, pe] = web.projected;
    {
        let WebWs {
            active_f,
            active_e,
            row_f,
            row_e,
            dtf,
            dte,
            tf_row,
            s,
            vx,
            fin,
            ein,
            ..
        } = &mut *web;
        let (fg, eg) = w.groups(batch, [&active_f[..], &active_e[..]], &field_src, &elem_src);
        let (caf, cae) = (fg.rows(), eg.rows());
        let fe = w.field_mlp.output(a);
        let ee = w.elem_mlp.output(wb);
        ensure(&mut dfe, caf * l);
        ensure(&mut dee, cae * l);
        ensure(dtf, caf * 2);
        ensure(dte, cae * 2);
        ensure(tf_row, nf * 2);
        ensure(s, nf * ne);
        for r in 0..b {
            let (f0, f1, e0, e1) = (row_f[r], row_f[r + 1], row_e[r], row_e[r + 1]);
            let (nfr, ner) = (f1 - f0, e1 - e0);
            let dl = &dlogits[r * n..(r + 1) * n];
            // Field type terms reach every element's logits, active or not.
            let dtr = &mut tf_row[..nf * 2];
            dtr.fill(0.0);
            for chunk in dl.chunks_exact(nf * 2) {
                for (a, x) in dtr.iter_mut().zip(chunk) {
                    *a += x;
                }
            }
            for (i, &(_, f)) in active_f[f0..f1].iter().enumerate() {
                dtf[(f0 + i) * 2..(f0 + i) * 2 + 2].copy_from_slice(&dtr[f * 2..f * 2 + 2]);
            }
            for (j, &(_, e)) in active_e[e0..e1].iter().enumerate() {
                let row = &dl[e * nf * 2..(e + 1) * nf * 2];
                let (mut g0, mut g1) = (0.0, 0.0);
                for pair in row.chunks_exact(2) {
                    g0 += pair[0];
                    g1 += pair[1];
                }
                dte[(e0 + j) * 2] = g0;
                dte[(e0 + j) * 2 + 1] = g1;
                for (i, &(_, f)) in active_f[f0..f1].iter().enumerate() {
                    s[i * ner + j] = row[f * 2] + row[f * 2 + 1];
                }
            }
            if nfr == 0 || ner == 0 {
                dfe[f0 * l..f1 * l].fill(0.0);
                dee[e0 * l..e1 * l].fill(0.0);
                continue;
            }
            let dsm = MatRef::from_row_major_slice(&s[..nfr * ner], nfr, ner);
            let fm = MatRef::from_row_major_slice(&fe[f0 * l..f1 * l], nfr, l);
            let em = MatRef::from_row_major_slice(&ee[e0 * l..e1 * l], ner, l);
            let dfm = MatMut::from_row_major_slice_mut(&mut dfe[f0 * l..f1 * l], nfr, l);
            gemm(dfm, Accum::Replace, dsm, em);
            let dem = MatMut::from_row_major_slice_mut(&mut dee[e0 * l..e1 * l], ner, l);
            gemm(dem, Accum::Replace, dsm.transpose(), fm);
        }
        ensure(&mut dtmp, (b * 2).max(caf).max(cae) * l);
        if let (Some(v), Some(dv)) = (&w.value, dvalues) {
            v.backward(params, grads, vx, &dv[..b], c, Some(&mut dtmp[..b * 2 * l]));
            for r in 0..b {
                let (f0, f1, e0, e1) = (row_f[r], row_f[r + 1], row_e[r], row_e[r + 1]);
                let dvx = &dtmp[r * 2 * l..(r + 1) * 2 * l];
                let ce = (e1 - e0).max(1) as f32;
                for row in dee[e0 * l..e1 * l].chunks_exact_mut(l) {
                    for (o, x) in row.iter_mut().zip(&dvx[..l]) {
                        *o += x / ce;
                    }
                }
                let cf = (f1 - f0).max(1) as f32;
                for row in dfe[f0 * l..f1 * l].chunks_exact_mut(l) {
                    for (o, x) in row.iter_mut().zip(&dvx[l..]) {
                        *o += x / cf;
                    }
                }
            }
        }
        w.type_f
            .backward(params, grads, fe, dtf, caf, Some(&mut dtmp));
        for (o, x) in dfe[..caf * l].iter_mut().zip(&dtmp[..caf * l]) {
            *o += x;
        }
        w.type_e
            .backward(params, grads, ee, dte, cae, Some(&mut dtmp));
        for (o, x) in dee[..cae * l].iter_mut().zip(&dtmp[..cae * l]) {
            *o += x;
        }
        #[rustfmt::skip]
        encode_backward(&w.embed, &w.field_mlp, &fg, pf, params, grads, &dfe, fin, &mut dtab, &mut dx, a);
        #[rustfmt::skip]
        encode_backward(&w.embed, &w.elem_mlp, &eg, pe, params, grads, &dee, ein, &mut dtab, &mut dx, wb);
    }
    web.dtab = dtab;
    web.dx = dx;
    web.dfe = dfe;
    web.dee = dee;
    web.dtmp = dtmp;
}
