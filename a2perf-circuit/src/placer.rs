//! A deterministic force-directed placer for soft macros and standard cells (and, for the
//! mixed-size run that seeds the environment's initial locations, hard macros too).
//!
//! **This is our placer, not Google's** (whose `optimize_stdcells` is closed). It follows the
//! schedules circuit_training passes to it: at the end of every episode ([`FdSchedule::default`])
//! three rounds of 100 steps, maximum move `f·max(W, H)/num_steps` per step with `f = 1`,
//! attraction factors `[100, 1e-3, 1e-5]` and repulsion factors `[0, 1e6, 1e7]`, I/O factor 1,
//! hard macros fixed; once in the environment's constructor ([`FdSchedule::mixed_size`]) the same
//! with `f = [1, 2, 2]`, repulsion `[0, 1e5, 1e6]` and the hard macros moving as well. Per step:
//!
//! - attraction: every net pulls each sink pin towards its driver pin and the driver towards each
//!   sink (spring ∝ distance × net weight × factor, × I/O factor when a port is involved); a pin
//!   sits at its owner's centre plus its (oriented) offset, so a moving hard macro is pulled at
//!   its pins;
//! - repulsion: every overlapping pair of macros pushes apart along the line of centres with
//!   `factor × max_move` (placed hard macros that do not move are obstacles; pairs are found with
//!   a bucket grid, not by testing all pairs);
//! - displacements are normalised per axis so the largest equals the round's maximum move (as
//!   plc_client_os does, so only the ratio of the factors matters within a step);
//! - a move that would leave the canvas is cancelled on that axis.
//!
//! Initial positions (`use_current_loc = False` in CT): every movable node at the exact canvas
//! centre, as circuit_training's placer and MacroPlacement's `plc_client_os` start. Two
//! overlapping objects with the same centre are pushed apart along `(−1, −1)/√2` (the one of lower
//! node index) and `(1, 1)/√2` (the other), `plc_client_os`'s rule; attraction to the fixed pins
//! separates most of them in the first round, which has no repulsion.
//!
//! Parity: `tests/fd_parity.rs` runs this placer against goldens from `plc_client_os`'s
//! `optimize_stdcells` (toy with six macro placements, Ariane133 legalized): positions agree to
//! rounding through the first round and the end-of-schedule proxy cost within 1e-3.
//!
//! Implementation (same forces, summed in a different order than a per-net loop would): springs
//! are linear, so all springs of an object to fixed pins fold into one term `h − g·p`, and
//! parallel springs between the same two objects merge into one; each object then gathers its
//! attraction from its partners without scattered writes. Overlapping pairs are collected without
//! data-dependent branches before their forces are computed. The schedule is sensitive to
//! rounding (overlap tests and cancelled moves are discontinuous), so such reorderings change the
//! final placement's proxy cost by tenths of a percent; the result is still bit-identical from
//! run to run.

use crate::cost::PlacementCost;
use crate::netlist::NodeKind;

/// The force-directed schedule.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct FdSchedule {
    /// Steps per round.
    pub num_steps: Vec<usize>,
    /// Maximum move per step, as a fraction of `max(W, H)/num_steps` of the round
    /// (circuit_training's `max_move_distance = f·canvas_size/s`).
    pub move_distance_factors: Vec<f64>,
    /// Attraction factor per round.
    pub attract: Vec<f64>,
    /// Repulsion factor per round.
    pub repel: Vec<f64>,
    /// Multiplier of attraction on nets with a port.
    pub io_factor: f64,
    /// Move the (non-fixed) hard macros too (`move_macros = True`); otherwise placed hard macros
    /// stay where they are and act as fixed obstacles and pin anchors.
    #[serde(default)]
    pub move_macros: bool,
}

impl Default for FdSchedule {
    /// circuit_training's end-of-episode schedule (`fd_placement_schedule` with its defaults).
    fn default() -> Self {
        Self {
            num_steps: vec![100, 100, 100],
            move_distance_factors: vec![1.0, 1.0, 1.0],
            attract: vec![100.0, 1e-3, 1e-5],
            repel: vec![0.0, 1e6, 1e7],
            io_factor: 1.0,
            move_macros: false,
        }
    }
}

impl FdSchedule {
    /// The mixed-size run of `CircuitEnv.__init__` (A2Perf's fork and circuit_training): every
    /// movable node, hard macros included, from the canvas centre; move factors `(1, 2, 2)`,
    /// attraction `(1e2, 1e-3, 1e-5)`, repulsion `(0, 1e5, 1e6)`. Its result is the initial
    /// `locations_x/y` of the observation.
    ///
    /// ```
    /// use a2perf_circuit::placer::FdSchedule;
    /// let s = FdSchedule::mixed_size();
    /// assert!(s.move_macros);
    /// assert_eq!(s.move_distance_factors, vec![1.0, 2.0, 2.0]);
    /// ```
    pub fn mixed_size() -> Self {
        Self {
            move_distance_factors: vec![1.0, 2.0, 2.0],
            repel: vec![0.0, 1e5, 1e6],
            move_macros: true,
            ..Self::default()
        }
    }
}

/// Reusable buffers of the placer (no allocation per run once warmed up).
///
/// Layout of the object slots: obstacles (placed hard macros that do not move) `[0, hard)`, then
/// movable nodes `[hard, nobj)`.
/// Fixed pins have no slots: their springs are folded into per-object linear terms.
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
    // Springs between two movable objects, per object (each spring listed at both ends), as
    // compressed rows over `[hard, nobj)`: partner slot and stiffness `w · fac` (without the
    // round's attraction factor). Gathering per object needs no scattered force writes.
    adj_start: Vec<u32>,
    adj_j: Vec<u32>,
    adj_c: Vec<f64>,
    edges: Vec<(u32, u32, u32, f64)>,
    // All springs of an object, `g = Σ c` over its partners, and `h = Σ c · q` over its fixed
    // partners q (hard-macro pins, ports): `force = attract · (h + Σ c_j p_j − g · p)`.
    lin_g: Vec<f64>,
    lin_h: Vec<[f64; 2]>,
    // Overlapping pairs of the current step.
    pairs: Vec<[u32; 2]>,
}

const NONE: u32 = u32::MAX;

/// One object's entry in a repulsion bucket: a copy of what the pair test needs, so a bucket's
/// pair loop streams through contiguous memory.
#[derive(Clone, Copy, Debug, Default)]
struct BucketItem {
    bbox: [f64; 4],
    ll: [u32; 2],
    k: u32,
}

/// Runs the force-directed placer on `cost`'s soft macros and standard cells (non-fixed; with
/// [`FdSchedule::move_macros`] the non-fixed hard macros too), then recomputes the costs.
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
    place_std_cells_steps(cost, schedule, s, usize::MAX);
}

/// [`place_std_cells`] stopped after the first `max_steps` steps of the schedule (counted across
/// rounds; each round keeps its own maximum move, `f·max(W, H)/num_steps`). Shows the state of the
/// placer part-way through a schedule, e.g. to compare it step by step with another
/// implementation; `usize::MAX` runs the whole schedule.
///
/// ```
/// use a2perf_circuit::{generate, GeneratorConfig, NodeKind, PlacementCost};
/// use a2perf_circuit::placer::{FdSchedule, FdScratch, place_std_cells_steps};
/// let g = generate(&GeneratorConfig::small(), 0);
/// let mut cost = PlacementCost::new(&g.netlist, g.settings.clone()).unwrap();
/// cost.apply_placement(&g.placement).unwrap();
/// place_std_cells_steps(&mut cost, &FdSchedule::default(), &mut FdScratch::default(), 0);
/// // No step taken: every soft macro still sits at the canvas centre, where the placer starts.
/// let centre = (g.settings.canvas_width / 2.0, g.settings.canvas_height / 2.0);
/// let soft = (0..cost.num_nodes()).find(|&i| cost.kind(i) == NodeKind::SoftMacro).unwrap();
/// assert_eq!(cost.position(soft), centre);
/// ```
pub fn place_std_cells_steps(
    cost: &mut PlacementCost,
    schedule: &FdSchedule,
    s: &mut FdScratch,
    max_steps: usize,
) {
    let n = cost.kind.len();
    let (cw, ch) = (cost.settings.canvas_width, cost.settings.canvas_height);
    let move_macros = schedule.move_macros;
    let is_mov = |cost: &PlacementCost, i: usize| {
        !cost.fixed[i]
            && match cost.kind[i] {
                NodeKind::SoftMacro | NodeKind::StdCell => true,
                NodeKind::HardMacro => move_macros,
                _ => false,
            }
    };
    // Obstacles first: placed hard macros that do not move.
    s.node.clear();
    s.node.extend((0..n as u32).filter(|&i| {
        let i = i as usize;
        cost.kind[i] == NodeKind::HardMacro && cost.placed[i] && !is_mov(cost, i)
    }));
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
    for (k, &i) in s.node.iter().enumerate() {
        let i = i as usize;
        s.obj_of[i] = k as u32;
        s.half.push([cost.w[i] / 2.0, cost.h[i] / 2.0]);
        if k < hard {
            s.pos.push([cost.x[i], cost.y[i]]);
        } else {
            s.pos.push([cw / 2.0, ch / 2.0]);
        }
    }
    // Springs to fixed pins (hard-macro pins, ports) are linear in the object's own position, so
    // all of an object's fixed springs fold into one term `h - g·p` (g = Σ w·fac, h = Σ w·fac·q
    // over its fixed partners q), evaluated once per object per step instead of once per pin.
    // Only springs between two movable objects stay per pin: nets with a movable driver, listed
    // driver first with their movable sinks. Sinks on the driver's own node are dropped (their
    // force is exactly zero), and so are springs between two fixed pins. A movable pin's offset
    // from its owner's centre (non-zero only for moving hard macros) is a constant of the spring
    // and folds into `h` as well: the pull on p's owner is `c·(q − o_p − p)`.
    s.edges.clear();
    s.lin_g.clear();
    s.lin_g.resize(nobj, 0.0);
    s.lin_h.clear();
    s.lin_h.resize(nobj, [0.0, 0.0]);
    for net in 0..cost.net_w.len() {
        let (a, b) = (
            cost.net_start[net] as usize,
            cost.net_start[net + 1] as usize,
        );
        let w = cost.net_w[net];
        let driver = cost.pin_owner[a] as usize;
        let driver_mov = is_mov(cost, driver);
        let driver_port = cost.kind[driver] == NodeKind::Port;
        let (qx, qy) = (cost.pin_x[a], cost.pin_y[a]);
        let (odx, ody) = (cost.pin_rdx[a], cost.pin_rdy[a]);
        for p in a + 1..b {
            let o = cost.pin_owner[p] as usize;
            let mov = is_mov(cost, o);
            let port = driver_port || cost.kind[o] == NodeKind::Port;
            let c = w * if port { schedule.io_factor } else { 1.0 };
            match (driver_mov, mov) {
                (true, true) if o != driver => {
                    let (kd, ko) = (s.obj_of[driver], s.obj_of[o]);
                    let seq = s.edges.len() as u32;
                    s.edges.push((kd, ko, seq, c));
                    s.edges.push((ko, kd, seq + 1, c));
                    s.lin_g[kd as usize] += c;
                    s.lin_g[ko as usize] += c;
                    let (dx, dy) = (cost.pin_rdx[p] - odx, cost.pin_rdy[p] - ody);
                    if dx != 0.0 || dy != 0.0 {
                        let (d, k) = (kd as usize, ko as usize);
                        s.lin_h[d][0] += c * dx;
                        s.lin_h[d][1] += c * dy;
                        s.lin_h[k][0] -= c * dx;
                        s.lin_h[k][1] -= c * dy;
                    }
                }
                (true, false) => {
                    let k = s.obj_of[driver] as usize;
                    s.lin_g[k] += c;
                    s.lin_h[k][0] += c * (cost.pin_x[p] - odx);
                    s.lin_h[k][1] += c * (cost.pin_y[p] - ody);
                }
                (false, true) => {
                    let k = s.obj_of[o] as usize;
                    s.lin_g[k] += c;
                    s.lin_h[k][0] += c * (qx - cost.pin_rdx[p]);
                    s.lin_h[k][1] += c * (qy - cost.pin_rdy[p]);
                }
                _ => {}
            }
        }
    }
    // Rows by object; parallel springs between the same two objects (clusters share many nets)
    // merge into one, summed in net order. The keys are unique, so the order is deterministic.
    s.edges.sort_unstable_by_key(|&(k, j, seq, _)| (k, j, seq));
    s.adj_start.clear();
    s.adj_start.resize(nobj - hard + 1, 0);
    s.adj_j.clear();
    s.adj_c.clear();
    let mut last = (NONE, NONE);
    for &(k, j, _, c) in &s.edges {
        if (k, j) == last {
            if let Some(sum) = s.adj_c.last_mut() {
                *sum += c;
            }
        } else {
            last = (k, j);
            s.adj_j.push(j);
            s.adj_c.push(c);
            s.adj_start[k as usize - hard + 1] += 1;
        }
    }
    for k in 0..nobj - hard {
        s.adj_start[k + 1] += s.adj_start[k];
    }
    s.force.clear();
    s.force.resize(nobj, [0.0, 0.0]);
    let max_soft = (hard..nobj)
        .map(|k| s.half[k][0].max(s.half[k][1]) * 2.0)
        .fold(0.0f64, f64::max);
    let rounds = schedule
        .num_steps
        .len()
        .min(schedule.attract.len())
        .min(schedule.repel.len())
        .min(schedule.move_distance_factors.len());
    let mut left = max_steps;
    for round in 0..rounds {
        let steps = schedule.num_steps[round];
        if steps == 0 {
            continue;
        }
        let max_move = schedule.move_distance_factors[round] * cw.max(ch) / steps as f64;
        let attract = schedule.attract[round];
        let run = steps.min(left);
        left -= run;
        for _ in 0..run {
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
    s.force[..hard].iter_mut().for_each(|f| *f = [0.0, 0.0]);
    if attract != 0.0 {
        let pos = &s.pos[..];
        for (((f, &[px, py]), (&g, &[hx, hy])), w) in s.force[hard..nobj]
            .iter_mut()
            .zip(&pos[hard..nobj])
            .zip(s.lin_g[hard..nobj].iter().zip(&s.lin_h[hard..nobj]))
            .zip(s.adj_start.windows(2))
        {
            let (a, b) = (w[0] as usize, w[1] as usize);
            // Two independent accumulators halve the add-latency chain.
            let (mut s0, mut s1) = ([hx, hy], [0.0, 0.0]);
            let (js, cs) = (&s.adj_j[a..b], &s.adj_c[a..b]);
            let mut pairs_j = js.chunks_exact(2);
            let mut pairs_c = cs.chunks_exact(2);
            for (j, c) in (&mut pairs_j).zip(&mut pairs_c) {
                let [x0, y0] = pos[j[0] as usize];
                let [x1, y1] = pos[j[1] as usize];
                s0 = [s0[0] + c[0] * x0, s0[1] + c[0] * y0];
                s1 = [s1[0] + c[1] * x1, s1[1] + c[1] * y1];
            }
            for (&j, &c) in pairs_j.remainder().iter().zip(pairs_c.remainder()) {
                let [x, y] = pos[j as usize];
                s0 = [s0[0] + c * x, s0[1] + c * y];
            }
            *f = [
                attract * ((s0[0] + s1[0]) - g * px),
                attract * ((s0[1] + s1[1]) - g * py),
            ];
        }
    } else {
        s.force.iter_mut().for_each(|f| *f = [0.0, 0.0]);
    }
    if repel != 0.0 {
        repulsion(s, (cw, ch), repel * max_move, max_soft, hard);
    }
    let (mut mx, mut my) = (0.0f64, 0.0f64);
    for f in &s.force[hard..nobj] {
        mx = mx.max(f[0].abs());
        my = my.max(f[1].abs());
    }
    // Rounded as plc_client_os rounds them (`f / max · move`, edges `x ± w/2 + d`), so that the
    // parity test compares the algorithms, not the association of their sums.
    let norm = |f: f64, m: f64| if m > 0.0 { f / m * max_move } else { 0.0 };
    for k in hard..nobj {
        let [hw, hh] = s.half[k];
        let [fx, fy] = s.force[k];
        let p = &mut s.pos[k];
        let (dx, dy) = (norm(fx, mx), norm(fy, my));
        // A move that would leave the canvas is cancelled on that axis.
        if p[0] - hw + dx > 0.0 && p[0] + hw + dx < cw {
            p[0] += dx;
        }
        if p[1] - hh + dy > 0.0 && p[1] + hh + dy < ch {
            p[1] += dy;
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
        // `as` maps NaN and negatives to 0.
        ((v * inv) as usize).min(n - 1)
    };
    let nb = bc * br;
    let nobj = s.node.len();
    s.bbox.clear();
    s.ll_bucket.clear();
    s.ur_bucket.clear();
    for (p, h) in s.pos[..nobj].iter().zip(&s.half[..nobj]) {
        let b = [p[0] - h[0], p[1] - h[1], p[0] + h[0], p[1] + h[1]];
        s.bbox.push(b);
        if b[0] < b[2] && b[1] < b[3] {
            s.ll_bucket
                .push([bucket(b[0], ibw, bc) as u32, bucket(b[1], ibh, br) as u32]);
            s.ur_bucket
                .push([bucket(b[2], ibw, bc) as u32, bucket(b[3], ibh, br) as u32]);
        } else {
            // No area, no overlap: an empty bucket range keeps it out of every bucket.
            s.ll_bucket.push([1, 1]);
            s.ur_bucket.push([0, 0]);
        }
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
    // Pass 1 collects the overlapping pairs without data-dependent branches (the overlap test is
    // unpredictable); pass 2 computes their forces, independent of one another.
    let mut n = 0;
    for b in 0..nb {
        let (lo, hi) = (s.bucket_start[b] as usize, s.bucket_start[b + 1] as usize);
        // Obstacles come first in a bucket and never repel each other.
        let first_mov = lo + s.bucket_hard[b] as usize;
        let (bcol, brow) = ((b % bc) as u32, (b / bc) as u32);
        let items = &s.bucket_items[..];
        for ia in lo..hi {
            let BucketItem {
                bbox: bu,
                ll: lu,
                k: u,
            } = items[ia];
            let cand = &items[(ia + 1).max(first_mov)..hi];
            if s.pairs.len() < n + cand.len() {
                s.pairs.resize(n + cand.len(), [0, 0]);
            }
            for it in cand {
                let (bv, lv) = (it.bbox, it.ll);
                // Plain comparisons instead of max/min: objects without area never reach a
                // bucket, so this is the test "intersection non-empty". The pair belongs to the
                // bucket of its intersection's lower-left corner, whose bucket is the max of the
                // two lower-left buckets (bucketing is monotone).
                let keep = (bu[0] < bv[2])
                    & (bv[0] < bu[2])
                    & (bu[1] < bv[3])
                    & (bv[1] < bu[3])
                    & (lu[0].max(lv[0]) == bcol)
                    & (lu[1].max(lv[1]) == brow);
                s.pairs[n] = [u, it.k];
                n += keep as usize;
            }
        }
    }
    let (bbox, node) = (&s.bbox[..], &s.node[..]);
    let force = &mut s.force[..];
    for &[u, v] in &s.pairs[..n] {
        let (u, v) = (u as usize, v as usize);
        // Centres as plc_client_os takes them, from the bounding boxes.
        let (bu, bv) = (bbox[u], bbox[v]);
        let ddx = (bu[0] + bu[2]) / 2.0 - (bv[0] + bv[2]) / 2.0;
        let ddy = (bu[1] + bu[3]) / 2.0 - (bv[1] + bv[3]) / 2.0;
        let (fx, fy) = if ddx == 0.0 && ddy == 0.0 {
            // Same centre (every node starts at the canvas centre): the lower node index goes
            // along (−1, −1)/√2, the other the opposite way.
            // `1/√2` rounded as plc_client_os computes it (one ulp below FRAC_1_SQRT_2).
            let c = mag * (1.0 / 2f64.sqrt());
            let c = if node[u] < node[v] { -c } else { c };
            (c, c)
        } else {
            let d = (ddx * ddx + ddy * ddy).sqrt();
            (mag * (ddx / d), mag * (ddy / d))
        };
        // Obstacles' force slots absorb their share unread (cleared each step), so no branch.
        force[u][0] += fx;
        force[u][1] += fy;
        force[v][0] -= fx;
        force[v][1] -= fy;
    }
}
