//! Weighted-average (WA) wirelength, the smooth HPWL of ePlace and DREAMPlace:
//! per net and axis, `Σ x e^{x/γ} / Σ e^{x/γ} − Σ x e^{−x/γ} / Σ e^{−x/γ}`, which tends to
//! `max − min` as `γ → 0`. The exponents are shifted by the net's maximum (minimum) so that
//! they never overflow.

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
    xs: Vec<f64>,
    ys: Vec<f64>,
    ea: Vec<f64>,
    eb: Vec<f64>,
}

/// Result of one evaluation.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct WaStats {
    /// Σ w · WA over the smooth nets.
    pub wa: f64,
    /// Σ w · HPWL over every net.
    pub hpwl: f64,
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
        let mut stats = WaStats::default();
        let inv = 1.0 / gamma;
        for n in 0..self.len() {
            let (a, b) = (self.start[n] as usize, self.start[n + 1] as usize);
            let pins = &self.pins[a..b];
            self.xs.clear();
            self.ys.clear();
            let (mut xmax, mut xmin) = (f64::NEG_INFINITY, f64::INFINITY);
            let (mut ymax, mut ymin) = (f64::NEG_INFINITY, f64::INFINITY);
            for p in pins {
                let (x, y) = if p.obj == FIXED {
                    (p.dx, p.dy)
                } else {
                    let q = pos[p.obj as usize];
                    (q[0] + p.dx, q[1] + p.dy)
                };
                xmax = xmax.max(x);
                xmin = xmin.min(x);
                ymax = ymax.max(y);
                ymin = ymin.min(y);
                self.xs.push(x);
                self.ys.push(y);
            }
            let w = self.weight[n];
            if pins.is_empty() {
                continue;
            }
            stats.hpwl += w * ((xmax - xmin) + (ymax - ymin));
            if !self.smooth[n] {
                continue;
            }
            for (axis, (vals, hi, lo)) in [(&self.xs, xmax, xmin), (&self.ys, ymax, ymin)]
                .into_iter()
                .enumerate()
            {
                let (mut sa, mut ta, mut sb, mut tb) = (0.0, 0.0, 0.0, 0.0);
                self.ea.clear();
                self.eb.clear();
                for &v in vals.iter() {
                    let ea = ((v - hi) * inv).exp();
                    let eb = ((lo - v) * inv).exp();
                    sa += ea;
                    ta += v * ea;
                    sb += eb;
                    tb += v * eb;
                    self.ea.push(ea);
                    self.eb.push(eb);
                }
                let (ma, mb) = (ta / sa, tb / sb);
                stats.wa += w * (ma - mb);
                for (((p, &v), &ea), &eb) in
                    pins.iter().zip(vals.iter()).zip(&self.ea).zip(&self.eb)
                {
                    if p.obj == FIXED {
                        continue;
                    }
                    let d = ea / sa * (1.0 + (v - ma) * inv) - eb / sb * (1.0 - (v - mb) * inv);
                    grad[p.obj as usize][axis] += w * d;
                }
            }
        }
        stats
    }
}
