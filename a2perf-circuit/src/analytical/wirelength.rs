//! Weighted-average (WA) wirelength, the smooth HPWL of ePlace and DREAMPlace:
//! per net and axis, `Σ x e^{x/γ} / Σ e^{x/γ} − Σ x e^{−x/γ} / Σ e^{−x/γ}`, which tends to
//! `max − min` as `γ → 0`. The exponents are shifted by the net's maximum (minimum) so that
//! they never overflow.
//!
//! Speed: nets are grouped by their number of pins, and each group is stored pin-major
//! (`[pin j][net i]`), so that every step of an evaluation (gather, bounds, exponentials, sums,
//! gradient) is one loop over the group's nets that the compiler vectorizes, with no per-net
//! loop overhead and no branch on the degree. The pins' positions, offsets and gradients are of
//! the kernels' float type `F` ([`Real`]: `f32` in the placer, as DREAMPlace's default `dtype`;
//! `f64` where the tests check gradients), the sums the placer reads are `f64`. The
//! exponential is [`Real::exp_clamped`] (branch-free, so it vectorizes; about eight times the
//! throughput of the C library's `exp`, and the same bits on every x86-64 CPU, which glibc's
//! FMA/non-FMA dispatch does not promise). Two-pin nets,
//! half of a typical netlist, take the closed form `|Δ|·tanh(|Δ|/2γ)` (one exponential per
//! axis). Pins of fixed objects read spare slots (position 0, their offset is their absolute
//! position) and write spare gradient slots, so no loop branches on them.

use super::real::Real;

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

/// Nets over movable objects, in compressed rows, their degree groups and per-evaluation
/// buffers.
#[derive(Clone, Debug, Default)]
pub struct WaNets<F: Real = f64> {
    start: Vec<u32>,
    pins: Vec<Pin>,
    weight: Vec<f64>,
    /// Whether the net enters the WA objective (DREAMPlace ignores nets of more than
    /// `ignore_net_degree` pins); every net enters the HPWL.
    smooth: Vec<bool>,
    /// The smooth nets of two or more pins by degree (built on the first evaluation after a
    /// change), and the other nets of two or more pins (HPWL only).
    groups: Vec<Group<F>>,
    hpwl_only: Vec<u32>,
    built: bool,
    /// Per axis, positions and gradient of the movable objects plus the spare slots.
    px: Vec<F>,
    py: Vec<F>,
    gx: Vec<F>,
    gy: Vec<F>,
    scratch: Scratch<F>,
    /// `(group, net)` of the nets too wide for one shared exponential on some axis.
    wide: Vec<(u32, u32)>,
}

/// Smooth nets of one degree, pin-major: pin `j` of net `i` at `j·n + i`.
#[derive(Clone, Debug, Default)]
struct Group<F> {
    deg: usize,
    weight: Vec<F>,
    slot: Vec<u32>,
    dx: Vec<F>,
    dy: Vec<F>,
}

/// Buffers of one group's evaluation on one axis.
#[derive(Clone, Debug, Default)]
struct Scratch<F> {
    v: Vec<F>,
    e: Vec<F>,
    r: Vec<F>,
    mid: Vec<F>,
    span: Vec<F>,
    ma: Vec<F>,
    mb: Vec<F>,
    ra: Vec<F>,
    rb: Vec<F>,
    /// Per net: its HPWL, then its WA.
    net: Vec<F>,
    wide: Vec<bool>,
}

/// Result of one evaluation.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct WaStats {
    /// Σ w · WA over the smooth nets.
    pub wa: f64,
    /// Σ w · HPWL over every net.
    pub hpwl: f64,
}

/// Spare slots of the fixed pins (positions 0, gradients thrown away).
const SPARE: usize = 16;

/// The interleaving of a group's nets (see `WaNets::build`).
const STRIDE: usize = 16;

/// Twice the widest span, in units of γ, that one shared exponential per pin covers (each
/// exponent within `EXP_LIMIT − 8`, so that sums over 100 pins stay finite): 1,400 in `f64`,
/// 158 in `f32`.
#[inline(always)]
fn wide_span<F: Real>() -> F {
    F::of(2.0 * (F::EXP_LIMIT - 8.0))
}

impl<F: Real> WaNets<F> {
    /// Removes every net (keeps the buffers).
    pub fn clear(&mut self) {
        self.start.clear();
        self.start.push(0);
        self.pins.clear();
        self.weight.clear();
        self.smooth.clear();
        self.built = false;
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
        self.built = false;
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

    vector_builds! {
        /// WA wirelength and HPWL of `pos`; adds `∂WA/∂pos` into `grad` (which must be zeroed
        /// by the caller).
        pub fn evaluate / evaluate_avx2 / evaluate_avx512 (
            &mut self,
            pos: &[[f64; 2]],
            gamma: f64,
            grad: &mut [[f64; 2]],
        ) -> WaStats = evaluate_generic
    }

    /// Sorts the nets into degree groups (pin-major).
    fn build(&mut self, m: usize) {
        self.groups.clear();
        self.hpwl_only.clear();
        let mut by_deg: Vec<Vec<u32>> = Vec::new();
        for n in 0..self.len() {
            let deg = (self.start[n + 1] - self.start[n]) as usize;
            if deg < 2 {
                // No extent: nothing to add to either sum.
                continue;
            }
            if !self.smooth[n] {
                self.hpwl_only.push(n as u32);
                continue;
            }
            if by_deg.len() <= deg {
                by_deg.resize(deg + 1, Vec::new());
            }
            by_deg[deg].push(n as u32);
        }
        let mut fixed_pins = 0usize;
        for (deg, nets) in by_deg.into_iter().enumerate() {
            if nets.is_empty() {
                continue;
            }
            let k = nets.len();
            // Nets in netlist order often share their driver, so that consecutive gradient
            // adds would hit one object, each waiting for the last; interleaved (net `r`, `r +
            // STRIDE`, …, then `r + 1`, …) they hit different objects.
            let nets: Vec<u32> = (0..STRIDE.min(k))
                .flat_map(|r| nets[r..].iter().step_by(STRIDE).copied())
                .collect();
            let mut g = Group {
                deg,
                weight: nets
                    .iter()
                    .map(|&n| F::of(self.weight[n as usize]))
                    .collect(),
                slot: vec![0; deg * k],
                dx: vec![F::zero(); deg * k],
                dy: vec![F::zero(); deg * k],
            };
            for (i, &n) in nets.iter().enumerate() {
                let a = self.start[n as usize] as usize;
                for j in 0..deg {
                    let p = &self.pins[a + j];
                    g.slot[j * k + i] = if p.obj == FIXED {
                        // Spread over the spare slots, for the same reason.
                        fixed_pins += 1;
                        (m + fixed_pins % SPARE) as u32
                    } else {
                        p.obj
                    };
                    g.dx[j * k + i] = F::of(p.dx);
                    g.dy[j * k + i] = F::of(p.dy);
                }
            }
            self.groups.push(g);
        }
        self.built = true;
    }

    #[inline(always)]
    fn evaluate_generic(&mut self, pos: &[[f64; 2]], gamma: f64, grad: &mut [[f64; 2]]) -> WaStats {
        let m = pos.len();
        // The spare slots start at `m`: a change of the number of objects rebuilds the groups.
        if !self.built || self.px.len() != m + SPARE {
            self.build(m);
        }
        self.px.clear();
        self.py.clear();
        self.px.extend(pos.iter().map(|p| F::of(p[0])));
        self.py.extend(pos.iter().map(|p| F::of(p[1])));
        self.px.resize(m + SPARE, F::zero());
        self.py.resize(m + SPARE, F::zero());
        self.gx.clear();
        self.gx.resize(m + SPARE, F::zero());
        self.gy.clear();
        self.gy.resize(m + SPARE, F::zero());
        let inv = F::one() / F::of(gamma);
        let mut stats = WaStats::default();
        self.wide.clear();
        for (gi, g) in self.groups.iter().enumerate() {
            for (p, off, gr) in [
                (&self.px, &g.dx, &mut self.gx),
                (&self.py, &g.dy, &mut self.gy),
            ] {
                let ax = Axis {
                    p,
                    off,
                    grad: gr,
                    inv,
                };
                let (wa, hpwl) = if g.deg == 2 {
                    two_pin_axis(g, ax, &mut self.scratch)
                } else {
                    group_axis(g, ax, &mut self.scratch, gi, &mut self.wide)
                };
                stats.wa += wa;
                stats.hpwl += hpwl;
            }
        }
        // Nets too wide for a shared exponential (rare: spans of more than 1,400 γ), with the
        // two shifted exponentials, net by net.
        self.wide.sort_unstable();
        self.wide.dedup();
        for &(gi, i) in &self.wide {
            let g = &self.groups[gi as usize];
            let k = g.weight.len();
            let w = g.weight[i as usize];
            for (p, off, gr) in [
                (&self.px, &g.dx, &mut self.gx),
                (&self.py, &g.dy, &mut self.gy),
            ] {
                let v: Vec<F> = (0..g.deg)
                    .map(|j| p[g.slot[j * k + i as usize] as usize] + off[j * k + i as usize])
                    .collect();
                let (hi, lo) = bounds(&v);
                if (hi - lo) * inv <= wide_span() {
                    continue;
                }
                let (mut sa, mut ta, mut sb, mut tb) = (F::zero(), F::zero(), F::zero(), F::zero());
                for &x in &v {
                    let (ea, eb) = (
                        ((x - hi) * inv).exp_clamped(),
                        ((lo - x) * inv).exp_clamped(),
                    );
                    sa += ea;
                    ta += x * ea;
                    sb += eb;
                    tb += x * eb;
                }
                let (ma, mb) = (ta / sa, tb / sb);
                stats.wa += (w * (ma - mb)).widen();
                let one = F::one();
                for (j, &x) in v.iter().enumerate() {
                    let (ea, eb) = (
                        ((x - hi) * inv).exp_clamped(),
                        ((lo - x) * inv).exp_clamped(),
                    );
                    gr[g.slot[j * k + i as usize] as usize] +=
                        w * (ea / sa * (one + (x - ma) * inv) - eb / sb * (one - (x - mb) * inv));
                }
            }
        }
        for &n in &self.hpwl_only {
            let (a, b) = (
                self.start[n as usize] as usize,
                self.start[n as usize + 1] as usize,
            );
            let pins = &self.pins[a..b];
            let at = |p: &Pin, d: usize| {
                let q = if p.obj == FIXED {
                    [0.0, 0.0]
                } else {
                    pos[p.obj as usize]
                };
                q[d] + if d == 0 { p.dx } else { p.dy }
            };
            for d in 0..2 {
                let v: Vec<f64> = pins.iter().map(|p| at(p, d)).collect();
                let (hi, lo) = bounds(&v);
                stats.hpwl += self.weight[n as usize] * (hi - lo);
            }
        }
        for ((g, x), y) in grad.iter_mut().zip(&self.gx).zip(&self.gy) {
            g[0] += x.widen();
            g[1] += y.widen();
        }
        stats
    }
}

/// One axis of an evaluation: the positions (with the spare slot), the pins' offsets of a
/// group, the gradient to add to, and `1/γ`.
struct Axis<'a, F> {
    p: &'a [F],
    off: &'a [F],
    grad: &'a mut [F],
    inv: F,
}

/// WA of the two-pin nets on one axis in closed form: with `d = b − a` and `t = |d|/γ`,
/// `WA = |d|·tanh(t/2)` and `∂WA/∂b = sign(d)·(tanh(t/2) + (t/2)·sech²(t/2))`, from
/// `e = e^{−t}` (never overflows). Returns `(Σ w·WA, Σ w·|d|)`.
///
/// Three passes (gather, arithmetic, scatter) so that the arithmetic, which is one long
/// dependency chain per net, runs four nets per instruction.
#[inline(always)]
fn two_pin_axis<F: Real>(g: &Group<F>, ax: Axis<'_, F>, s: &mut Scratch<F>) -> (f64, f64) {
    let Axis { p, off, grad, inv } = ax;
    let k = g.weight.len();
    let (s0, s1) = g.slot.split_at(k);
    let (o0, o1) = off.split_at(k);
    for b in [&mut s.mid, &mut s.span, &mut s.ma, &mut s.mb] {
        b.resize(k, F::zero());
    }
    let (d, gb, wa, hpwl) = (
        &mut s.mid[..k],
        &mut s.span[..k],
        &mut s.ma[..k],
        &mut s.mb[..k],
    );
    for (i, d) in d.iter_mut().enumerate() {
        *d = (p[s1[i] as usize] + o1[i]) - (p[s0[i] as usize] + o0[i]);
    }
    let (one, two) = (F::one(), F::of(2.0));
    for i in 0..k {
        let ad = d[i].abs();
        let t = ad * inv;
        let e = (-t).exp_clamped();
        let q = one / (one + e);
        let th = (one - e) * q;
        let w = g.weight[i];
        wa[i] = w * ad * th;
        hpwl[i] = w * ad;
        let v = w * (th + two * t * e * q * q);
        gb[i] = if d[i] < F::zero() { -v } else { v };
    }
    for ((&a, &b), &v) in s0.iter().zip(s1).zip(gb.iter()) {
        grad[b as usize] += v;
        grad[a as usize] -= v;
    }
    (sum_lanes(wa), sum_lanes(hpwl))
}

/// WA of a group of nets of three or more pins on one axis; the nets too wide for one shared
/// exponential are left out and listed in `wide`. Returns `(Σ w·WA, Σ w·HPWL)`.
///
/// WA is a ratio of sums, so the exponentials of a net may share any factor: `e^{(v−mid)/γ}`
/// and its reciprocal serve both soft extremes with one exponential, as long as
/// `|v − mid|/γ` stays in range.
#[inline(always)]
fn group_axis<F: Real>(
    g: &Group<F>,
    ax: Axis<'_, F>,
    s: &mut Scratch<F>,
    gi: usize,
    wide: &mut Vec<(u32, u32)>,
) -> (f64, f64) {
    let Axis { p, off, grad, inv } = ax;
    let (k, deg) = (g.weight.len(), g.deg);
    let len = deg * k;
    for b in [&mut s.v, &mut s.e, &mut s.r] {
        b.resize(len, F::zero());
    }
    for b in [
        &mut s.mid,
        &mut s.span,
        &mut s.ma,
        &mut s.mb,
        &mut s.ra,
        &mut s.rb,
    ] {
        b.resize(k, F::zero());
    }
    s.wide.resize(k, false);
    let (v, e, r) = (&mut s.v[..len], &mut s.e[..len], &mut s.r[..len]);
    for ((v, &sl), &o) in v.iter_mut().zip(&g.slot).zip(off) {
        *v = p[sl as usize] + o;
    }
    // Bounds: `mid` holds the maximum, `span` the minimum, until both are known.
    let (hi, lo) = (&mut s.mid[..k], &mut s.span[..k]);
    hi.copy_from_slice(&v[..k]);
    lo.copy_from_slice(&v[..k]);
    for vj in v[k..].chunks_exact(k) {
        for ((h, l), &x) in hi.iter_mut().zip(lo.iter_mut()).zip(vj) {
            *h = if x > *h { x } else { *h };
            *l = if x < *l { x } else { *l };
        }
    }
    s.net.resize(k, F::zero());
    let (half, wide_span) = (F::of(0.5), wide_span::<F>());
    for (i, ((h, l), wd)) in hi
        .iter_mut()
        .zip(lo.iter_mut())
        .zip(&mut s.wide[..k])
        .enumerate()
    {
        let span = *h - *l;
        s.net[i] = g.weight[i] * span;
        *wd = span * inv > wide_span;
        *h = half * (*h + *l);
        *l = span;
    }
    let hpwl = sum_lanes(&s.net[..k]);
    if s.wide[..k].iter().any(|&w| w) {
        wide.extend(
            s.wide[..k]
                .iter()
                .enumerate()
                .filter(|&(_, &w)| w)
                .map(|(i, _)| (gi as u32, i as u32)),
        );
    }
    let mid = &s.mid[..k];
    let (sa, ta, sb, tb) = (
        &mut s.ma[..k],
        &mut s.mb[..k],
        &mut s.ra[..k],
        &mut s.rb[..k],
    );
    for b in [&mut *sa, &mut *ta, &mut *sb, &mut *tb] {
        b.iter_mut().for_each(|x| *x = F::zero());
    }
    let one = F::one();
    for ((vj, ej), rj) in v
        .chunks_exact(k)
        .zip(e.chunks_exact_mut(k))
        .zip(r.chunks_exact_mut(k))
    {
        for i in 0..k {
            let x = vj[i];
            let ea = ((x - mid[i]) * inv).exp_clamped();
            let eb = one / ea;
            ej[i] = ea;
            rj[i] = eb;
            sa[i] += ea;
            ta[i] += x * ea;
            sb[i] += eb;
            tb[i] += x * eb;
        }
    }
    // Soft extremes, WA and the gradient's factors; zero for the wide nets.
    let wa = &mut s.net[..k];
    for i in 0..k {
        let (isa, isb) = (one / sa[i], one / sb[i]);
        let (ma, mb) = (ta[i] * isa, tb[i] * isb);
        let w = if s.wide[i] { F::zero() } else { g.weight[i] };
        wa[i] = if s.wide[i] { F::zero() } else { w * (ma - mb) };
        // `sa`, `sb` become the gradient's factors, `ta`, `tb` the soft extremes.
        ta[i] = ma;
        tb[i] = mb;
        sa[i] = w * isa;
        sb[i] = w * isb;
    }
    // The gradient per pin (over `e`), then the scatter: apart, the arithmetic vectorizes.
    let wide = &s.wide[..k];
    for (j, vj) in v.chunks_exact(k).enumerate() {
        let (ej, rj) = (&mut e[j * k..(j + 1) * k], &r[j * k..(j + 1) * k]);
        for i in 0..k {
            let x = vj[i];
            let d = sa[i] * ej[i] * (one + (x - ta[i]) * inv)
                - sb[i] * rj[i] * (one - (x - tb[i]) * inv);
            ej[i] = if wide[i] { F::zero() } else { d };
        }
    }
    for (&sl, &d) in g.slot.iter().zip(e.iter()) {
        grad[sl as usize] += d;
    }
    (sum_lanes(wa), hpwl)
}

/// `Σ v` in four `f64` lanes (so that it vectorizes, the same on every build).
#[inline(always)]
fn sum_lanes<F: Real>(v: &[F]) -> f64 {
    let mut acc = [0.0f64; 4];
    let chunks = v.chunks_exact(4);
    let rest = chunks.remainder();
    for c in chunks {
        for (a, x) in acc.iter_mut().zip(c) {
            *a += x.widen();
        }
    }
    for (a, x) in acc.iter_mut().zip(rest) {
        *a += x.widen();
    }
    (acc[0] + acc[1]) + (acc[2] + acc[3])
}

/// `(max, min)` of a non-empty slice.
#[inline]
fn bounds<F: Real>(v: &[F]) -> (F, F) {
    v.iter()
        .fold((F::neg_infinity(), F::infinity()), |(hi, lo), &x| {
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

    /// One net's WA against the definition, in `F`, to relative tolerance `tol`; whether the
    /// net took the wide path.
    fn check_one_net<F: Real>(gamma: f64, tol: f64) -> bool {
        let pos = [[0.0, 1.0], [10.0, 2.0], [90.0, 2.5], [89.9, 1.5]];
        let mut nets = WaNets::<F>::default();
        nets.push_net(
            (0..4).map(|k| Pin {
                obj: k,
                dx: 0.0,
                dy: 0.0,
            }),
            1.0,
            true,
        );
        let mut grad = [[0.0; 2]; 4];
        let stats = nets.evaluate(&pos, gamma, &mut grad);
        let (wx, gx) = wa_reference(&pos.map(|p| p[0]), gamma);
        let (wy, gy) = wa_reference(&pos.map(|p| p[1]), gamma);
        assert!(
            (stats.wa - (wx + wy)).abs() <= tol * (wx + wy),
            "γ {gamma}: {} against {}",
            stats.wa,
            wx + wy
        );
        for k in 0..4 {
            assert!((grad[k][0] - gx[k]).abs() <= tol, "γ {gamma} x {k}");
            assert!((grad[k][1] - gy[k]).abs() <= tol, "γ {gamma} y {k}");
        }
        !nets.wide.is_empty()
    }

    #[test]
    fn shared_and_wide_net_exponentials_agree_with_the_definition() {
        // x spans 0..90: with γ = 30 one shared exponential serves the net; with γ = 0.05 the
        // span is 1,800 γ, so the net takes the two shifted exponentials in either type, and
        // with γ = 0.5 (180 γ) in `f32` only. y stays narrow. In `f32` a position near 90 is
        // known to 4e-6, and the gradient reads it divided by γ.
        for (gamma, wide64, wide32) in
            [(30.0, false, false), (0.5, false, true), (0.05, true, true)]
        {
            assert_eq!(check_one_net::<f64>(gamma, 1e-12), wide64, "γ {gamma}");
            let tol = 1e-5f64.max(2e-5 / gamma);
            assert_eq!(check_one_net::<f32>(gamma, tol), wide32, "γ {gamma}");
        }
    }

    fn vector_builds_agree<F: Real>() {
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx2") && std::arch::is_x86_feature_detected!("fma")
        {
            let pos: Vec<[f64; 2]> = (0..40)
                .map(|k| [(k * 37 % 101) as f64 * 0.7, (k * 53 % 89) as f64 * 0.3])
                .collect();
            let mut nets = WaNets::<F>::default();
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
                // SAFETY: the CPU has AVX2 and FMA (checked above).
                let s2 = unsafe { nets.evaluate_avx2(&pos, gamma, &mut g2) };
                assert_eq!(s1, s2);
                assert_eq!(g1, g2);
                if std::arch::is_x86_feature_detected!("avx512f") {
                    let mut g3 = vec![[0.0; 2]; 40];
                    // SAFETY: the CPU has AVX-512F (checked just above).
                    let s3 = unsafe { nets.evaluate_avx512(&pos, gamma, &mut g3) };
                    assert_eq!(s1, s3);
                    assert_eq!(g1, g3);
                }
            }
        }
    }

    #[test]
    fn the_vector_builds_give_the_same_bits_as_the_generic_one() {
        vector_builds_agree::<f64>();
        vector_builds_agree::<f32>();
    }
}
