//! Electrostatic density (ePlace / DREAMPlace): every object is a charge spread over the bins it
//! overlaps, the potential solves Poisson's equation on the canvas with Neumann boundaries, and
//! the penalty is the system's energy.
//!
//! The solve is spectral: a 2-D DCT-II of the charge map, a division by the eigenvalues
//! `(πu/W)² + (πv/H)²` of the Laplacian (the constant mode dropped), and a 2-D DCT-III back. With
//! `ψ = G q` and `G` symmetric, the energy `E = ½ qᵀψ` has the gradient `∂E/∂x = (∂q/∂x)ᵀ ψ`:
//! a rectangle's charge changes only in the bins under its left and right edges, so the
//! gradient of one object is `ψ` under its right edge minus `ψ` under its left edge, weighted
//! by the vertical overlap (and likewise in y). This is the exact derivative of the discrete
//! energy (what the finite-difference property test checks); DREAMPlace uses the spectral
//! field `−∇ψ` integrated over the footprint instead, which is the same quantity on a smooth
//! potential.
//!
//! The 1-D transforms are rustfft's complex FFTs, two real rows (or columns) per FFT by
//! Makhoul's reordering. rustfft picks its AVX, SSE or scalar code by CPU, so the last bits of a
//! run may differ between CPU kinds (all x86-64 CPUs with AVX and FMA take the same code), never
//! between runs or thread counts.
//!
//! The maps, the transforms and the potential are of the kernels' float type `F` ([`Real`]:
//! `f32` in the placer, DREAMPlace's default `dtype`; `f64` where the tests check gradients);
//! the geometry (bin shares and their slopes), the gradient's sums and the statistics are `f64`.
//!
//! As DREAMPlace, a movable object narrower than `√2` bins is stretched to `√2` bins with its
//! charge scaled down to keep its area, so that a small cell always feels the field of more
//! than one bin; fixed objects deposit their exact footprint times the target density.

use std::sync::Arc;

use a2perf_core::copy::copy_slice;
use rustdct::rustfft::num_complex::Complex;
use rustdct::rustfft::{Fft, FftPlanner};

use super::real::Real;

/// Bins, potential solver and buffers of the density term (reused from run to run).
pub struct Electrostatics<F: Real = f64> {
    nx: usize,
    ny: usize,
    bx: f64,
    by: f64,
    width: f64,
    height: f64,
    /// `1/λ_uv` times the normalisation of the transforms, transposed layout `[u·ny + v]`.
    inv_lambda: Vec<F>,
    /// The 1-D transforms along x (rows) and y (columns).
    tx: PairDct<F>,
    ty: PairDct<F>,
    /// Pairs of rows packed as complex numbers for the passes along x, pairs of columns for
    /// the passes along y, and the FFTs' scratch.
    packed: Vec<Complex<F>>,
    packed_y: Vec<Complex<F>>,
    fft_scratch: Vec<Complex<F>>,
    /// Charge of the fixed objects (area per bin times the target density), `[iy·nx + ix]`.
    fixed: Vec<F>,
    /// Total charge of the current evaluation.
    map: Vec<F>,
    /// Potential of the current evaluation.
    psi: Vec<F>,
    /// When `ny` is odd: the transform along x of the zero row past the last (the partner of
    /// the last row), which the pass back along x reads.
    pad: Vec<F>,
    /// The partner of the last row when `ny` is odd (a row of zeros).
    zeros: Vec<F>,
    /// A pair of rows' DCT-IIs along x, `[A_0..A_nx | B_0..B_nx]`, before they are scattered
    /// into the pass along y.
    coef: Vec<F>,
    /// Every movable object's smoothed shares of the bins in x and in y (see
    /// [`smooth_weights`]), computed once per evaluation for the deposit and the gradient.
    wx: Vec<F>,
    wy: Vec<F>,
    foot: Vec<Footprint>,
    dx: Vec<f64>,
    dy: Vec<f64>,
    /// Per row of bins: whether it holds charge (its transform along x is not zero), and
    /// whether its potential is needed; the pairs of rows whose transforms along x run.
    rows_in: Vec<bool>,
    rows_out: Vec<bool>,
    pairs: Vec<usize>,
}

impl<F: Real> std::fmt::Debug for Electrostatics<F> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Electrostatics")
            .field("nx", &self.nx)
            .field("ny", &self.ny)
            .field("width", &self.width)
            .field("height", &self.height)
            .finish_non_exhaustive()
    }
}

/// A rectangle charge: centre-relative half sizes (stretched) and charge per unit area.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Charge {
    /// Half width (after stretching).
    pub hw: f64,
    /// Half height (after stretching).
    pub hh: f64,
    /// Charge per unit area (`area / stretched area`, 1 for objects wider than √2 bins).
    pub ratio: f64,
}

/// Density statistics of one evaluation.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct DensityStats {
    /// Electrostatic energy `½ qᵀψ`.
    pub energy: f64,
    /// `Σ_b max(q_b − target·bin area, 0)` (divide by the movable area for DREAMPlace's
    /// overflow).
    pub overflow_area: f64,
    /// Largest bin charge over the bin area.
    pub max_density: f64,
}

/// `(Σ max(q − cap, 0), max q)` over the bins, each in four lanes so that the pass
/// vectorizes (and gives the same bits on every build).
#[inline(always)]
fn bin_sums<F: Real>(map: &[F], cap: f64) -> ([f64; 4], [f64; 4]) {
    let (mut over, mut top) = ([0.0f64; 4], [0.0f64; 4]);
    let qs = map.chunks_exact(4);
    let q_rest = qs.remainder();
    for q in qs {
        for l in 0..4 {
            let q = q[l].widen();
            over[l] += if q > cap { q - cap } else { 0.0 };
            top[l] = if q > top[l] { q } else { top[l] };
        }
    }
    for (l, &q) in q_rest.iter().enumerate() {
        let q = q.widen();
        over[l] += if q > cap { q - cap } else { 0.0 };
        top[l] = if q > top[l] { q } else { top[l] };
    }
    (over, top)
}

/// `Σ qψ` over the bins in four lanes.
#[inline(always)]
fn bin_dot<F: Real>(map: &[F], psi: &[F]) -> [f64; 4] {
    let mut dot = [0.0f64; 4];
    let (qs, ps) = (map.chunks_exact(4), psi.chunks_exact(4));
    let (q_rest, p_rest) = (qs.remainder(), ps.remainder());
    for (q, p) in qs.zip(ps) {
        for l in 0..4 {
            dot[l] += q[l].widen() * p[l].widen();
        }
    }
    for (l, (&q, &p)) in q_rest.iter().zip(p_rest).enumerate() {
        dot[l] += q.widen() * p.widen();
    }
    dot
}

/// Where a movable object's shares lie: columns `c0..c0 + cw` (at `ox` in the x shares), rows
/// `r0..r0 + rw` (at `oy` in the y shares); `cw == 0` for an object outside the canvas.
#[derive(Clone, Copy, Debug, Default)]
struct Footprint {
    c0: usize,
    cw: usize,
    r0: usize,
    rw: usize,
    ox: usize,
    oy: usize,
}

/// Columns (or rows) `[lo, hi]` of bins of size `b` overlapped by `[a0, a1]`, clamped to `n`
/// bins; `None` when the span is empty or outside.
#[inline]
fn span(a0: f64, a1: f64, b: f64, n: usize) -> Option<(usize, usize)> {
    // NaN bounds give no span.
    if a1.partial_cmp(&a0) != Some(std::cmp::Ordering::Greater) || a1 <= 0.0 || a0 >= b * n as f64 {
        return None;
    }
    let lo = ((a0 / b).floor().max(0.0) as usize).min(n - 1);
    let hi = ((a1 / b).floor().max(0.0) as usize).min(n - 1);
    Some((lo, hi))
}

/// Overlap of `[a0, a1]` with bin `i` of size `b`.
#[inline]
fn overlap(a0: f64, a1: f64, i: usize, b: f64) -> f64 {
    let (l, r) = (i as f64 * b, (i + 1) as f64 * b);
    (a1.min(r) - a0.max(l)).max(0.0)
}

impl<F: Real> Electrostatics<F> {
    /// Bins `nx × ny` over a `width × height` canvas.
    pub fn new(width: f64, height: f64, nx: usize, ny: usize) -> Self {
        let mut planner = FftPlanner::<F>::new();
        let (tx, ty) = (
            PairDct::new(&mut planner, nx),
            PairDct::new(&mut planner, ny),
        );
        let scratch_len = tx.scratch_len().max(ty.scratch_len());
        let (bx, by) = (width / nx as f64, height / ny as f64);
        // DCT-III(DCT-II(x)) = (n/2)·x in each dimension; the bin area turns charge into density.
        let norm = 4.0 / (nx * ny) as f64 / (bx * by);
        // A zero row past the last: the partner of the last column when `nx` is odd.
        let mut inv_lambda = vec![F::zero(); (nx + 1) * ny];
        let (kx, ky) = (std::f64::consts::PI / width, std::f64::consts::PI / height);
        for u in 0..nx {
            for v in 0..ny {
                let l = (kx * u as f64).powi(2) + (ky * v as f64).powi(2);
                if l > 0.0 {
                    inv_lambda[u * ny + v] = F::of(norm / l);
                }
            }
        }
        Self {
            nx,
            ny,
            bx,
            by,
            width,
            height,
            inv_lambda,
            tx,
            ty,
            packed: vec![Complex::default(); ny.div_ceil(2) * nx],
            packed_y: vec![Complex::default(); nx.div_ceil(2) * ny],
            fft_scratch: vec![Complex::default(); scratch_len],
            fixed: vec![F::zero(); nx * ny],
            map: vec![F::zero(); nx * ny],
            psi: vec![F::zero(); nx * ny],
            pad: vec![F::zero(); nx],
            zeros: vec![F::zero(); nx],
            coef: vec![F::zero(); 2 * nx],
            wx: Vec::new(),
            wy: Vec::new(),
            foot: Vec::new(),
            dx: vec![0.0; nx],
            dy: vec![0.0; ny],
            rows_in: vec![false; ny],
            rows_out: vec![false; ny],
            pairs: Vec::with_capacity(ny.div_ceil(2)),
        }
    }

    /// Whether this solver fits a canvas and bin counts (so it can be reused).
    pub fn fits(&self, width: f64, height: f64, nx: usize, ny: usize) -> bool {
        self.nx == nx && self.ny == ny && self.width == width && self.height == height
    }

    /// Bin sizes `(bx, by)`.
    pub fn bin_size(&self) -> (f64, f64) {
        (self.bx, self.by)
    }

    /// The stretched charge of a movable object of size `w × h` (DREAMPlace's `√2` bins).
    pub fn movable_charge(&self, w: f64, h: f64) -> Charge {
        let s = std::f64::consts::SQRT_2;
        let (sw, sh) = (w.max(s * self.bx), h.max(s * self.by));
        Charge {
            hw: sw / 2.0,
            hh: sh / 2.0,
            ratio: if sw * sh > 0.0 {
                w * h / (sw * sh)
            } else {
                0.0
            },
        }
    }

    /// Clears the fixed charge.
    pub fn clear_fixed(&mut self) {
        self.fixed.iter_mut().for_each(|v| *v = F::zero());
    }

    /// Adds a fixed rectangle `[x0, x1] × [y0, y1]` (call [`Self::finish_fixed`] after the
    /// last one).
    pub fn add_fixed(&mut self, x0: f64, y0: f64, x1: f64, y1: f64) {
        deposit(
            &mut self.fixed,
            (self.nx, self.ny),
            (self.bx, self.by),
            [x0, y0, x1, y1],
            1.0,
        );
    }

    /// As DREAMPlace: fixed objects may overlap, so each bin's fixed charge is capped at the
    /// bin's area, then scaled by the target density.
    pub fn finish_fixed(&mut self, target_density: f64) {
        let cap = self.bx * self.by;
        for q in &mut self.fixed {
            *q = F::of(q.widen().min(cap) * target_density);
        }
    }

    /// Charge map of `pos` (centres) with `charges`, potential, energy and statistics;
    /// writes `∂E/∂pos` into `grad` (overwritten).
    pub fn evaluate(
        &mut self,
        pos: &[[f64; 2]],
        charges: &[Charge],
        target_density: f64,
        grad: &mut [[f64; 2]],
    ) -> DensityStats {
        self.evaluate_with(pos, charges, target_density, grad, true)
    }

    /// [`Self::evaluate`] without the energy (NaN in the result): the potential is solved
    /// only in the rows of bins under the movable objects, which is all the gradient reads.
    /// The gradient and the other statistics are the same, bit for bit.
    pub fn evaluate_gradient(
        &mut self,
        pos: &[[f64; 2]],
        charges: &[Charge],
        target_density: f64,
        grad: &mut [[f64; 2]],
    ) -> DensityStats {
        self.evaluate_with(pos, charges, target_density, grad, false)
    }

    vector_builds! {
        /// Both of the above: `full` solves the potential in every row and sums the energy.
        fn evaluate_with / evaluate_avx2 / evaluate_avx512 (
            &mut self,
            pos: &[[f64; 2]],
            charges: &[Charge],
            target_density: f64,
            grad: &mut [[f64; 2]],
            full: bool,
        ) -> DensityStats = evaluate_generic
    }

    #[inline(always)]
    fn evaluate_generic(
        &mut self,
        pos: &[[f64; 2]],
        charges: &[Charge],
        target_density: f64,
        grad: &mut [[f64; 2]],
        full: bool,
    ) -> DensityStats {
        let (bx, by) = (self.bx, self.by);
        // Not `copy_from_slice`: the two maps are allocated one after the other (a2perf_core::copy).
        copy_slice(&mut self.map, &self.fixed);
        self.wx.clear();
        self.wy.clear();
        self.foot.clear();
        self.rows_out.iter_mut().for_each(|r| *r = full);
        for (p, c) in pos.iter().zip(charges) {
            let (ox, oy) = (self.wx.len(), self.wy.len());
            // Plain control flow, no closure: a closure was compiled out of line, outside the
            // vector builds.
            let x = smooth_weights(p[0] - c.hw, p[0] + c.hw, bx, self.nx, &mut self.wx);
            let y = match x {
                Some(_) => smooth_weights(p[1] - c.hh, p[1] + c.hh, by, self.ny, &mut self.wy),
                None => None,
            };
            let f = match (x, y) {
                (Some((c0, cw)), Some((r0, rw))) => Some(Footprint {
                    c0,
                    cw,
                    r0,
                    rw,
                    ox,
                    oy,
                }),
                _ => None,
            };
            let Some(f) = f else {
                // Outside the canvas: no charge, no gradient.
                self.wx.truncate(ox);
                self.foot.push(Footprint::default());
                continue;
            };
            let (wx, wy) = (&self.wx[ox..ox + f.cw], &self.wy[oy..oy + f.rw]);
            self.rows_out[f.r0..f.r0 + f.rw]
                .iter_mut()
                .for_each(|r| *r = true);
            for (r, &wy) in (f.r0..f.r0 + f.rw).zip(wy) {
                let base = r * self.nx + f.c0;
                let wy = F::of(c.ratio * wy.widen());
                for (m, &wx) in self.map[base..base + f.cw].iter_mut().zip(wx) {
                    *m += wy * wx;
                }
            }
            self.foot.push(f);
        }
        let zero = F::zero();
        for (r, row) in self.rows_in.iter_mut().zip(self.map.chunks_exact(self.nx)) {
            // A fold, not `any`: without the early exit the test vectorizes (most rows of a
            // small netlist's map are empty, and were scanned one bin at a time).
            *r = row.iter().fold(false, |a, &q| a | (q != zero));
        }
        self.solve();
        let cap = target_density * bx * by;
        let (over, top) = bin_sums(&self.map, cap);
        let lanes = |v: [f64; 4]| (v[0] + v[1]) + (v[2] + v[3]);
        let energy = if full {
            0.5 * lanes(bin_dot(&self.map, &self.psi))
        } else {
            f64::NAN
        };
        let overflow_area = lanes(over);
        let max_q = top.into_iter().fold(0.0f64, f64::max);
        for (((p, c), g), k) in pos.iter().zip(charges).zip(grad.iter_mut()).zip(0..) {
            *g = self.rect_gradient(
                k,
                [p[0] - c.hw, p[1] - c.hh, p[0] + c.hw, p[1] + c.hh],
                c.ratio,
            );
        }
        DensityStats {
            energy,
            overflow_area,
            max_density: max_q / (bx * by),
        }
    }

    /// `(∂E/∂x, ∂E/∂y)` of movable object `k`'s smoothed charge (rectangle
    /// `[x0, y0, x1, y1]`) with the current potential.
    #[inline(always)]
    fn rect_gradient(&mut self, k: usize, [x0, y0, x1, y1]: [f64; 4], ratio: f64) -> [f64; 2] {
        let f = self.foot[k];
        if f.cw == 0 {
            return [0.0, 0.0];
        }
        let nx = self.nx;
        let (wx, wy) = (&self.wx[f.ox..f.ox + f.cw], &self.wy[f.oy..f.oy + f.rw]);
        smooth_slopes(x0, x1, self.bx, f.c0, f.cw, &mut self.dx);
        smooth_slopes(y0, y1, self.by, f.r0, f.rw, &mut self.dy);
        let mut g = [0.0, 0.0];
        for ((r, wy), dy) in (f.r0..).zip(wy).zip(&self.dy[..f.rw]) {
            let base = r * nx + f.c0;
            let row = &self.psi[base..base + f.cw];
            let (mut sx, mut s) = (0.0, 0.0);
            for ((p, wx), dx) in row.iter().zip(wx).zip(&self.dx[..f.cw]) {
                let p = p.widen();
                sx += dx * p;
                s += wx.widen() * p;
            }
            g[0] += wy.widen() * sx;
            g[1] += dy * s;
        }
        [ratio * g[0], ratio * g[1]]
    }

    /// `psi = G · map`: DCT-II along x then y, the division by the eigenvalues, DCT-III along
    /// y then x. Each pass transforms the rows two at a time, packed as one complex FFT. The
    /// pass along x writes each coefficient straight where the pass along y packs it (column
    /// `k` of the x transform is the real part of column pair `k/2` if `k` is even, the
    /// imaginary part if odd; row `iy` sits at Makhoul's position [`makhoul`]), and the pass
    /// back along x reads them from there. Only the pairs of rows with charge (`rows_in`) are
    /// transformed along x (the others' transforms are zero), and only the pairs whose
    /// potential is needed (`rows_out`) come back; every pair that runs is computed as it would
    /// be alone.
    #[inline(always)]
    fn solve(&mut self) {
        let (nx, ny) = (self.nx, self.ny);
        let zero = F::zero();
        // Slices, not vectors: a store through a slice cannot move the slice itself, so the
        // loops keep its address in a register.
        let (map, psi, pad) = (&self.map[..], &mut self.psi[..], &mut self.pad[..]);
        let (packed, py, scratch, zeros) = (
            &mut self.packed[..],
            &mut self.packed_y[..],
            &mut self.fft_scratch[..],
            &self.zeros[..],
        );
        let row = |r: usize| {
            if r < ny {
                &map[r * nx..(r + 1) * nx]
            } else {
                &zeros[..nx]
            }
        };
        let pairs = &mut self.pairs;
        let select = |pairs: &mut Vec<usize>, rows: &[bool]| {
            pairs.clear();
            pairs.extend(
                (0..ny.div_ceil(2)).filter(|&j| rows[2 * j] || rows.get(2 * j + 1) == Some(&true)),
            );
        };
        // Rows of the map: DCT-II along x, into the y pass's buffer.
        select(pairs, &self.rows_in);
        let px = &mut packed[..pairs.len() * nx];
        for (&j, z) in pairs.iter().zip(px.chunks_exact_mut(nx)) {
            self.tx.pack_forward(z, row(2 * j), row(2 * j + 1));
        }
        if !px.is_empty() {
            self.tx.forward.process_with_scratch(px, scratch);
        }
        let (ca, cb) = self.coef.split_at_mut(nx);
        let mut next = pairs.iter().zip(px.chunks_exact(nx)).peekable();
        for j in 0..ny.div_ceil(2) {
            match next.next_if(|(p, _)| **p == j) {
                Some((_, z)) => {
                    // The arithmetic first, in a loop of its own, then the scatter.
                    self.tx.unpack_forward(z, ca, cb);
                    for (k, (&a, &b)) in ca.iter().zip(&*cb).enumerate() {
                        put_half(py, pad, ny, k, 2 * j, a);
                        put_half(py, pad, ny, k, 2 * j + 1, b);
                    }
                }
                None => {
                    for k in 0..nx {
                        put_half(py, pad, ny, k, 2 * j, zero);
                        put_half(py, pad, ny, k, 2 * j + 1, zero);
                    }
                }
            }
        }
        if nx % 2 == 1 {
            // The last column has no partner: its pair's imaginary parts are zero.
            for z in &mut py[nx / 2 * ny..] {
                z.im = zero;
            }
        }
        // Columns: DCT-II along y, times 1/λ, DCT-III along y, in place.
        self.ty.forward.process_with_scratch(py, scratch);
        for (j, z) in py.chunks_exact_mut(ny).enumerate() {
            let il = &self.inv_lambda[2 * j * ny..(2 * j + 2) * ny];
            let (ila, ilb) = il.split_at(ny);
            self.ty.spectral_filter(z, ila, ilb);
        }
        self.ty.inverse.process_with_scratch(py, scratch);
        // The values of the column pairs (Makhoul's order undone on reading): DCT-III along x
        // into the rows of psi that are needed.
        select(pairs, &self.rows_out);
        let px = &mut packed[..pairs.len() * nx];
        for (&j, z) in pairs.iter().zip(px.chunks_exact_mut(nx)) {
            self.tx.pack_inverse(z, |k| {
                (
                    get_half(py, pad, ny, k, 2 * j),
                    get_half(py, pad, ny, k, 2 * j + 1),
                )
            });
        }
        if !px.is_empty() {
            self.tx.inverse.process_with_scratch(px, scratch);
        }
        for (&j, z) in pairs.iter().zip(px.chunks_exact(nx)) {
            let (a, b) = (2 * j * nx, (2 * j + 1) * nx);
            if b < psi.len() {
                let (pa, pb) = psi[a..b + nx].split_at_mut(nx);
                self.tx.unpack_inverse(z, pa, Some(pb));
            } else {
                self.tx.unpack_inverse(z, &mut psi[a..b], None);
            }
        }
    }

    /// The potential of the last evaluation, `[iy·nx + ix]`.
    pub fn potential(&self) -> &[F] {
        &self.psi
    }

    /// The charge map of the last evaluation, `[iy·nx + ix]`.
    pub fn charge_map(&self) -> &[F] {
        &self.map
    }
}

/// Writes column `k`, row `iy` of the map transformed along x into the y pass's buffer `py`
/// (row `ny`, the partner of an odd last row, into `pad`).
#[inline(always)]
fn put_half<F: Real>(py: &mut [Complex<F>], pad: &mut [F], ny: usize, k: usize, iy: usize, v: F) {
    if iy == ny {
        pad[k] = v;
    } else {
        let z = &mut py[k / 2 * ny + makhoul(iy, ny)];
        if k % 2 == 1 {
            z.im = v;
        } else {
            z.re = v;
        }
    }
}

/// Reads what [`put_half`] wrote (after the passes along y, the values they left there).
#[inline(always)]
fn get_half<F: Real>(py: &[Complex<F>], pad: &[F], ny: usize, k: usize, iy: usize) -> F {
    if iy == ny {
        pad[k]
    } else {
        let z = py[k / 2 * ny + makhoul(iy, ny)];
        if k % 2 == 1 { z.im } else { z.re }
    }
}

/// Makhoul's position of sample `i` of `n` (the even samples first, then the odd ones
/// backwards): where [`PairDct::pack_forward`] puts it and [`PairDct::unpack_inverse`] finds it.
#[inline(always)]
fn makhoul(i: usize, n: usize) -> usize {
    if i.is_multiple_of(2) {
        i / 2
    } else {
        n - 1 - i / 2
    }
}

/// `2·∫ max(0, b − |u − c|) du − b²` from −∞ to `c + d` (twice the integral of a tent of
/// half-width `b`, shifted by a constant that cancels in differences): with `u = d` clamped to
/// `[−b, b]`, `(b + min(u, 0))² − (b − max(u, 0))²`. Branch-free, so that the loops over bins
/// vectorize.
#[inline(always)]
fn tent_integral2(d: f64, b: f64) -> f64 {
    let u = if d < -b {
        -b
    } else if d > b {
        b
    } else {
        d
    };
    let (l, r) = (
        b + if u < 0.0 { u } else { 0.0 },
        b - if u > 0.0 { u } else { 0.0 },
    );
    l * l - r * r
}

/// Share of a movable interval `[a0, a1]` in each bin of size `b` after smoothing it with a
/// box one bin wide (cloud-in-cell): `(1/b)·∫ |bin ∩ [s − b/2, s + b/2]| ds` over the
/// interval, which is a C¹ function of the interval's position, so the energy's gradient is
/// continuous. Appends the bins' shares to `out` and returns `(first bin, len)`.
#[inline(always)]
fn smooth_weights<F: Real>(
    a0: f64,
    a1: f64,
    b: f64,
    n: usize,
    out: &mut Vec<F>,
) -> Option<(usize, usize)> {
    let h = b / 2.0;
    let (lo, hi) = span(a0 - h, a1 + h, b, n)?;
    let half_inv = 0.5 / b;
    // A loop rather than `extend`, which the compiler kept out of line (and out of the
    // vector builds).
    out.reserve(hi - lo + 1);
    for i in lo..=hi {
        let c = (i as f64 + 0.5) * b;
        out.push(F::of(
            (tent_integral2(a1 - c, b) - tent_integral2(a0 - c, b)) * half_inv,
        ));
    }
    Some((lo, hi - lo + 1))
}

/// The derivatives of [`smooth_weights`] with respect to the interval's position.
#[inline]
fn smooth_slopes(a0: f64, a1: f64, b: f64, lo: usize, len: usize, out: &mut [f64]) {
    let tent = |d: f64| (b - d.abs()).max(0.0);
    for (k, i) in (lo..lo + len).enumerate() {
        let c = (i as f64 + 0.5) * b;
        out[k] = (tent(a1 - c) - tent(a0 - c)) / b;
    }
}

/// Adds `scale` × the overlap area of `[x0, x1] × [y0, y1]` to every bin of `map`.
fn deposit<F: Real>(
    map: &mut [F],
    (nx, ny): (usize, usize),
    (bx, by): (f64, f64),
    [x0, y0, x1, y1]: [f64; 4],
    scale: f64,
) {
    let (Some((c0, c1)), Some((r0, r1))) = (span(x0, x1, bx, nx), span(y0, y1, by, ny)) else {
        return;
    };
    for r in r0..=r1 {
        let oy = scale * overlap(y0, y1, r, by);
        let base = r * nx;
        for c in c0..=c1 {
            map[base + c] += F::of(oy * overlap(x0, x1, c, bx));
        }
    }
}

/// [`PairDct::dct2_coefficient`] with its `cos(πk/2N)/2`, `sin(πk/2N)/2` given: the pair's
/// DCT-IIs `(A_k, B_k)` from coefficients `p = k` and `q = N − k` of its forward FFT.
#[inline(always)]
fn dct2_of<F: Real>(c: F, s: F, p: Complex<F>, q: Complex<F>) -> (F, F) {
    (
        c * (p.re + q.re) + s * (p.im - q.im),
        c * (p.im + q.im) - s * (p.re - q.re),
    )
}

/// Two real DCTs (rustdct's unnormalized DCT-II, `X_k = Σ x_n cos(πk(2n+1)/2N)`, and its
/// DCT-III, `x_n = X_0/2 + Σ_{k≥1} X_k cos(πk(2n+1)/2N)`) of length `N` by one complex FFT
/// of length `N` (Makhoul's reordering; the two real sequences as the real and imaginary
/// parts). Glue around rustfft: the transforms themselves are rustfft's.
struct PairDct<F: Real> {
    n: usize,
    forward: Arc<dyn Fft<F>>,
    inverse: Arc<dyn Fft<F>>,
    /// `cos(πk/2N)/2`, `sin(πk/2N)/2`.
    half_cos: Vec<F>,
    half_sin: Vec<F>,
}

impl<F: Real> PairDct<F> {
    fn new(planner: &mut FftPlanner<F>, n: usize) -> Self {
        let angle = |k: usize| std::f64::consts::PI * k as f64 / (2 * n) as f64;
        Self {
            n,
            forward: planner.plan_fft_forward(n),
            inverse: planner.plan_fft_inverse(n),
            half_cos: (0..n).map(|k| F::of(angle(k).cos() / 2.0)).collect(),
            half_sin: (0..n).map(|k| F::of(angle(k).sin() / 2.0)).collect(),
        }
    }

    fn scratch_len(&self) -> usize {
        self.forward
            .get_inplace_scratch_len()
            .max(self.inverse.get_inplace_scratch_len())
    }

    /// `z` = the pair `(a, b)` in Makhoul's order (even samples first, then the odd ones
    /// backwards), ready for the forward FFT.
    #[inline(always)]
    fn pack_forward(&self, z: &mut [Complex<F>], a: &[F], b: &[F]) {
        let n = self.n;
        let (lo, hi) = z[..n].split_at_mut(n.div_ceil(2));
        for (h, zh) in lo.iter_mut().enumerate() {
            *zh = Complex::new(a[2 * h], b[2 * h]);
        }
        for (h, zh) in hi.iter_mut().rev().enumerate() {
            *zh = Complex::new(a[2 * h + 1], b[2 * h + 1]);
        }
    }

    /// The two DCT-IIs `A_k`, `B_k` from the forward FFT `z` of a packed pair, into `a` and
    /// `b`. Coefficient `k` reads `z[k]` and `z[N − k]`: one loop over `k` with the second
    /// read backwards and nothing else in it (the scatter into the pass along y follows).
    #[inline(always)]
    fn unpack_forward(&self, z: &[Complex<F>], a: &mut [F], b: &mut [F]) {
        let n = self.n;
        (a[0], b[0]) = self.dct2_coefficient(0, z[0], z[0]);
        let (c, s) = (&self.half_cos[1..n], &self.half_sin[1..n]);
        for (((((a, b), p), q), &c), &s) in a[1..n]
            .iter_mut()
            .zip(&mut b[1..n])
            .zip(&z[1..n])
            .zip(z[1..n].iter().rev())
            .zip(c)
            .zip(s)
        {
            (*a, *b) = dct2_of(c, s, *p, *q);
        }
    }

    /// `z` = the packed spectrum whose inverse FFT is the pair of DCT-IIIs of `X(k) = (A_k, B_k)`.
    #[inline(always)]
    fn pack_inverse(&self, z: &mut [Complex<F>], x: impl Fn(usize) -> (F, F)) {
        let n = self.n;
        for (k, zk) in z.iter_mut().enumerate().take(n) {
            let xr = if k == 0 {
                (F::zero(), F::zero())
            } else {
                x(n - k)
            };
            *zk = self.packed_coefficient(k, x(k), xr);
        }
    }

    /// Coefficient `k` of the packed spectrum from `X_k` and `X_{N−k}` (zero for `k = 0`):
    /// `V = (c + i s)(X_k − i X_{N−k})` for each sequence, then `V_a + i V_b`.
    #[inline(always)]
    fn packed_coefficient(&self, k: usize, (a, b): (F, F), (ar, br): (F, F)) -> Complex<F> {
        let (c, s) = (self.half_cos[k], self.half_sin[k]);
        let (va_re, va_im) = (c * a + s * ar, s * a - c * ar);
        let (vb_re, vb_im) = (c * b + s * br, s * b - c * br);
        Complex::new(va_re - vb_im, va_im + vb_re)
    }

    /// The pair's DCT-IIs `(A_k, B_k)` from coefficients `k` and `N − k` of its forward FFT.
    #[inline(always)]
    fn dct2_coefficient(&self, k: usize, p: Complex<F>, q: Complex<F>) -> (F, F) {
        dct2_of(self.half_cos[k], self.half_sin[k], p, q)
    }

    /// The forward FFT `z` of a packed pair turned, in place, into the packed spectrum of the
    /// pair's DCT-IIIs after scaling the DCT-II coefficients by `sa` (a) and `sb` (b).
    /// Coefficients `k` and `N − k` depend on each other only, so they are done together.
    #[inline(always)]
    fn spectral_filter(&self, z: &mut [Complex<F>], sa: &[F], sb: &[F]) {
        let n = self.n;
        let scaled = |k: usize, (a, b): (F, F)| (a * sa[k], b * sb[k]);
        let x = scaled(0, self.dct2_coefficient(0, z[0], z[0]));
        z[0] = self.packed_coefficient(0, x, (F::zero(), F::zero()));
        for k in 1..=n / 2 {
            let k2 = n - k;
            let (p, q) = (z[k], z[k2]);
            let x = scaled(k, self.dct2_coefficient(k, p, q));
            let x2 = scaled(k2, self.dct2_coefficient(k2, q, p));
            z[k] = self.packed_coefficient(k, x, x2);
            z[k2] = self.packed_coefficient(k2, x2, x);
        }
    }

    /// The pair of sequences `(a, b)` from the inverse FFT `z` of a packed spectrum (Makhoul's
    /// order undone); `b` is dropped when `None`.
    #[inline(always)]
    fn unpack_inverse(&self, z: &[Complex<F>], a: &mut [F], b: Option<&mut [F]>) {
        let n = self.n;
        let (lo, hi) = z[..n].split_at(n.div_ceil(2));
        for (h, zh) in lo.iter().enumerate() {
            a[2 * h] = zh.re;
        }
        for (h, zh) in hi.iter().rev().enumerate() {
            a[2 * h + 1] = zh.re;
        }
        if let Some(b) = b {
            for (h, zh) in lo.iter().enumerate() {
                b[2 * h] = zh.im;
            }
            for (h, zh) in hi.iter().rev().enumerate() {
                b[2 * h + 1] = zh.im;
            }
        }
    }
}
#[cfg(test)]
mod tests {
    use super::*;
    use rustdct::DctPlanner;

    #[test]
    fn dct3_inverts_dct2_up_to_half_the_length() {
        let mut planner = DctPlanner::<f64>::new();
        let n = 16;
        let x: Vec<f64> = (0..n).map(|i| ((i * 7) % 5) as f64 - 1.5).collect();
        let mut y = x.clone();
        planner.plan_dct2(n).process_dct2(&mut y);
        planner.plan_dct3(n).process_dct3(&mut y);
        for (a, b) in x.iter().zip(&y) {
            assert!((a * n as f64 / 2.0 - b).abs() < 1e-9, "{a} {b}");
        }
    }

    #[test]
    fn the_potential_solves_poisson_with_the_mean_removed() {
        // −∇²ψ = ρ − mean(ρ) on the bins, checked with the 5-point Laplacian on a smooth
        // charge (a wide Gaussian), away from the boundary; even and odd bin counts (the
        // transforms pair rows and columns, an odd one out with zeros).
        for (w, h, nx, ny) in [
            (64.0, 32.0, 64, 32),
            (63.0, 31.5, 63, 21),
            (60.0, 30.0, 48, 33),
        ] {
            let mut e = Electrostatics::<f64>::new(w, h, nx, ny);
            let (bx, by) = e.bin_size();
            for iy in 0..ny {
                for ix in 0..nx {
                    let (x, y) = ((ix as f64 + 0.5) * bx, (iy as f64 + 0.5) * by);
                    let d2 = (x - 30.0).powi(2) + (y - 17.0).powi(2);
                    e.fixed[iy * nx + ix] = (-d2 / 40.0).exp() * bx * by;
                }
            }
            let mut g = [[0.0; 2]; 0];
            e.evaluate(&[], &[], 1.0, &mut g);
            let mean = e.map.iter().sum::<f64>() / (nx * ny) as f64 / (bx * by);
            let psi = |ix: usize, iy: usize| e.psi[iy * nx + ix];
            let mut worst = 0.0f64;
            for iy in 4..ny - 4 {
                for ix in 4..nx - 4 {
                    let lap = (psi(ix + 1, iy) - 2.0 * psi(ix, iy) + psi(ix - 1, iy)) / (bx * bx)
                        + (psi(ix, iy + 1) - 2.0 * psi(ix, iy) + psi(ix, iy - 1)) / (by * by);
                    let rho = e.map[iy * nx + ix] / (bx * by) - mean;
                    worst = worst.max((-lap - rho).abs());
                }
            }
            assert!(worst < 0.02, "{nx} x {ny}: Poisson residual {worst}");
        }
    }

    #[test]
    fn the_paired_transforms_equal_rustdcts() {
        let mut planner = DctPlanner::<f64>::new();
        let mut fft = FftPlanner::<f64>::new();
        for n in [1, 2, 5, 8, 12, 17] {
            let t = PairDct::new(&mut fft, n);
            let a: Vec<f64> = (0..n).map(|i| ((i * 7) % 5) as f64 - 1.5).collect();
            let b: Vec<f64> = (0..n).map(|i| ((i * 3) % 7) as f64 * 0.25).collect();
            let mut z = vec![Complex::default(); n];
            let mut scratch = vec![Complex::default(); t.scratch_len()];
            t.pack_forward(&mut z, &a, &b);
            t.forward.process_with_scratch(&mut z, &mut scratch);
            let (mut da, mut db) = (a.clone(), b.clone());
            planner.plan_dct2(n).process_dct2(&mut da);
            planner.plan_dct2(n).process_dct2(&mut db);
            let (mut ga, mut gb) = (vec![0.0; n], vec![0.0; n]);
            t.unpack_forward(&z, &mut ga, &mut gb);
            for k in 0..n {
                assert!((ga[k] - da[k]).abs() < 1e-12 && (gb[k] - db[k]).abs() < 1e-12);
            }
            // DCT-III of (a, b) as spectra.
            t.pack_inverse(&mut z, |k| (a[k], b[k]));
            t.inverse.process_with_scratch(&mut z, &mut scratch);
            let (mut ia, mut ib) = (vec![0.0; n], vec![0.0; n]);
            t.unpack_inverse(&z, &mut ia, Some(&mut ib));
            let (mut ra, mut rb) = (a.clone(), b.clone());
            planner.plan_dct3(n).process_dct3(&mut ra);
            planner.plan_dct3(n).process_dct3(&mut rb);
            for k in 0..n {
                assert!(
                    (ia[k] - ra[k]).abs() < 1e-12 && (ib[k] - rb[k]).abs() < 1e-12,
                    "{n}"
                );
            }
        }
    }
}
