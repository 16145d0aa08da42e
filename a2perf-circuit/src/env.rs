//! The macro-placement environment (`CircuitTraining-*`).
//!
//! # Episode
//! One hard macro per step, in A2Perf's order (descending area, ties in descending node index;
//! fixed macros excluded). The action is a placement-grid cell (`Discrete{cols·rows}`,
//! `cell = row·cols + col`) or, with `padded_action`, A2Perf's padded 128×128 layout
//! ([`cell_to_padded_action`]; the padding is always masked). The macro's centre goes to the cell
//! centre. Reward is 0 until the last macro; then soft macros and standard cells are placed by the
//! standard-cell placer (`std_cell_placer`) and the reward is `−proxy_cost`:
//!
//! - `fd` (default, the original's): our force-directed placer ([`crate::placer`], from the
//!   canvas centre whatever their current positions, as circuit_training's
//!   `use_current_loc=False`);
//! - `dreamplace` (A2Perf's baselines): our analytical placer with circuit_training's
//!   DREAMPlace parameters ([`crate::analytical`]), from their current positions (the
//!   initial locations), placed hard macros fixed;
//! - `none`: they stay where they are.
//!
//! In `dreamplace` mode a macro left without a legal cell ends the episode as circuit_training
//! does: the remaining hard macros are placed analytically with the soft macros and standard
//! cells (mixed-size, then marked placed), the reward is the real `−proxy_cost` (not
//! `infeasible_reward`), `info` has the real costs and `infeasible = 1`, and
//! `infeasible_auto_reset` decides, as below, between the reset observation (A2Perf's fork,
//! which resets in this mode too) and the final state (`step` then asks for a `reset`).
//!
//! If a macro has no legal cell left the episode terminates with reward `infeasible_reward`, by
//! default [`INFEASIBLE_REWARD`] = −4.0 (circuit_training's current value). A2Perf's fork uses
//! −1.0 ([`A2PERF_INFEASIBLE_REWARD`]), which under its own proxy weights is *better* than most
//! feasible placements (random legal placements of Ariane cost ≈ 1.40, good ones ≈ 1.15), so an
//! agent could learn to make the placement infeasible on purpose. A2Perf's fork also resets
//! itself on that step: it returns `(reset observation, −1.0, terminated = True, truncated = True,
//! {wirelength, congestion, density: −1})`, and the environment is then at the start of a new
//! episode (a `step` without `reset` continues it; a `reset` gives the same observation again).
//! `infeasible_auto_reset = true` reproduces that step; by default the stranded state is returned
//! (`truncated = false`) and `step` asks for a `reset`.
//! Info at the end: `wirelength` (the wirelength cost), `density`, `congestion`, `proxy`,
//! `wirelength_hpwl`, `infeasible`.
//!
//! # Initial locations
//! As A2Perf's `CircuitEnv.__init__`, the constructor runs a mixed-size placement of every
//! movable node, hard macros included: force-directed ([`FdSchedule::mixed_size`]; our placer,
//! Google's is closed), or in `dreamplace` mode the analytical placer with every hard macro
//! movable (circuit_training's `update_num_non_movable_macros(0)`). Its result is what the observation shows for a macro until the agent places it, and
//! where soft macros and standard cells sit during the episode. `initial_locations = "plc"` keeps
//! the positions of the `.plc` (or the generator) instead.
//!
//! # Observation layout
//! Tensors, in order (`M` = macros (hard then soft… in node-index order, as `get_macro_indices`),
//! `G = cols·rows`, `E` = macro-adjacency edges):
//!
//! | name | shape | dtype | meaning |
//! |---|---|---|---|
//! | `features` | `[134]` | float32 | `[w/W, h/H, placed fraction, legal-cell fraction, area/(W·H), unplaced hard-macro area/(W·H)]` of the current macro, then an 8×8 density map (mean cell density per block), then an 8×8 congestion map (mean of (H+V)/2 per block) |
//! | `grid` | `[4, rows, cols]` | float32 | channel 0 cell density, 1 congestion (H+V)/2, 2 legality of the current macro (0/1), 3 wirelength hint: `1 − Δ/maxΔ` where Δ is the HPWL increase of the current macro's nets if its centre were at that cell (pins at the centre; only placed/fixed pins count) |
//! | `locations_x`, `locations_y` | `[M]` | float32 | macro centres / (W+H) (A2Perf normalisation): a placed hard macro's cell centre, otherwise its initial location |
//! | `is_node_placed` | `[M]` | int32 | 1 for placed (or fixed) hard macros; soft macros 0 unless fixed, as A2Perf (`soft_macros_placed = true`: 1, at their current location) |
//! | `current_node` | `[1]` | int32 | position in `M` of the macro to place (0 when done) |
//! | `node_types` | `[M]` | int32 | 1 hard, 2 soft |
//! | `macros_w`, `macros_h` | `[M]` | float32 | size / (W+H) (0 for soft macros, as A2Perf) |
//! | `sparse_adj_i`, `sparse_adj_j`, `sparse_adj_weight` | `[E]` | int32, int32, float32 | macro adjacency (positions in `M`, `i < j`), weights ÷ (their mean + 10⁻⁶), as A2Perf |
//!
//! The mask is [`Observation::action_mask`] (`true` = legal). Unlike A2Perf, node tensors are not
//! zero-padded to 3500, port clusters are not included, and `mask`, `fake_net_heatmap` and
//! `netlist_index` are not tensors (the README's "Differences from the original A2Perf" says
//! why).
//!
//! # Rendering
//! [`Env::render`] draws the current placement, on demand only: `"rgb_array"` rasterizes it
//! ([`render_rgb`], [`RGB_SIZE`] pixels on the longer canvas side) and `"svg"` returns
//! [`render_svg`]'s picture ([`SVG_SIZE`] pixels, titled with the netlist's name: what
//! `a2perf circuit render` draws with its default size; hard macros not placed yet are not
//! drawn, so for a finished placement the two are identical).

use std::collections::BTreeMap;
use std::hash::{DefaultHasher, Hash, Hasher};
use std::path::Path;
use std::sync::{Arc, Mutex, MutexGuard, PoisonError, Weak};

use a2perf_core::{
    Action, DType, Env, EnvEntry, EnvError, EnvSpec, Frame, Observation, ParamKind, ParamSpec,
    Params, Registry, Space, Step, TaskRef, Tensor, Value,
};

use crate::analytical::{
    AnalyticalParams, AnalyticalScratch, MovableMacros, check_capacity, place_analytical,
};
use crate::cost::{CostSettings, CostWeights, PlacementCost};
use crate::generator::{GeneratorConfig, generate};
use crate::netlist::{Netlist, NodeKind, SoftMacroRule};
use crate::placer::{FdSchedule, FdScratch, place_std_cells};
use crate::plc::{Placement, parse_header};
use crate::render::{RGB_SIZE, SVG_SIZE, render_rgb, render_svg};

/// Default reward when a macro has no legal cell left: circuit_training's current value, below
/// the proxy cost of any realistic feasible placement.
pub const INFEASIBLE_REWARD: f64 = -4.0;
/// A2Perf's fork value of the infeasible reward (the paper's environment; see the module docs).
pub const A2PERF_INFEASIBLE_REWARD: f64 = -1.0;
/// Side of A2Perf's padded action canvas.
pub const PADDED_GRID: usize = 128;
/// Side of the downsampled maps in `features`.
pub const FEATURE_MAP: usize = 8;
/// `node_types` value of a hard macro (A2Perf's encoding).
pub const NODE_TYPE_HARD: i32 = 1;
/// `node_types` value of a soft macro.
pub const NODE_TYPE_SOFT: i32 = 2;
/// `node_types` value of a port cluster in A2Perf (we have none; it bounds the box as there).
pub const NODE_TYPE_PORT_CLUSTER: i32 = 3;
/// Length of the `features` tensor.
pub const FEATURE_DIM: usize = 6 + 2 * FEATURE_MAP * FEATURE_MAP;
/// Channels of the `grid` tensor.
pub const GRID_CHANNELS: usize = 4;
/// Added to the mean adjacency weight before dividing by it (A2Perf's `EPSILON`).
const ADJACENCY_EPSILON: f64 = 1e-6;

/// A2Perf's placement of a `cols × rows` grid on the 128×128 action canvas: `(up, right)` =
/// `((128 − rows)/2, (128 − cols)/2)`, the padding rows before the grid's first row and padding
/// columns before its first column (A2Perf calls the latter `right_pad`).
///
/// ```
/// // circuit_training's toy netlist (20×10) and Ariane (35×33).
/// assert_eq!(a2perf_circuit::env::padding(20, 10), (59, 54));
/// assert_eq!(a2perf_circuit::env::padding(35, 33), (47, 46));
/// ```
pub fn padding(cols: usize, rows: usize) -> (usize, usize) {
    (
        PADDED_GRID.saturating_sub(rows) / 2,
        PADDED_GRID.saturating_sub(cols) / 2,
    )
}

/// The padded action of placement-grid `cell` (A2Perf's `translate_to_padded_canvas`).
///
/// ```
/// use a2perf_circuit::env::{cell_to_padded_action, padded_action_to_cell};
/// // Toy netlist: cell 41 (row 2, col 1) is action (2 + 59)·128 + (1 + 54).
/// assert_eq!(cell_to_padded_action(41, 20, 10), 7863);
/// assert_eq!(padded_action_to_cell(7863, 20, 10), Some(41));
/// assert_eq!(padded_action_to_cell(0, 20, 10), None);
/// ```
pub fn cell_to_padded_action(cell: usize, cols: usize, rows: usize) -> usize {
    let (up, right) = padding(cols, rows);
    (cell / cols + up) * PADDED_GRID + (cell % cols + right)
}

/// The placement-grid cell of a padded action, `None` when it falls in the padding or outside
/// the 128×128 canvas.
pub fn padded_action_to_cell(action: usize, cols: usize, rows: usize) -> Option<usize> {
    if action >= PADDED_GRID * PADDED_GRID {
        return None;
    }
    let (up, right) = padding(cols, rows);
    let r = (action / PADDED_GRID).checked_sub(up)?;
    let c = (action % PADDED_GRID).checked_sub(right)?;
    (r < rows && c < cols).then_some(r * cols + c)
}

/// Hard macros to place, A2Perf order: descending area, ties in descending node index.
pub fn placement_order(netlist: &Netlist, fixed: &[bool]) -> Vec<usize> {
    let mut hard: Vec<usize> = netlist
        .nodes
        .iter()
        .enumerate()
        .filter(|(i, n)| n.kind == NodeKind::HardMacro && !fixed.get(*i).copied().unwrap_or(false))
        .map(|(i, _)| i)
        .collect();
    // Python: sorted(ascending area, stable)[::-1] ⇒ equal areas end in descending index.
    hard.sort_by(|&a, &b| {
        let (na, nb) = (&netlist.nodes[a], &netlist.nodes[b]);
        (na.width * na.height)
            .total_cmp(&(nb.width * nb.height))
            .then(a.cmp(&b))
    });
    hard.reverse();
    hard
}

/// Where the initial node locations come from (what the observation shows for a macro until it
/// is placed, and where soft macros and standard cells sit during an episode).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum InitialLocations {
    /// A mixed-size force-directed run at construction ([`FdSchedule::mixed_size`]), as A2Perf's
    /// `CircuitEnv.__init__` (parameter value `fd`).
    #[default]
    MixedSizeFd,
    /// The initial placement as given (the `.plc` file or the generator's placement; `plc`).
    Plc,
}

impl InitialLocations {
    /// The parameter value naming this choice.
    pub fn name(self) -> &'static str {
        match self {
            Self::MixedSizeFd => "fd",
            Self::Plc => "plc",
        }
    }
}

/// The standard-cell placer run at the end of an episode (parameter `std_cell_placer`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum StdCellPlacer {
    /// Our force-directed placer with circuit_training's schedule (`fd`, the original's
    /// default).
    #[default]
    Fd,
    /// Our analytical placer with circuit_training's DREAMPlace parameters (`dreamplace`,
    /// what A2Perf's baselines name): [`crate::analytical`].
    DreamPlace,
    /// None: soft macros and standard cells stay where they are (`none`).
    None,
}

impl StdCellPlacer {
    /// The parameter value naming this choice.
    ///
    /// ```
    /// assert_eq!(a2perf_circuit::StdCellPlacer::DreamPlace.name(), "dreamplace");
    /// ```
    pub fn name(self) -> &'static str {
        match self {
            Self::Fd => "fd",
            Self::DreamPlace => "dreamplace",
            Self::None => "none",
        }
    }
}

/// Options of a [`CircuitEnv`].
#[derive(Clone, Debug, PartialEq)]
pub struct CircuitEnvConfig {
    /// Id recorded in the spec.
    pub id: String,
    /// Use A2Perf's padded 128×128 action layout.
    pub padded_action: bool,
    /// The standard-cell placer at the end of an episode.
    pub std_cell_placer: StdCellPlacer,
    /// The force-directed placer's schedule.
    pub fd_schedule: FdSchedule,
    /// The analytical placer's parameters.
    pub analytical: AnalyticalParams,
    /// Proxy weights.
    pub weights: CostWeights,
    /// Reward of an episode that ends because a macro has no legal cell left.
    pub infeasible_reward: f64,
    /// On that step, behave as A2Perf's fork: return the reset observation with `terminated`
    /// and `truncated` both set, and leave the environment reset.
    pub infeasible_auto_reset: bool,
    /// Report soft macros as placed, at their current location (ours before the A2Perf review);
    /// `false` reports them as A2Perf does: not placed (unless fixed), at their initial location.
    pub soft_macros_placed: bool,
    /// Where the initial node locations come from.
    pub initial_locations: InitialLocations,
}

impl Default for CircuitEnvConfig {
    fn default() -> Self {
        Self {
            id: "CircuitTraining-Custom-v0".into(),
            padded_action: false,
            std_cell_placer: StdCellPlacer::Fd,
            fd_schedule: FdSchedule::default(),
            analytical: AnalyticalParams::circuit_training(),
            weights: CostWeights::default(),
            infeasible_reward: INFEASIBLE_REWARD,
            infeasible_auto_reset: false,
            soft_macros_placed: false,
            initial_locations: InitialLocations::MixedSizeFd,
        }
    }
}

/// The macro-placement environment.
///
/// ```
/// use a2perf_circuit::{generate, CircuitEnv, CircuitEnvConfig, GeneratorConfig};
/// use a2perf_core::{Action, Env};
/// let g = generate(&GeneratorConfig::small(), 0);
/// let mut env = CircuitEnv::new(&g.netlist, Some(&g.placement), g.settings.clone(),
///                               CircuitEnvConfig::default()).unwrap();
/// let mut obs = env.reset(Some(0)).unwrap();
/// loop {
///     let mask = obs.action_mask.clone().unwrap();
///     let Some(a) = mask.iter().position(|m| *m) else { break };
///     let step = env.step(&Action::Discrete(a)).unwrap();
///     obs = step.observation.clone();
///     if step.done() { assert!(step.reward < 0.0); break; }
/// }
/// ```
pub struct CircuitEnv {
    spec: EnvSpec,
    config: CircuitEnvConfig,
    base_x: Vec<f64>,
    base_y: Vec<f64>,
    cost: PlacementCost,
    order: Vec<usize>,
    macros: Vec<usize>,
    macro_pos: Vec<usize>,
    current: usize,
    needs_reset: bool,
    mask: Vec<bool>,
    fd: FdScratch,
    analytical: AnalyticalScratch,
    static_tensors: Vec<Tensor>,
    // Scratch.
    dens: Vec<f64>,
    xcost: Vec<f64>,
    ycost: Vec<f64>,
    // Per placement cell: its congestion-grid cell and its block of the downsampled feature
    // maps (fixed for the env; integer divisions per cell and step are slow).
    cell_ccell: Vec<u32>,
    cell_block: Vec<u16>,
    block_counts: [u32; FEATURE_MAP * FEATURE_MAP],
    /// The cells chosen this episode, in order (the key of `ends`).
    cells: Vec<u32>,
    /// The cache of episode ends: shared with every environment of the process with the same
    /// [`start_fingerprint`] (`ends_shared`), or private; `None` = off.
    ends: Option<Arc<Mutex<EndCache>>>,
    ends_shared: bool,
    /// Episode ends restored from `ends` by this environment.
    end_hits: u64,
}

/// Episode ends already placed. Every episode starts from the same state and places the macros
/// in a fixed order, and both standard-cell placers are deterministic functions of their start
/// (the analytical placer's noise stream is seeded afresh on every call), so the placement at
/// the end of an episode is a function of the cells chosen. A repeated episode restores it
/// instead of running the placer again: the same positions, then the same `recompute` the
/// placers end with, so rewards, infos and the state are bit-identical. This pays wherever
/// placements repeat: the toy's two macros have 9,144 legal placements, and a greedy policy
/// evaluated on a deterministic environment places the same way in every episode.
#[derive(Debug, Default)]
struct EndCache {
    map: std::collections::HashMap<Vec<u32>, Arc<EndState>>,
    /// Approximate bytes held; the cache is emptied when it would exceed `limit`.
    bytes: usize,
    limit: usize,
}

/// What the placer changed: the moved nodes' positions and the placed flags of the macros in
/// placement order.
#[derive(Debug)]
struct EndState {
    moved: Vec<(u32, f64, f64)>,
    placed: Vec<bool>,
}

/// Default byte budget of a private [`EndCache`] (about 1,700 Ariane episode ends).
const END_CACHE_BYTES: usize = 32 << 20;

/// Byte budget of the [`EndCache`] shared by the environments of one start state and placer
/// (about 6,700 Ariane episode ends; the toy's are a few hundred bytes each). It counts in the
/// process's memory, so it stays below what five private caches could hold.
const SHARED_END_CACHE_BYTES: usize = 128 << 20;

/// The shared caches of episode ends, by [`start_fingerprint`]. Weak, so that a cache is freed
/// with the last environment using it.
static SHARED_ENDS: Mutex<BTreeMap<[u64; 2], Weak<Mutex<EndCache>>>> = Mutex::new(BTreeMap::new());

/// Locks `m`, also after a panic elsewhere: every cache operation leaves a valid cache (at
/// worst its byte count is off), and a hit equals a miss bit for bit.
fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    m.lock().unwrap_or_else(PoisonError::into_inner)
}

/// The cache shared by the environments whose start state and end placer have fingerprint
/// `fingerprint`: the vector environments of a run, its evaluation environment and other runs
/// of the same task in the process.
fn shared_end_cache(fingerprint: [u64; 2]) -> Arc<Mutex<EndCache>> {
    let mut registry = lock(&SHARED_ENDS);
    registry.retain(|_, cache| cache.strong_count() > 0);
    if let Some(cache) = registry.get(&fingerprint).and_then(Weak::upgrade) {
        return cache;
    }
    let cache = Arc::new(Mutex::new(EndCache::new(SHARED_END_CACHE_BYTES)));
    registry.insert(fingerprint, Arc::downgrade(&cache));
    cache
}

/// Feeds every write to two hashers started differently: a 128-bit fingerprint from std's
/// 64-bit SipHash (two environments that share a cache by a collision would give wrong ends).
struct Hasher128(DefaultHasher, DefaultHasher);

impl Hasher128 {
    fn new() -> Self {
        let (mut a, mut b) = (DefaultHasher::new(), DefaultHasher::new());
        a.write_u8(1);
        b.write_u8(2);
        Self(a, b)
    }

    fn f64s(&mut self, values: &[f64]) {
        self.write_usize(values.len());
        for v in values {
            self.write_u64(v.to_bits());
        }
    }
}

impl Hasher for Hasher128 {
    fn write(&mut self, bytes: &[u8]) {
        self.0.write(bytes);
        self.1.write(bytes);
    }

    fn finish(&self) -> u64 {
        self.0.finish()
    }
}

/// What an episode's end is a function of, besides the cells chosen: the whole start state of
/// `cost` (the netlist as the cost model holds it, the initial placement after the
/// construction-time placement, orientations, placed and fixed flags, blockages, settings and
/// weights) and every option of `config` (the placer, its schedule or parameters, and the rest,
/// which costs at most a few hits). Computed once, when the environment is built.
fn start_fingerprint(
    netlist: &Netlist,
    cost: &PlacementCost,
    config: &CircuitEnvConfig,
) -> [u64; 2] {
    let mut h = Hasher128::new();
    netlist.content_hash.hash(&mut h);
    // Debug prints every field, floats exactly (shortest round-trip form), and keeps covering
    // the fields added later.
    format!("{config:?}").hash(&mut h);
    format!("{:?} {:?} {:?}", cost.settings, cost.pgrid, cost.cgrid).hash(&mut h);
    for v in [
        &cost.x,
        &cost.y,
        &cost.w,
        &cost.h,
        &cost.net_w,
        &cost.net_cw,
        &cost.pin_ox,
        &cost.pin_oy,
    ] {
        h.f64s(v);
    }
    cost.kind.hash(&mut h);
    cost.orient.hash(&mut h);
    cost.placed.hash(&mut h);
    cost.fixed.hash(&mut h);
    cost.pin_rot.hash(&mut h);
    for v in [
        &cost.net_start,
        &cost.pin_owner,
        &cost.node_pin_start,
        &cost.node_pins,
        &cost.node_net_start,
        &cost.node_nets,
        &cost.area_nodes,
        &cost.hard_macros,
    ] {
        v.hash(&mut h);
    }
    h.f64s(&cost.macro_blockages.concat());
    let blockages: Vec<f64> = cost.blockages.iter().flat_map(|b| b.rect).collect();
    h.f64s(&blockages);
    [h.0.finish(), h.1.finish()]
}

impl EndCache {
    fn new(limit: usize) -> Self {
        Self {
            limit,
            ..Self::default()
        }
    }

    fn insert(&mut self, key: Vec<u32>, state: EndState) {
        let size = key.len() * 4 + state.moved.len() * 24 + state.placed.len() + 64;
        if size > self.limit || self.map.contains_key(&key) {
            // Too big, or placed meanwhile by another environment sharing the cache (the same
            // state: the placers are deterministic).
            return;
        }
        if self.bytes + size > self.limit {
            // Emptied, not evicted one by one: simple, and as deterministic.
            self.map.clear();
            self.bytes = 0;
        }
        self.bytes += size;
        self.map.insert(key, Arc::new(state));
    }
}

fn bad_param(name: &str, reason: impl Into<String>) -> EnvError {
    EnvError::InvalidParameter {
        name: name.into(),
        reason: reason.into(),
    }
}

impl CircuitEnv {
    /// Builds the environment for `netlist` with an optional initial placement.
    pub fn new(
        netlist: &Netlist,
        init: Option<&Placement>,
        mut settings: CostSettings,
        config: CircuitEnvConfig,
    ) -> Result<Self, EnvError> {
        settings.weights = config.weights;
        let mut cost = PlacementCost::new(netlist, settings.clone())
            .map_err(|e| bad_param("settings", e.to_string()))?;
        if let Some(p) = init {
            cost.apply_placement(p)
                .map_err(|e| bad_param("init_placement", e.to_string()))?;
        }
        // circuit_training reads blockages from the first of [netlist, plc] that has any.
        let netlist_blockages = parse_header(&netlist.comments).blockages;
        if !netlist_blockages.is_empty() {
            cost.set_blockages(&netlist_blockages);
        }
        let (cols, rows) = cost.grid();
        if config.padded_action && (cols > PADDED_GRID || rows > PADDED_GRID) {
            return Err(bad_param(
                "padded_action",
                format!("grid {cols}x{rows} exceeds {PADDED_GRID}x{PADDED_GRID}"),
            ));
        }
        let fixed: Vec<bool> = (0..cost.num_nodes()).map(|i| cost.is_fixed(i)).collect();
        let order = placement_order(netlist, &fixed);
        if order.is_empty() {
            return Err(EnvError::BadFile {
                path: netlist.name.clone(),
                reason: "the netlist has no movable hard macro".into(),
            });
        }
        let macros: Vec<usize> = (0..cost.num_nodes())
            .filter(|&i| matches!(cost.kind(i), NodeKind::HardMacro | NodeKind::SoftMacro))
            .collect();
        let mut macro_pos = vec![usize::MAX; cost.num_nodes()];
        for (k, &m) in macros.iter().enumerate() {
            macro_pos[m] = k;
        }
        let (cw, ch) = (settings.canvas_width, settings.canvas_height);
        let norm = cw + ch;
        // Static graph features.
        let m = macros.len();
        // Node positions are int32 tensors (as A2Perf's), so they must fit one.
        if i32::try_from(m).is_err() {
            return Err(EnvError::BadFile {
                path: netlist.name.clone(),
                reason: format!("{m} macros do not fit the int32 node indices of the observation"),
            });
        }
        let node_types: Vec<i32> = macros
            .iter()
            .map(|&i| {
                if cost.kind(i) == NodeKind::HardMacro {
                    NODE_TYPE_HARD
                } else {
                    NODE_TYPE_SOFT
                }
            })
            .collect();
        let (mw, mh): (Vec<f32>, Vec<f32>) = macros
            .iter()
            .map(|&i| {
                if cost.kind(i) == NodeKind::HardMacro {
                    let (w, h) = cost.size(i);
                    ((w / norm) as f32, (h / norm) as f32)
                } else {
                    (0.0, 0.0)
                }
            })
            .unzip();
        let mut adj: BTreeMap<(usize, usize), f64> = BTreeMap::new();
        let owner = |p: usize| -> Option<usize> {
            let n = &netlist.nodes[p];
            let o = if n.kind.is_pin() { n.macro_index? } else { p };
            (macro_pos[o] != usize::MAX).then_some(macro_pos[o])
        };
        for net in &netlist.nets {
            let Some(d) = owner(net.driver) else { continue };
            for &s in &net.sinks {
                if let Some(t) = owner(s)
                    && t != d
                {
                    *adj.entry((d.min(t), d.max(t))).or_insert(0.0) += net.weight;
                }
            }
        }
        let mean = if adj.is_empty() {
            1.0
        } else {
            adj.values().sum::<f64>() / adj.len() as f64
        } + ADJACENCY_EPSILON;
        let e = adj.len();
        let last_node = m.saturating_sub(1) as f64;
        let index_box = |len: usize| Space::uniform_box_of(&[len], DType::I32, 0.0, last_node);
        // (tensor, its box) of the features that do not change during an episode; the
        // integer ones are int32 as in A2Perf's observation config.
        let static_tensors: Vec<(Tensor, Space)> = vec![
            (
                Tensor::new("node_types", &[m], node_types),
                Space::uniform_box_of(&[m], DType::I32, 0.0, f64::from(NODE_TYPE_PORT_CLUSTER)),
            ),
            (
                Tensor::new("macros_w", &[m], mw),
                Space::uniform_box(&[m], 0.0, f32::INFINITY),
            ),
            (
                Tensor::new("macros_h", &[m], mh),
                Space::uniform_box(&[m], 0.0, f32::INFINITY),
            ),
            (
                Tensor::new(
                    "sparse_adj_i",
                    &[e],
                    adj.keys().map(|k| k.0 as i32).collect::<Vec<_>>(),
                ),
                index_box(e),
            ),
            (
                Tensor::new(
                    "sparse_adj_j",
                    &[e],
                    adj.keys().map(|k| k.1 as i32).collect::<Vec<_>>(),
                ),
                index_box(e),
            ),
            (
                Tensor::new(
                    "sparse_adj_weight",
                    &[e],
                    adj.values().map(|w| (w / mean) as f32).collect::<Vec<_>>(),
                ),
                Space::uniform_box(&[e], 0.0, f32::INFINITY),
            ),
        ];
        let n_actions = if config.padded_action {
            PADDED_GRID * PADDED_GRID
        } else {
            cols * rows
        };
        let mut dict = vec![
            (
                "features".to_string(),
                Space::uniform_box(&[FEATURE_DIM], 0.0, f32::INFINITY),
            ),
            (
                "grid".to_string(),
                Space::uniform_box(&[GRID_CHANNELS, rows, cols], 0.0, f32::INFINITY),
            ),
            (
                "locations_x".to_string(),
                Space::uniform_box(&[m], 0.0, 1.0),
            ),
            (
                "locations_y".to_string(),
                Space::uniform_box(&[m], 0.0, 1.0),
            ),
            (
                "is_node_placed".to_string(),
                Space::uniform_box_of(&[m], DType::I32, 0.0, 1.0),
            ),
            ("current_node".to_string(), index_box(1)),
        ];
        for (t, space) in &static_tensors {
            dict.push((t.name.clone(), space.clone()));
        }
        let static_tensors: Vec<Tensor> = static_tensors.into_iter().map(|(t, _)| t).collect();
        let mut metadata = BTreeMap::new();
        metadata.insert("netlist".into(), netlist.name.clone());
        metadata.insert("netlist_hash".into(), netlist.content_hash.clone());
        metadata.insert("grid".into(), format!("{cols}x{rows}"));
        metadata.insert("canvas".into(), format!("{cw}x{ch}"));
        metadata.insert("hard_macros".into(), order.len().to_string());
        metadata.insert(
            "cost_settings".into(),
            serde_json::to_string(&settings).unwrap_or_default(),
        );
        metadata.insert(
            "std_cell_placer".into(),
            match config.std_cell_placer {
                StdCellPlacer::Fd => "a2perf-circuit force-directed (ours), CT schedule".into(),
                StdCellPlacer::DreamPlace => format!(
                    "a2perf-circuit analytical (ours), CT DREAMPlace parameters: {}",
                    serde_json::to_string(&config.analytical).unwrap_or_default()
                ),
                StdCellPlacer::None => "none".into(),
            },
        );
        metadata.insert(
            "infeasible_reward".into(),
            config.infeasible_reward.to_string(),
        );
        metadata.insert(
            "infeasible_auto_reset".into(),
            config.infeasible_auto_reset.to_string(),
        );
        metadata.insert(
            "soft_macros_placed".into(),
            config.soft_macros_placed.to_string(),
        );
        metadata.insert(
            "initial_locations".into(),
            config.initial_locations.name().into(),
        );
        metadata.insert(
            "congestion_grid".into(),
            match settings.congestion_grid {
                None => "legacy".into(),
                Some((c, r)) => format!("{c}x{r}"),
            },
        );
        metadata.insert(
            "action_layout".into(),
            if config.padded_action {
                "padded128".into()
            } else {
                "grid".into()
            },
        );
        let spec = EnvSpec {
            id: config.id.clone(),
            observation_space: Space::Dict(dict),
            action_space: Space::Discrete { n: n_actions },
            max_episode_steps: Some(order.len()),
            metadata,
        };
        let n = cost.num_nodes();
        let (ccols, crows) = cost.congestion_grid();
        let fm = FEATURE_MAP;
        let mut cell_ccell = Vec::with_capacity(cols * rows);
        let mut cell_block = Vec::with_capacity(cols * rows);
        let mut block_counts = [0u32; FEATURE_MAP * FEATURE_MAP];
        for cell in 0..cols * rows {
            let (r, c) = (cell / cols, cell % cols);
            let cr = (r * crows / rows).min(crows - 1);
            let cc = (c * ccols / cols).min(ccols - 1);
            cell_ccell.push((cr * ccols + cc) as u32);
            let b = (r * fm / rows) * fm + c * fm / cols;
            cell_block.push(b as u16);
            block_counts[b] += 1;
        }
        let mut fd = FdScratch::default();
        let mut analytical = AnalyticalScratch::default();
        if config.std_cell_placer == StdCellPlacer::DreamPlace {
            check_capacity(&cost, config.analytical.target_density).map_err(|e| {
                EnvError::BadFile {
                    path: netlist.name.clone(),
                    reason: e.to_string(),
                }
            })?;
        }
        if config.initial_locations == InitialLocations::MixedSizeFd {
            // circuit_training runs its end-of-episode placer once in mixed-size mode.
            if config.std_cell_placer == StdCellPlacer::DreamPlace {
                place_analytical(
                    &mut cost,
                    &config.analytical,
                    MovableMacros::All,
                    &mut analytical,
                )
                .map_err(|e| bad_param("std_cell_placer", e.to_string()))?;
            } else {
                place_std_cells(&mut cost, &FdSchedule::mixed_size(), &mut fd);
            }
        }
        let base_x = (0..n).map(|i| cost.position(i).0).collect();
        let base_y = (0..n).map(|i| cost.position(i).1).collect();
        let ends = shared_end_cache(start_fingerprint(netlist, &cost, &config));
        Ok(Self {
            spec,
            config,
            base_x,
            base_y,
            mask: vec![false; cols * rows],
            cost,
            order,
            macros,
            macro_pos,
            current: 0,
            needs_reset: true,
            fd,
            analytical,
            static_tensors,
            dens: Vec::new(),
            xcost: vec![0.0; cols],
            ycost: vec![0.0; rows],
            cell_ccell,
            cell_block,
            block_counts,
            cells: Vec::new(),
            ends: Some(ends),
            ends_shared: true,
            end_hits: 0,
        })
    }

    /// The cost model (current placement).
    pub fn cost(&self) -> &PlacementCost {
        &self.cost
    }

    /// Mutable cost model (e.g. to query congestion maps). Detaches this environment from the
    /// cache of episode ends it shares with others (it gets an empty private one), since the
    /// caller may change what the ends depend on; the other environments keep theirs.
    pub fn cost_mut(&mut self) -> &mut PlacementCost {
        if let Some(ends) = &self.ends {
            let limit = if self.ends_shared {
                END_CACHE_BYTES
            } else {
                lock(ends).limit
            };
            self.set_end_cache_bytes(limit);
        }
        &mut self.cost
    }

    /// Gives this environment a private cache of placed episode ends of `bytes` (0 turns its
    /// cache off), instead of the one it shares with the environments of the same start state
    /// and placer. Results do not depend on it, only the time the end of a repeated episode
    /// takes.
    ///
    /// ```
    /// use a2perf_circuit::{generate, CircuitEnv, CircuitEnvConfig, GeneratorConfig};
    /// use a2perf_core::{Action, Env};
    /// let g = generate(&GeneratorConfig::small(), 0);
    /// let new_env = || CircuitEnv::new(&g.netlist, Some(&g.placement), g.settings.clone(),
    ///                                  CircuitEnvConfig::default()).unwrap();
    /// let episode = |env: &mut CircuitEnv| {
    ///     let mut obs = env.reset(Some(0)).unwrap();
    ///     loop {
    ///         let a = obs.action_mask.clone().unwrap().iter().position(|m| *m).unwrap();
    ///         let step = env.step(&Action::Discrete(a)).unwrap();
    ///         if step.done() { return step.reward; }
    ///         obs = step.observation.clone();
    ///     }
    /// };
    /// let (mut env, mut other) = (new_env(), new_env());
    /// let first = episode(&mut env);
    /// assert!(env.end_cache_len() >= 1);
    /// // The same start state and placer: `other` restores the end `env` placed.
    /// assert_eq!(episode(&mut other).to_bits(), first.to_bits());
    /// assert_eq!(other.end_cache_hits(), 1);
    /// env.set_end_cache_bytes(0);
    /// assert_eq!(episode(&mut env).to_bits(), first.to_bits()); // placed again
    /// assert_eq!((env.end_cache_len(), env.end_cache_hits()), (0, 0));
    /// ```
    pub fn set_end_cache_bytes(&mut self, bytes: usize) {
        self.ends = (bytes > 0).then(|| Arc::new(Mutex::new(EndCache::new(bytes))));
        self.ends_shared = false;
    }

    /// Number of episode ends in this environment's cache (shared or private).
    pub fn end_cache_len(&self) -> usize {
        self.ends.as_ref().map_or(0, |ends| lock(ends).map.len())
    }

    /// Episode ends this environment restored from its cache instead of placing them.
    pub fn end_cache_hits(&self) -> u64 {
        self.end_hits
    }

    /// Runs the end-of-episode placer (`macros` as the placer takes them), or restores its
    /// result when these cells were placed before (by this environment or one sharing its
    /// cache). The lock is held for the lookup and the insertion only, never while placing.
    fn place_end(&mut self, macros: MovableMacros) -> Result<(), EnvError> {
        if self.config.std_cell_placer == StdCellPlacer::None {
            // Nothing to place, so nothing is cached: no lock, no lookup.
            return Ok(());
        }
        let hit = self
            .ends
            .as_ref()
            .and_then(|ends| lock(ends).map.get(&self.cells).cloned());
        if let Some(state) = hit {
            for &(i, x, y) in &state.moved {
                self.cost.x[i as usize] = x;
                self.cost.y[i as usize] = y;
            }
            for (&i, &p) in self.order.iter().zip(&state.placed) {
                self.cost.placed[i] = p;
            }
            self.cost.recompute();
            self.end_hits += 1;
            return Ok(());
        }
        match self.config.std_cell_placer {
            StdCellPlacer::Fd => {
                place_std_cells(&mut self.cost, &self.config.fd_schedule, &mut self.fd);
            }
            StdCellPlacer::DreamPlace => self.place_analytically(macros)?,
            StdCellPlacer::None => return Ok(()),
        }
        if let Some(ends) = &self.ends {
            let moved = (0..self.base_x.len())
                .filter(|&i| {
                    self.cost.x[i].to_bits() != self.base_x[i].to_bits()
                        || self.cost.y[i].to_bits() != self.base_y[i].to_bits()
                })
                .map(|i| (i as u32, self.cost.x[i], self.cost.y[i]))
                .collect();
            let placed = self.order.iter().map(|&i| self.cost.placed[i]).collect();
            lock(ends).insert(self.cells.clone(), EndState { moved, placed });
        }
        Ok(())
    }

    /// Hard macros in placement order.
    pub fn order(&self) -> &[usize] {
        &self.order
    }

    /// Converts an action to a placement-grid cell (None when it falls in the padding).
    pub fn action_to_cell(&self, a: usize) -> Option<usize> {
        let (cols, rows) = self.cost.grid();
        if self.config.padded_action {
            padded_action_to_cell(a, cols, rows)
        } else {
            (a < cols * rows).then_some(a)
        }
    }

    /// Converts a placement-grid cell to an action.
    pub fn cell_to_action(&self, cell: usize) -> usize {
        let (cols, rows) = self.cost.grid();
        if self.config.padded_action {
            cell_to_padded_action(cell, cols, rows)
        } else {
            cell
        }
    }

    /// Runs the analytical placer on the current placement.
    fn place_analytically(&mut self, macros: MovableMacros) -> Result<(), EnvError> {
        place_analytical(
            &mut self.cost,
            &self.config.analytical,
            macros,
            &mut self.analytical,
        )
        .map(|_| ())
        .map_err(|e| EnvError::Backend(format!("analytical placer: {e}")))
    }

    /// The terminal reward and info of a placement whose cost is computed.
    fn finish(&mut self, out: &mut Step, infeasible: bool) {
        let c = self.cost.costs();
        out.reward = -c.proxy_cost;
        out.terminated = true;
        out.info.set("wirelength", c.wirelength_cost);
        out.info.set("density", c.density_cost);
        out.info.set("congestion", c.congestion_cost);
        out.info.set("proxy", c.proxy_cost);
        out.info.set("wirelength_hpwl", c.wirelength);
        out.info
            .set("infeasible", if infeasible { 1.0 } else { 0.0 });
    }

    /// Puts every macro to place back at its initial location, unplaced, at the first step.
    fn restart(&mut self) {
        self.cost.x.copy_from_slice(&self.base_x);
        self.cost.y.copy_from_slice(&self.base_y);
        for &i in &self.order {
            self.cost.placed[i] = false;
        }
        self.cost.recompute();
        self.cells.clear();
        self.current = 0;
        self.needs_reset = false;
    }

    fn write_obs(&mut self, obs: &mut Observation) {
        let (cols, rows) = self.cost.grid();
        let g = cols * rows;
        let done = self.current >= self.order.len();
        // Mask.
        if done {
            self.mask.iter_mut().for_each(|m| *m = false);
        } else {
            let node = self.order[self.current];
            self.cost.node_mask(node, &mut self.mask);
        }
        let n_actions = match self.spec.action_space {
            Space::Discrete { n } => n,
            _ => g,
        };
        let am = obs.action_mask.get_or_insert_with(Vec::new);
        am.clear();
        am.resize(n_actions, false);
        for (cell, &legal) in self.mask.iter().enumerate() {
            if legal {
                let a = if self.config.padded_action {
                    cell_to_padded_action(cell, cols, rows)
                } else {
                    cell
                };
                am[a] = true;
            }
        }
        let legal_count = self.mask.iter().filter(|m| **m).count();
        // Tensor slots.
        let m = self.macros.len();
        let names_shapes: [(&str, usize, DType); 6] = [
            ("features", FEATURE_DIM, DType::F32),
            ("grid", GRID_CHANNELS * g, DType::F32),
            ("locations_x", m, DType::F32),
            ("locations_y", m, DType::F32),
            ("is_node_placed", m, DType::I32),
            ("current_node", 1, DType::I32),
        ];
        let total = names_shapes.len() + self.static_tensors.len();
        obs.tensors.truncate(total);
        for (k, (name, len, dtype)) in names_shapes.iter().enumerate() {
            let shape: &[usize] = if *name == "grid" {
                &[GRID_CHANNELS, rows, cols]
            } else {
                &[*len]
            };
            if let Some(t) = obs.tensors.get_mut(k) {
                t.reset_zeroed(name, shape, *dtype);
            } else {
                obs.tensors.push(Tensor::zeros_of(name, shape, *dtype));
            }
        }
        for (k, st) in self.static_tensors.iter().enumerate() {
            let idx = names_shapes.len() + k;
            if let Some(t) = obs.tensors.get_mut(idx) {
                // Copying is cheaper than comparing the data element by element.
                t.copy_from(st);
            } else {
                obs.tensors.push(st.clone());
            }
        }
        let [features, grid, loc_x, loc_y, placed_t, current_t, ..] = &mut obs.tensors[..] else {
            return;
        };
        // The slots were just given these types, so the typed views exist.
        let (Some(feat), Some(grid_t), Some(loc_x), Some(loc_y), Some(placed_t), Some(current_t)) = (
            features.data.as_f32_mut(),
            grid.data.as_f32_mut(),
            loc_x.data.as_f32_mut(),
            loc_y.data.as_f32_mut(),
            placed_t.data.as_i32_mut(),
            current_t.data.as_i32_mut(),
        ) else {
            return;
        };
        // Density and congestion per cell (congestion on the congestion grid mapped by centre).
        self.cost.density_cells(&mut self.dens);
        let (cw, ch) = {
            let s = self.cost.settings();
            (s.canvas_width, s.canvas_height)
        };
        let (hmap, vmap) = self.cost.congestion_maps();
        for cell in 0..g {
            let ci = self.cell_ccell[cell] as usize;
            grid_t[cell] = self.dens[cell] as f32;
            grid_t[g + cell] = ((hmap[ci] + vmap[ci]) / 2.0) as f32;
            grid_t[2 * g + cell] = if self.mask[cell] { 1.0 } else { 0.0 };
        }
        // Wirelength hint.
        if !done {
            self.wl_hint(self.order[self.current], cw, ch);
            let mut max = 0.0f64;
            for r in 0..rows {
                for c in 0..cols {
                    max = max.max(self.xcost[c] + self.ycost[r]);
                }
            }
            for r in 0..rows {
                for c in 0..cols {
                    let v = self.xcost[c] + self.ycost[r];
                    grid_t[3 * g + r * cols + c] = if max > 0.0 {
                        (1.0 - v / max) as f32
                    } else {
                        1.0
                    };
                }
            }
        }
        // Features.
        let placed = self.current.min(self.order.len());
        if !done {
            let (w, h) = self.cost.size(self.order[self.current]);
            feat[0] = (w / cw) as f32;
            feat[1] = (h / ch) as f32;
            feat[4] = (w * h / (cw * ch)) as f32;
        }
        feat[2] = placed as f32 / self.order.len() as f32;
        feat[3] = legal_count as f32 / g as f32;
        let remaining: f64 = self.order[placed..]
            .iter()
            .map(|&i| {
                let (w, h) = self.cost.size(i);
                w * h
            })
            .sum();
        feat[5] = (remaining / (cw * ch)) as f32;
        let fm = FEATURE_MAP;
        let counts = &self.block_counts;
        let grid_ref = &*grid_t;
        let mut dmap = [0f32; FEATURE_MAP * FEATURE_MAP];
        let mut cmap = [0f32; FEATURE_MAP * FEATURE_MAP];
        for cell in 0..g {
            let b = self.cell_block[cell] as usize;
            dmap[b] += grid_ref[cell];
            cmap[b] += grid_ref[g + cell];
        }
        for b in 0..fm * fm {
            let n = counts[b].max(1) as f32;
            feat[6 + b] = dmap[b] / n;
            feat[6 + fm * fm + b] = cmap[b] / n;
        }
        // Dynamic A2Perf features.
        let norm = cw + ch;
        for (k, &i) in self.macros.iter().enumerate() {
            // A2Perf marks a soft macro placed only if it is fixed and never updates its location
            // (the end-of-episode placer moves it after the last observation it would update).
            let (placed, (x, y)) = match self.cost.kind(i) {
                NodeKind::SoftMacro if self.config.soft_macros_placed => {
                    (true, self.cost.position(i))
                }
                NodeKind::SoftMacro => (self.cost.is_fixed(i), (self.base_x[i], self.base_y[i])),
                _ => (self.cost.is_placed(i), self.cost.position(i)),
            };
            loc_x[k] = (x / norm) as f32;
            loc_y[k] = (y / norm) as f32;
            placed_t[k] = i32::from(placed);
        }
        // Positions fit int32: checked when the environment was built.
        current_t[0] = if done {
            0
        } else {
            self.macro_pos[self.order[self.current]] as i32
        };
    }

    /// Per-column / per-row HPWL increase of node's nets if its centre moved there.
    fn wl_hint(&mut self, node: usize, cw: f64, ch: f64) {
        let (cols, rows) = self.cost.grid();
        self.xcost.iter_mut().for_each(|v| *v = 0.0);
        self.ycost.iter_mut().for_each(|v| *v = 0.0);
        let c = &self.cost;
        let (gw, gh) = (cw / cols as f64, ch / rows as f64);
        for k in c.node_net_start[node] as usize..c.node_net_start[node + 1] as usize {
            let net = c.node_nets[k] as usize;
            let (mut x0, mut x1, mut y0, mut y1) = (
                f64::INFINITY,
                f64::NEG_INFINITY,
                f64::INFINITY,
                f64::NEG_INFINITY,
            );
            for p in c.net_start[net] as usize..c.net_start[net + 1] as usize {
                let o = c.pin_owner[p] as usize;
                if o == node || (c.kind[o] == NodeKind::HardMacro && !c.placed[o]) {
                    continue;
                }
                x0 = x0.min(c.pin_x[p]);
                x1 = x1.max(c.pin_x[p]);
                y0 = y0.min(c.pin_y[p]);
                y1 = y1.max(c.pin_y[p]);
            }
            if !x0.is_finite() {
                continue;
            }
            let w = c.net_w[net];
            for col in 0..cols {
                let x = (col as f64 + 0.5) * gw;
                self.xcost[col] += w * (x0 - x).max(x - x1).max(0.0);
            }
            for row in 0..rows {
                let y = (row as f64 + 0.5) * gh;
                self.ycost[row] += w * (y0 - y).max(y - y1).max(0.0);
            }
        }
    }
}

impl Env for CircuitEnv {
    fn spec(&self) -> &EnvSpec {
        &self.spec
    }

    fn reset_into(&mut self, _seed: Option<u64>, obs: &mut Observation) -> Result<(), EnvError> {
        // Deterministic: the episode does not depend on the seed (the node order is fixed).
        self.restart();
        self.write_obs(obs);
        Ok(())
    }

    fn step_into(&mut self, action: &Action, out: &mut Step) -> Result<(), EnvError> {
        if self.needs_reset || self.current >= self.order.len() {
            return Err(EnvError::NeedsReset);
        }
        let Action::Discrete(a) = *action else {
            return Err(EnvError::InvalidAction {
                action: action.clone(),
                reason: "expected a discrete action".into(),
            });
        };
        let Some(cell) = self.action_to_cell(a) else {
            return Err(EnvError::InvalidAction {
                action: action.clone(),
                reason: "outside the placement grid".into(),
            });
        };
        if !self.mask[cell] {
            return Err(EnvError::InvalidAction {
                action: action.clone(),
                reason: "cell is masked (overlap or outside the canvas)".into(),
            });
        }
        let node = self.order[self.current];
        self.cost.place_at_cell(node, cell);
        self.cells.push(cell as u32);
        self.current += 1;
        out.info.clear();
        out.truncated = false;
        if self.current == self.order.len() {
            self.place_end(MovableMacros::None)?;
            self.finish(out, false);
            self.needs_reset = true;
            self.write_obs(&mut out.observation);
            return Ok(());
        }
        self.write_obs(&mut out.observation);
        if self.mask.iter().any(|m| *m) {
            out.reward = -0.0;
            out.terminated = false;
        } else if self.config.std_cell_placer == StdCellPlacer::DreamPlace {
            // circuit_training's DREAMPlace mode: the remaining hard macros are placed with
            // the soft macros and standard cells (mixed-size), and the real cost is the reward.
            self.place_end(MovableMacros::Unplaced)?;
            self.finish(out, true);
            self.current = self.order.len();
            if self.config.infeasible_auto_reset {
                out.truncated = true;
                self.restart();
            } else {
                self.needs_reset = true;
            }
            self.write_obs(&mut out.observation);
        } else {
            out.reward = self.config.infeasible_reward;
            out.terminated = true;
            out.info.set("infeasible", 1.0);
            out.info.set("wirelength", -1.0);
            out.info.set("density", -1.0);
            out.info.set("congestion", -1.0);
            if self.config.infeasible_auto_reset {
                // A2Perf's fork: `obs, _ = self.reset(); return obs, -1.0, True, True, info`.
                out.truncated = true;
                self.restart();
                self.write_obs(&mut out.observation);
            } else {
                self.needs_reset = true;
            }
        }
        Ok(())
    }

    fn render_modes(&self) -> &'static [&'static str] {
        &["rgb_array", "svg"]
    }

    /// `"rgb_array"`: [`render_rgb`] of the current placement; `"svg"`: [`render_svg`] of it,
    /// titled with the netlist's name (see the module documentation).
    fn render(&mut self, mode: &str) -> Result<Frame, EnvError> {
        match mode {
            "rgb_array" => Ok(render_rgb(&mut self.cost, RGB_SIZE)),
            "svg" => {
                let title = self
                    .spec
                    .metadata
                    .get("netlist")
                    .cloned()
                    .unwrap_or_default();
                Ok(Frame::Text(render_svg(&mut self.cost, &title, SVG_SIZE)))
            }
            other => Err(EnvError::unsupported_render_mode(
                other,
                self.render_modes(),
            )),
        }
    }
}

fn common_params() -> Vec<ParamSpec> {
    vec![
        ParamSpec::new(
            "padded_action",
            ParamKind::Bool,
            Value::Bool(false),
            "A2Perf's padded 128x128 action space (Discrete(16384), grid centred, padding always masked); false = one action per grid cell",
        ),
        ParamSpec::new(
            "std_cell_placer",
            ParamKind::Choice(&["fd", "dreamplace", "none"]),
            Value::Str("fd".into()),
            "standard-cell placement at episode end: fd = our force-directed placer with circuit_training's schedule (the original's default); dreamplace = our analytical placer with circuit_training's DREAMPlace parameters (A2Perf's baselines), which also places the remaining hard macros when one is left without a legal cell (the episode then ends with the real cost, infeasible_reward unused) and runs the mixed-size placement at construction; none = no placement",
        ),
        ParamSpec::new(
            "wirelength_weight",
            ParamKind::Float,
            Value::Float(1.0),
            "proxy weight of the wirelength cost",
        ),
        ParamSpec::new(
            "density_weight",
            ParamKind::Float,
            Value::Float(1.0),
            "proxy weight of the density cost",
        ),
        ParamSpec::new(
            "congestion_weight",
            ParamKind::Float,
            Value::Float(0.5),
            "proxy weight of the congestion cost",
        ),
        ParamSpec::new(
            "infeasible_reward",
            ParamKind::Float,
            Value::Float(INFEASIBLE_REWARD),
            "reward when a macro has no legal cell left (A2Perf's fork: -1.0, better than most feasible placements)",
        ),
        ParamSpec::new(
            "infeasible_auto_reset",
            ParamKind::Bool,
            Value::Bool(false),
            "when a macro is left without a legal cell, return the reset observation with terminated and truncated both set and leave the env reset (A2Perf's fork: true; false = the stranded state, terminated only)",
        ),
        ParamSpec::new(
            "initial_locations",
            ParamKind::Choice(&["fd", "plc"]),
            Value::Str("fd".into()),
            "initial node locations: fd = mixed-size force-directed run at construction (as A2Perf; our placer), plc = the .plc / generator placement",
        ),
        ParamSpec::new(
            "soft_macros_placed",
            ParamKind::Bool,
            Value::Bool(false),
            "report soft macros as placed at their current location in is_node_placed/locations (false = as A2Perf: unplaced unless fixed, at their initial location)",
        ),
        ParamSpec::new(
            "smooth_range",
            ParamKind::Float,
            Value::Null,
            "congestion smoothing range (default 5, CT)",
        ),
        ParamSpec::new(
            "grid_cols",
            ParamKind::Int,
            Value::Null,
            "override placement grid columns",
        ),
        ParamSpec::new(
            "grid_rows",
            ParamKind::Int,
            Value::Null,
            "override placement grid rows",
        ),
        ParamSpec::new(
            "congestion_grid",
            ParamKind::Choice(&["legacy", "ct"]),
            Value::Str("legacy".into()),
            "congestion grid: legacy = the placement grid (Google's computation, verified); ct = A2Perf's separate grid of 2000/(70.33+74.51) um cells (its use by the closed binary assumed: the same routing model on that grid)",
        ),
    ]
}

fn config_from(
    id: &str,
    p: &Params,
    settings: &mut CostSettings,
) -> Result<CircuitEnvConfig, EnvError> {
    let perr = |e: a2perf_core::ParamError| bad_param("params", e.to_string());
    let weights = CostWeights {
        wirelength: p.f64("wirelength_weight").map_err(perr)?,
        density: p.f64("density_weight").map_err(perr)?,
        congestion: p.f64("congestion_weight").map_err(perr)?,
    };
    if let Some(v) = p.get("smooth_range") {
        settings.smooth_range = v
            .as_f64()
            .ok_or_else(|| bad_param("smooth_range", "expected a number"))?;
    }
    for (key, slot) in [
        ("grid_cols", &mut settings.grid_cols),
        ("grid_rows", &mut settings.grid_rows),
    ] {
        if p.get(key).is_some() {
            let v = p.usize(key).map_err(perr)?;
            if v == 0 || v > PADDED_GRID {
                return Err(bad_param(key, format!("must be in 1..={PADDED_GRID}")));
            }
            *slot = v;
        }
    }
    if p.str("congestion_grid").map_err(perr)? == "ct" {
        settings.congestion_grid = Some(settings.ct_congestion_grid());
    }
    Ok(CircuitEnvConfig {
        id: id.to_string(),
        padded_action: p.bool("padded_action").map_err(perr)?,
        std_cell_placer: match p.str("std_cell_placer").map_err(perr)? {
            "dreamplace" => StdCellPlacer::DreamPlace,
            "none" => StdCellPlacer::None,
            _ => StdCellPlacer::Fd,
        },
        fd_schedule: FdSchedule::default(),
        analytical: AnalyticalParams::circuit_training(),
        weights,
        infeasible_reward: infeasible_reward(p)?,
        infeasible_auto_reset: p.bool("infeasible_auto_reset").map_err(perr)?,
        soft_macros_placed: p.bool("soft_macros_placed").map_err(perr)?,
        initial_locations: match p.str("initial_locations").map_err(perr)? {
            "plc" => InitialLocations::Plc,
            _ => InitialLocations::MixedSizeFd,
        },
    })
}

fn infeasible_reward(p: &Params) -> Result<f64, EnvError> {
    let r = p
        .f64("infeasible_reward")
        .map_err(|e| bad_param("infeasible_reward", e.to_string()))?;
    if !r.is_finite() || r > 0.0 {
        return Err(bad_param(
            "infeasible_reward",
            format!("must be a finite value <= 0, found {r}"),
        ));
    }
    Ok(r)
}

fn file_env(id: &str, p: &Params) -> Result<Box<dyn Env>, EnvError> {
    let path = p
        .opt_str("netlist_file")
        .map_err(|e| bad_param("netlist_file", e.to_string()))?;
    let Some(path) = path else {
        return Err(bad_param(
            "netlist_file",
            "required: path to a circuit_training netlist.pb.txt (e.g. test_data/toy_macro_stdcell/netlist.pb.txt)",
        ));
    };
    let netlist =
        Netlist::from_file(path, SoftMacroRule::default()).map_err(|e| EnvError::BadFile {
            path: path.to_string(),
            reason: e.to_string(),
        })?;
    let init = match p
        .opt_str("init_placement")
        .map_err(|e| bad_param("init_placement", e.to_string()))?
    {
        Some(f) => Some(Placement::from_file(f).map_err(|e| EnvError::BadFile {
            path: f.to_string(),
            reason: e.to_string(),
        })?),
        None => {
            // CT convention: initial.plc next to the netlist.
            let guess = Path::new(path).with_file_name("initial.plc");
            if guess.exists() {
                Some(Placement::from_file(&guess).map_err(|e| EnvError::BadFile {
                    path: guess.display().to_string(),
                    reason: e.to_string(),
                })?)
            } else {
                None
            }
        }
    };
    // A canvas the files state but that is not a positive finite rectangle is an error naming
    // the file (circuit_training would silently fall back to another canvas).
    let init_path = p.opt_str("init_placement").ok().flatten().map_or_else(
        || {
            Path::new(path)
                .with_file_name("initial.plc")
                .display()
                .to_string()
        },
        str::to_string,
    );
    for (file, comments) in [(path.to_string(), &netlist.comments)]
        .into_iter()
        .chain(init.as_ref().map(|i| (init_path, &i.comments)))
    {
        if let Some(reason) = crate::plc::canvas_problem(comments) {
            return Err(EnvError::BadFile { path: file, reason });
        }
    }
    let mut settings = CostSettings::ct_env(&netlist, init.as_ref().map(|p| &p.header));
    let config = config_from(id, p, &mut settings)?;
    // Errors about the netlist's contents name the file it came from.
    let env = CircuitEnv::new(&netlist, init.as_ref(), settings, config).map_err(|e| match e {
        EnvError::BadFile { reason, .. } => EnvError::BadFile {
            path: path.to_string(),
            reason,
        },
        EnvError::InvalidParameter { name, reason } if name == "settings" => EnvError::BadFile {
            path: path.to_string(),
            reason: format!("settings from the netlist and placement: {reason}"),
        },
        other => other,
    })?;
    Ok(Box::new(env))
}

fn synthetic_env(
    id: &str,
    generator: &GeneratorConfig,
    p: &Params,
) -> Result<Box<dyn Env>, EnvError> {
    let seed = p
        .u64("netlist_seed")
        .map_err(|e| bad_param("netlist_seed", e.to_string()))?;
    let g = generate(generator, seed);
    let mut settings = g.settings.clone();
    let config = config_from(id, p, &mut settings)?;
    let mut env = CircuitEnv::new(&g.netlist, Some(&g.placement), settings, config)?;
    env.spec
        .metadata
        .insert("netlist_seed".into(), seed.to_string());
    env.spec.metadata.insert(
        "generator".into(),
        serde_json::to_string(generator).unwrap_or_default(),
    );
    Ok(Box::new(env))
}

/// Registers the `CircuitTraining-*` environments and the circuit generalization suite.
///
/// ```
/// let mut reg = a2perf_core::Registry::new();
/// a2perf_circuit::register(&mut reg);
/// let mut env = reg.make_env("CircuitTraining-Synthetic-Small-v0", &Default::default()).unwrap();
/// let obs = env.reset(Some(0)).unwrap();
/// assert!(obs.tensor("features").is_some());
/// assert!(!reg.generalization("circuit_training").is_empty());
/// ```
pub fn register(reg: &mut Registry) {
    for (id, summary) in [
        (
            "CircuitTraining-ToyMacro-v0",
            "CT toy macro/stdcell netlist (needs netlist_file)",
        ),
        (
            "CircuitTraining-Ariane-v0",
            "CT Ariane RISC-V, 133 hard macros (needs netlist_file)",
        ),
    ] {
        let mut params = vec![
            ParamSpec::new(
                "netlist_file",
                ParamKind::Path,
                Value::Null,
                "circuit_training netlist.pb.txt (plain or .gz)",
            ),
            ParamSpec::new(
                "init_placement",
                ParamKind::Path,
                Value::Null,
                "initial .plc (default: initial.plc next to the netlist)",
            ),
        ];
        params.extend(common_params());
        let idc = id.to_string();
        reg.register_env(EnvEntry {
            id: id.into(),
            domain: "circuit_training".into(),
            summary: summary.into(),
            params,
            make: Arc::new(move |p: &Params| file_env(&idc, p)),
        });
    }
    for (id, summary, generator) in [
        (
            "CircuitTraining-Synthetic-Small-v0",
            "generated circuit, 12 hard macros, 16x16 grid (no files)",
            GeneratorConfig::small(),
        ),
        (
            "CircuitTraining-Synthetic-Medium-v0",
            "generated circuit, 32 hard macros, 24x20 grid (no files)",
            GeneratorConfig::medium(),
        ),
        (
            "CircuitTraining-Synthetic-Ariane-v0",
            "generated Ariane-scale circuit, 133 hard macros, 35x33 grid (no files)",
            GeneratorConfig::ariane_scale(),
        ),
    ] {
        let mut params = vec![ParamSpec::new(
            "netlist_seed",
            ParamKind::Int,
            Value::Int(0),
            "seed of the generated netlist",
        )];
        params.extend(common_params());
        let idc = id.to_string();
        reg.register_env(EnvEntry {
            id: id.into(),
            domain: "circuit_training".into(),
            summary: summary.into(),
            params,
            make: Arc::new(move |p: &Params| synthetic_env(&idc, &generator, p)),
        });
    }
    let task = |name: &str, id: &str, seed: i64| {
        let mut params = BTreeMap::new();
        params.insert("netlist_seed".to_string(), Value::Int(seed));
        TaskRef {
            name: name.into(),
            env_id: id.into(),
            params,
        }
    };
    reg.register_generalization(
        "circuit_training",
        vec![
            task("small_seed1", "CircuitTraining-Synthetic-Small-v0", 1),
            task("small_seed2", "CircuitTraining-Synthetic-Small-v0", 2),
            task("small_seed3", "CircuitTraining-Synthetic-Small-v0", 3),
            task("medium_seed1", "CircuitTraining-Synthetic-Medium-v0", 1),
            task("medium_seed2", "CircuitTraining-Synthetic-Medium-v0", 2),
        ],
    );
}
