//! Butterworth low-pass filtering, bit-for-bit in the style of SciPy 1.11.
//!
//! Both originals smooth learning curves with `b, a = scipy.signal.butter(8, thresh)` (transfer
//! function, "ba" form) followed by `scipy.signal.filtfilt(b, a, y, padlen=min(len(y)-1, 27))`.
//! This module ports that chain step by step so the numbers agree:
//!
//! 1. `buttap`: analog prototype poles `-exp(iπm/2N)`, `m = -N+1, -N+3, …, N-1`, gain 1;
//! 2. pre-warp `wo = 4·tan(π·Wn/2)` (`fs = 2`), `lp2lp_zpk` scales poles by `wo`, gain by `wo^N`;
//! 3. `bilinear_zpk` with `fs2 = 4`: poles `(4+p)/(4−p)`, `N` zeros at −1,
//!    gain `k·Re(1/Π(4−p))`;
//! 4. `zpk2tf`: `b = k·poly(zeros)`, `a = Re(poly(poles))` with `poly` as repeated convolution;
//! 5. `filtfilt` (method `pad`, `padtype="odd"`): odd extension by `padlen`, `lfilter_zi` steady
//!    state scaled by the first sample, forward `lfilter`, then backward with the state scaled by
//!    the last output, and the padding cut off again.
//!
//! Complex arithmetic follows NumPy (Smith's division; `poly` through OpenBLAS `zdotu`) and `lfilter` uses the
//! direct form II transposed update of SciPy's C kernel in the same evaluation order.
//! `lfilter_zi` solves `(I − Aᵀ) zi = b[1:] − a[1:]·b[0]` the way NumPy 1.26's `linalg.solve`
//! does it through its bundled OpenBLAS 0.3.23 on the reference machine (see [`lfilter_zi`]).
//!
//! The order-8 filter at cutoff 0.01 is **ill-conditioned** in ba form (Σb ≈ 9e-13): one ulp in
//! a single `a` coefficient moves the filtered curves by up to 1.5e-2, and SciPy itself gives
//! curves 3.2e-3 apart depending on which OpenBLAS kernels the CPU selects. The golden values are
//! reproduced bit for bit only because every step above is; at 0.1 the filter is well
//! conditioned (~1e-10). See Oppenheim & Schafer, *Discrete-Time Signal Processing*, §7.1
//! (bilinear transform) and Gustafsson (1996) for the forward–backward scheme.

use thiserror::Error;

/// Errors from filter design or application.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum FilterError {
    /// The normalised cutoff must lie strictly between 0 and 1 (1 = Nyquist).
    #[error("cutoff {0} must be strictly between 0 and 1 (1 = Nyquist frequency)")]
    Cutoff(f64),
    /// The filter order must be at least 1.
    #[error("filter order must be at least 1")]
    Order,
    /// The padding must be shorter than the signal.
    #[error("signal of length {len} is too short for padlen {padlen}")]
    TooShort {
        /// Signal length.
        len: usize,
        /// Requested padding.
        padlen: usize,
    },
    /// The steady-state system of `lfilter_zi` is singular.
    #[error("singular steady-state system in lfilter_zi")]
    Singular,
}

#[derive(Clone, Copy, Debug, PartialEq)]
struct C {
    re: f64,
    im: f64,
}

impl C {
    const fn new(re: f64, im: f64) -> Self {
        Self { re, im }
    }
    fn mul(self, o: C) -> C {
        C::new(
            self.re * o.re - self.im * o.im,
            self.re * o.im + self.im * o.re,
        )
    }
    /// NumPy's complex division (Smith's algorithm).
    fn div(self, o: C) -> C {
        let (ar, ai, br, bi) = (self.re, self.im, o.re, o.im);
        if br.abs() >= bi.abs() {
            let rat = bi / br;
            let scl = 1.0 / (br + bi * rat);
            C::new((ar + ai * rat) * scl, (ai - ar * rat) * scl)
        } else {
            let rat = br / bi;
            let scl = 1.0 / (bi + br * rat);
            C::new((ar * rat + ai) * scl, (ai * rat - ar) * scl)
        }
    }
}

/// Transfer-function coefficients of a digital filter (`a[0] == 1`).
#[derive(Clone, Debug, PartialEq)]
pub struct TransferFunction {
    /// Numerator coefficients.
    pub b: Vec<f64>,
    /// Denominator coefficients.
    pub a: Vec<f64>,
}

/// `scipy.signal.butter(order, cutoff)`: a digital low-pass Butterworth filter in ba form.
/// `cutoff` is normalised so that 1 is the Nyquist frequency.
///
/// ```
/// let tf = a2perf_metrics::filter::butter_lowpass(2, 0.5).unwrap();
/// // butter(2, 0.5) = [0.2929, 0.5858, 0.2929], [1, 0, 0.1716]
/// assert!((tf.b[1] - 0.5857864376269049).abs() < 1e-12);
/// assert!((tf.a[2] - 0.1715728752538099).abs() < 1e-12);
/// ```
pub fn butter_lowpass(order: usize, cutoff: f64) -> Result<TransferFunction, FilterError> {
    if order == 0 {
        return Err(FilterError::Order);
    }
    if !(cutoff > 0.0 && cutoff < 1.0) {
        return Err(FilterError::Cutoff(cutoff));
    }
    let n = order as i64;
    // buttap: poles on the left half of the unit circle.
    let poles: Vec<C> = (0..order as i64)
        .map(|i| {
            let m = -n + 1 + 2 * i;
            let theta = std::f64::consts::PI * m as f64 / (2 * n) as f64;
            C::new(-theta.cos(), -theta.sin())
        })
        .collect();
    // Pre-warp (fs = 2) and lp2lp_zpk.
    let fs = 2.0;
    let wo = 2.0 * fs * (std::f64::consts::PI * cutoff / fs).tan();
    let poles: Vec<C> = poles.iter().map(|p| C::new(wo, 0.0).mul(*p)).collect();
    let k_lp = wo.powf(order as f64);
    // bilinear_zpk.
    let fs2 = 2.0 * fs;
    let pz: Vec<C> = poles
        .iter()
        .map(|p| C::new(fs2 + p.re, p.im).div(C::new(fs2 - p.re, -p.im)))
        .collect();
    let mut prod = C::new(1.0, 0.0);
    for p in &poles {
        prod = prod.mul(C::new(fs2 - p.re, -p.im));
    }
    let k = k_lp * C::new(1.0, 0.0).div(prod).re;
    // zpk2tf: zeros at -1 give binomial coefficients exactly.
    let mut b = vec![1.0];
    for _ in 0..order {
        b = convolve_real(&b, &[1.0, 1.0]);
    }
    let b = b.into_iter().map(|c| k * c).collect();
    let mut a = vec![C::new(1.0, 0.0)];
    for p in &pz {
        a = convolve_complex(&a, &[C::new(1.0, 0.0), C::new(-p.re, -p.im)]);
    }
    // Poles come in exact conjugate pairs, so the imaginary parts are rounding noise (NumPy's
    // `poly` drops them after the same check).
    let a = a.into_iter().map(|c| c.re).collect();
    Ok(TransferFunction { b, a })
}

fn convolve_real(x: &[f64], v: &[f64]) -> Vec<f64> {
    let mut out = vec![0.0; x.len() + v.len() - 1];
    for (i, xi) in x.iter().enumerate() {
        for (j, vj) in v.iter().enumerate() {
            out[i + j] += xi * vj;
        }
    }
    out
}

/// `np.convolve` of a polynomial with a linear factor `[1, -r]`. NumPy computes each output as
/// a BLAS `zdotu` over the overlapping window (`correlate(a, v[::-1])`); OpenBLAS accumulates the
/// four real partial products separately and combines them at the end, `re = Σxr·yr − Σxi·yi`,
/// `im = Σxr·yi + Σxi·yr`. The ill-conditioned filters need that exact association.
fn convolve_complex(a: &[C], v: &[C; 2]) -> Vec<C> {
    let n = a.len();
    let mut out = Vec::with_capacity(n + 1);
    for k in 0..=n {
        let mut dot = [0.0f64; 4];
        let mut add = |x: C, y: C| {
            dot[0] += x.re * y.re;
            dot[1] += x.im * y.im;
            dot[2] += x.re * y.im;
            dot[3] += x.im * y.re;
        };
        // Window order: a[k-1]·v[1], then a[k]·v[0].
        if k >= 1 {
            add(a[k - 1], v[1]);
        }
        if k < n {
            add(a[k], v[0]);
        }
        out.push(C::new(dot[0] - dot[1], dot[2] + dot[3]));
    }
    out
}

/// `scipy.signal.lfilter_zi(b, a)`: the initial state giving the steady-state step response.
///
/// Solves `(I − companion(a)ᵀ) zi = b[1:] − a[1:]·b[0]` like NumPy's `linalg.solve` (LAPACK
/// `dgesv` in NumPy 1.26's bundled OpenBLAS 0.3.23). For the ill-conditioned order-8 filters the
/// result depends on the exact operation order, which in OpenBLAS depends on the CPU and the
/// thread count. We follow the configuration that produced the reference data: AVX-512
/// (SkylakeX/Cooperlake) kernels and two threads (NumPy's OpenBLAS is built with
/// `MAX_THREADS=2`), under which `dgetrf` takes the blocked `getrf_parallel` path (a 4-column
/// panel, a TRSM/GEMM update, another panel for order 8) rather than the unblocked `getf2` of
/// the single-threaded path. That choice changes the filtered golden curves by up to 1.2e-3;
/// with it they agree bit for bit. Checked bit for bit against NumPy for orders 1–8 (the
/// originals use 8); larger systems reach kernel paths that are not emulated (four-way strided
/// `ddot`, four-column `dgemv` blocks), so there the result agrees only to rounding, which the
/// conditioning of these systems amplifies.
pub fn lfilter_zi(tf: &TransferFunction) -> Result<Vec<f64>, FilterError> {
    let (b, a) = normalised(tf);
    let n = b.len().max(a.len());
    let mut a = a;
    let mut b = b;
    a.resize(n, 0.0);
    b.resize(n, 0.0);
    let m = n - 1;
    if m == 0 {
        return Ok(Vec::new());
    }
    // Column-major I − companion(a)ᵀ: first column 1 + a1, a2, …; superdiagonal −1; unit
    // diagonal below row 0.
    let mut mat = vec![0.0; m * m];
    for i in 0..m {
        mat[i] = if i == 0 { 1.0 + a[1] } else { a[i + 1] };
        if i >= 1 {
            mat[i + i * m] += 1.0;
        }
        if i + 1 < m {
            mat[i + (i + 1) * m] = -1.0;
        }
    }
    let rhs: Vec<f64> = (1..n).map(|i| b[i] - a[i] * b[0]).collect();
    solve(mat, rhs, m)
}

/// Solves `A x = rhs` for column-major `A` (see [`lfilter_zi`] for why this order).
fn solve(a: Vec<f64>, mut x: Vec<f64>, n: usize) -> Result<Vec<f64>, FilterError> {
    let mut lu = Lu {
        a,
        n,
        ipiv: (0..n).collect(),
    };
    lu.getrf_parallel(0, n)?;
    let a = &lu.a;
    // `dgetrs` with one right-hand side: row interchanges, then the unit-lower and upper
    // triangular solves of OpenBLAS' column-oriented `dtrsv` (an `axpy` per column).
    for (i, &ip) in lu.ipiv.iter().enumerate() {
        if ip != i {
            x.swap(i, ip);
        }
    }
    for i in 0..n {
        let xi = x[i];
        for r in i + 1..n {
            x[r] = (-xi).mul_add(a[r + i * n], x[r]);
        }
    }
    for i in (0..n).rev() {
        x[i] /= a[i + i * n];
        let xi = x[i];
        for r in 0..i {
            x[r] = (-xi).mul_add(a[r + i * n], x[r]);
        }
    }
    Ok(x)
}

/// Blocking parameters of OpenBLAS' double-precision SkylakeX/Cooperlake kernels (`param.h`),
/// which is what NumPy 1.26's bundled OpenBLAS 0.3.23 selects on AVX-512 machines.
const GEMM_UNROLL_N: usize = 2;
const GEMM_UNROLL_M: usize = 16;
const GEMM_Q: usize = 384;
/// NumPy's OpenBLAS is built with `MAX_THREADS=2`; on any machine with two or more cores
/// `dgesv` takes the threaded `getrf_parallel` path, whose blocking (not its thread split)
/// changes the rounding.
const THREADS: f64 = 2.0;

/// In-place LU factorisation with partial pivoting that follows OpenBLAS' `dgetrf` call tree
/// (`getrf_parallel` → recursive panels → `getrf_single` → `getf2`) and its kernels'
/// operation order: left-looking `getf2` inside panels, right-looking blocked updates
/// (`trsm_kernel_LT` + `dgemm_kernel`) between them. Rows are `0..n`, the matrix is square and
/// column-major; `ipiv[j]` is the (global, 0-based) row swapped with row `j`.
struct Lu {
    a: Vec<f64>,
    n: usize,
    ipiv: Vec<usize>,
}

fn round_up(v: usize, to: usize) -> usize {
    v.div_ceil(to) * to
}

impl Lu {
    fn at(&self, r: usize, c: usize) -> f64 {
        self.a[r + c * self.n]
    }

    fn swap_rows(&mut self, r1: usize, r2: usize, cols: std::ops::Range<usize>) {
        let n = self.n;
        for c in cols {
            self.a.swap(r1 + c * n, r2 + c * n);
        }
    }

    /// `LASWP_PLUS`: applies the interchanges `ipiv[rows]` to the columns `cols`.
    fn laswp(&mut self, rows: std::ops::Range<usize>, cols: std::ops::Range<usize>) {
        for i in rows {
            let ip = self.ipiv[i];
            if ip != i {
                self.swap_rows(i, ip, cols.clone());
            }
        }
    }

    /// `getf2` on columns `off..off + nr`, rows `off..n` (left-looking, unblocked): `dot` for the
    /// strictly upper part, `gemv` for the rest, both as fused multiply-add chains, then
    /// `idamax`, row swap within the panel and scaling by the reciprocal pivot.
    fn getf2(&mut self, off: usize, nr: usize) -> Result<(), FilterError> {
        let n = self.n;
        let m = n - off;
        for j in 0..nr {
            let col = off + j;
            let len = j.min(m);
            for i in 0..len {
                let ip = self.ipiv[off + i];
                if ip != off + i {
                    self.a.swap(off + i + col * n, ip + col * n);
                }
            }
            for i in 1..len {
                let mut d = 0.0;
                for k in 0..i {
                    d = self.at(off + i, off + k).mul_add(self.at(off + k, col), d);
                }
                self.a[off + i + col * n] -= d;
            }
            if j >= m {
                continue;
            }
            for r in j..m {
                let mut d = 0.0;
                for k in 0..j {
                    d = self.at(off + r, off + k).mul_add(self.at(off + k, col), d);
                }
                self.a[off + r + col * n] -= d;
            }
            let mut p = j;
            let mut best = self.at(off + j, col).abs();
            for r in j + 1..m {
                let v = self.at(off + r, col).abs();
                if v > best {
                    best = v;
                    p = r;
                }
            }
            if best == 0.0 || !best.is_finite() {
                return Err(FilterError::Singular);
            }
            self.ipiv[off + j] = off + p;
            if p != j {
                self.swap_rows(off + j, off + p, off..col + 1);
            }
            let recip = 1.0 / self.at(off + j, col);
            for r in j + 1..m {
                self.a[off + r + col * n] *= recip;
            }
        }
        Ok(())
    }

    /// The blocked update after factoring the panel `p0..p0 + bk`: interchanges on the trailing
    /// columns `cols`, `U12 = L11⁻¹·A12` (OpenBLAS' generic `trsm_kernel_LT`: row chunks of
    /// `GEMM_UNROLL_M`, 8, 4, 2, 1; a GEMM update from earlier chunks, then right-looking
    /// substitution with fused updates), then `A22 −= L21·U12` (the GEMM kernel accumulates each
    /// dot product as one FMA chain and subtracts it once).
    fn update(&mut self, p0: usize, bk: usize, cols: std::ops::Range<usize>) {
        let n = self.n;
        self.laswp(p0..p0 + bk, cols.clone());
        let mut chunks = Vec::new();
        let mut s = 0;
        while s + GEMM_UNROLL_M <= bk {
            chunks.push((s, GEMM_UNROLL_M));
            s += GEMM_UNROLL_M;
        }
        let mut size = GEMM_UNROLL_M / 2;
        while size > 0 {
            if bk & size != 0 {
                chunks.push((s, size));
                s += size;
            }
            size /= 2;
        }
        for c in cols.clone() {
            for &(s, len) in &chunks {
                for r in s..s + len {
                    if s > 0 {
                        let mut acc = 0.0;
                        for k in 0..s {
                            acc = self.at(p0 + r, p0 + k).mul_add(self.at(p0 + k, c), acc);
                        }
                        self.a[p0 + r + c * n] -= acc;
                    }
                }
                for i in s..s + len {
                    let bb = self.at(p0 + i, c);
                    for k in i + 1..s + len {
                        let v = (-bb).mul_add(self.at(p0 + k, p0 + i), self.at(p0 + k, c));
                        self.a[p0 + k + c * n] = v;
                    }
                }
            }
            for r in p0 + bk..n {
                let mut acc = 0.0;
                for k in 0..bk {
                    acc = self.at(r, p0 + k).mul_add(self.at(p0 + k, c), acc);
                }
                self.a[r + c * n] -= acc;
            }
        }
    }

    /// `getrf_single` on columns `off..off + nr`.
    fn getrf_single(&mut self, off: usize, nr: usize) -> Result<(), FilterError> {
        let m = self.n - off;
        let mn = m.min(nr);
        if mn == 0 {
            return Ok(());
        }
        let blocking = round_up(mn / 2, GEMM_UNROLL_N).min(GEMM_Q);
        if blocking <= 2 * GEMM_UNROLL_N {
            return self.getf2(off, nr);
        }
        let mut j = 0;
        while j < mn {
            let jb = (mn - j).min(blocking);
            self.getrf_single(off + j, jb)?;
            if j + jb < nr {
                self.update(off + j, jb, off + j + jb..off + nr);
            }
            j += jb;
        }
        let mut j = 0;
        while j < mn {
            let jb = (mn - j).min(blocking);
            self.laswp(off + j + jb..off + mn, off + j..off + j + jb);
            j += jb;
        }
        Ok(())
    }

    /// `getrf_parallel` on columns `off..off + nr`; the panel widths come from OpenBLAS'
    /// `FORMULA1`/`FORMULA2` load-balancing heuristics for two threads.
    fn getrf_parallel(&mut self, off: usize, nr: usize) -> Result<(), FilterError> {
        let m = self.n - off;
        let mn = m.min(nr);
        if mn == 0 {
            return Ok(());
        }
        let init_bk = round_up(mn / 2, GEMM_UNROLL_N).min(GEMM_Q);
        if init_bk <= GEMM_UNROLL_N {
            return self.getf2(off, nr);
        }
        let formula1 = |is: usize, bk: usize| -> i64 {
            let mm = (m - is - bk) as f64;
            let nn = (nr - is - bk) as f64;
            let b = bk as f64;
            ((nn + mm * b * (1.0 - THREADS) / (b + mm)) / THREADS) as i64
        };
        let formula2 = |is: usize, bk: usize| -> i64 {
            ((nr - is + bk) as f64 * (1.0 - (1.0 - 1.0 / THREADS).sqrt())) as i64
        };
        let u = GEMM_UNROLL_N as i64;
        // The panel widths, computed once so the final interchange pass sees the same blocks.
        let mut blocks = Vec::new();
        let mut next_bk = init_bk;
        let mut bk = mn.min(next_bk);
        self.getrf_parallel(off, bk)?;
        let mut is = 0;
        while is < mn {
            let width = (((formula1(is, bk) + u - 1) / u) * u).min((mn - is - bk) as i64);
            if width < bk as i64 {
                let nb = ((formula2(is, bk) + u) / u) * u;
                next_bk = (nb.max(0) as usize).min(bk);
            }
            blocks.push((is, bk));
            if nr > is + bk {
                self.update(off + is, bk, off + is + bk..off + nr);
            }
            is += bk;
            bk = (mn - is).min(next_bk);
            if bk > 0 {
                self.getrf_single(off + is, bk)?;
            }
        }
        for (is, bk) in blocks {
            self.laswp(off + is + bk..off + mn, off + is..off + is + bk);
        }
        Ok(())
    }
}

fn normalised(tf: &TransferFunction) -> (Vec<f64>, Vec<f64>) {
    let a0 = tf.a.first().copied().unwrap_or(1.0);
    if a0 == 1.0 || a0 == 0.0 {
        (tf.b.clone(), tf.a.clone())
    } else {
        (
            tf.b.iter().map(|v| v / a0).collect(),
            tf.a.iter().map(|v| v / a0).collect(),
        )
    }
}

/// `scipy.signal.lfilter(b, a, x, zi=zi)` in place; `zi` is the state and is updated.
/// `b` and `a` must have equal length and `a[0] == 1`.
fn lfilter_in_place(b: &[f64], a: &[f64], x: &mut [f64], z: &mut [f64]) {
    let len_b = b.len();
    for xn in x.iter_mut() {
        let xv = *xn;
        if len_b > 1 {
            let y = z[0] + b[0] * xv;
            for n in 0..len_b - 2 {
                z[n] = z[n + 1] + xv * b[n + 1] - y * a[n + 1];
            }
            z[len_b - 2] = xv * b[len_b - 1] - y * a[len_b - 1];
            *xn = y;
        } else {
            *xn = xv * b[0];
        }
    }
}

/// `scipy.signal.filtfilt(b, a, x, padlen=padlen)` with odd padding.
///
/// ```
/// use a2perf_metrics::filter::{butter_lowpass, filtfilt};
/// let tf = butter_lowpass(8, 0.1).unwrap();
/// // A constant passes through a low-pass filter unchanged.
/// let y = filtfilt(&tf, &[2.0; 40], 27).unwrap();
/// assert!(y.iter().all(|v| (v - 2.0).abs() < 1e-9));
/// ```
pub fn filtfilt(tf: &TransferFunction, x: &[f64], padlen: usize) -> Result<Vec<f64>, FilterError> {
    if x.len() <= padlen {
        return Err(FilterError::TooShort {
            len: x.len(),
            padlen,
        });
    }
    let (mut b, mut a) = normalised(tf);
    let n = b.len().max(a.len());
    b.resize(n, 0.0);
    a.resize(n, 0.0);
    let zi = lfilter_zi(tf)?;
    // Odd extension: 2·x[0] − x[padlen..0], x, 2·x[-1] − x[-2..-(padlen+2)].
    let len = x.len();
    let mut ext = Vec::with_capacity(len + 2 * padlen);
    for i in (1..=padlen).rev() {
        ext.push(2.0 * x[0] - x[i]);
    }
    ext.extend_from_slice(x);
    for i in 1..=padlen {
        ext.push(2.0 * x[len - 1] - x[len - 1 - i]);
    }
    let x0 = ext[0];
    let mut z: Vec<f64> = zi.iter().map(|v| v * x0).collect();
    lfilter_in_place(&b, &a, &mut ext, &mut z);
    let y0 = ext[ext.len() - 1];
    ext.reverse();
    let mut z: Vec<f64> = zi.iter().map(|v| v * y0).collect();
    lfilter_in_place(&b, &a, &mut ext, &mut z);
    ext.reverse();
    Ok(ext[padlen..padlen + len].to_vec())
}

/// The originals' `lowpass_filter`: `butter(8, cutoff)` then `filtfilt` with
/// `padlen = min(len − 1, 3·max(len(a), len(b)))` (27 for order 8).
///
/// ```
/// let y: Vec<f64> = (0..50).map(|t| (t as f64 * 0.7).sin()).collect();
/// let smooth = a2perf_metrics::filter::lowpass(&y, 0.1).unwrap();
/// assert_eq!(smooth.len(), y.len());
/// ```
pub fn lowpass(y: &[f64], cutoff: f64) -> Result<Vec<f64>, FilterError> {
    let tf = butter_lowpass(8, cutoff)?;
    lowpass_with(&tf, y)
}

/// [`lowpass`] with a pre-designed filter (design once, filter many curves).
pub fn lowpass_with(tf: &TransferFunction, y: &[f64]) -> Result<Vec<f64>, FilterError> {
    if y.is_empty() {
        return Ok(Vec::new());
    }
    let ntaps = tf.a.len().max(tf.b.len());
    let padlen = (y.len() - 1).min(3 * ntaps);
    filtfilt(tf, y, padlen)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rejects_bad_cutoffs() {
        assert!(butter_lowpass(8, 0.0).is_err());
        assert!(butter_lowpass(8, 1.0).is_err());
        assert!(butter_lowpass(8, f64::NAN).is_err());
        assert!(butter_lowpass(0, 0.5).is_err());
    }

    #[test]
    fn dc_gain_is_one() {
        let tf = butter_lowpass(8, 0.1).unwrap();
        let g: f64 = tf.b.iter().sum::<f64>() / tf.a.iter().sum::<f64>();
        assert!((g - 1.0).abs() < 1e-9, "{g}");
    }

    /// `scipy.signal.lfilter_zi(*scipy.signal.butter(8, 0.01))` from SciPy 1.11.4 with NumPy
    /// 1.26.4 (bundled OpenBLAS 0.3.23, AVX-512 kernels, two threads) — the configuration behind
    /// the golden data. The single-threaded path gives 0.987478531135179… and AVX2-only CPUs
    /// 0.9886136495962651…, so this pins the blocked factorisation, not just "a" solution.
    #[test]
    fn lfilter_zi_matches_numpy_bit_for_bit() {
        let want = [
            0.9868199208606127,
            -6.748829841810551,
            19.782527945152246,
            -32.21822531810619,
            31.485545783226243,
            -18.463334959288357,
            6.015533732399041,
            -0.8400372622919937,
        ];
        let zi = lfilter_zi(&butter_lowpass(8, 0.01).unwrap()).unwrap();
        assert_eq!(zi, want);
    }

    #[test]
    fn lfilter_zi_solves_the_steady_state_system() {
        for order in 1..=20 {
            let tf = butter_lowpass(order, 0.3).unwrap();
            let zi = lfilter_zi(&tf).unwrap();
            let (b, a) = (&tf.b, &tf.a);
            // zi = companion(a)ᵀ·zi + (b[1:] − a[1:]·b[0]), row by row.
            for i in 0..order {
                let next = if i + 1 < order { zi[i + 1] } else { 0.0 };
                let rhs = -a[i + 1] * zi[0] + next + (b[i + 1] - a[i + 1] * b[0]);
                assert!((zi[i] - rhs).abs() < 1e-9, "order {order} row {i}");
            }
        }
    }

    #[test]
    fn short_signals_are_handled() {
        assert_eq!(lowpass(&[], 0.1).unwrap(), Vec::<f64>::new());
        assert_eq!(lowpass(&[3.0], 0.1).unwrap().len(), 1);
        assert!(filtfilt(&butter_lowpass(2, 0.3).unwrap(), &[1.0, 2.0], 5).is_err());
    }
}
