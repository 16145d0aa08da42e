//! A deterministic force-directed placer for soft macros and standard cells.
//!
//! **This is our placer, not Google's** (whose `optimize_stdcells` is closed). It follows the
//! schedule circuit_training passes to it at the end of every episode: three rounds of 100 steps,
//! maximum move `max(W, H)/100` per step, attraction factors `[100, 1e-3, 1e-5]` and repulsion
//! factors `[0, 1e6, 1e7]`, I/O factor 1, hard macros fixed. Per step:
//!
//! - attraction: every net pulls each sink towards its driver and the driver towards each sink
//!   (spring ∝ distance × net weight × factor, × I/O factor when a port is involved);
//! - repulsion: every overlapping pair of macros pushes apart along the line of centres with
//!   `factor × max_move` (hard macros do not move; found with a bucket grid, not all pairs);
//! - displacements are normalised per axis so the largest equals the round's maximum move (as
//!   plc_client_os does, so only the ratio of the factors matters within a step);
//! - a move that would leave the canvas is cancelled on that axis.
//!
//! Initial positions (`use_current_loc = False` in CT): every movable node at the canvas centre,
//! offset on a tiny golden-angle spiral so that repulsion has a direction (ours).

use crate::cost::PlacementCost;
use crate::netlist::NodeKind;

/// The force-directed schedule.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct FdSchedule {
    /// Steps per round.
    pub num_steps: Vec<usize>,
    /// Maximum move per step, as a fraction of `max(W, H)/100`.
    pub move_distance_factors: Vec<f64>,
    /// Attraction factor per round.
    pub attract: Vec<f64>,
    /// Repulsion factor per round.
    pub repel: Vec<f64>,
    /// Multiplier of attraction on nets with a port.
    pub io_factor: f64,
}

impl Default for FdSchedule {
    /// circuit_training's end-of-episode schedule (`fd_placement_schedule`).
    fn default() -> Self {
        Self {
            num_steps: vec![100, 100, 100],
            move_distance_factors: vec![1.0, 1.0, 1.0],
            attract: vec![100.0, 1e-3, 1e-5],
            repel: vec![0.0, 1e6, 1e7],
            io_factor: 1.0,
        }
    }
}

/// Reusable buffers of the placer (no allocation per run once warmed up).
///
/// Positions live in compact per-object arrays (placed hard macros first, then the movable
/// nodes) so the inner loops stay in cache.
#[derive(Clone, Debug, Default)]
pub struct FdScratch {
    node: Vec<u32>,
    ox: Vec<f64>,
    oy: Vec<f64>,
    ohw: Vec<f64>,
    ohh: Vec<f64>,
    dx: Vec<f64>,
    dy: Vec<f64>,
    obj_of: Vec<u32>,
    bucket_start: Vec<u32>,
    bucket_items: Vec<u32>,
    bucket_fill: Vec<u32>,
    // Active nets (at least one movable endpoint), flattened.
    a_start: Vec<u32>,
    a_obj: Vec<u32>,
    a_fac: Vec<f64>,
    a_w: Vec<f64>,
}

const NONE: u32 = u32::MAX;

/// Runs the force-directed placer on `cost`'s soft macros and standard cells (non-fixed), then
/// recomputes the costs.
///
/// ```
/// use a2perf_circuit::{generate, GeneratorConfig, PlacementCost};
/// use a2perf_circuit::placer::{FdSchedule, FdScratch, place_std_cells};
/// let g = generate(&GeneratorConfig::small(), 0);
/// let mut cost = PlacementCost::new(&g.netlist, g.settings.clone()).unwrap();
/// let mut s = FdSchedule::default();
/// s.num_steps = vec![5, 5, 5];
/// place_std_cells(&mut cost, &s, &mut FdScratch::default());
/// assert!(cost.costs().proxy_cost.is_finite());
/// ```
pub fn place_std_cells(cost: &mut PlacementCost, schedule: &FdSchedule, s: &mut FdScratch) {
    let n = cost.kind.len();
    let (cw, ch) = (cost.settings.canvas_width, cost.settings.canvas_height);
    let is_mov = |cost: &PlacementCost, i: usize| {
        matches!(cost.kind[i], NodeKind::SoftMacro | NodeKind::StdCell) && !cost.fixed[i]
    };
    s.node.clear();
    s.node.extend(
        (0..n as u32)
            .filter(|&i| cost.kind[i as usize] == NodeKind::HardMacro && cost.placed[i as usize]),
    );
    let hard = s.node.len();
    s.node
        .extend((0..n as u32).filter(|&i| is_mov(cost, i as usize)));
    let nobj = s.node.len();
    if nobj == hard {
        return;
    }
    s.obj_of.clear();
    s.obj_of.resize(n, NONE);
    s.ox.clear();
    s.oy.clear();
    s.ohw.clear();
    s.ohh.clear();
    let r0 = 1e-3 * cw.min(ch);
    for (k, &i) in s.node.iter().enumerate() {
        let i = i as usize;
        s.obj_of[i] = k as u32;
        s.ohw.push(cost.w[i] / 2.0);
        s.ohh.push(cost.h[i] / 2.0);
        if k < hard {
            s.ox.push(cost.x[i]);
            s.oy.push(cost.y[i]);
        } else {
            // Centre start on a golden-angle spiral (CT starts from the centre).
            let j = k - hard;
            let a = j as f64 * 2.399_963_229_728_653;
            let r = r0 * ((j + 1) as f64).sqrt();
            s.ox.push(cw / 2.0 + r * a.cos());
            s.oy.push(ch / 2.0 + r * a.sin());
        }
    }
    // Active nets. Every fixed pin (hard-macro pin, port) gets its own slot after the objects,
    // holding its position, so the attraction loop has no branches; forces written to those slots
    // are ignored. Pins of the same movable node coincide, so they exert no force on each other.
    s.a_start.clear();
    s.a_obj.clear();
    s.a_fac.clear();
    s.a_w.clear();
    s.a_start.push(0);
    for net in 0..cost.net_w.len() {
        let (a, b) = (
            cost.net_start[net] as usize,
            cost.net_start[net + 1] as usize,
        );
        if !(a..b).any(|p| is_mov(cost, cost.pin_owner[p] as usize)) {
            continue;
        }
        let driver_port = cost.kind[cost.pin_owner[a] as usize] == NodeKind::Port;
        for p in a..b {
            let o = cost.pin_owner[p] as usize;
            if is_mov(cost, o) {
                s.a_obj.push(s.obj_of[o]);
            } else {
                s.a_obj.push(s.ox.len() as u32);
                s.ox.push(cost.pin_x[p]);
                s.oy.push(cost.pin_y[p]);
            }
            let port = driver_port || cost.kind[o] == NodeKind::Port;
            s.a_fac.push(if port { schedule.io_factor } else { 1.0 });
        }
        s.a_start.push(s.a_obj.len() as u32);
        s.a_w.push(cost.net_w[net]);
    }
    s.dx.clear();
    s.dx.resize(s.ox.len(), 0.0);
    s.dy.clear();
    s.dy.resize(s.ox.len(), 0.0);
    let max_soft = (hard..nobj)
        .map(|k| s.ohw[k].max(s.ohh[k]) * 2.0)
        .fold(0.0f64, f64::max);
    let rounds = schedule
        .num_steps
        .len()
        .min(schedule.attract.len())
        .min(schedule.repel.len())
        .min(schedule.move_distance_factors.len());
    for round in 0..rounds {
        let max_move = schedule.move_distance_factors[round] * cw.max(ch) / 100.0;
        for _ in 0..schedule.num_steps[round] {
            step(
                s,
                (cw, ch),
                schedule.attract[round],
                schedule.repel[round],
                max_move,
                max_soft,
                hard,
            );
        }
    }
    for k in hard..nobj {
        let i = s.node[k] as usize;
        cost.x[i] = s.ox[k];
        cost.y[i] = s.oy[k];
    }
    cost.recompute();
}

#[allow(clippy::too_many_arguments)]
fn step(
    s: &mut FdScratch,
    (cw, ch): (f64, f64),
    attract: f64,
    repel: f64,
    max_move: f64,
    max_soft: f64,
    hard: usize,
) {
    let nobj = s.node.len();
    s.dx.iter_mut().for_each(|v| *v = 0.0);
    s.dy.iter_mut().for_each(|v| *v = 0.0);
    if attract != 0.0 {
        for net in 0..s.a_w.len() {
            let (a, b) = (s.a_start[net] as usize, s.a_start[net + 1] as usize);
            let d = s.a_obj[a] as usize;
            let (dxp, dyp) = (s.ox[d], s.oy[d]);
            let w = s.a_w[net] * attract;
            let (mut fdx, mut fdy) = (0.0, 0.0);
            for p in a + 1..b {
                let o = s.a_obj[p] as usize;
                let f = w * s.a_fac[p];
                let (fx, fy) = (f * (s.ox[o] - dxp), f * (s.oy[o] - dyp));
                fdx += fx;
                fdy += fy;
                s.dx[o] -= fx;
                s.dy[o] -= fy;
            }
            s.dx[d] += fdx;
            s.dy[d] += fdy;
        }
    }
    if repel != 0.0 {
        repulsion(s, (cw, ch), repel * max_move, max_soft, hard);
    }
    let (mut mx, mut my) = (0.0f64, 0.0f64);
    for k in hard..nobj {
        mx = mx.max(s.dx[k].abs());
        my = my.max(s.dy[k].abs());
    }
    let sx = if mx > 0.0 { max_move / mx } else { 0.0 };
    let sy = if my > 0.0 { max_move / my } else { 0.0 };
    for k in hard..nobj {
        let nx = s.ox[k] + s.dx[k] * sx;
        let ny = s.oy[k] + s.dy[k] * sy;
        // A move that would leave the canvas is cancelled on that axis.
        if nx - s.ohw[k] > 0.0 && nx + s.ohw[k] < cw {
            s.ox[k] = nx;
        }
        if ny - s.ohh[k] > 0.0 && ny + s.ohh[k] < ch {
            s.oy[k] = ny;
        }
    }
}

/// Pairwise repulsion of overlapping objects using a uniform bucket grid; each pair is handled
/// once (in the bucket holding the lower-left corner of their intersection).
fn repulsion(s: &mut FdScratch, (cw, ch): (f64, f64), mag: f64, max_soft: f64, hard: usize) {
    let cell = max_soft.max(cw.max(ch) / 64.0).max(1e-9);
    let bc = ((cw / cell).ceil() as usize).clamp(1, 256);
    let br = ((ch / cell).ceil() as usize).clamp(1, 256);
    let (ibw, ibh) = (bc as f64 / cw, br as f64 / ch);
    let bucket = |v: f64, inv: f64, n: usize| -> usize {
        let b = v * inv;
        if b.is_nan() || b < 0.0 {
            0
        } else {
            (b as usize).min(n - 1)
        }
    };
    let nb = bc * br;
    let nobj = s.node.len();
    s.bucket_start.clear();
    s.bucket_start.resize(nb + 1, 0);
    for k in 0..nobj {
        let (x0, x1) = (s.ox[k] - s.ohw[k], s.ox[k] + s.ohw[k]);
        let (y0, y1) = (s.oy[k] - s.ohh[k], s.oy[k] + s.ohh[k]);
        for r in bucket(y0, ibh, br)..=bucket(y1, ibh, br) {
            for c in bucket(x0, ibw, bc)..=bucket(x1, ibw, bc) {
                s.bucket_start[r * bc + c + 1] += 1;
            }
        }
    }
    for b in 0..nb {
        s.bucket_start[b + 1] += s.bucket_start[b];
    }
    s.bucket_fill.clear();
    s.bucket_fill.extend_from_slice(&s.bucket_start[..nb]);
    s.bucket_items.clear();
    s.bucket_items.resize(s.bucket_start[nb] as usize, 0);
    for k in 0..nobj {
        let (x0, x1) = (s.ox[k] - s.ohw[k], s.ox[k] + s.ohw[k]);
        let (y0, y1) = (s.oy[k] - s.ohh[k], s.oy[k] + s.ohh[k]);
        for r in bucket(y0, ibh, br)..=bucket(y1, ibh, br) {
            for c in bucket(x0, ibw, bc)..=bucket(x1, ibw, bc) {
                let slot = &mut s.bucket_fill[r * bc + c];
                s.bucket_items[*slot as usize] = k as u32;
                *slot += 1;
            }
        }
    }
    for b in 0..nb {
        let (lo, hi) = (s.bucket_start[b] as usize, s.bucket_start[b + 1] as usize);
        for ia in lo..hi {
            let u = s.bucket_items[ia] as usize;
            for ib in ia + 1..hi {
                let v = s.bucket_items[ib] as usize;
                if u < hard && v < hard {
                    continue;
                }
                let ix = (s.ox[u] - s.ohw[u]).max(s.ox[v] - s.ohw[v]);
                let iy = (s.oy[u] - s.ohh[u]).max(s.oy[v] - s.ohh[v]);
                let ix1 = (s.ox[u] + s.ohw[u]).min(s.ox[v] + s.ohw[v]);
                let iy1 = (s.oy[u] + s.ohh[u]).min(s.oy[v] + s.ohh[v]);
                if ix >= ix1 || iy >= iy1 {
                    continue;
                }
                // Handle the pair only in the bucket of the intersection's lower-left corner.
                if bucket(iy, ibh, br) * bc + bucket(ix, ibw, bc) != b {
                    continue;
                }
                let (mut ddx, mut ddy) = (s.ox[u] - s.ox[v], s.oy[u] - s.oy[v]);
                let d = (ddx * ddx + ddy * ddy).sqrt();
                if d == 0.0 {
                    ddx = -std::f64::consts::FRAC_1_SQRT_2;
                    ddy = -std::f64::consts::FRAC_1_SQRT_2;
                } else {
                    ddx /= d;
                    ddy /= d;
                }
                if u >= hard {
                    s.dx[u] += mag * ddx;
                    s.dy[u] += mag * ddy;
                }
                if v >= hard {
                    s.dx[v] -= mag * ddx;
                    s.dy[v] -= mag * ddy;
                }
            }
        }
    }
}
