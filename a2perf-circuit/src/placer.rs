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
/// Layout of the position slots: placed hard macros `[0, hard)`, movable nodes `[hard, nobj)`, then
/// one read-only slot per fixed pin of an active net. Forces exist only for the objects plus
/// [`SINKS`] sink slots after them, where forces on fixed pins land (and are never read), so the
/// per-step clearing and the force writes stay within a small, cache-resident array.
#[derive(Clone, Debug, Default)]
pub struct FdScratch {
    node: Vec<u32>,
    pos: Vec<[f64; 2]>,
    half: Vec<[f64; 2]>,
    force: Vec<[f64; 2]>,
    obj_of: Vec<u32>,
    // Per-step repulsion data: bounding box and the bucket of its lower-left corner.
    bbox: Vec<[f64; 4]>,
    ll_bucket: Vec<[u32; 2]>,
    ur_bucket: Vec<[u32; 2]>,
    bucket_start: Vec<u32>,
    bucket_hard: Vec<u32>,
    bucket_items: Vec<BucketItem>,
    bucket_fill: Vec<u32>,
    // Active nets (at least one movable endpoint), flattened; driver first.
    a_start: Vec<u32>,
    a_obj: Vec<u32>,
    a_fac: Vec<f64>,
    a_w: Vec<f64>,
    // Per-pin attraction factor of the current round, `(w · attract) · fac`.
    a_f: Vec<f64>,
}

const NONE: u32 = u32::MAX;

/// Number of sink slots for forces on fixed pins. Consecutive fixed pins write to different
/// sinks, so their read-modify-writes do not form one long dependency chain through memory.
const SINKS: u32 = 16;

/// Force slot of position slot `o` (objects write to themselves, fixed pins to a sink).
#[inline(always)]
fn force_slot(o: u32, nobj: u32) -> usize {
    (if o < nobj {
        o
    } else {
        nobj + (o & (SINKS - 1))
    }) as usize
}

/// One object's entry in a repulsion bucket: a copy of what the pair test needs, so a bucket's
/// pair loop streams through contiguous memory.
#[derive(Clone, Copy, Debug, Default)]
struct BucketItem {
    bbox: [f64; 4],
    ll: [u32; 2],
    k: u32,
}

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
    s.pos.clear();
    s.half.clear();
    let r0 = 1e-3 * cw.min(ch);
    for (k, &i) in s.node.iter().enumerate() {
        let i = i as usize;
        s.obj_of[i] = k as u32;
        s.half.push([cost.w[i] / 2.0, cost.h[i] / 2.0]);
        if k < hard {
            s.pos.push([cost.x[i], cost.y[i]]);
        } else {
            // Centre start on a golden-angle spiral (CT starts from the centre).
            let j = k - hard;
            let a = j as f64 * 2.399_963_229_728_653;
            let r = r0 * ((j + 1) as f64).sqrt();
            s.pos.push([cw / 2.0 + r * a.cos(), ch / 2.0 + r * a.sin()]);
        }
    }
    // Active nets. Every fixed pin (hard-macro pin, port) gets its own read-only slot after the
    // objects, holding its position, so the attraction loop has no branches. Pins whose force
    // could only land on fixed slots are dropped: fixed sinks of a net with a fixed driver, and
    // sinks on the driver's own node (their force is exactly zero).
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
        let driver = cost.pin_owner[a] as usize;
        let driver_mov = is_mov(cost, driver);
        let driver_port = cost.kind[driver] == NodeKind::Port;
        for p in a..b {
            let o = cost.pin_owner[p] as usize;
            let mov = is_mov(cost, o);
            if p > a && ((!mov && !driver_mov) || (mov && o == driver)) {
                continue;
            }
            if mov {
                s.a_obj.push(s.obj_of[o]);
            } else {
                s.a_obj.push(s.pos.len() as u32);
                s.pos.push([cost.pin_x[p], cost.pin_y[p]]);
            }
            let port = driver_port || cost.kind[o] == NodeKind::Port;
            s.a_fac.push(if port { schedule.io_factor } else { 1.0 });
        }
        s.a_start.push(s.a_obj.len() as u32);
        s.a_w.push(cost.net_w[net]);
    }
    s.force.clear();
    s.force.resize(nobj + SINKS as usize, [0.0, 0.0]);
    let max_soft = (hard..nobj)
        .map(|k| s.half[k][0].max(s.half[k][1]) * 2.0)
        .fold(0.0f64, f64::max);
    let rounds = schedule
        .num_steps
        .len()
        .min(schedule.attract.len())
        .min(schedule.repel.len())
        .min(schedule.move_distance_factors.len());
    for round in 0..rounds {
        let max_move = schedule.move_distance_factors[round] * cw.max(ch) / 100.0;
        let attract = schedule.attract[round];
        s.a_f.clear();
        for net in 0..s.a_w.len() {
            let w = s.a_w[net] * attract;
            let (a, b) = (s.a_start[net] as usize, s.a_start[net + 1] as usize);
            s.a_f.extend(s.a_fac[a..b].iter().map(|&fac| w * fac));
        }
        for _ in 0..schedule.num_steps[round] {
            step(
                s,
                (cw, ch),
                attract,
                schedule.repel[round],
                max_move,
                max_soft,
                hard,
            );
        }
    }
    for k in hard..nobj {
        let i = s.node[k] as usize;
        cost.x[i] = s.pos[k][0];
        cost.y[i] = s.pos[k][1];
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
    let nobj32 = nobj as u32;
    s.force.iter_mut().for_each(|f| *f = [0.0, 0.0]);
    if attract != 0.0 {
        let (pos, force) = (&s.pos[..], &mut s.force[..]);
        let (a_obj, a_f) = (&s.a_obj[..], &s.a_f[..]);
        for w in s.a_start.windows(2) {
            let (a, b) = (w[0] as usize, w[1] as usize);
            let d = a_obj[a];
            let [dxp, dyp] = pos[d as usize];
            let (mut fdx, mut fdy) = (0.0, 0.0);
            for (&o, &f) in a_obj[a + 1..b].iter().zip(&a_f[a + 1..b]) {
                let [ox, oy] = pos[o as usize];
                let (fx, fy) = (f * (ox - dxp), f * (oy - dyp));
                fdx += fx;
                fdy += fy;
                let t = &mut force[force_slot(o, nobj32)];
                t[0] -= fx;
                t[1] -= fy;
            }
            let t = &mut force[force_slot(d, nobj32)];
            t[0] += fdx;
            t[1] += fdy;
        }
    }
    if repel != 0.0 {
        repulsion(s, (cw, ch), repel * max_move, max_soft, hard);
    }
    let (mut mx, mut my) = (0.0f64, 0.0f64);
    for f in &s.force[hard..nobj] {
        mx = mx.max(f[0].abs());
        my = my.max(f[1].abs());
    }
    let sx = if mx > 0.0 { max_move / mx } else { 0.0 };
    let sy = if my > 0.0 { max_move / my } else { 0.0 };
    for k in hard..nobj {
        let [hw, hh] = s.half[k];
        let [fx, fy] = s.force[k];
        let p = &mut s.pos[k];
        let nx = p[0] + fx * sx;
        let ny = p[1] + fy * sy;
        // A move that would leave the canvas is cancelled on that axis.
        if nx - hw > 0.0 && nx + hw < cw {
            p[0] = nx;
        }
        if ny - hh > 0.0 && ny + hh < ch {
            p[1] = ny;
        }
    }
}

/// Pairwise repulsion of overlapping objects using a uniform bucket grid; each pair is handled
/// once (in the bucket holding the lower-left corner of their intersection). Pairs are visited
/// bucket by bucket, in object order within a bucket, so the force sums are deterministic.
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
    s.bbox.clear();
    s.ll_bucket.clear();
    s.ur_bucket.clear();
    for (p, h) in s.pos[..nobj].iter().zip(&s.half[..nobj]) {
        let b = [p[0] - h[0], p[1] - h[1], p[0] + h[0], p[1] + h[1]];
        s.bbox.push(b);
        s.ll_bucket
            .push([bucket(b[0], ibw, bc) as u32, bucket(b[1], ibh, br) as u32]);
        s.ur_bucket
            .push([bucket(b[2], ibw, bc) as u32, bucket(b[3], ibh, br) as u32]);
    }
    s.bucket_start.clear();
    s.bucket_start.resize(nb + 1, 0);
    s.bucket_hard.clear();
    s.bucket_hard.resize(nb, 0);
    for (k, (ll, ur)) in s.ll_bucket.iter().zip(&s.ur_bucket).enumerate() {
        for r in ll[1] as usize..=ur[1] as usize {
            for c in ll[0] as usize..=ur[0] as usize {
                s.bucket_start[r * bc + c + 1] += 1;
                if k < hard {
                    s.bucket_hard[r * bc + c] += 1;
                }
            }
        }
    }
    for b in 0..nb {
        s.bucket_start[b + 1] += s.bucket_start[b];
    }
    s.bucket_fill.clear();
    s.bucket_fill.extend_from_slice(&s.bucket_start[..nb]);
    s.bucket_items.clear();
    s.bucket_items
        .resize(s.bucket_start[nb] as usize, BucketItem::default());
    for (k, ((b, ll), ur)) in s
        .bbox
        .iter()
        .zip(&s.ll_bucket)
        .zip(&s.ur_bucket)
        .enumerate()
    {
        for r in ll[1] as usize..=ur[1] as usize {
            for c in ll[0] as usize..=ur[0] as usize {
                let slot = &mut s.bucket_fill[r * bc + c];
                s.bucket_items[*slot as usize] = BucketItem {
                    bbox: *b,
                    ll: *ll,
                    k: k as u32,
                };
                *slot += 1;
            }
        }
    }
    let pos = &s.pos[..];
    let force = &mut s.force[..];
    for b in 0..nb {
        let (lo, hi) = (s.bucket_start[b] as usize, s.bucket_start[b + 1] as usize);
        // Hard macros come first in a bucket and never repel each other.
        let first_mov = lo + s.bucket_hard[b] as usize;
        let (bcol, brow) = ((b % bc) as u32, (b / bc) as u32);
        let items = &s.bucket_items[..];
        for ia in lo..hi {
            let BucketItem {
                bbox: bu, ll: lu, ..
            } = items[ia];
            let u = items[ia].k as usize;
            for it in &items[(ia + 1).max(first_mov)..hi] {
                // The pair belongs to the bucket of its intersection's lower-left corner, whose
                // bucket is the max of the two lower-left buckets (bucketing is monotone).
                let lv = it.ll;
                if lu[0].max(lv[0]) != bcol || lu[1].max(lv[1]) != brow {
                    continue;
                }
                let (bv, v) = (it.bbox, it.k as usize);
                let ix = bu[0].max(bv[0]);
                let iy = bu[1].max(bv[1]);
                let ix1 = bu[2].min(bv[2]);
                let iy1 = bu[3].min(bv[3]);
                if ix >= ix1 || iy >= iy1 {
                    continue;
                }
                let (mut ddx, mut ddy) = (pos[u][0] - pos[v][0], pos[u][1] - pos[v][1]);
                let d = (ddx * ddx + ddy * ddy).sqrt();
                if d == 0.0 {
                    ddx = -std::f64::consts::FRAC_1_SQRT_2;
                    ddy = -std::f64::consts::FRAC_1_SQRT_2;
                } else {
                    ddx /= d;
                    ddy /= d;
                }
                if u >= hard {
                    force[u][0] += mag * ddx;
                    force[u][1] += mag * ddy;
                }
                if v >= hard {
                    force[v][0] -= mag * ddx;
                    force[v][1] -= mag * ddy;
                }
            }
        }
    }
}
