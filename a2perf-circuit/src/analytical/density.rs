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
//! As DREAMPlace, a movable object narrower than `√2` bins is stretched to `√2` bins with its
//! charge scaled down to keep its area, so that a small cell always feels the field of more
//! than one bin; fixed objects deposit their exact footprint times the target density.

use std::sync::Arc;

use rustdct::{Dct2, Dct3, DctPlanner};

/// Bins, potential solver and buffers of the density term (reused from run to run).
pub struct Electrostatics {
    nx: usize,
    ny: usize,
    bx: f64,
    by: f64,
    width: f64,
    height: f64,
    /// `1/λ_uv` times the normalisation of the transforms, transposed layout `[u·ny + v]`.
    inv_lambda: Vec<f64>,
    dct2_x: Arc<dyn Dct2<f64>>,
    dct2_y: Arc<dyn Dct2<f64>>,
    dct3_x: Arc<dyn Dct3<f64>>,
    dct3_y: Arc<dyn Dct3<f64>>,
    fft_scratch: Vec<f64>,
    /// Charge of the fixed objects (area per bin times the target density), `[iy·nx + ix]`.
    fixed: Vec<f64>,
    /// Total charge of the current evaluation.
    map: Vec<f64>,
    /// Potential of the current evaluation.
    psi: Vec<f64>,
    transposed: Vec<f64>,
    /// Every movable object's smoothed shares of the bins in x and in y (see
    /// [`smooth_weights`]), computed once per evaluation for the deposit and the gradient.
    wx: Vec<f64>,
    wy: Vec<f64>,
    foot: Vec<Footprint>,
    dx: Vec<f64>,
    dy: Vec<f64>,
}

impl std::fmt::Debug for Electrostatics {
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

impl Electrostatics {
    /// Bins `nx × ny` over a `width × height` canvas.
    pub fn new(width: f64, height: f64, nx: usize, ny: usize) -> Self {
        let mut planner = DctPlanner::new();
        let dct2_x = planner.plan_dct2(nx);
        let dct2_y = planner.plan_dct2(ny);
        let dct3_x = planner.plan_dct3(nx);
        let dct3_y = planner.plan_dct3(ny);
        let scratch_len = [
            dct2_x.get_scratch_len(),
            dct2_y.get_scratch_len(),
            dct3_x.get_scratch_len(),
            dct3_y.get_scratch_len(),
        ]
        .into_iter()
        .max()
        .unwrap_or(0);
        let (bx, by) = (width / nx as f64, height / ny as f64);
        // DCT-III(DCT-II(x)) = (n/2)·x in each dimension; the bin area turns charge into density.
        let norm = 4.0 / (nx * ny) as f64 / (bx * by);
        let mut inv_lambda = vec![0.0; nx * ny];
        let (kx, ky) = (std::f64::consts::PI / width, std::f64::consts::PI / height);
        for u in 0..nx {
            for v in 0..ny {
                let l = (kx * u as f64).powi(2) + (ky * v as f64).powi(2);
                if l > 0.0 {
                    inv_lambda[u * ny + v] = norm / l;
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
            dct2_x,
            dct2_y,
            dct3_x,
            dct3_y,
            fft_scratch: vec![0.0; scratch_len],
            fixed: vec![0.0; nx * ny],
            map: vec![0.0; nx * ny],
            psi: vec![0.0; nx * ny],
            transposed: vec![0.0; nx * ny],
            wx: Vec::new(),
            wy: Vec::new(),
            foot: Vec::new(),
            dx: vec![0.0; nx],
            dy: vec![0.0; ny],
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
        self.fixed.iter_mut().for_each(|v| *v = 0.0);
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
            *q = q.min(cap) * target_density;
        }
    }

    /// Charge map of `pos` (centres) with `charges`, potential, energy and statistics; writes
    /// `∂E/∂pos` into `grad` (overwritten).
    pub fn evaluate(
        &mut self,
        pos: &[[f64; 2]],
        charges: &[Charge],
        target_density: f64,
        grad: &mut [[f64; 2]],
    ) -> DensityStats {
        let (bx, by) = (self.bx, self.by);
        self.map.copy_from_slice(&self.fixed);
        self.wx.clear();
        self.wy.clear();
        self.foot.clear();
        for (p, c) in pos.iter().zip(charges) {
            let (ox, oy) = (self.wx.len(), self.wy.len());
            let f = smooth_weights(p[0] - c.hw, p[0] + c.hw, bx, self.nx, &mut self.wx).and_then(
                |(c0, cw)| {
                    let (r0, rw) =
                        smooth_weights(p[1] - c.hh, p[1] + c.hh, by, self.ny, &mut self.wy)?;
                    Some(Footprint {
                        c0,
                        cw,
                        r0,
                        rw,
                        ox,
                        oy,
                    })
                },
            );
            let Some(f) = f else {
                // Outside the canvas: no charge, no gradient.
                self.wx.truncate(ox);
                self.foot.push(Footprint::default());
                continue;
            };
            let (wx, wy) = (&self.wx[ox..ox + f.cw], &self.wy[oy..oy + f.rw]);
            for (r, &wy) in (f.r0..f.r0 + f.rw).zip(wy) {
                let base = r * self.nx + f.c0;
                let wy = c.ratio * wy;
                for (m, &wx) in self.map[base..base + f.cw].iter_mut().zip(wx) {
                    *m += wy * wx;
                }
            }
            self.foot.push(f);
        }
        self.solve();
        let energy = 0.5
            * self
                .map
                .iter()
                .zip(&self.psi)
                .map(|(q, p)| q * p)
                .sum::<f64>();
        let cap = target_density * bx * by;
        let (mut overflow_area, mut max_q) = (0.0f64, 0.0f64);
        for &q in &self.map {
            overflow_area += (q - cap).max(0.0);
            max_q = max_q.max(q);
        }
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
        for r in 0..f.rw {
            let base = (f.r0 + r) * nx + f.c0;
            let row = &self.psi[base..base + f.cw];
            let (mut sx, mut s) = (0.0, 0.0);
            for ((p, wx), dx) in row.iter().zip(wx).zip(&self.dx[..f.cw]) {
                sx += dx * p;
                s += wx * p;
            }
            g[0] += wy[r] * sx;
            g[1] += self.dy[r] * s;
        }
        [ratio * g[0], ratio * g[1]]
    }

    /// `psi = G · map`.
    fn solve(&mut self) {
        let (nx, ny) = (self.nx, self.ny);
        self.psi.copy_from_slice(&self.map);
        for row in self.psi.chunks_exact_mut(nx) {
            self.dct2_x
                .process_dct2_with_scratch(row, &mut self.fft_scratch);
        }
        transpose(&self.psi, &mut self.transposed, nx, ny);
        for (col, il) in self
            .transposed
            .chunks_exact_mut(ny)
            .zip(self.inv_lambda.chunks_exact(ny))
        {
            self.dct2_y
                .process_dct2_with_scratch(col, &mut self.fft_scratch);
            col.iter_mut().zip(il).for_each(|(a, l)| *a *= l);
            self.dct3_y
                .process_dct3_with_scratch(col, &mut self.fft_scratch);
        }
        transpose(&self.transposed, &mut self.psi, ny, nx);
        for row in self.psi.chunks_exact_mut(nx) {
            self.dct3_x
                .process_dct3_with_scratch(row, &mut self.fft_scratch);
        }
    }

    /// The potential of the last evaluation, `[iy·nx + ix]`.
    pub fn potential(&self) -> &[f64] {
        &self.psi
    }

    /// The charge map of the last evaluation, `[iy·nx + ix]`.
    pub fn charge_map(&self) -> &[f64] {
        &self.map
    }
}

/// `∫ max(0, b − |u − c|) du` from −∞ to `c + d` (the integral of a tent of half-width `b`).
#[inline]
fn tent_integral(d: f64, b: f64) -> f64 {
    if d <= -b {
        0.0
    } else if d <= 0.0 {
        (b + d) * (b + d) / 2.0
    } else if d < b {
        b * b - (b - d) * (b - d) / 2.0
    } else {
        b * b
    }
}

/// Share of a movable interval `[a0, a1]` in each bin of size `b` after smoothing it with a
/// box one bin wide (cloud-in-cell): `(1/b)·∫ |bin ∩ [s − b/2, s + b/2]| ds` over the
/// interval, which is a C¹ function of the interval's position, so the energy's gradient is
/// continuous. Appends the bins' shares to `out` and returns `(first bin, len)`.
#[inline]
fn smooth_weights(
    a0: f64,
    a1: f64,
    b: f64,
    n: usize,
    out: &mut Vec<f64>,
) -> Option<(usize, usize)> {
    let h = b / 2.0;
    let (lo, hi) = span(a0 - h, a1 + h, b, n)?;
    out.extend((lo..=hi).map(|i| {
        let c = (i as f64 + 0.5) * b;
        (tent_integral(a1 - c, b) - tent_integral(a0 - c, b)) / b
    }));
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
fn deposit(
    map: &mut [f64],
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
            map[base + c] += oy * overlap(x0, x1, c, bx);
        }
    }
}

/// `dst[c·rows + r] = src[r·cols + c]` for a `rows × cols` row-major `src`.
fn transpose(src: &[f64], dst: &mut [f64], cols: usize, rows: usize) {
    const B: usize = 16;
    for r0 in (0..rows).step_by(B) {
        for c0 in (0..cols).step_by(B) {
            for r in r0..(r0 + B).min(rows) {
                for c in c0..(c0 + B).min(cols) {
                    dst[c * rows + r] = src[r * cols + c];
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

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
        // charge (a wide Gaussian), away from the boundary.
        let (w, h, nx, ny) = (64.0, 32.0, 64, 32);
        let mut e = Electrostatics::new(w, h, nx, ny);
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
        assert!(worst < 0.02, "Poisson residual {worst}");
    }
}
