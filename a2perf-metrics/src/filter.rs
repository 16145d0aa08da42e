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
//! `lfilter_zi` solves `(I − Aᵀ) zi = b[1:] − a[1:]·b[0]` by LU with partial pivoting in the
//! operation order of OpenBLAS' `dgetf2`/`dtrsv` (NumPy's `linalg.solve` backend).
//!
//! The order-8 filter at cutoff 0.01 is **ill-conditioned** in ba form (Σb ≈ 9e-13): results are
//! only reproducible to ~1e-3 absolute, and no implementation (SciPy's included) is "exact" there.
//! At 0.1 the filter is well conditioned (~1e-10). See Oppenheim & Schafer, *Discrete-Time Signal
//! Processing*, §7.1 (bilinear transform) and Gustafsson (1996) for the forward–backward scheme.

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
/// Solves `(I − companion(a)ᵀ) zi = b[1:] − a[1:]·b[0]` like NumPy's `linalg.solve`. For the
/// ill-conditioned order-8 filters this system amplifies rounding differences, so the solver
/// follows the operation order of OpenBLAS' `dgetf2` (left-looking LU with partial pivoting,
/// fused multiply-adds, scaling by the reciprocal pivot) and its column-oriented `dtrsv`; that is
/// the variant closest to SciPy's output on the golden data.
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
fn solve(mut a: Vec<f64>, mut x: Vec<f64>, n: usize) -> Result<Vec<f64>, FilterError> {
    let mut ipiv = vec![0usize; n];
    for j in 0..n {
        for (i, &ip) in ipiv.iter().enumerate().take(j) {
            if ip != i {
                a.swap(i + j * n, ip + j * n);
            }
        }
        for i in 1..j {
            let mut d = 0.0;
            for k in 0..i {
                d = a[i + k * n].mul_add(a[k + j * n], d);
            }
            a[i + j * n] -= d;
        }
        for r in j..n {
            let mut d = 0.0;
            for k in 0..j {
                d = a[r + k * n].mul_add(a[k + j * n], d);
            }
            a[r + j * n] -= d;
        }
        let mut p = j;
        let mut best = a[j + j * n].abs();
        for r in j + 1..n {
            if a[r + j * n].abs() > best {
                best = a[r + j * n].abs();
                p = r;
            }
        }
        if best == 0.0 || !best.is_finite() {
            return Err(FilterError::Singular);
        }
        ipiv[j] = p;
        if p != j {
            for c in 0..=j {
                a.swap(j + c * n, p + c * n);
            }
        }
        let r = 1.0 / a[j + j * n];
        for row in j + 1..n {
            a[row + j * n] *= r;
        }
    }
    for (i, &ip) in ipiv.iter().enumerate() {
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

    #[test]
    fn short_signals_are_handled() {
        assert_eq!(lowpass(&[], 0.1).unwrap(), Vec::<f64>::new());
        assert_eq!(lowpass(&[3.0], 0.1).unwrap().len(), 1);
        assert!(filtfilt(&butter_lowpass(2, 0.3).unwrap(), &[1.0, 2.0], 5).is_err());
    }
}
