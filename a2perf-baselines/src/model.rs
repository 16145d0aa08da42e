//! Policy and value networks, chosen from an environment's observation and action spaces.
//!
//! | observation | network | paper's network |
//! |---|---|---|
//! | anything (fallback) | all tensors flattened → MLP (`hidden_sizes`, ReLU) for logits or mean, a separate MLP for the value | QL actor/value `fc_layer_params=(512, 256)` |
//! | circuit (`features`, `grid` `[C, rows, cols]`, `Discrete(rows·cols)`) | MLP over `features` → global embedding *g*; per-cell hidden layer `relu(W_c·[cell channels, cell position] + W_g·g)` → one score per cell (a 1×1 convolution conditioned on *g*, plus the cell's position `x, y, |x|, |y|` in [−1, 1]); value MLP on *g* (32-8-1) | GCN encoder over the netlist graph, deconvolution head 8×8×32 → 128×128, value head 32-8-1. We have no graph tensor in the contract, so the summary features stand in for the GCN embedding; the per-cell head replaces the deconvolution because our grid is the env's own. With A2Perf's padded action space (`padded_action`, metadata `action_layout = "padded128"`: `Discrete(128·128)`, the grid centred on the canvas) the same scores are placed at the padded actions of their cells and the padding gets `−∞`, so the network, its parameters and its choices are those of the unpadded layout. |
//! | web (`profile_*`, `dom_*`, `Discrete(E·F·2)`) | token embeddings (`embedding_dim`, paper 100) mean-pooled per attribute; element MLP over the 5 pooled attributes + 8 DOM features → `latent_dim` (paper 50); field MLP over pooled key + value → `latent_dim`; logit(e, f, k) = ⟨field_f, element_e⟩ + type_k(element_e) + type_k(field_f); value MLP on the mean element and mean field embeddings | sonnet `WebLSTMEncoder`: same embedding/latent sizes and the same dot-product + action-type logits; an LSTM runs over the DOM sequence. We drop the LSTM (elements are scored independently plus their 8 geometry/state features), which keeps inference allocation-free and fast. |

use a2perf_core::{EnvSpec, PolicyError, RngStream, Space};
use serde::{Deserialize, Serialize};

use crate::batch::{ObsBatch, ObsLayout};
use crate::nn::{Activation, Linear, Mlp, MlpWs, ParamAlloc, ensure};

mod web;
pub use web::{WebArch, WebPath};

/// Network choices shared by every algorithm (hyperparameters).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct NetOptions {
    /// `auto` (pick from the spaces), `mlp` (always the flat fallback).
    pub architecture: String,
    /// Hidden layer sizes of MLPs.
    pub hidden_sizes: Vec<usize>,
    /// Token embedding width (web).
    pub embedding_dim: usize,
    /// Latent width of element and field encodings (web) and per-cell hidden width (circuit).
    pub latent_dim: usize,
}

impl Default for NetOptions {
    fn default() -> Self {
        Self {
            architecture: "auto".into(),
            hidden_sizes: vec![64, 64],
            embedding_dim: 100,
            latent_dim: 50,
        }
    }
}

/// Circuit placement network (see the module table).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct CircuitArch {
    features: usize,
    #[serde(default)]
    features_dim: usize,
    grid: usize,
    channels: usize,
    cells: usize,
    /// Grid `(rows, cols)` of the current layout (for the cell-position inputs).
    #[serde(default)]
    shape: (usize, usize),
    /// Cell-position inputs appended to each cell's channels ([`CELL_POSITION_INPUTS`]; 0 in
    /// checkpoints written before they existed, which then run as before).
    #[serde(default)]
    position_inputs: usize,
    /// Side of the padded square canvas the actions are laid out on ([`PADDED_CANVAS`] for
    /// A2Perf's `padded128` layout), or 0 when an action is a grid cell.
    #[serde(default)]
    padded_side: usize,
    global: Mlp,
    global_to_cell: Linear,
    cell_in: Linear,
    score: Linear,
    value: Option<Mlp>,
}

/// Which network computes the logits.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub enum DiscreteArch {
    /// Flattened observation → MLP.
    Flat {
        /// Logits MLP.
        policy: Mlp,
        /// Value MLP.
        value: Option<Mlp>,
    },
    /// Circuit placement.
    Circuit(CircuitArch),
    /// Web navigation.
    Web(WebArch),
}

#[derive(Clone, Debug, Default)]
struct Ws {
    x: Vec<f32>,
    logits: Vec<f32>,
    values: Vec<f32>,
    a: MlpWs,
    b: MlpWs,
    c: MlpWs,
    v: [Vec<f32>; 12],
    web: web::WebWs,
    batch: usize,
    /// Width of a row of `logits`: the number of actions, or of scored actions after a
    /// [`DiscreteNet::forward_scored`].
    width: usize,
    /// Whether the last forward pass kept what [`DiscreteNet::backward`] reads (not after
    /// [`DiscreteNet::infer_scored`]).
    kept: bool,
}

/// A network mapping observation batches to logits `[B, n]` (or Q-values) and, optionally, state
/// values `[B]`. Owns its activation workspace; parameters are passed in.
#[derive(Clone, Debug)]
pub struct DiscreteNet {
    /// The architecture (serialised into checkpoints).
    pub arch: DiscreteArch,
    n: usize,
    num_params: usize,
    ws: Ws,
}

fn flat_mlps(
    alloc: &mut ParamAlloc,
    input: usize,
    hidden: &[usize],
    out: usize,
    with_value: bool,
) -> (Mlp, Option<Mlp>) {
    let sizes = |o: usize| {
        let mut s = vec![input];
        s.extend_from_slice(hidden);
        s.push(o);
        s
    };
    let policy = Mlp::new(alloc, &sizes(out), Activation::Relu);
    let value = with_value.then(|| Mlp::new(alloc, &sizes(1), Activation::Relu));
    (policy, value)
}

impl DiscreteNet {
    /// Builds the network for `spec` (which must have a discrete action space).
    pub fn for_spec(
        spec: &EnvSpec,
        layout: &ObsLayout,
        opts: &NetOptions,
        with_value: bool,
    ) -> Result<Self, PolicyError> {
        let n = match spec.action_space {
            Space::Discrete { n } => n,
            _ => {
                return Err(PolicyError::BadObservation(
                    "a discrete network needs a discrete action space".into(),
                ));
            }
        };
        let mut alloc = ParamAlloc::new();
        let auto = opts.architecture == "auto";
        let arch = if let (true, Some(a)) = (
            auto,
            web::web_arch(spec, layout, opts, n, with_value, &mut alloc),
        ) {
            a
        } else if let (true, Some(a)) = (
            auto,
            circuit_arch(spec, layout, opts, n, with_value, &mut alloc),
        ) {
            a
        } else {
            alloc = ParamAlloc::new();
            let (policy, value) = flat_mlps(
                &mut alloc,
                layout.total_dim(),
                &opts.hidden_sizes,
                n,
                with_value,
            );
            DiscreteArch::Flat { policy, value }
        };
        Ok(Self::from_arch(arch, n, alloc.len()))
    }

    /// Rebuilds a network from its serialised architecture.
    pub fn from_arch(arch: DiscreteArch, n: usize, num_params: usize) -> Self {
        Self {
            arch,
            n,
            num_params,
            ws: Ws::default(),
        }
    }

    /// Number of actions.
    pub fn num_actions(&self) -> usize {
        self.n
    }

    /// Number of parameters.
    pub fn num_params(&self) -> usize {
        self.num_params
    }

    /// Short name of the architecture (`mlp`, `circuit`, `web`).
    pub fn kind(&self) -> &'static str {
        match self.arch {
            DiscreteArch::Flat { .. } => "mlp",
            DiscreteArch::Circuit(_) => "circuit",
            DiscreteArch::Web(_) => "web",
        }
    }

    /// Whether the network has a value head.
    pub fn has_value(&self) -> bool {
        match &self.arch {
            DiscreteArch::Flat { value, .. } => value.is_some(),
            DiscreteArch::Circuit(c) => c.value.is_some(),
            DiscreteArch::Web(w) => w.value.is_some(),
        }
    }

    /// Fresh parameters (policy-output layers are scaled down so the initial policy is near
    /// uniform, as in standard PPO implementations).
    pub fn init_params(&self, rng: &mut RngStream) -> Vec<f32> {
        let mut p = vec![0.0; self.num_params];
        match &self.arch {
            DiscreteArch::Flat { policy, value } => {
                policy.init(&mut p, rng, 0.01);
                if let Some(v) = value {
                    v.init(&mut p, rng, 1.0);
                }
            }
            DiscreteArch::Circuit(c) => {
                c.global.init(&mut p, rng, std::f32::consts::SQRT_2);
                c.global_to_cell.init(&mut p, rng, 1.0);
                c.cell_in.init(&mut p, rng, 1.0);
                c.score.init(&mut p, rng, 0.01);
                if let Some(v) = &c.value {
                    v.init(&mut p, rng, 1.0);
                }
            }
            DiscreteArch::Web(w) => {
                w.embed.init(&mut p, rng);
                w.field_mlp.init(&mut p, rng, 1.0);
                w.elem_mlp.init(&mut p, rng, 1.0);
                w.type_e.init(&mut p, rng, 0.01);
                w.type_f.init(&mut p, rng, 0.01);
                if let Some(v) = &w.value {
                    v.init(&mut p, rng, 1.0);
                }
            }
        }
        p
    }

    /// Chooses how the web network computes its first layers ([`WebPath`]; the default picks
    /// the cheaper for each batch). Both paths agree up to float rounding; tests and benches
    /// compare them. Other networks ignore it.
    ///
    /// ```
    /// use a2perf_baselines::model::{DiscreteArch, DiscreteNet, WebPath};
    /// use a2perf_baselines::nn::{Activation, Mlp, ParamAlloc};
    /// let mut alloc = ParamAlloc::new();
    /// let policy = Mlp::new(&mut alloc, &[2, 3], Activation::Relu);
    /// let flat = DiscreteArch::Flat { policy, value: None };
    /// let mut net = DiscreteNet::from_arch(flat, 3, alloc.len());
    /// net.set_web_path(WebPath::Direct); // the reference path, for a web network
    /// assert_eq!(net.kind(), "mlp");
    /// ```
    pub fn set_web_path(&mut self, path: WebPath) {
        self.ws.web.path = path;
    }

    /// Logits of the last forward pass, `[B, n]` (unmasked), or `[B, m]` over the
    /// [scored actions](Self::scored_actions_into) after [`forward_scored`](Self::forward_scored)
    /// (see [`logit_width`](Self::logit_width)).
    pub fn logits(&self) -> &[f32] {
        &self.ws.logits[..self.ws.batch * self.ws.width]
    }

    /// Width of a row of [`logits`](Self::logits) after the last forward pass.
    pub fn logit_width(&self) -> usize {
        self.ws.width
    }

    /// Writes into `out`, in increasing order, the actions the network scores when that is not
    /// every action, and returns `true`; returns `false` (and leaves `out` empty) when every
    /// action is scored. Only A2Perf's padded circuit layout scores fewer: its actions are the
    /// grid's cells laid out on a 128×128 canvas, and every other action's logit is always
    /// `−∞` and never legal (the environment masks the padding).
    ///
    /// ```
    /// use a2perf_baselines::model::{DiscreteArch, DiscreteNet};
    /// use a2perf_baselines::nn::{Activation, Mlp, ParamAlloc};
    /// let mut alloc = ParamAlloc::new();
    /// let policy = Mlp::new(&mut alloc, &[2, 3], Activation::Relu);
    /// let net = DiscreteNet::from_arch(DiscreteArch::Flat { policy, value: None }, 3, alloc.len());
    /// let mut scored = vec![7];
    /// assert!(!net.scored_actions_into(&mut scored));
    /// assert!(scored.is_empty());
    /// ```
    pub fn scored_actions_into(&self, out: &mut Vec<usize>) -> bool {
        out.clear();
        match &self.arch {
            DiscreteArch::Circuit(c) if c.padded_side > 0 => {
                let (rows, cols) = c.shape;
                out.extend((0..c.cells).map(|i| padded_action(i, rows, cols, c.padded_side)));
                true
            }
            _ => false,
        }
    }

    /// The observation tensors the network reads (indices into its layout), or `None` when it
    /// reads every one (a flat MLP). A batch it alone reads need hold only these
    /// ([`ObsBatch::keep_tensors`]): the circuit network reads `features` and `grid`, not the
    /// netlist's graph.
    ///
    /// ```
    /// use a2perf_baselines::model::{DiscreteArch, DiscreteNet};
    /// use a2perf_baselines::nn::{Activation, Mlp, ParamAlloc};
    /// let mut alloc = ParamAlloc::new();
    /// let policy = Mlp::new(&mut alloc, &[2, 3], Activation::Relu);
    /// let net = DiscreteNet::from_arch(DiscreteArch::Flat { policy, value: None }, 3, alloc.len());
    /// assert_eq!(net.inputs(), None);
    /// ```
    pub fn inputs(&self) -> Option<Vec<usize>> {
        match &self.arch {
            DiscreteArch::Flat { .. } => None,
            DiscreteArch::Circuit(c) => Some(vec![c.features, c.grid]),
            DiscreteArch::Web(w) => Some(w.inputs()),
        }
    }

    /// Forward pass that computes only the logits of the
    /// [scored actions](Self::scored_actions_into): [`logits`](Self::logits) is then
    /// `[B, m]`, column `j` being the `j`-th scored action. Every value is the same, bit for
    /// bit, as the corresponding one of [`forward`](Self::forward); the padding, always `−∞`,
    /// is not written. A network that scores every action runs [`forward`](Self::forward).
    /// [`backward`](Self::backward) then takes logit gradients of the same width.
    pub fn forward_scored(&mut self, params: &[f32], batch: &ObsBatch) {
        self.forward_as(params, batch, true, true);
    }

    /// [`forward_scored`](Self::forward_scored), the same values bit for bit, for a pass that
    /// no [`backward`](Self::backward) follows (a learner's targets): the circuit network then
    /// holds one batch row's cell activations at a time, in cache, not the whole batch's (26 MB
    /// for 256 Ariane pages). A backward pass after it panics.
    ///
    /// ```
    /// use a2perf_baselines::batch::{ObsBatch, ObsLayout};
    /// use a2perf_baselines::model::{DiscreteArch, DiscreteNet};
    /// use a2perf_baselines::nn::{Activation, Mlp, ParamAlloc};
    /// let mut alloc = ParamAlloc::new();
    /// let policy = Mlp::new(&mut alloc, &[2, 3], Activation::Relu);
    /// let mut net = DiscreteNet::from_arch(DiscreteArch::Flat { policy, value: None }, 3, alloc.len());
    /// let params = vec![0.1; net.num_params()];
    /// let mut batch = ObsBatch::new(&ObsLayout::floats(vec![("obs".into(), vec![2])], Some(3)));
    /// batch.resize(1);
    /// net.forward_scored(&params, &batch);
    /// let kept = net.logits().to_vec();
    /// net.infer_scored(&params, &batch);
    /// assert_eq!(net.logits(), &kept[..]);
    /// ```
    pub fn infer_scored(&mut self, params: &[f32], batch: &ObsBatch) {
        self.forward_as(params, batch, true, false);
    }

    /// Values of the last forward pass, `[B]` (zeros without a value head).
    pub fn values(&self) -> &[f32] {
        &self.ws.values[..self.ws.batch]
    }

    /// Forward pass over every row of `batch`.
    pub fn forward(&mut self, params: &[f32], batch: &ObsBatch) {
        self.forward_as(params, batch, false, true);
    }

    /// [`forward`](Self::forward), or [`forward_scored`](Self::forward_scored) when `scored`.
    fn forward_as(&mut self, params: &[f32], batch: &ObsBatch, scored: bool, keep: bool) {
        let b = batch.len();
        let n = match &self.arch {
            DiscreteArch::Circuit(c) if scored => c.cells,
            _ => self.n,
        };
        let ws = &mut self.ws;
        ws.batch = b;
        ws.width = n;
        ws.kept = keep;
        ensure(&mut ws.logits, b * n);
        ensure(&mut ws.values, b);
        ws.values[..b].fill(0.0);
        match &self.arch {
            DiscreteArch::Flat { policy, value } => {
                batch.concat_into(&mut ws.x);
                let y = policy.forward(params, &ws.x, b, &mut ws.a);
                ws.logits[..b * n].copy_from_slice(y);
                if let Some(v) = value {
                    let y = v.forward(params, &ws.x, b, &mut ws.b);
                    ws.values[..b].copy_from_slice(y);
                }
            }
            DiscreteArch::Circuit(c) => circuit_forward(c, params, batch, ws, scored, keep),
            DiscreteArch::Web(w) => web::web_forward(w, params, batch, ws),
        }
    }

    /// Backward pass for the last forward: accumulates parameter gradients of
    /// `Σ dlogits·logits + Σ dvalues·values` into `grads` (`dlogits` as wide as
    /// [`logits`](Self::logits)).
    pub fn backward(
        &mut self,
        params: &[f32],
        grads: &mut [f32],
        batch: &ObsBatch,
        dlogits: &[f32],
        dvalues: Option<&[f32]>,
    ) {
        let b = self.ws.batch;
        let ws = &mut self.ws;
        assert!(
            ws.kept,
            "a backward pass needs a forward that keeps its activations"
        );
        match &self.arch {
            DiscreteArch::Flat { policy, value } => {
                policy.backward(params, grads, &ws.x, dlogits, &mut ws.a, None);
                if let (Some(v), Some(dv)) = (value, dvalues) {
                    v.backward(params, grads, &ws.x, &dv[..b], &mut ws.b, None);
                }
            }
            DiscreteArch::Circuit(c) => {
                circuit_backward(c, params, grads, batch, ws, dlogits, dvalues)
            }
            DiscreteArch::Web(w) => {
                web::web_backward(w, params, grads, batch, ws, dlogits, dvalues)
            }
        }
    }
}

impl DiscreteArch {
    /// Whether this network can read `layout`'s element types (a network saved before
    /// observations were typed is checked against the environment it is loaded for): the web
    /// network's token tensors must be integers and its other tensors floats, the circuit
    /// network's `features` and `grid` floats.
    pub fn check_dtypes(&self, layout: &ObsLayout) -> Result<(), String> {
        let fits = match self {
            DiscreteArch::Flat { .. } => true,
            DiscreteArch::Circuit(c) => {
                !layout.is_integer(c.features) && !layout.is_integer(c.grid)
            }
            DiscreteArch::Web(w) => w.dtypes_fit(layout),
        };
        if fits {
            Ok(())
        } else {
            Err(
                "the environment's tensor types (int32 ids, float32 features) differ from what \
                 the network reads"
                    .into(),
            )
        }
    }
}

impl CircuitArch {
    /// Points the network at another netlist's observations. Its parameters depend only on the
    /// `features` width and the grid's channel count, and it scores any number of cells, so a
    /// placement policy can run on circuits it was not trained on (the generalization tasks).
    /// Fails, saying why, when the new layout differs in anything the parameters depend on.
    pub(crate) fn retarget(&mut self, spec: &EnvSpec, new: &ObsLayout) -> Result<(), String> {
        let features = new
            .index("features")
            .ok_or("the environment has no `features` tensor")?;
        let grid = new
            .index("grid")
            .ok_or("the environment has no `grid` tensor")?;
        if new.dim(features) != self.features_dim {
            return Err(format!(
                "`features` has {} values, the network was trained on {}",
                new.dim(features),
                self.features_dim
            ));
        }
        if new.is_integer(features) || new.is_integer(grid) {
            return Err("`features` and `grid` must be float32 tensors".into());
        }
        let shape = &new.tensors[grid].1;
        let cells: usize = shape.iter().skip(1).product();
        if shape.len() != 3 || shape[0] != self.channels {
            return Err(format!(
                "`grid` has shape {shape:?}, the network needs {} channels",
                self.channels
            ));
        }
        let padded_side = action_canvas(spec, shape[1], shape[2], new.num_actions.unwrap_or(0))
            .ok_or_else(|| {
                format!(
                    "the action space has {:?} actions, neither the grid's {cells} cells nor a \
                     padded {PADDED_CANVAS}×{PADDED_CANVAS} canvas holding the {}×{} grid",
                    new.num_actions, shape[2], shape[1]
                )
            })?;
        self.features = features;
        self.grid = grid;
        self.cells = cells;
        self.shape = (shape[1], shape[2]);
        self.padded_side = padded_side;
        Ok(())
    }
}

/// Side of A2Perf's padded action canvas (`max_grid_size`): its `padded128` action layout has
/// 128·128 actions whatever the netlist's grid.
pub const PADDED_CANVAS: usize = 128;

/// How `n` actions map onto a `rows × cols` grid: `Some(0)` when an action is a grid cell,
/// `Some(PADDED_CANVAS)` for A2Perf's padded layout (declared by the environment's metadata
/// `action_layout = "padded128"`), `None` when neither fits.
fn action_canvas(spec: &EnvSpec, rows: usize, cols: usize, n: usize) -> Option<usize> {
    let padded = spec.metadata.get("action_layout").map(String::as_str) == Some("padded128");
    if padded {
        (n == PADDED_CANVAS * PADDED_CANVAS && rows <= PADDED_CANVAS && cols <= PADDED_CANVAS)
            .then_some(PADDED_CANVAS)
    } else {
        (n == rows * cols && n > 0).then_some(0)
    }
}

/// The padded action of grid cell `cell`: the grid centred on a `side × side` canvas with
/// `(side − rows)/2` rows above it and `(side − cols)/2` columns left of it, row-major. This is
/// A2Perf's `translate_to_padded_canvas`, as `a2perf_circuit::env::cell_to_padded_action` (the
/// baselines do not depend on the circuit crate; `tests/circuit_padded.rs` checks that the two
/// agree). The map keeps the cells' order, so masked argmax, inverse-CDF sampling and ε-greedy
/// draws pick the same cell under either layout.
fn padded_action(cell: usize, rows: usize, cols: usize, side: usize) -> usize {
    let (up, left) = ((side - rows) / 2, (side - cols) / 2);
    (cell / cols + up) * side + cell % cols + left
}

fn circuit_arch(
    spec: &EnvSpec,
    layout: &ObsLayout,
    opts: &NetOptions,
    n: usize,
    with_value: bool,
    alloc: &mut ParamAlloc,
) -> Option<DiscreteArch> {
    let features = layout.index("features")?;
    let grid = layout.index("grid")?;
    let shape = &layout.tensors[grid].1;
    if shape.len() != 3 || layout.is_integer(features) || layout.is_integer(grid) {
        return None;
    }
    let padded_side = action_canvas(spec, shape[1], shape[2], n)?;
    let cells = shape[1] * shape[2];
    let channels = shape[0];
    let d = layout.dim(features);
    let mut sizes = vec![d];
    sizes.extend_from_slice(&opts.hidden_sizes);
    let h = *sizes.last()?;
    let k = opts.latent_dim;
    let global = Mlp::encoder(alloc, &sizes, Activation::Relu);
    let global_to_cell = Linear::new(alloc, h, k);
    let cell_in = Linear::new(alloc, channels + CELL_POSITION_INPUTS, k);
    let score = Linear::new(alloc, k, 1);
    let value = with_value.then(|| Mlp::new(alloc, &[h, 32, 8, 1], Activation::Relu));
    Some(DiscreteArch::Circuit(CircuitArch {
        features,
        features_dim: d,
        grid,
        channels,
        cells,
        shape: (shape[1], shape[2]),
        position_inputs: CELL_POSITION_INPUTS,
        padded_side,
        global,
        global_to_cell,
        cell_in,
        score,
        value,
    }))
}

/// Inputs describing a cell's place on the canvas: `x`, `y` in [−1, 1] and their magnitudes
/// (distance from the centre line, i.e. nearness to an edge). The grid channels say what is
/// around a cell but not where it is, and where matters: real designs put macros along the
/// edges and keep the centre for the logic (the paper's deconvolution head knows positions).
pub const CELL_POSITION_INPUTS: usize = 4;

/// The circuit network's forward pass; `scored`: the cells' scores only, `[B, cells]`, even on
/// the padded canvas; `keep`: keep every row's cell inputs and activations for a backward pass
/// (else one row's at a time).
fn circuit_forward(
    c: &CircuitArch,
    params: &[f32],
    batch: &ObsBatch,
    ws: &mut Ws,
    scored: bool,
    keep: bool,
) {
    let b = batch.len();
    let (nc, ch, k) = (c.cells, c.channels, c.cell_in.out);
    let (pi, (rows, cols)) = (c.position_inputs, c.shape);
    let stride = ch + pi;
    let g = c
        .global
        .forward(params, batch.tensor(c.features), b, &mut ws.a);
    let [gc, cx, h, _, _, _, _, scores, pos, ..] = &mut ws.v;
    ensure(gc, b * k);
    c.global_to_cell.forward(params, g, b, gc);
    // The cells' position inputs, the same in every row.
    let with_pos = pi == CELL_POSITION_INPUTS && rows * cols == nc;
    if with_pos {
        ensure(pos, nc * CELL_POSITION_INPUTS);
        for (i, p) in pos
            .chunks_exact_mut(CELL_POSITION_INPUTS)
            .take(nc)
            .enumerate()
        {
            let x = 2.0 * ((i % cols) as f32 + 0.5) / cols as f32 - 1.0;
            let y = 2.0 * ((i / cols) as f32 + 0.5) / rows as f32 - 1.0;
            p.copy_from_slice(&[x, y, x.abs(), y.abs()]);
        }
    }
    // Without a backward pass to come, every row reuses the first row's place.
    let kept_rows = if keep { b } else { b.min(1) };
    ensure(cx, kept_rows * nc * stride);
    ensure(h, kept_rows * nc * k);
    // The cells' scores: the logits themselves, or laid out on the padded canvas below.
    let direct = c.padded_side == 0 || scored;
    let out: &mut [f32] = if direct {
        &mut ws.logits
    } else {
        ensure(scores, b * nc);
        scores
    };
    let grid = batch.tensor(c.grid);
    // One batch row at a time: its cells' inputs, hidden layer, ReLU and scores while they are
    // in cache (256 Ariane pages hold 129,024 cells, a 26 MB hidden layer). Every value is the
    // one the whole batch at once gives: a row of a layer's output reads that row of its input
    // only (the cell-wise GEMM's products and sums run in the same order).
    for r in 0..b {
        let src = &grid[r * ch * nc..(r + 1) * ch * nc];
        let at = if keep { r } else { 0 };
        let dst = &mut cx[at * nc * stride..(at + 1) * nc * stride];
        for chn in 0..ch {
            for i in 0..nc {
                dst[i * stride + chn] = src[chn * nc + i];
            }
        }
        if with_pos {
            for (cell, p) in dst
                .chunks_exact_mut(stride)
                .zip(pos.chunks_exact(CELL_POSITION_INPUTS))
            {
                // Four stores, not a copy of a slice of unknown length (a `memmove` call per
                // cell and row).
                if let (Some(d), Ok(p)) = (
                    cell.last_chunk_mut::<CELL_POSITION_INPUTS>(),
                    <&[f32; CELL_POSITION_INPUTS]>::try_from(p),
                ) {
                    *d = *p;
                }
            }
        } else if pi > 0 {
            for i in 0..nc {
                dst[i * stride + ch..(i + 1) * stride].fill(0.0);
            }
        }
        let hr = &mut h[at * nc * k..(at + 1) * nc * k];
        c.cell_in.forward(params, dst, nc, hr);
        let gr = &gc[r * k..(r + 1) * k];
        for row in hr.chunks_exact_mut(k) {
            for (x, g) in row.iter_mut().zip(gr) {
                *x = (*x + g).max(0.0);
            }
        }
        c.score
            .forward(params, hr, nc, &mut out[r * nc..(r + 1) * nc]);
    }
    if !direct {
        // Lay the cells' scores out on the padded canvas; the padding is never legal.
        let n = c.padded_side * c.padded_side;
        for r in 0..b {
            let row = &mut ws.logits[r * n..(r + 1) * n];
            row.fill(f32::NEG_INFINITY);
            for (i, &z) in scores[r * nc..(r + 1) * nc].iter().enumerate() {
                row[padded_action(i, rows, cols, c.padded_side)] = z;
            }
        }
    }
    if let Some(v) = &c.value {
        let y = v.forward(params, c.global.output(&ws.a), b, &mut ws.c);
        ws.values[..b].copy_from_slice(y);
    }
}

fn circuit_backward(
    c: &CircuitArch,
    params: &[f32],
    grads: &mut [f32],
    batch: &ObsBatch,
    ws: &mut Ws,
    dlogits: &[f32],
    dvalues: Option<&[f32]>,
) {
    let b = ws.batch;
    let (nc, k) = (c.cells, c.cell_in.out);
    let h_dim = c.global.out();
    let [_gc, cx, h, dh, dgc, dg, dg2, dscores, ..] = &mut ws.v;
    // One entry per cell already: the unpadded layout, or a scored forward.
    let dlogits = if ws.width == nc {
        dlogits
    } else {
        // Only the cells' entries depend on the parameters.
        let (rows, cols) = c.shape;
        let n = c.padded_side * c.padded_side;
        ensure(dscores, b * nc);
        for r in 0..b {
            for i in 0..nc {
                dscores[r * nc + i] = dlogits[r * n + padded_action(i, rows, cols, c.padded_side)];
            }
        }
        &dscores[..b * nc]
    };
    ensure(dh, b * nc * k);
    c.score
        .backward(params, grads, h, dlogits, b * nc, Some(dh));
    ensure(dgc, b * k);
    dgc[..b * k].fill(0.0);
    for r in 0..b {
        let dgr = &mut dgc[r * k..(r + 1) * k];
        let hr = &h[r * nc * k..(r + 1) * nc * k];
        for (drow, hrow) in dh[r * nc * k..(r + 1) * nc * k]
            .chunks_exact_mut(k)
            .zip(hr.chunks_exact(k))
        {
            for ((d, y), g) in drow.iter_mut().zip(hrow).zip(dgr.iter_mut()) {
                // A select (vectorizes; see `Activation::backward`).
                *d = if *y <= 0.0 { 0.0 } else { *d };
                *g += *d;
            }
        }
    }
    c.cell_in.backward(params, grads, cx, dh, b * nc, None);
    ensure(dg, b * h_dim);
    let g = c.global.output(&ws.a);
    c.global_to_cell
        .backward(params, grads, g, dgc, b, Some(dg));
    if let (Some(v), Some(dv)) = (&c.value, dvalues) {
        ensure(dg2, b * h_dim);
        v.backward(params, grads, g, &dv[..b], &mut ws.c, Some(dg2));
        for (a, x) in dg[..b * h_dim].iter_mut().zip(&dg2[..b * h_dim]) {
            *a += x;
        }
    }
    c.global
        .backward(params, grads, batch.tensor(c.features), dg, &mut ws.a, None);
}

/// Continuous-action network: Gaussian policy with a state-independent log-std (PPO, BC), plus an
/// optional separate value MLP.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct GaussianArch {
    /// Mean MLP.
    pub actor: Mlp,
    /// Value MLP.
    pub critic: Option<Mlp>,
    /// Offset of the `log_std` vector.
    pub log_std: usize,
    /// Action dimensions.
    pub act_dim: usize,
    /// Number of parameters.
    pub num_params: usize,
}

impl GaussianArch {
    /// Actor (and critic) MLPs over the flattened observation.
    pub fn new(obs_dim: usize, act_dim: usize, hidden: &[usize], with_value: bool) -> Self {
        let mut alloc = ParamAlloc::new();
        let sizes = |o: usize| {
            let mut s = vec![obs_dim];
            s.extend_from_slice(hidden);
            s.push(o);
            s
        };
        let actor = Mlp::new(&mut alloc, &sizes(act_dim), Activation::Tanh);
        let critic = with_value.then(|| Mlp::new(&mut alloc, &sizes(1), Activation::Tanh));
        let log_std = alloc.take(act_dim);
        Self {
            actor,
            critic,
            log_std,
            act_dim,
            num_params: alloc.len(),
        }
    }

    /// Fresh parameters with every `log_std` at `init_log_std`.
    pub fn init_params(&self, rng: &mut RngStream, init_log_std: f32) -> Vec<f32> {
        let mut p = vec![0.0; self.num_params];
        self.actor.init(&mut p, rng, 0.01);
        if let Some(c) = &self.critic {
            c.init(&mut p, rng, 1.0);
        }
        p[self.log_std..self.log_std + self.act_dim].fill(init_log_std);
        p
    }

    /// The actor's forward pass over `batch` rows of `x` into `wa`, and the critic's (when
    /// there is one) into `wc`, the two on two threads of rayon's pool when it has a free one.
    /// The networks share no workspace and no result, so the values are exactly those of the
    /// two passes one after the other.
    ///
    /// ```
    /// use a2perf_baselines::model::GaussianArch;
    /// use a2perf_baselines::nn::MlpWs;
    /// use a2perf_core::RngStream;
    /// let arch = GaussianArch::new(3, 2, &[8], true);
    /// let p = arch.init_params(&mut RngStream::new(0, "init"), -1.0);
    /// let x = [0.5, -1.0, 2.0, 0.1, 0.2, 0.3];
    /// let (mut wa, mut wc) = (MlpWs::default(), MlpWs::default());
    /// arch.forward_both(&p, &x, 2, &mut wa, &mut wc);
    /// let critic = arch.critic.as_ref().unwrap();
    /// let v = critic.forward(&p, &x, 2, &mut MlpWs::default()).to_vec();
    /// assert_eq!(critic.output(&wc), &v[..]);
    /// ```
    pub fn forward_both(
        &self,
        params: &[f32],
        x: &[f32],
        batch: usize,
        wa: &mut MlpWs,
        wc: &mut MlpWs,
    ) {
        match &self.critic {
            Some(c) => {
                rayon::join(
                    || self.actor.forward(params, x, batch, wa),
                    || c.forward(params, x, batch, wc),
                );
            }
            None => {
                self.actor.forward(params, x, batch, wa);
            }
        }
    }

    /// The backward passes of the last [`forward_both`](Self::forward_both): the actor's from
    /// the mean gradients `dmean` and the critic's from the value gradients `dvalues`, each
    /// accumulated into its own parameters' part of `grads`, the two on two threads of rayon's
    /// pool when it has a free one. The values are exactly those of the two
    /// [`Mlp::backward`] calls one after the other (a test holds it to the bit).
    #[allow(clippy::too_many_arguments)] // two networks' inputs, gradients and workspaces
    pub fn backward_both(
        &self,
        params: &[f32],
        grads: &mut [f32],
        x: &[f32],
        dmean: &[f32],
        dvalues: &[f32],
        wa: &mut MlpWs,
        wc: &mut MlpWs,
    ) {
        let Some(c) = &self.critic else {
            self.actor.backward(params, grads, x, dmean, wa, None);
            return;
        };
        let (ra, rc) = (self.actor.param_range(), c.param_range());
        let (ga, gc) = if ra.end <= rc.start {
            let (lo, hi) = grads.split_at_mut(rc.start);
            (&mut lo[ra], &mut hi[..rc.len()])
        } else if rc.end <= ra.start {
            let (lo, hi) = grads.split_at_mut(ra.start);
            (&mut hi[..ra.len()], &mut lo[rc])
        } else {
            // Overlapping parameters (never from `new`): one after the other.
            self.actor.backward(params, grads, x, dmean, wa, None);
            c.backward(params, grads, x, dvalues, wc, None);
            return;
        };
        rayon::join(
            || self.actor.backward_local(params, ga, x, dmean, wa, None),
            || c.backward_local(params, gc, x, dvalues, wc, None),
        );
    }
}

/// SAC actor: an MLP emitting the mean and the raw log-std of a tanh-squashed Gaussian.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SquashedArch {
    /// MLP `obs → [mean | raw log-std]`.
    pub actor: Mlp,
    /// Action dimensions.
    pub act_dim: usize,
    /// Number of parameters.
    pub num_params: usize,
}

impl SquashedArch {
    /// Actor MLP over the flattened observation (ReLU, as the paper's SAC networks).
    pub fn new(obs_dim: usize, act_dim: usize, hidden: &[usize]) -> Self {
        let mut alloc = ParamAlloc::new();
        let mut sizes = vec![obs_dim];
        sizes.extend_from_slice(hidden);
        sizes.push(2 * act_dim);
        let actor = Mlp::new(&mut alloc, &sizes, Activation::Relu);
        Self {
            actor,
            act_dim,
            num_params: alloc.len(),
        }
    }
}
