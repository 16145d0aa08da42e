//! Weighted-average (WA) wirelength, the smooth HPWL of ePlace and DREAMPlace:
//! per net and axis, `Σ x e^{x/γ} / Σ e^{x/γ} − Σ x e^{−x/γ} / Σ e^{−x/γ}`, which tends to
//! `max − min` as `γ → 0`. The exponents are shifted by the net's maximum (minimum) so that
//! they never overflow.
//!
//! Speed: one evaluation gathers every pin's position into flat arrays, writes all exponents,
//! takes them in one pass with [`exp_clamped`] (branch-free, so the compiler vectorizes
//! it; about eight times the throughput of the C library's `exp`, and the same bits on every
//! x86-64 CPU, which glibc's FMA/non-FMA dispatch does not promise), then sums per net and
//! scatters the gradient. Pins of fixed objects read and write a spare slot past the movable
//! objects, so no loop branches on them.

/// Pin of a net: a movable object (with an offset from its centre) or a fixed point.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Pin {
    /// Movable object index, or [`FIXED`].
    pub obj: u32,
    /// Offset from the object's centre, or the absolute position of a fixed pin.
    pub dx: f64,
    /// See `dx`.
    pub dy: f64,
}

/// `Pin::obj` of a pin that does not move.
pub const FIXED: u32 = u32::MAX;

/// Nets over movable objects, in compressed rows, and per-evaluation buffers.
#[derive(Clone, Debug, Default)]
pub struct WaNets {
    start: Vec<u32>,
    pins: Vec<Pin>,
    weight: Vec<f64>,
    /// Whether the net enters the WA objective (DREAMPlace ignores nets of more than
    /// `ignore_net_degree` pins); every net enters the HPWL.
    smooth: Vec<bool>,
    /// Per pin: x, y, then the weights of the upper and lower soft extremes in x and in y
    /// (`e^{(x−mid)/γ}` and its reciprocal; see `evaluate`).
    xs: Vec<f64>,
    ys: Vec<f64>,
    exps: Vec<[f64; 4]>,
    /// `(net, axis, max, min)` of the axes too wide for one shared exponential.
    wide: Vec<(u32, u8, f64, f64)>,
    /// Positions and gradient of the movable objects plus the spare slot of fixed pins.
    ext: Vec<[f64; 2]>,
    grad: Vec<[f64; 2]>,
}

/// Result of one evaluation.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct WaStats {
    /// Σ w · WA over the smooth nets.
    pub wa: f64,
    /// Σ w · HPWL over every net.
    pub hpwl: f64,
}

/// Half the widest span, in units of γ, that one shared exponential per pin covers.
const WIDE: f64 = 700.0;

/// `e^x` for `|x| ≤ 708` to within 2 ulp; `x` below −708 gives 0 (`e^x` would be subnormal),
/// above 708 gives `e^708`; NaN stays NaN.
///
/// Straight-line code (no branch, no call), so that a loop over a slice of exponents is
/// vectorized: `x = n·ln2 + r` with `|r| ≤ ln2/2`, `e^r` by its Taylor polynomial of degree 13
/// (remainder below 2⁻⁵⁸), and `2ⁿ` built in the exponent bits.
///
/// ```
/// use a2perf_circuit::analytical::wirelength::exp_clamped;
/// for x in [0.0, -1e-9, -0.5, 1.0, -37.25, 200.0, -700.0] {
///     let (ours, libm) = (exp_clamped(x), f64::exp(x));
///     assert!((ours - libm).abs() <= 4.0 * f64::EPSILON * libm, "{x}");
/// }
/// assert_eq!(exp_clamped(-800.0), 0.0);
/// ```
#[inline]
pub fn exp_clamped(x: f64) -> f64 {
    // ln 2 split (fdlibm's): the high part has trailing zero bits, so n·LN2_HI is exact.
    const LN2_HI: f64 = f64::from_bits(0x3fe6_2e42_fee0_0000);
    const LN2_LO: f64 = f64::from_bits(0x3dea_39ef_3579_3c76);
    // 1.5·2⁵²: adding it rounds to an integer held in the low mantissa bits.
    const SHIFT: f64 = 6_755_399_441_055_744.0;
    // `clamp` keeps a NaN.
    let xc = x.clamp(-708.0, 708.0);
    let t = xc * std::f64::consts::LOG2_E + SHIFT;
    let n = t - SHIFT;
    let r = (xc - n * LN2_HI) - n * LN2_LO;
    // Taylor coefficients 1/k!, k = 13 … 0, by Horner.
    const C: [f64; 14] = [
        1.0 / 6_227_020_800.0,
        1.0 / 479_001_600.0,
        1.0 / 39_916_800.0,
        1.0 / 3_628_800.0,
        1.0 / 362_880.0,
        1.0 / 40_320.0,
        1.0 / 5_040.0,
        1.0 / 720.0,
        1.0 / 120.0,
        1.0 / 24.0,
        1.0 / 6.0,
        0.5,
        1.0,
        1.0,
    ];
    let mut p = C[0];
    for c in &C[1..] {
        p = p * r + c;
    }
    // |n| ≤ 1022, so 2ⁿ is a normal number; the mantissa of `t` holds 2⁵¹ + n.
    let ni = (t.to_bits() & ((1 << 52) - 1)) as i64 - (1 << 51);
    let scale = f64::from_bits(((ni + 1023) as u64) << 52);
    let y = p * scale;
    if x < -708.0 { 0.0 } else { y }
}

impl WaNets {
    /// Removes every net (keeps the buffers).
    pub fn clear(&mut self) {
        self.start.clear();
        self.start.push(0);
        self.pins.clear();
        self.weight.clear();
        self.smooth.clear();
    }

    /// Adds a net.
    pub fn push_net(&mut self, pins: impl IntoIterator<Item = Pin>, weight: f64, smooth: bool) {
        if self.start.is_empty() {
            self.start.push(0);
        }
        self.pins.extend(pins);
        self.start.push(self.pins.len() as u32);
        self.weight.push(weight);
        self.smooth.push(smooth);
    }

    /// Number of nets.
    pub fn len(&self) -> usize {
        self.weight.len()
    }

    /// Whether there is no net.
    pub fn is_empty(&self) -> bool {
        self.weight.is_empty()
    }

    /// Σ over each object's pins of the net weight, for smooth nets (DREAMPlace's
    /// preconditioner term), added into `out`.
    pub fn add_pin_weights(&self, out: &mut [f64]) {
        for n in 0..self.len() {
            if !self.smooth[n] {
                continue;
            }
            let (a, b) = (self.start[n] as usize, self.start[n + 1] as usize);
            for p in &self.pins[a..b] {
                if p.obj != FIXED {
                    out[p.obj as usize] += self.weight[n];
                }
            }
        }
    }

    /// WA wirelength and HPWL of `pos`; adds `∂WA/∂pos` into `grad` (which must be zeroed by
    /// the caller).
    pub fn evaluate(&mut self, pos: &[[f64; 2]], gamma: f64, grad: &mut [[f64; 2]]) -> WaStats {
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx2") {
            // SAFETY: the CPU has AVX2, the only feature `evaluate_avx2` is compiled for.
            return unsafe { self.evaluate_avx2(pos, gamma, grad) };
        }
        self.evaluate_generic(pos, gamma, grad)
    }

    /// [`Self::evaluate`] compiled for AVX2: four lanes instead of SSE2's two in the
    /// exponential pass. Rust never fuses a multiply and an add on its own, so both builds
    /// round every operation alike and give the same bits.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    fn evaluate_avx2(&mut self, pos: &[[f64; 2]], gamma: f64, grad: &mut [[f64; 2]]) -> WaStats {
        self.evaluate_generic(pos, gamma, grad)
    }

    #[inline(always)]
    fn evaluate_generic(&mut self, pos: &[[f64; 2]], gamma: f64, grad: &mut [[f64; 2]]) -> WaStats {
        let m = pos.len();
        let slot = |p: &Pin| (p.obj as usize).min(m);
        self.ext.clear();
        self.ext.extend_from_slice(pos);
        self.ext.push([0.0, 0.0]);
        let np = self.pins.len();
        self.xs.resize(np, 0.0);
        self.ys.resize(np, 0.0);
        self.exps.resize(np, [0.0; 4]);
        for ((p, x), y) in self.pins.iter().zip(&mut self.xs).zip(&mut self.ys) {
            let q = self.ext[slot(p)];
            *x = q[0] + p.dx;
            *y = q[1] + p.dy;
        }
        // Bounds, HPWL and the exponents. WA is a ratio of sums, so each axis's exponentials
        // may share any factor: `e = e^{(v−mid)/γ}` and `1/e` serve both sums with one
        // exponential, as long as `|v − mid|/γ` stays in range; wider nets (rare: spans of
        // more than 1,400 γ) take the two shifted exponentials after the vector pass.
        let mut stats = WaStats::default();
        let inv = 1.0 / gamma;
        self.wide.clear();
        for n in 0..self.len() {
            let (a, b) = (self.start[n] as usize, self.start[n + 1] as usize);
            if a == b {
                continue;
            }
            let (xs, ys) = (&self.xs[a..b], &self.ys[a..b]);
            let (xhi, xlo) = bounds(xs);
            let (yhi, ylo) = bounds(ys);
            stats.hpwl += self.weight[n] * ((xhi - xlo) + (yhi - ylo));
            let exps = &mut self.exps[a..b];
            if !self.smooth[n] {
                exps.iter_mut().for_each(|e| *e = [0.0; 4]);
                continue;
            }
            for (axis, (vals, hi, lo)) in [(xs, xhi, xlo), (ys, yhi, ylo)].into_iter().enumerate() {
                let mid = 0.5 * (hi + lo);
                if (hi - lo) * inv > 2.0 * WIDE {
                    self.wide.push((n as u32, axis as u8, hi, lo));
                    exps.iter_mut().for_each(|e| e[2 * axis] = 0.0);
                } else {
                    for (e, &v) in exps.iter_mut().zip(vals) {
                        e[2 * axis] = (v - mid) * inv;
                    }
                }
            }
        }
        for e in &mut self.exps {
            let (x, y) = (exp_clamped(e[0]), exp_clamped(e[2]));
            *e = [x, 1.0 / x, y, 1.0 / y];
        }
        for &(n, axis, hi, lo) in &self.wide {
            let (a, b) = (
                self.start[n as usize] as usize,
                self.start[n as usize + 1] as usize,
            );
            let vals = if axis == 0 {
                &self.xs[a..b]
            } else {
                &self.ys[a..b]
            };
            let i = 2 * axis as usize;
            for (e, &v) in self.exps[a..b].iter_mut().zip(vals) {
                e[i] = exp_clamped((v - hi) * inv);
                e[i + 1] = exp_clamped((lo - v) * inv);
            }
        }
        // Sums per net, then the gradient.
        self.grad.clear();
        self.grad.resize(m + 1, [0.0, 0.0]);
        for n in 0..self.len() {
            if !self.smooth[n] {
                continue;
            }
            let (a, b) = (self.start[n] as usize, self.start[n + 1] as usize);
            if a == b {
                continue;
            }
            let w = self.weight[n];
            let pins = &self.pins[a..b];
            let exps = &self.exps[a..b];
            for (axis, vals) in [&self.xs[a..b], &self.ys[a..b]].into_iter().enumerate() {
                let (ia, ib) = (2 * axis, 2 * axis + 1);
                let (mut sa, mut ta, mut sb, mut tb) = (0.0, 0.0, 0.0, 0.0);
                for (e, &v) in exps.iter().zip(vals) {
                    sa += e[ia];
                    ta += v * e[ia];
                    sb += e[ib];
                    tb += v * e[ib];
                }
                let (isa, isb) = (1.0 / sa, 1.0 / sb);
                let (ma, mb) = (ta * isa, tb * isb);
                stats.wa += w * (ma - mb);
                let (ra, rb) = (w * isa, w * isb);
                for ((p, e), &v) in pins.iter().zip(exps).zip(vals) {
                    let d =
                        ra * e[ia] * (1.0 + (v - ma) * inv) - rb * e[ib] * (1.0 - (v - mb) * inv);
                    self.grad[slot(p)][axis] += d;
                }
            }
        }
        for (g, e) in grad.iter_mut().zip(&self.grad) {
            g[0] += e[0];
            g[1] += e[1];
        }
        stats
    }
}

/// `(max, min)` of a non-empty slice.
#[inline]
fn bounds(v: &[f64]) -> (f64, f64) {
    v.iter()
        .fold((f64::NEG_INFINITY, f64::INFINITY), |(hi, lo), &x| {
            (hi.max(x), lo.min(x))
        })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// WA and its gradient of one net on one axis, straight from the definition with each
    /// soft extreme shifted by its own extreme (libm's `exp`).
    fn wa_reference(v: &[f64], gamma: f64) -> (f64, Vec<f64>) {
        let (hi, lo) = bounds(v);
        let ea: Vec<f64> = v.iter().map(|x| ((x - hi) / gamma).exp()).collect();
        let eb: Vec<f64> = v.iter().map(|x| ((lo - x) / gamma).exp()).collect();
        let (sa, sb) = (ea.iter().sum::<f64>(), eb.iter().sum::<f64>());
        let ma = v.iter().zip(&ea).map(|(x, e)| x * e).sum::<f64>() / sa;
        let mb = v.iter().zip(&eb).map(|(x, e)| x * e).sum::<f64>() / sb;
        let grad = v
            .iter()
            .zip(ea.iter().zip(&eb))
            .map(|(x, (a, b))| {
                a / sa * (1.0 + (x - ma) / gamma) - b / sb * (1.0 - (x - mb) / gamma)
            })
            .collect();
        (ma - mb, grad)
    }

    #[test]
    fn shared_and_wide_net_exponentials_agree_with_the_definition() {
        // x spans 0..90: with γ = 30 one shared exponential serves the net; with γ = 0.05 the
        // span is 1,800 γ, so the net takes the two shifted exponentials. y stays narrow.
        let pos = [[0.0, 1.0], [10.0, 2.0], [90.0, 2.5], [89.9, 1.5]];
        let mut nets = WaNets::default();
        nets.push_net(
            (0..4).map(|k| Pin {
                obj: k,
                dx: 0.0,
                dy: 0.0,
            }),
            1.0,
            true,
        );
        for gamma in [30.0, 0.05] {
            let mut grad = [[0.0; 2]; 4];
            let stats = nets.evaluate(&pos, gamma, &mut grad);
            let (wx, gx) = wa_reference(&pos.map(|p| p[0]), gamma);
            let (wy, gy) = wa_reference(&pos.map(|p| p[1]), gamma);
            assert!(
                (stats.wa - (wx + wy)).abs() <= 1e-12 * (wx + wy),
                "γ {gamma}"
            );
            for k in 0..4 {
                assert!((grad[k][0] - gx[k]).abs() <= 1e-12, "γ {gamma} x {k}");
                assert!((grad[k][1] - gy[k]).abs() <= 1e-12, "γ {gamma} y {k}");
            }
            assert_eq!(nets.wide.len(), usize::from(gamma < 1.0));
        }
    }

    #[test]
    fn the_avx2_build_gives_the_same_bits_as_the_generic_one() {
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx2") {
            let pos: Vec<[f64; 2]> = (0..40)
                .map(|k| [(k * 37 % 101) as f64 * 0.7, (k * 53 % 89) as f64 * 0.3])
                .collect();
            let mut nets = WaNets::default();
            for n in 0..25u32 {
                let pins = (0..2 + n % 7).map(|j| Pin {
                    obj: if j == 3 { FIXED } else { (n * 7 + j * 11) % 40 },
                    dx: 0.1 * j as f64,
                    dy: -0.2 * j as f64,
                });
                nets.push_net(pins, 1.0 + 0.1 * n as f64, n % 11 != 0);
            }
            for gamma in [0.01, 0.7, 25.0] {
                let (mut g1, mut g2) = (vec![[0.0; 2]; 40], vec![[0.0; 2]; 40]);
                let s1 = nets.evaluate_generic(&pos, gamma, &mut g1);
                // SAFETY: the CPU has AVX2 (checked above).
                let s2 = unsafe { nets.evaluate_avx2(&pos, gamma, &mut g2) };
                assert_eq!(s1, s2);
                assert_eq!(g1, g2);
            }
        }
    }

    #[test]
    fn exp_clamped_is_within_two_ulp_of_libm() {
        let mut worst = 0.0f64;
        let mut x = 708.0f64;
        while x > -708.0 {
            let (ours, libm) = (exp_clamped(x), x.exp());
            worst = worst.max((ours - libm).abs() / libm);
            x -= 0.012_345_678_9;
        }
        assert!(worst <= 2.0 * f64::EPSILON, "worst relative error {worst}");
        assert_eq!(exp_clamped(-709.0), 0.0);
        assert_eq!(exp_clamped(f64::NEG_INFINITY), 0.0);
        assert!(exp_clamped(f64::NAN).is_nan());
        assert_eq!(exp_clamped(0.0), 1.0);
    }
}
