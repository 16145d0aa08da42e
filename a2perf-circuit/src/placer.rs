//! A deterministic force-directed placer for soft macros and standard cells (and, for the
//! mixed-size run that seeds the environment's initial locations, hard macros too).
//!
//! **This is our placer, not Google's** (whose `optimize_stdcells` is closed); on the
//! end-of-episode schedule it computes what MacroPlacement's open re-implementation
//! `plc_client_os` computes, to the bit (`plc_client_os` cannot move hard macros). It follows the
//! schedules circuit_training passes to it: at the end of every episode
//! ([`FdSchedule::default`]) three rounds of 100 steps, maximum move `f·max(W, H)/num_steps` per
//! step with `f = 1`, attraction factors `[100, 1e-3, 1e-5]` and repulsion factors
//! `[0, 1e6, 1e7]`, I/O factor 1, hard macros fixed; once in the environment's constructor ([`FdSchedule::mixed_size`]) the same
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
//! `optimize_stdcells` (the toy with six macro placements, Ariane133 `legalized.plc`): the
//! positions are the same to the bit through the schedule, so is the final proxy cost.
//!
//! Implementation: every sum is formed in `plc_client_os`'s order, because the schedule amplifies
//! rounding (on Ariane a reordered attraction sum drifts from 1e-12 µm at step 50 to 77 µm at step
//! 100, and overlap tests and cancelled moves are discontinuous): each object's springs in net
//! order and sink order, its pushes in increasing order of the other object's node index, centres
//! taken from the bounding boxes, displacements normalised as `f / max · move`. Each object
//! gathers its springs from a per-object list, without scattered writes; overlapping pairs are
//! found with a bucket grid and collected without data-dependent branches, then sorted into that
//! order. The result is bit-identical from run to run.

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
    // Springs per movable object, as compressed rows over `[hard, nobj)`, each row in the order
    // plc_client_os visits them (nets in driver order, sinks in input order; a spring between two
    // pins of the same object is listed twice, as there): the summation order of its forces.
    term_start: Vec<u32>,
    terms: Vec<Term>,
    term_seq: Vec<(u32, Term)>,
    // `c · attract` of every term for the current round.
    coef: Vec<f64>,
    // Overlapping pairs of the current step.
    pairs: Vec<[u32; 2]>,
}

const NONE: u32 = u32::MAX;

/// One spring seen from the object that it pulls: `force += c · attract · (q' − (p + own))`, where
/// `q' = q` for a fixed partner pin (`j == NONE`) and `q' = pos[j] + q` for a movable one.
#[derive(Clone, Copy, Debug, Default)]
struct Term {
    j: u32,
    c: f64,
    own: [f64; 2],
    q: [f64; 2],
}

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
    // Each spring pulls its driver pin towards its sink pin and the sink towards the driver with
    // `w · attract · distance` (× the I/O factor when a port is involved). The terms are kept per
    // pulled object in plc_client_os's order, so that each object's force is the same sum of the
    // same products as there: Ariane's first round is unstable enough that a reordered sum
    // drifts off after ~60 steps. A pin's position is its owner's centre plus its oriented
    // offset (fixed pins: their current position).
    s.term_seq.clear();
    for net in 0..cost.net_w.len() {
        let (a, b) = (
            cost.net_start[net] as usize,
            cost.net_start[net + 1] as usize,
        );
        let w = cost.net_w[net];
        let driver = cost.pin_owner[a] as usize;
        let driver_port = cost.kind[driver] == NodeKind::Port;
        for p in a + 1..b {
            let o = cost.pin_owner[p] as usize;
            let port = driver_port || cost.kind[o] == NodeKind::Port;
            let c = if port { w * schedule.io_factor } else { w };
            // (pulled pin, partner pin)
            for (me, other) in [(a, p), (p, a)] {
                let k = s.obj_of[cost.pin_owner[me] as usize];
                if k == NONE || (k as usize) < hard {
                    continue;
                }
                let j = s.obj_of[cost.pin_owner[other] as usize];
                let partner_moves = j != NONE && j as usize >= hard;
                s.term_seq.push((
                    k,
                    Term {
                        j: if partner_moves { j } else { NONE },
                        c,
                        own: [cost.pin_rdx[me], cost.pin_rdy[me]],
                        q: if partner_moves {
                            [cost.pin_rdx[other], cost.pin_rdy[other]]
                        } else {
                            [cost.pin_x[other], cost.pin_y[other]]
                        },
                    },
                ));
            }
        }
    }
    // Stable: each object's terms stay in visiting order.
    s.term_seq.sort_by_key(|&(k, _)| k);
    s.term_start.clear();
    s.term_start.resize(nobj - hard + 1, 0);
    s.terms.clear();
    for &(k, t) in &s.term_seq {
        s.term_start[k as usize - hard + 1] += 1;
        s.terms.push(t);
    }
    for k in 0..nobj - hard {
        s.term_start[k + 1] += s.term_start[k];
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
        // Each spring's force factor of the round, `(w · io) · attract` as plc_client_os rounds it.
        s.coef.clear();
        s.coef.extend(s.terms.iter().map(|t| t.c * attract));
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
        for ((f, &[px, py]), w) in s.force[hard..nobj]
            .iter_mut()
            .zip(&pos[hard..nobj])
            .zip(s.term_start.windows(2))
        {
            let mut sum = [0.0, 0.0];
            let (a, b) = (w[0] as usize, w[1] as usize);
            for (t, &coef) in s.terms[a..b].iter().zip(&s.coef[a..b]) {
                let q = if t.j == NONE {
                    t.q
                } else {
                    let [x, y] = pos[t.j as usize];
                    [x + t.q[0], y + t.q[1]]
                };
                sum[0] += coef * (q[0] - (px + t.own[0]));
                sum[1] += coef * (q[1] - (py + t.own[1]));
            }
            *f = sum;
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
    // plc_client_os visits the pairs by node index (lower node outer, higher inner), so each
    // object receives its pushes in increasing order of the other's node index; summed in that
    // order they round as there.
    s.pairs[..n].sort_unstable_by_key(|&[u, v]| {
        let (a, b) = (node[u as usize], node[v as usize]);
        (a.min(b), a.max(b))
    });
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
