//! A native analytical global placer with circuit_training's DREAMPlace parameters
//! (`std_cell_placer = "dreamplace"`).
//!
//! **This is ours, written from DREAMPlace's published algorithm, not DREAMPlace itself.** It
//! follows the configuration circuit_training's `get_dreamplace_params` gives DREAMPlace
//! ([`AnalyticalParams::circuit_training`]):
//!
//! - one global-placement stage: Nesterov's method with DREAMPlace's step-size prediction and
//!   backtracking (`NesterovAcceleratedGradientOptimizer`, no Barzilai–Borwein step), the
//!   weighted-average wirelength ([`wirelength`]) and the electrostatic density ([`density`]),
//!   at most 1,000 iterations, initial learning rate 0.01 (refined by DREAMPlace's
//!   `estimate_initial_learning_rate`);
//! - bins from `get_bin_size(W, H, 128·128)` ([`bin_counts`]; the toy's 200 × 100 canvas gets
//!   256 × 64);
//! - target density 1.0, initial density weight `8e-5 · |∇WL|₁ / |∇D|₁`, updated every
//!   iteration by RePlAce's rule (`×1.05·1.05^(−ΔHPWL/350,000)` clamped to `[0.95, 1.05]`
//!   when the HPWL grew, `×1.05·max(0.9999^k, 0.98)` when it shrank);
//! - `γ = 4·(bin width + bin height) · 10^((overflow − 0.1)·20/9 − 1)`, starting at ten times
//!   the base;
//! - the gradient preconditioned by `max(1, Σ pin net weights + λ·area)`;
//! - stop after iteration 100 once the overflow is below 0.1 and the HPWL grew, or the largest
//!   bin density is below the target; or on DREAMPlace's divergence test (overflow above
//!   that of 50 iterations before and HPWL more than twice that of the lowest-overflow
//!   iteration);
//! - no fillers, no legalization, no detailed placement; `gp_noise_ratio` 0.001: every movable
//!   object is moved by `(u − ½)·size·0.001`, `u` uniform from a seeded stream, so the result
//!   is the same from run to run. Objects start where they are (no random-centre start).
//!
//! What moves: soft macros and standard cells (not fixed); hard macros only as
//! [`MovableMacros`] says. Placed hard macros that stay, blockages of rate ≥ 0.99 and fixed
//! nodes are obstacles; ports are fixed pins. Nets of more than 100 pins are left out of the
//! smooth wirelength (DREAMPlace's `ignore_net_degree`) but count in the HPWL it monitors.
//!
//! When the divergence test stops it, the result is the iterate of lowest overflow (as
//! DREAMPlace's roll-back; its finer `check_divergence` heuristic is not reproduced). Left out:
//! the quadratic density penalty and entropy injection of DREAMPlace's newer releases (both
//! only for placements stuck at overflow ≥ 0.9).
//!
//! Arithmetic: the wirelength and density kernels compute in `f32`, as DREAMPlace does by
//! default (`dtype` `float32`; circuit_training does not change it), with every sum the
//! stopping tests read in `f64`; positions and the optimizer are `f64`. The kernels are
//! generic ([`real::Real`]), and the tests check their `f64` instances against finite
//! differences and the `f32` ones against those.
//!
//! ```
//! use a2perf_circuit::{generate, GeneratorConfig, PlacementCost};
//! use a2perf_circuit::analytical::{place_analytical, AnalyticalParams, AnalyticalScratch, MovableMacros};
//! let g = generate(&GeneratorConfig::small(), 0);
//! let mut cost = PlacementCost::new(&g.netlist, g.settings.clone()).unwrap();
//! cost.apply_placement(&g.placement).unwrap();
//! let mut params = AnalyticalParams::circuit_training();
//! params.max_iterations = 30;
//! let report = place_analytical(&mut cost, &params, MovableMacros::None, &mut AnalyticalScratch::default()).unwrap();
//! assert!(report.iterations <= 30 && report.hpwl.is_finite());
//! ```

/// Inside an `impl`: `$vis fn $name(&mut self, …) -> R` that runs `$generic` compiled for
/// AVX-512 (`$avx512`) or for AVX2 and FMA (`$avx2`) when the CPU has them, else as it is. The
/// builds round every operation alike (Rust fuses a multiply and an add only where the code
/// says `mul_add`, which is exact on every build), so they give the same bits; wider vectors
/// only run more lanes of the loops written to vectorize.
macro_rules! vector_builds {
    ($(#[$doc:meta])* $vis:vis fn $name:ident / $avx2:ident / $avx512:ident
        (&mut self $(, $arg:ident : $ty:ty)* $(,)?) -> $ret:ty = $generic:ident) => {
        $(#[$doc])*
        $vis fn $name(&mut self $(, $arg: $ty)*) -> $ret {
            #[cfg(target_arch = "x86_64")]
            {
                use std::arch::is_x86_feature_detected as has;
                if has!("avx512f") && has!("fma") {
                    // SAFETY: the CPU has the features the AVX-512 build is compiled for.
                    return unsafe { self.$avx512($($arg),*) };
                }
                if has!("avx2") && has!("fma") {
                    // SAFETY: the CPU has the features the AVX2 build is compiled for.
                    return unsafe { self.$avx2($($arg),*) };
                }
            }
            self.$generic($($arg),*)
        }

        #[cfg(target_arch = "x86_64")]
        #[target_feature(enable = "avx2,fma")]
        fn $avx2(&mut self $(, $arg: $ty)*) -> $ret {
            self.$generic($($arg),*)
        }

        #[cfg(target_arch = "x86_64")]
        #[target_feature(enable = "avx512f,avx2,fma")]
        fn $avx512(&mut self $(, $arg: $ty)*) -> $ret {
            self.$generic($($arg),*)
        }
    };
}

pub mod density;
pub mod real;
pub mod wirelength;

use a2perf_core::RngStream;

use crate::cost::PlacementCost;
use crate::netlist::NodeKind;
use density::{Charge, Electrostatics};
use wirelength::{FIXED, Pin, WaNets};

/// The kernels' float type: DREAMPlace's default `dtype` (see [`real`]).
type Kernel = f32;

/// Errors of the analytical placer.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum AnalyticalError {
    /// The canvas is not a positive finite rectangle.
    #[error("the canvas {width} x {height} is not a positive finite rectangle")]
    Canvas {
        /// Width.
        width: f64,
        /// Height.
        height: f64,
    },
    /// The movable objects cannot fit the free canvas at the target density.
    #[error(
        "the movable soft macros and standard cells ({movable_area:.6} um^2) do not fit the canvas \
         area left by the hard macros and blockages at target density {target_density} \
         ({free_area:.6} um^2)"
    )]
    Capacity {
        /// Total area of the movable objects.
        movable_area: f64,
        /// Free canvas area times the target density.
        free_area: f64,
        /// The target density.
        target_density: f64,
    },
    /// A parameter is out of range.
    #[error("analytical placer parameter {name}: {reason}")]
    Param {
        /// The parameter.
        name: &'static str,
        /// What is wrong.
        reason: String,
    },
}

/// Parameters of the analytical placer.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct AnalyticalParams {
    /// Maximum number of Nesterov iterations (1,000).
    pub max_iterations: usize,
    /// The step of the initial learning-rate estimate (0.01).
    pub learning_rate: f64,
    /// Total number of bins for `get_bin_size` (128·128); `bins` overrides it.
    pub num_bins: usize,
    /// Explicit `(x, y)` bin counts.
    pub bins: Option<(usize, usize)>,
    /// Target density (1.0, A2Perf's fork; newer circuit_training defaults to 0.425).
    pub target_density: f64,
    /// Initial density weight relative to the gradient norms (8e-5).
    pub density_weight: f64,
    /// Stop once the overflow is below this (0.1).
    pub stop_overflow: f64,
    /// Base γ in bin sizes (DREAMPlace's `gamma`, 4.0).
    pub gamma: f64,
    /// Nets with more pins are left out of the smooth wirelength (100).
    pub ignore_net_degree: usize,
    /// Initial noise as a fraction of each object's size (0.001).
    pub noise_ratio: f64,
    /// Seed of the noise stream.
    pub seed: u64,
    /// RePlAce's reference HPWL of the density-weight update (350,000).
    pub ref_hpwl: f64,
    /// RePlAce's lower and upper bounds of the density-weight factor (0.95, 1.05).
    pub pcof: (f64, f64),
    /// Minimum iterations before the stopping tests apply (100).
    pub min_iterations: usize,
}

impl Default for AnalyticalParams {
    fn default() -> Self {
        Self::circuit_training()
    }
}

impl AnalyticalParams {
    /// circuit_training's `get_dreamplace_params(canvas_width, canvas_height)` with A2Perf's
    /// target density 1.0 and `deterministic_flag` on.
    ///
    /// ```
    /// let p = a2perf_circuit::analytical::AnalyticalParams::circuit_training();
    /// assert_eq!((p.max_iterations, p.target_density, p.density_weight), (1000, 1.0, 8e-5));
    /// ```
    pub fn circuit_training() -> Self {
        Self {
            max_iterations: 1000,
            learning_rate: 0.01,
            num_bins: 128 * 128,
            bins: None,
            target_density: 1.0,
            density_weight: 8e-5,
            stop_overflow: 0.1,
            gamma: 4.0,
            ignore_net_degree: 100,
            noise_ratio: 0.001,
            seed: 0,
            ref_hpwl: 350_000.0,
            pcof: (0.95, 1.05),
            min_iterations: 100,
        }
    }

    fn validate(&self) -> Result<(), AnalyticalError> {
        let bad = |name, reason: &str| {
            Err(AnalyticalError::Param {
                name,
                reason: reason.into(),
            })
        };
        if !(self.target_density > 0.0 && self.target_density.is_finite()) {
            return bad("target_density", "must be positive and finite");
        }
        if !(self.learning_rate > 0.0 && self.learning_rate.is_finite()) {
            return bad("learning_rate", "must be positive and finite");
        }
        if !(self.gamma > 0.0 && self.gamma.is_finite()) {
            return bad("gamma", "must be positive and finite");
        }
        if !(self.density_weight > 0.0 && self.density_weight.is_finite()) {
            return bad("density_weight", "must be positive and finite");
        }
        if !(self.noise_ratio >= 0.0 && self.noise_ratio.is_finite()) {
            return bad("noise_ratio", "must be non-negative and finite");
        }
        match self.bins {
            Some((x, y)) if x == 0 || y == 0 || x.saturating_mul(y) > 1 << 22 => {
                bad("bins", "must be positive, at most 2^22 in all")
            }
            None if self.num_bins == 0 || self.num_bins > 1 << 22 => {
                bad("num_bins", "must be in 1..=2^22")
            }
            _ => Ok(()),
        }
    }
}

/// circuit_training's `get_bin_size`: the power of two nearest `√(n·W/H)` bins in x (ties to
/// even, as Python's `round`), clamped to `[1, n]`, and `n / that` in y.
///
/// ```
/// use a2perf_circuit::analytical::bin_counts;
/// assert_eq!(bin_counts(200.0, 100.0, 128 * 128), (256, 64));
/// assert_eq!(bin_counts(1433.406, 1433.406, 128 * 128), (128, 128));
/// ```
pub fn bin_counts(width: f64, height: f64, n: usize) -> (usize, usize) {
    let bx = (n as f64 * width / height).sqrt();
    let e = (bx.ln() / std::f64::consts::LN_2).round_ties_even();
    let bx = if e.is_finite() {
        (2f64.powf(e.clamp(0.0, 62.0)) as usize).clamp(1, n.max(1))
    } else {
        1
    };
    (bx, (n / bx).max(1))
}

/// Which hard macros the placer moves.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum MovableMacros {
    /// None: the end of an episode (placed hard macros are fixed).
    None,
    /// Those not placed yet (the mixed-size run of an infeasible episode).
    Unplaced,
    /// Every hard macro that is not fixed (the mixed-size run at construction).
    All,
}

/// What a run did.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct AnalyticalReport {
    /// Nesterov iterations.
    pub iterations: usize,
    /// Objective and gradient evaluations.
    pub evaluations: usize,
    /// HPWL of the movable objects' nets at the start of the last iteration (the placer's
    /// own measure: pins as the cost model places them).
    pub hpwl: f64,
    /// Overflow at the start of the last iteration.
    pub overflow: f64,
    /// Whether it stopped on its criteria before the iteration limit (DREAMPlace's
    /// "converged").
    pub converged: bool,
    /// Movable objects.
    pub movable: usize,
}

/// Reusable state of the placer: nets, bins, potential solver and the optimizer's vectors.
/// Nothing is allocated per iteration; buffers are kept from run to run.
#[derive(Debug, Default)]
pub struct AnalyticalScratch {
    node: Vec<u32>,
    obj_of: Vec<u32>,
    area: Vec<f64>,
    size: Vec<[f64; 2]>,
    charge: Vec<Charge>,
    pin_weight: Vec<f64>,
    nets: WaNets<Kernel>,
    net_pins: Vec<Pin>,
    es: Option<Electrostatics<Kernel>>,
    pos: Vec<[f64; 2]>,
    g_wl: Vec<[f64; 2]>,
    g_den: Vec<[f64; 2]>,
    /// Both terms' gradients at the start, evaluated once for the three uses there.
    g_wl0: Vec<[f64; 2]>,
    g_den0: Vec<[f64; 2]>,
    u_k: Vec<[f64; 2]>,
    v_k: Vec<[f64; 2]>,
    g_k: Vec<[f64; 2]>,
    v_k1: Vec<[f64; 2]>,
    g_k1: Vec<[f64; 2]>,
    u_kp1: Vec<[f64; 2]>,
    v_kp1: Vec<[f64; 2]>,
    g_kp1: Vec<[f64; 2]>,
    history: Vec<(f64, f64)>,
    best_pos: Vec<[f64; 2]>,
}

/// Checks that the canvas is sound and that the soft macros and standard cells (not fixed)
/// fit the canvas left by every hard macro and blockage at `target_density`.
///
/// ```
/// use a2perf_circuit::{generate, GeneratorConfig, PlacementCost};
/// use a2perf_circuit::analytical::check_capacity;
/// let g = generate(&GeneratorConfig::small(), 0);
/// let cost = PlacementCost::new(&g.netlist, g.settings.clone()).unwrap();
/// assert!(check_capacity(&cost, 1.0).is_ok());
/// assert!(check_capacity(&cost, 1e-6).is_err());
/// ```
pub fn check_capacity(cost: &PlacementCost, target_density: f64) -> Result<(), AnalyticalError> {
    let (w, h) = (cost.settings.canvas_width, cost.settings.canvas_height);
    if !(w.is_finite() && h.is_finite() && w > 0.0 && h > 0.0) {
        return Err(AnalyticalError::Canvas {
            width: w,
            height: h,
        });
    }
    let mut movable = 0.0;
    let mut blocked = 0.0;
    for i in 0..cost.kind.len() {
        let a = cost.w[i] * cost.h[i];
        match cost.kind[i] {
            NodeKind::HardMacro => blocked += a,
            NodeKind::SoftMacro | NodeKind::StdCell if cost.fixed[i] => blocked += a,
            NodeKind::SoftMacro | NodeKind::StdCell => movable += a,
            _ => {}
        }
    }
    for b in cost.blockages() {
        let [x0, y0, x1, y1, rate] = b.rect;
        if rate >= 0.99 {
            blocked += ((x1 - x0) * (y1 - y0)).max(0.0);
        }
    }
    let free = target_density * (w * h - blocked).max(0.0);
    if movable > free {
        return Err(AnalyticalError::Capacity {
            movable_area: movable,
            free_area: free,
            target_density,
        });
    }
    Ok(())
}

/// Places the soft macros and standard cells of `cost` (and the hard macros `macros` names)
/// analytically, writes their centres back and recomputes the costs. Hard macros it moves
/// are marked placed.
pub fn place_analytical(
    cost: &mut PlacementCost,
    params: &AnalyticalParams,
    macros: MovableMacros,
    s: &mut AnalyticalScratch,
) -> Result<AnalyticalReport, AnalyticalError> {
    params.validate()?;
    let (cw, ch) = (cost.settings.canvas_width, cost.settings.canvas_height);
    if !(cw.is_finite() && ch.is_finite() && cw > 0.0 && ch > 0.0) {
        return Err(AnalyticalError::Canvas {
            width: cw,
            height: ch,
        });
    }
    if cost.offsets_dirty {
        cost.recompute();
    }
    let n = cost.kind.len();
    let is_mov = |cost: &PlacementCost, i: usize| {
        !cost.fixed[i]
            && match cost.kind[i] {
                NodeKind::SoftMacro | NodeKind::StdCell => true,
                NodeKind::HardMacro => match macros {
                    MovableMacros::None => false,
                    MovableMacros::Unplaced => !cost.placed[i],
                    MovableMacros::All => true,
                },
                _ => false,
            }
    };
    s.node.clear();
    s.node
        .extend((0..n as u32).filter(|&i| is_mov(cost, i as usize)));
    let m = s.node.len();
    if m == 0 {
        return Ok(AnalyticalReport::default());
    }
    s.obj_of.clear();
    s.obj_of.resize(n, FIXED);
    for (k, &i) in s.node.iter().enumerate() {
        s.obj_of[i as usize] = k as u32;
    }
    // Bins and the potential solver (rebuilt only when the canvas or bins change).
    let (nbx, nby) = params
        .bins
        .unwrap_or_else(|| bin_counts(cw, ch, params.num_bins));
    if !s.es.as_ref().is_some_and(|e| e.fits(cw, ch, nbx, nby)) {
        s.es = Some(Electrostatics::new(cw, ch, nbx, nby));
    }
    let Some(es) = s.es.as_mut() else {
        return Ok(AnalyticalReport::default());
    };
    let (bx, by) = es.bin_size();
    // Fixed charge: hard macros that stay (placed), fixed area nodes, full blockages.
    es.clear_fixed();
    for i in 0..n {
        let k = cost.kind[i];
        let obstacle = k.has_area()
            && !is_mov(cost, i)
            && (cost.placed[i] || k != NodeKind::HardMacro || cost.fixed[i]);
        if obstacle {
            let (x, y, hw, hh) = (cost.x[i], cost.y[i], cost.w[i] / 2.0, cost.h[i] / 2.0);
            es.add_fixed(x - hw, y - hh, x + hw, y + hh);
        }
    }
    for b in cost.blockages() {
        let [x0, y0, x1, y1, rate] = b.rect;
        if rate >= 0.99 {
            es.add_fixed(x0, y0, x1, y1);
        }
    }
    es.finish_fixed(params.target_density);
    // Movable objects.
    s.area.clear();
    s.size.clear();
    s.charge.clear();
    s.pos.clear();
    for &i in &s.node {
        let i = i as usize;
        let (w, h) = (cost.w[i], cost.h[i]);
        s.area.push(w * h);
        s.size.push([w, h]);
        s.charge.push(es.movable_charge(w, h));
        s.pos.push([cost.x[i], cost.y[i]]);
    }
    let movable_area: f64 = s.area.iter().sum();
    // Nets with at least one movable pin.
    s.nets.clear();
    for net in 0..cost.net_w.len() {
        let (a, b) = (
            cost.net_start[net] as usize,
            cost.net_start[net + 1] as usize,
        );
        s.net_pins.clear();
        let mut any_mov = false;
        for p in a..b {
            let o = cost.pin_owner[p] as usize;
            let k = s.obj_of[o];
            let (dx, dy) = (cost.pin_rdx[p], cost.pin_rdy[p]);
            if k == FIXED {
                s.net_pins.push(Pin {
                    obj: FIXED,
                    dx: cost.x[o] + dx,
                    dy: cost.y[o] + dy,
                });
            } else {
                any_mov = true;
                s.net_pins.push(Pin { obj: k, dx, dy });
            }
        }
        if any_mov {
            let smooth = b - a <= params.ignore_net_degree;
            s.nets
                .push_net(s.net_pins.iter().copied(), cost.net_w[net], smooth);
        }
    }
    s.pin_weight.clear();
    s.pin_weight.resize(m, 0.0);
    s.nets.add_pin_weights(&mut s.pin_weight);
    for v in [
        &mut s.g_wl,
        &mut s.g_den,
        &mut s.g_wl0,
        &mut s.g_den0,
        &mut s.u_k,
        &mut s.v_k,
        &mut s.g_k,
        &mut s.v_k1,
        &mut s.g_k1,
        &mut s.u_kp1,
        &mut s.v_kp1,
        &mut s.g_kp1,
        &mut s.best_pos,
    ] {
        v.clear();
        v.resize(m, [0.0, 0.0]);
    }
    s.history.clear();

    let mut prob = Problem {
        nets: &mut s.nets,
        es,
        charge: &s.charge,
        size: &s.size,
        area: &s.area,
        pin_weight: &s.pin_weight,
        g_wl: &mut s.g_wl,
        g_den: &mut s.g_den,
        canvas: (cw, ch),
        target: params.target_density,
        movable_area,
        gamma: 10.0 * params.gamma * (bx + by),
        lambda: 0.0,
        last: Metric::default(),
        evaluations: 0,
    };
    // Noise, then the boundary.
    if params.noise_ratio > 0.0 {
        let mut rng = RngStream::new(params.seed, "analytical/noise");
        for (p, sz) in s.pos.iter_mut().zip(&s.size) {
            p[0] += (rng.uniform() - 0.5) * sz[0] * params.noise_ratio;
            p[1] += (rng.uniform() - 0.5) * sz[1] * params.noise_ratio;
        }
    }
    prob.clamp(&mut s.pos);
    // The start's terms serve three uses (the first step's estimate, the density weight and
    // the first iteration's gradient): evaluated once, kept, and put back, which gives the
    // same bits as evaluating them again (same point, same γ).
    // DREAMPlace estimates the first step with the density weight still 0.
    let (lr, at_start) = {
        prob.obj_grad(&s.pos, &mut s.g_k);
        let at_start = prob.keep_terms(&mut s.g_wl0, &mut s.g_den0);
        for ((v, p), g) in s.v_k1.iter_mut().zip(&s.pos).zip(&s.g_k) {
            *v = [
                p[0] - params.learning_rate * g[0],
                p[1] - params.learning_rate * g[1],
            ];
        }
        prob.obj_grad(&s.v_k1, &mut s.g_k1);
        let lr = ratio(norm_diff(&s.pos, &s.v_k1), norm_diff(&s.g_k, &s.g_k1), 0.0);
        (lr, at_start)
    };
    // The density weight: 8e-5 × |∇WL|₁ / |∇D|₁ at the start.
    prob.put_terms(&s.g_wl0, &s.g_den0, at_start);
    prob.init_lambda(params.density_weight);
    let base_gamma = params.gamma * (bx + by);
    let mut report = AnalyticalReport {
        movable: m,
        ..Default::default()
    };
    // Optimizer state (DREAMPlace's step without BB).
    let mut a_k = 1.0f64;
    let mut alpha_k = 0.0f64;
    let mut started = false;
    let mut best: Option<Metric> = None;
    for it in 0..params.max_iterations {
        // The metric at v_k: the last evaluation was at this point (the accepted trial, or the
        // density-weight initialisation on the first iteration).
        let metric = prob.last;
        s.history.push((metric.hpwl, metric.overflow));
        if best.is_none_or(|b| b.overflow > metric.overflow) {
            best = Some(metric);
            s.best_pos
                .copy_from_slice(prob_pos(&s.pos, &s.v_k, started));
        }
        report.iterations = it + 1;
        report.hpwl = metric.hpwl;
        report.overflow = metric.overflow;
        if !started {
            started = true;
            s.u_k.copy_from_slice(&s.pos);
            s.v_k.copy_from_slice(&s.pos);
            prob.put_terms(&s.g_wl0, &s.g_den0, at_start);
            prob.combine(&mut s.g_k);
            for ((v, p), g) in s.v_k1.iter_mut().zip(&s.v_k).zip(&s.g_k) {
                *v = [p[0] - lr * g[0], p[1] - lr * g[1]];
            }
            prob.obj_grad(&s.v_k1, &mut s.g_k1);
            alpha_k = ratio(norm_diff(&s.v_k, &s.v_k1), norm_diff(&s.g_k, &s.g_k1), lr);
        }
        let a_kp1 = (1.0 + (4.0 * a_k * a_k + 1.0).sqrt()) / 2.0;
        let coef = (a_k - 1.0) / a_kp1;
        for backtrack in 1..=10 {
            for (((u1, v1), (v, g)), u) in s
                .u_kp1
                .iter_mut()
                .zip(s.v_kp1.iter_mut())
                .zip(s.v_k.iter().zip(&s.g_k))
                .zip(&s.u_k)
            {
                for d in 0..2 {
                    u1[d] = v[d] - alpha_k * g[d];
                    v1[d] = u1[d] + coef * (u1[d] - u[d]);
                }
            }
            prob.clamp(&mut s.v_kp1);
            prob.obj_grad(&s.v_kp1, &mut s.g_kp1);
            let alpha_kp1 = ratio(
                norm_diff(&s.v_kp1, &s.v_k),
                norm_diff(&s.g_kp1, &s.g_k),
                alpha_k,
            );
            let accept = alpha_kp1 > 0.95 * alpha_k || backtrack == 10;
            alpha_k = alpha_kp1;
            if accept {
                break;
            }
        }
        std::mem::swap(&mut s.v_k1, &mut s.v_k);
        std::mem::swap(&mut s.g_k1, &mut s.g_k);
        std::mem::swap(&mut s.u_k, &mut s.u_kp1);
        std::mem::swap(&mut s.v_k, &mut s.v_kp1);
        std::mem::swap(&mut s.g_k, &mut s.g_kp1);
        a_k = a_kp1;
        // Density weight (from the second iteration on) and γ, from this iteration's metric.
        if it >= 1 {
            let prev = s.history[it - 1].0;
            let delta = metric.hpwl - prev;
            let (lo, hi) = params.pcof;
            let mu = if delta < 0.0 {
                hi * 0.9999f64.powf((it + 1) as f64).max(0.98)
            } else {
                hi * hi.powf(-delta / params.ref_hpwl).clamp(lo, hi)
            };
            prob.lambda *= mu;
        }
        prob.gamma = base_gamma * 10f64.powf((metric.overflow - 0.1) * 20.0 / 9.0 - 1.0);
        // Stopping tests.
        if it > params.min_iterations && it >= 1 {
            let prev = s.history[it - 1].0;
            if (metric.overflow < params.stop_overflow && metric.hpwl > prev)
                || metric.max_density < params.target_density
            {
                report.converged = true;
                break;
            }
        }
        if s.history.len() > 50 {
            let old = s.history[s.history.len() - 50];
            if let Some(b) = best
                && metric.overflow > old.1
                && metric.hpwl > 2.0 * b.hpwl
            {
                // Diverging: back to the iterate of lowest overflow (DREAMPlace's roll-back).
                s.v_k.copy_from_slice(&s.best_pos);
                report.hpwl = b.hpwl;
                report.overflow = b.overflow;
                report.converged = true;
                break;
            }
        }
    }
    if !started {
        s.v_k.copy_from_slice(&s.pos);
    }
    report.evaluations = prob.evaluations;
    for (k, &i) in s.node.iter().enumerate() {
        let i = i as usize;
        cost.x[i] = s.v_k[k][0];
        cost.y[i] = s.v_k[k][1];
        if cost.kind[i] == NodeKind::HardMacro {
            cost.placed[i] = true;
        }
    }
    cost.recompute();
    Ok(report)
}

/// The current iterate: the start before the first step, then `v_k`.
fn prob_pos<'a>(start: &'a [[f64; 2]], v_k: &'a [[f64; 2]], started: bool) -> &'a [[f64; 2]] {
    if started { v_k } else { start }
}

/// `a / b`, or `fallback` when that is not a positive finite number.
fn ratio(a: f64, b: f64, fallback: f64) -> f64 {
    let r = a / b;
    if r.is_finite() && r > 0.0 {
        r
    } else {
        fallback
    }
}

/// `‖a − b‖₂`.
fn norm_diff(a: &[[f64; 2]], b: &[[f64; 2]]) -> f64 {
    a.iter()
        .zip(b)
        .map(|(p, q)| (p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2))
        .sum::<f64>()
        .sqrt()
}

/// HPWL, overflow and largest density at one point.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
struct Metric {
    hpwl: f64,
    overflow: f64,
    max_density: f64,
}

/// The objective `WA + λ·E`: its preconditioned gradient.
struct Problem<'a> {
    nets: &'a mut WaNets<Kernel>,
    es: &'a mut Electrostatics<Kernel>,
    charge: &'a [Charge],
    size: &'a [[f64; 2]],
    area: &'a [f64],
    pin_weight: &'a [f64],
    g_wl: &'a mut [[f64; 2]],
    g_den: &'a mut [[f64; 2]],
    canvas: (f64, f64),
    target: f64,
    movable_area: f64,
    gamma: f64,
    lambda: f64,
    last: Metric,
    evaluations: usize,
}

impl Problem<'_> {
    /// Keeps every object inside the canvas (DREAMPlace's `move_boundary`).
    fn clamp(&self, pos: &mut [[f64; 2]]) {
        let (w, h) = self.canvas;
        for (p, sz) in pos.iter_mut().zip(self.size) {
            let (hw, hh) = (sz[0] / 2.0, sz[1] / 2.0);
            p[0] = if hw * 2.0 >= w {
                w / 2.0
            } else {
                p[0].clamp(hw, w - hw)
            };
            p[1] = if hh * 2.0 >= h {
                h / 2.0
            } else {
                p[1].clamp(hh, h - hh)
            };
        }
    }

    /// Raw gradients of both terms at `pos` into `g_wl`, `g_den`; records the metric. (The
    /// objective's value is not needed: the step sizes come from gradients alone, so the
    /// density's energy is not summed.)
    fn terms(&mut self, pos: &[[f64; 2]]) {
        self.evaluations += 1;
        self.g_wl.iter_mut().for_each(|g| *g = [0.0, 0.0]);
        let wl = self.nets.evaluate(pos, self.gamma, self.g_wl);
        let d = self
            .es
            .evaluate_gradient(pos, self.charge, self.target, self.g_den);
        self.last = Metric {
            hpwl: wl.hpwl,
            overflow: if self.movable_area > 0.0 {
                d.overflow_area / self.movable_area
            } else {
                0.0
            },
            max_density: d.max_density,
        };
    }

    /// The objective's preconditioned gradient at `pos`.
    fn obj_grad(&mut self, pos: &[[f64; 2]], grad: &mut [[f64; 2]]) {
        self.terms(pos);
        self.combine(grad);
    }

    /// Copies the last evaluation's gradients of both terms into `wl` and `den`; returns its
    /// metric.
    fn keep_terms(&self, wl: &mut [[f64; 2]], den: &mut [[f64; 2]]) -> Metric {
        wl.copy_from_slice(self.g_wl);
        den.copy_from_slice(self.g_den);
        self.last
    }

    /// Makes `wl`, `den` and `metric` (from [`Problem::keep_terms`]) the last evaluation again.
    fn put_terms(&mut self, wl: &[[f64; 2]], den: &[[f64; 2]], metric: Metric) {
        self.g_wl.copy_from_slice(wl);
        self.g_den.copy_from_slice(den);
        self.last = metric;
    }

    /// The preconditioned gradient of the objective from the last evaluation's terms.
    fn combine(&self, grad: &mut [[f64; 2]]) {
        let lambda = self.lambda;
        for ((((g, gw), gd), pw), a) in grad
            .iter_mut()
            .zip(self.g_wl.iter())
            .zip(self.g_den.iter())
            .zip(self.pin_weight)
            .zip(self.area)
        {
            let pre = 1.0 / (pw + lambda * a).max(1.0);
            *g = [
                (gw[0] + lambda * gd[0]) * pre,
                (gw[1] + lambda * gd[1]) * pre,
            ];
        }
    }

    /// λ = `weight · |∇WL|₁ / |∇E|₁` from the last evaluation's terms (DREAMPlace's
    /// `initialize_density_weight`, at the start).
    fn init_lambda(&mut self, weight: f64) {
        let l1 = |g: &[[f64; 2]]| g.iter().map(|v| v[0].abs() + v[1].abs()).sum::<f64>();
        let (gw, gd) = (l1(self.g_wl), l1(self.g_den));
        self.lambda = ratio(weight * gw, gd, weight);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bin_counts_follow_get_bin_size() {
        assert_eq!(bin_counts(200.0, 100.0, 16384), (256, 64));
        assert_eq!(bin_counts(100.0, 100.0, 16384), (128, 128));
        assert_eq!(bin_counts(100.0, 400.0, 16384), (64, 256));
        assert_eq!(bin_counts(1e9, 1.0, 16384), (16384, 1));
        assert_eq!(bin_counts(1.0, 1e9, 16384), (1, 16384));
    }
}
