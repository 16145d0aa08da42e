//! The placement cost: wirelength, density and congestion exactly as Google's `plc_wrapper_main`
//! (as re-implemented by TILOS MacroPlacement's `plc_client_os`), with incremental updates.
//!
//! Data layout: positions and sizes are flat per-node arrays; net endpoints ("pins") are one CSR
//! array (driver first), with the owning node and the N-frame offset of each; every node knows the
//! pins and nets it touches. Moving one node updates only its nets (half-perimeter wirelength and
//! the raw H/V net routing counts, which are sums of integer weights and therefore exact under
//! add/subtract), its density footprint, and marks the hard-macro routing allocation stale.
//! Smoothing and the top-k means are recomputed per query from preallocated scratch buffers.

use crate::netlist::{Netlist, NodeKind, Orientation};
use crate::plc::{Blockage, Placement, PlcEntry, PlcHeader};

/// Errors building or updating a [`PlacementCost`].
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum CostError {
    /// A setting is out of range.
    #[error("invalid cost setting: {0}")]
    Settings(String),
    /// A placement names a node that does not exist or cannot be placed.
    #[error("placement line for node {index}: {reason}")]
    BadNode {
        /// Node index.
        index: usize,
        /// What is wrong.
        reason: String,
    },
}

/// Weights of the proxy cost.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct CostWeights {
    /// Wirelength weight (1.0).
    pub wirelength: f64,
    /// Density weight (1.0, as the A2Perf code).
    pub density: f64,
    /// Congestion weight (0.5).
    pub congestion: f64,
}

impl Default for CostWeights {
    fn default() -> Self {
        Self {
            wirelength: 1.0,
            density: 1.0,
            congestion: 0.5,
        }
    }
}

/// Settings of a [`PlacementCost`].
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct CostSettings {
    /// Canvas width (µm).
    pub canvas_width: f64,
    /// Canvas height (µm).
    pub canvas_height: f64,
    /// Placement grid columns.
    pub grid_cols: usize,
    /// Placement grid rows.
    pub grid_rows: usize,
    /// Horizontal routing tracks per µm.
    pub hroutes_per_micron: f64,
    /// Vertical routing tracks per µm.
    pub vroutes_per_micron: f64,
    /// Horizontal tracks used per µm of hard macro.
    pub hrouting_alloc: f64,
    /// Vertical tracks used per µm of hard macro.
    pub vrouting_alloc: f64,
    /// Congestion smoothing range (floored).
    pub smooth_range: f64,
    /// Make every soft macro a square of the same area (CT env does).
    pub make_soft_macros_square: bool,
    /// Separate congestion grid `(cols, rows)`; `None` = the placement grid ("legacy", the
    /// semantics verified against Google). The separate grid's use in the binary is unknown; ours
    /// applies the same routing model on it.
    pub congestion_grid: Option<(usize, usize)>,
    /// Proxy weights.
    pub weights: CostWeights,
}

/// CT/A2Perf routing resources.
pub const CT_ROUTES_PER_MICRON: (f64, f64) = (70.33, 74.51);
/// CT/A2Perf macro routing allocation.
pub const CT_MACRO_ROUTING_ALLOC: (f64, f64) = (51.79, 51.79);
/// CT/A2Perf smoothing range.
pub const CT_SMOOTH_RANGE: f64 = 5.0;

impl CostSettings {
    /// Google binary defaults: canvas √(area/0.6) square, 10×10 grid, 57.031/56.818 routes,
    /// 39.583/30.303 allocation, no smoothing.
    pub fn google_binary_defaults(netlist: &Netlist) -> Self {
        let side = (netlist.total_area() / 0.6).sqrt();
        let side = if side.is_finite() && side > 0.0 {
            side
        } else {
            1.0
        };
        Self {
            canvas_width: side,
            canvas_height: side,
            grid_cols: 10,
            grid_rows: 10,
            hroutes_per_micron: 57.031,
            vroutes_per_micron: 56.818,
            hrouting_alloc: 39.583,
            vrouting_alloc: 30.303,
            smooth_range: 0.0,
            make_soft_macros_square: false,
            congestion_grid: None,
            weights: CostWeights::default(),
        }
    }

    /// The CT / A2Perf environment settings: canvas and grid from the comments at the top of the
    /// netlist and then of the `.plc` (a later value wins, as circuit_training's
    /// `extract_sizes_from_comments([netlist, plc])`: `FP bbox: {x0 y0} {W H}` and
    /// `Width : W  Height : H` give the canvas, `Columns : c  Rows : r` the grid), else the binary
    /// defaults; routes 70.33/74.51, allocation 51.79/51.79, smoothing 5, square soft macros,
    /// legacy congestion grid.
    ///
    /// ```
    /// use a2perf_circuit::{CostSettings, Netlist, SoftMacroRule};
    /// let text = r#"# FP bbox: {0.0 0.0} {200.0 100.0}
    /// ## Columns : 20  Rows : 10
    /// node { name: "M" attr { key: "type" value { placeholder: "MACRO" } }
    ///        attr { key: "width" value { f: 10 } } attr { key: "height" value { f: 10 } } }
    /// "#;
    /// let netlist = Netlist::parse(text, SoftMacroRule::default()).unwrap();
    /// let s = CostSettings::ct_env(&netlist, None);
    /// assert_eq!((s.canvas_width, s.canvas_height, s.grid_cols, s.grid_rows), (200.0, 100.0, 20, 10));
    /// ```
    pub fn ct_env(netlist: &Netlist, header: Option<&PlcHeader>) -> Self {
        let mut s = Self::google_binary_defaults(netlist);
        for line in &netlist.comments {
            let line = std::slice::from_ref(line);
            // CT's regex takes the second pair of `FP bbox` as the width and height.
            if let Some([_, _, w, h]) = crate::netlist::parse_fp_bbox(line)
                && w > 0.0
                && h > 0.0
            {
                s.canvas_width = w;
                s.canvas_height = h;
            }
            let h = crate::plc::parse_header(line);
            if let Some((w, hh)) = h.canvas {
                s.canvas_width = w;
                s.canvas_height = hh;
            }
            if let Some((c, r)) = h.grid {
                s.grid_cols = c;
                s.grid_rows = r;
            }
        }
        if let Some(h) = header {
            if let Some((w, hh)) = h.canvas {
                s.canvas_width = w;
                s.canvas_height = hh;
            }
            if let Some((c, r)) = h.grid {
                s.grid_cols = c;
                s.grid_rows = r;
            }
        }
        s.hroutes_per_micron = CT_ROUTES_PER_MICRON.0;
        s.vroutes_per_micron = CT_ROUTES_PER_MICRON.1;
        s.hrouting_alloc = CT_MACRO_ROUTING_ALLOC.0;
        s.vrouting_alloc = CT_MACRO_ROUTING_ALLOC.1;
        s.smooth_range = CT_SMOOTH_RANGE;
        s.make_soft_macros_square = true;
        s
    }

    /// Settings as written in a `.plc` header: every header value that is present is used, the
    /// rest are the CT environment's values. Soft macros are not squared.
    pub fn from_header(netlist: &Netlist, header: &PlcHeader) -> Self {
        let mut s = Self::ct_env(netlist, Some(header));
        if let Some((h, v)) = header.routes_per_micron {
            s.hroutes_per_micron = h;
            s.vroutes_per_micron = v;
        }
        if let Some((h, v)) = header.macro_routing_alloc {
            s.hrouting_alloc = h;
            s.vrouting_alloc = v;
        }
        if let Some(k) = header.smooth_range {
            s.smooth_range = k;
        }
        s.make_soft_macros_square = false;
        s
    }

    /// CT's separate congestion grid for these routes: cell size 2·1000/(h+v) µm.
    pub fn ct_congestion_grid(&self) -> (usize, usize) {
        let size = 2.0 * 1000.0 / (self.hroutes_per_micron + self.vroutes_per_micron);
        let c = ((self.canvas_width / size) as usize).max(1);
        let r = ((self.canvas_height / size) as usize).max(1);
        (c, r)
    }

    /// Checks ranges.
    pub fn validate(&self) -> Result<(), CostError> {
        let pos = |v: f64, what: &str| {
            if v.is_finite() && v > 0.0 {
                Ok(())
            } else {
                Err(CostError::Settings(format!(
                    "{what} must be positive, got {v}"
                )))
            }
        };
        pos(self.canvas_width, "canvas width")?;
        pos(self.canvas_height, "canvas height")?;
        pos(self.hroutes_per_micron, "horizontal routes per micron")?;
        pos(self.vroutes_per_micron, "vertical routes per micron")?;
        let nonneg = |v: f64, what: &str| {
            if v.is_finite() && v >= 0.0 {
                Ok(())
            } else {
                Err(CostError::Settings(format!("{what} must be ≥ 0, got {v}")))
            }
        };
        nonneg(self.hrouting_alloc, "horizontal macro routing allocation")?;
        nonneg(self.vrouting_alloc, "vertical macro routing allocation")?;
        nonneg(self.smooth_range, "smoothing range")?;
        if self.smooth_range > 1e6 {
            return Err(CostError::Settings("smoothing range too large".into()));
        }
        let grid_ok = |c: usize, r: usize| c >= 1 && r >= 1 && c.saturating_mul(r) <= 1 << 24;
        if !grid_ok(self.grid_cols, self.grid_rows) {
            return Err(CostError::Settings(format!(
                "grid {}x{} must have ≥ 1 column and row and ≤ 2^24 cells",
                self.grid_cols, self.grid_rows
            )));
        }
        if let Some((c, r)) = self.congestion_grid
            && !grid_ok(c, r)
        {
            return Err(CostError::Settings(format!(
                "congestion grid {c}x{r} is invalid"
            )));
        }
        for (v, what) in [
            (self.weights.wirelength, "wirelength weight"),
            (self.weights.density, "density weight"),
            (self.weights.congestion, "congestion weight"),
        ] {
            nonneg(v, what)?;
        }
        Ok(())
    }
}

/// All cost terms of a placement.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct CostBreakdown {
    /// Σ w·HPWL.
    pub wirelength: f64,
    /// Σ net weights.
    pub net_count: f64,
    /// WL / ((W+H)·net_count).
    pub wirelength_cost: f64,
    /// 0.5 · mean of the top 10 % cell densities.
    pub density_cost: f64,
    /// Mean of the top 5 % of the concatenated V and H congestion.
    pub congestion_cost: f64,
    /// Top 5 % mean of H congestion alone.
    pub h_congestion_cost: f64,
    /// Top 5 % mean of V congestion alone.
    pub v_congestion_cost: f64,
    /// Weighted sum with the settings' weights.
    pub proxy_cost: f64,
}

/// `v.floor()` without the libm call (x86-64's baseline has no `roundsd`, so `f64::floor` is a
/// function call; this sits on the per-pin hot path). Exact for every input.
#[inline]
pub(crate) fn floor_f64(v: f64) -> f64 {
    // Beyond 2^52 every f64 is an integer (and NaN/inf pass through unchanged).
    if v.abs() < 4_503_599_627_370_496.0 {
        let t = v as i64 as f64;
        if t == v {
            v
        } else if t > v {
            t - 1.0
        } else {
            t
        }
    } else {
        v
    }
}

/// `floor(v)` saturated to ±1e12 as an integer (NaN → 0), exactly as
/// `v.floor().clamp(-1e12, 1e12) as i64`.
#[inline]
fn floor_i64(v: f64) -> i64 {
    if (-1e12..=1e12).contains(&v) {
        let t = v as i64;
        t - ((t as f64) > v) as i64
    } else if v > 0.0 {
        1_000_000_000_000
    } else if v < 0.0 {
        -1_000_000_000_000
    } else {
        0 // NaN
    }
}

/// Grid geometry helper.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Grid {
    pub(crate) cols: usize,
    pub(crate) rows: usize,
    pub(crate) gw: f64,
    pub(crate) gh: f64,
}

impl Grid {
    fn new(w: f64, h: f64, cols: usize, rows: usize) -> Self {
        Self {
            cols,
            rows,
            gw: w / cols as f64,
            gh: h / rows as f64,
        }
    }

    /// Clamped cell (row, col) of a point.
    #[inline]
    fn cell(&self, x: f64, y: f64) -> (u32, u32) {
        let (r, c) = self.raw_cell(x, y);
        (
            r.clamp(0, self.rows as i64 - 1) as u32,
            c.clamp(0, self.cols as i64 - 1) as u32,
        )
    }

    /// Unclamped (row, col) of a point, as plc_client_os computes it (`floor(y/gh)`,
    /// `floor(x/gw)`), saturated to a sane range.
    #[inline]
    fn raw_cell(&self, x: f64, y: f64) -> (i64, i64) {
        (floor_i64(y / self.gh), floor_i64(x / self.gw))
    }

    /// Cell rectangle covered by a box, plc_client_os style (None when it lies below/left).
    #[inline]
    fn range(
        &self,
        xmin: f64,
        ymin: f64,
        xmax: f64,
        ymax: f64,
    ) -> Option<(usize, usize, usize, usize)> {
        let ur_r = floor_f64(ymax / self.gh);
        let ur_c = floor_f64(xmax / self.gw);
        if !(ur_r >= 0.0 && ur_c >= 0.0) {
            return None;
        }
        let bl_r = floor_f64(ymin / self.gh).max(0.0);
        let bl_c = floor_f64(xmin / self.gw).max(0.0);
        if bl_r.is_nan() || bl_c.is_nan() {
            return None;
        }
        let ur_r = (ur_r.min(1e12) as usize).min(self.rows - 1);
        let ur_c = (ur_c.min(1e12) as usize).min(self.cols - 1);
        let bl_r = bl_r.min(1e12) as usize;
        let bl_c = bl_c.min(1e12) as usize;
        Some((bl_r, bl_c, ur_r, ur_c))
    }
}

/// The placement cost of a netlist, with incremental updates.
///
/// ```
/// use a2perf_circuit::{CostSettings, Netlist, PlacementCost, SoftMacroRule};
/// let text = r#"
/// node { name: "M0" attr { key: "type" value { placeholder: "MACRO" } }
///   attr { key: "width" value { f: 10 } } attr { key: "height" value { f: 10 } }
///   attr { key: "x" value { f: 25 } } attr { key: "y" value { f: 25 } } }
/// node { name: "M0/P" input: "P0" attr { key: "type" value { placeholder: "MACRO_PIN" } }
///   attr { key: "macro_name" value { placeholder: "M0" } } }
/// node { name: "P0" attr { key: "type" value { placeholder: "PORT" } }
///   attr { key: "x" value { f: 0 } } attr { key: "y" value { f: 0 } } }
/// "#;
/// let netlist = Netlist::parse(text, SoftMacroRule::default()).unwrap();
/// let mut s = CostSettings::google_binary_defaults(&netlist);
/// (s.canvas_width, s.canvas_height) = (100.0, 100.0);
/// let mut cost = PlacementCost::new(&netlist, s).unwrap();
/// assert_eq!(cost.wirelength(), 50.0);
/// cost.set_position(0, 75.0, 25.0); // incremental
/// assert_eq!(cost.wirelength(), 100.0);
/// assert!(cost.costs().proxy_cost > 0.0);
/// ```
#[derive(Clone, Debug)]
pub struct PlacementCost {
    pub(crate) settings: CostSettings,
    pub(crate) pgrid: Grid,
    pub(crate) cgrid: Grid,
    pub(crate) kind: Vec<NodeKind>,
    pub(crate) x: Vec<f64>,
    pub(crate) y: Vec<f64>,
    pub(crate) w: Vec<f64>,
    pub(crate) h: Vec<f64>,
    pub(crate) orient: Vec<Orientation>,
    pub(crate) placed: Vec<bool>,
    pub(crate) fixed: Vec<bool>,
    // Nets (CSR over pins, driver first).
    pub(crate) net_start: Vec<u32>,
    pub(crate) net_w: Vec<f64>,
    pub(crate) net_cw: Vec<f64>,
    pub(crate) net_hpwl: Vec<f64>,
    pub(crate) net_count: f64,
    pub(crate) wl_total: f64,
    pub(crate) pin_owner: Vec<u32>,
    pub(crate) pin_ox: Vec<f64>,
    pub(crate) pin_oy: Vec<f64>,
    pub(crate) pin_rot: Vec<bool>,
    // Offsets in the owner's current orientation (−0.0 for pins at the owner's centre, so that
    // `x + offset` is exactly `x`); refreshed when an orientation changes.
    pub(crate) pin_rdx: Vec<f64>,
    pub(crate) pin_rdy: Vec<f64>,
    pub(crate) offsets_dirty: bool,
    pub(crate) pin_x: Vec<f64>,
    pub(crate) pin_y: Vec<f64>,
    pub(crate) pin_cell: Vec<(i64, i64)>,
    // Node → pins, node → nets (CSR).
    pub(crate) node_pin_start: Vec<u32>,
    pub(crate) node_pins: Vec<u32>,
    pub(crate) node_net_start: Vec<u32>,
    pub(crate) node_nets: Vec<u32>,
    // Objects with area, in density order (soft macros, hard macros, standard cells).
    pub(crate) area_nodes: Vec<u32>,
    pub(crate) hard_macros: Vec<u32>,
    // Blockage rectangles `[minx, miny, maxx, maxy]` that hard macros may not overlap.
    pub(crate) macro_blockages: Vec<[f64; 4]>,
    pub(crate) blockages: Vec<Blockage>,
    // Grids.
    pub(crate) occupied: Vec<f64>,
    pub(crate) h_net: Vec<f64>,
    // Column-major (`col·rows + row`), so that a vertical run is contiguous.
    pub(crate) v_net: Vec<f64>,
    pub(crate) h_macro: Vec<f64>,
    pub(crate) v_macro: Vec<f64>,
    pub(crate) macro_dirty: bool,
    // Scratch.
    pub(crate) cells: Vec<(i64, i64)>,
    // Per congestion cell: generation of the last net that touched it (distinct-cell sets).
    pub(crate) stamp: Vec<u32>,
    pub(crate) stamp_gen: u32,
    pub(crate) h_tot: Vec<f64>,
    pub(crate) v_tot: Vec<f64>,
    pub(crate) sort_buf: Vec<f64>,
    pub(crate) scratch_f64: Vec<f64>,
}

/// A source cell's share of routing demand `raw` spread over `n` cells after normalising by
/// `routes`; zero for an empty cell, which the reference skips (adding `+0.0` to a sum that
/// started at `+0.0` leaves it unchanged, so skipping and adding agree bit for bit).
#[inline(always)]
fn spread_share(raw: f64, routes: f64, n: usize) -> f64 {
    if raw == 0.0 {
        0.0
    } else {
        (raw / routes) / n as f64
    }
}

/// circuit_training's smoothed routing demand: the vertical demand `v_net` (column-major,
/// `col·rows + row`) normalised by `vr` and spread along each row over `±k` columns, into
/// `v_out`; the horizontal demand `h_net` (row-major) normalised by `hr` and spread along each
/// column over `±k` rows, into `h_out` (both row-major). Each source's share is split evenly
/// over the cells of its window that exist.
///
/// Each cell's sum runs over its sources in ascending order from `+0.0`, as the reference's
/// loop over sources adds them, so the result is the same bit for bit; it is written as one
/// shifted slice addition per window offset (a whole row at a time for `h`), which vectorizes.
fn smooth_demand(
    (v_net, h_net): (&[f64], &[f64]),
    (cols, rows, k): (usize, usize, usize),
    (vr, hr): (f64, f64),
    val: &mut Vec<f64>,
    (v_out, h_out): (&mut [f64], &mut [f64]),
) {
    val.clear();
    val.resize(cols, 0.0);
    for r in 0..rows {
        for (c, v) in val.iter_mut().enumerate() {
            let n = (c + k).min(cols - 1) - c.saturating_sub(k) + 1;
            *v = spread_share(v_net[c * rows + r], vr, n);
        }
        let o = &mut v_out[r * cols..(r + 1) * cols];
        o.fill(0.0);
        // Target `t` takes source `t + j − k`: ascending sources for ascending `j`.
        for j in 0..=2 * k {
            let (s, right) = if j <= k {
                (k - j, true)
            } else {
                (j - k, false)
            };
            if s >= cols {
                continue;
            }
            let (o, v) = if right {
                (&mut o[s..], &val[..cols - s])
            } else {
                (&mut o[..cols - s], &val[s..])
            };
            for (o, v) in o.iter_mut().zip(v) {
                *o += v;
            }
        }
    }
    val.clear();
    val.extend((0..rows).flat_map(|r| {
        let n = (r + k).min(rows - 1) - r.saturating_sub(k) + 1;
        h_net[r * cols..(r + 1) * cols]
            .iter()
            .map(move |&raw| spread_share(raw, hr, n))
    }));
    h_out.fill(0.0);
    for (t, o) in h_out.chunks_exact_mut(cols).enumerate() {
        for s in t.saturating_sub(k)..(t + k + 1).min(rows) {
            for (o, v) in o.iter_mut().zip(&val[s * cols..(s + 1) * cols]) {
                *o += v;
            }
        }
    }
}

/// Mean of the `k` largest values (sequential sum in descending order, like the reference);
/// `k == 0` → max.
fn top_mean(values: &[f64], frac: f64, buf: &mut Vec<f64>) -> f64 {
    if values.is_empty() {
        return 0.0;
    }
    let k = (values.len() as f64 * frac).floor() as usize;
    buf.clear();
    buf.extend_from_slice(values);
    if k == 0 {
        return buf.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    }
    if k < buf.len() {
        buf.select_nth_unstable_by(k - 1, |a, b| b.total_cmp(a));
    }
    let top = &mut buf[..k];
    top.sort_unstable_by(|a, b| b.total_cmp(a));
    top.iter().sum::<f64>() / k as f64
}

impl PlacementCost {
    /// Builds the cost model of `netlist` at its netlist coordinates (all nodes placed).
    pub fn new(netlist: &Netlist, settings: CostSettings) -> Result<Self, CostError> {
        settings.validate()?;
        let n = netlist.nodes.len();
        let pgrid = Grid::new(
            settings.canvas_width,
            settings.canvas_height,
            settings.grid_cols,
            settings.grid_rows,
        );
        let (cc, cr) = settings
            .congestion_grid
            .unwrap_or((settings.grid_cols, settings.grid_rows));
        let cgrid = Grid::new(settings.canvas_width, settings.canvas_height, cc, cr);
        let mut kind = Vec::with_capacity(n);
        let mut x = Vec::with_capacity(n);
        let mut y = Vec::with_capacity(n);
        let mut w = Vec::with_capacity(n);
        let mut h = Vec::with_capacity(n);
        let mut orient = Vec::with_capacity(n);
        for node in &netlist.nodes {
            kind.push(node.kind);
            x.push(node.x);
            y.push(node.y);
            let (mut nw, mut nh) = (node.width, node.height);
            if settings.make_soft_macros_square && node.kind == NodeKind::SoftMacro {
                let s = (nw * nh).sqrt();
                nw = s;
                nh = s;
            }
            w.push(nw);
            h.push(nh);
            orient.push(node.orientation);
        }
        let mut net_start = vec![0u32];
        let mut net_w = Vec::new();
        let mut net_cw = Vec::new();
        let mut pin_owner = Vec::new();
        let mut pin_ox = Vec::new();
        let mut pin_oy = Vec::new();
        let mut pin_rot = Vec::new();
        for net in &netlist.nets {
            for &p in std::iter::once(&net.driver).chain(&net.sinks) {
                let node = &netlist.nodes[p];
                match (node.kind, node.macro_index) {
                    (NodeKind::HardMacroPin, Some(m)) => {
                        pin_owner.push(m as u32);
                        pin_ox.push(node.x_offset);
                        pin_oy.push(node.y_offset);
                        pin_rot.push(true);
                    }
                    (NodeKind::SoftMacroPin, Some(m)) => {
                        pin_owner.push(m as u32);
                        pin_ox.push(0.0);
                        pin_oy.push(0.0);
                        pin_rot.push(false);
                    }
                    _ => {
                        pin_owner.push(p as u32);
                        pin_ox.push(0.0);
                        pin_oy.push(0.0);
                        pin_rot.push(false);
                    }
                }
            }
            net_start.push(pin_owner.len() as u32);
            net_w.push(net.weight);
            let driver_kind = netlist.nodes[net.driver].kind;
            net_cw.push(if driver_kind == NodeKind::Port {
                1.0
            } else {
                net.congestion_weight
            });
        }
        let npins = pin_owner.len();
        // Node → pins / nets.
        let mut counts = vec![0u32; n + 1];
        for &o in &pin_owner {
            counts[o as usize + 1] += 1;
        }
        for i in 0..n {
            counts[i + 1] += counts[i];
        }
        let node_pin_start = counts.clone();
        let mut fill = counts;
        let mut node_pins = vec![0u32; npins];
        for (p, &o) in pin_owner.iter().enumerate() {
            node_pins[fill[o as usize] as usize] = p as u32;
            fill[o as usize] += 1;
        }
        let mut pin_net = vec![0u32; npins];
        for ni in 0..net_w.len() {
            for p in net_start[ni]..net_start[ni + 1] {
                pin_net[p as usize] = ni as u32;
            }
        }
        let mut node_net_start = vec![0u32];
        let mut node_nets = Vec::new();
        for i in 0..n {
            let start = node_nets.len();
            for &p in &node_pins[node_pin_start[i] as usize..node_pin_start[i + 1] as usize] {
                node_nets.push(pin_net[p as usize]);
            }
            node_nets[start..].sort_unstable();
            let mut k = start;
            for j in start..node_nets.len() {
                if j == start || node_nets[j] != node_nets[k - 1] {
                    node_nets[k] = node_nets[j];
                    k += 1;
                }
            }
            node_nets.truncate(k);
            node_net_start.push(node_nets.len() as u32);
        }
        let mut area_nodes = Vec::new();
        for k in [NodeKind::SoftMacro, NodeKind::HardMacro, NodeKind::StdCell] {
            area_nodes.extend(
                kind.iter()
                    .enumerate()
                    .filter(|(_, kk)| **kk == k)
                    .map(|(i, _)| i as u32),
            );
        }
        let hard_macros = kind
            .iter()
            .enumerate()
            .filter(|(_, k)| **k == NodeKind::HardMacro)
            .map(|(i, _)| i as u32)
            .collect();
        let pcells = pgrid.cols * pgrid.rows;
        let ccells = cgrid.cols * cgrid.rows;
        let nets = net_w.len();
        let mut me = Self {
            net_count: {
                let s: f64 = net_w.iter().sum();
                if s == 0.0 { 1.0 } else { s }
            },
            wl_total: 0.0,
            settings,
            pgrid,
            cgrid,
            fixed: kind.iter().map(|k| *k == NodeKind::Port).collect(),
            placed: vec![true; n],
            kind,
            x,
            y,
            w,
            h,
            orient,
            net_start,
            net_w,
            net_cw,
            net_hpwl: vec![0.0; nets],
            pin_owner,
            pin_ox,
            pin_oy,
            pin_rot,
            pin_rdx: vec![-0.0; npins],
            pin_rdy: vec![-0.0; npins],
            offsets_dirty: true,
            pin_x: vec![0.0; npins],
            pin_y: vec![0.0; npins],
            pin_cell: vec![(0, 0); npins],
            node_pin_start,
            node_pins,
            node_net_start,
            node_nets,
            area_nodes,
            hard_macros,
            macro_blockages: Vec::new(),
            blockages: Vec::new(),
            occupied: vec![0.0; pcells],
            h_net: vec![0.0; ccells],
            v_net: vec![0.0; ccells],
            h_macro: vec![0.0; ccells],
            v_macro: vec![0.0; ccells],
            macro_dirty: true,
            cells: Vec::with_capacity(64),
            stamp: vec![0; ccells],
            stamp_gen: 0,
            h_tot: vec![0.0; ccells],
            v_tot: vec![0.0; ccells],
            sort_buf: Vec::with_capacity(2 * ccells),
            scratch_f64: Vec::with_capacity(2 * ccells.max(pcells)),
        };
        me.recompute();
        Ok(me)
    }

    /// The settings in force.
    pub fn settings(&self) -> &CostSettings {
        &self.settings
    }

    /// Number of nodes.
    pub fn num_nodes(&self) -> usize {
        self.kind.len()
    }

    /// Kind of node `i`.
    pub fn kind(&self, i: usize) -> NodeKind {
        self.kind[i]
    }

    /// Centre of node `i`.
    pub fn position(&self, i: usize) -> (f64, f64) {
        (self.x[i], self.y[i])
    }

    /// Size of node `i` (after squaring soft macros).
    pub fn size(&self, i: usize) -> (f64, f64) {
        (self.w[i], self.h[i])
    }

    /// Orientation of node `i`.
    pub fn orientation(&self, i: usize) -> Orientation {
        self.orient[i]
    }

    /// Whether node `i` is placed (unplaced hard macros count in neither density nor routing
    /// allocation; their pins still sit at their last position).
    pub fn is_placed(&self, i: usize) -> bool {
        self.placed[i]
    }

    /// Whether node `i` is fixed.
    pub fn is_fixed(&self, i: usize) -> bool {
        self.fixed[i]
    }

    /// Sets the fixed flag.
    pub fn set_fixed(&mut self, i: usize, fixed: bool) {
        self.fixed[i] = fixed;
    }

    /// Placement grid `(cols, rows)`.
    pub fn grid(&self) -> (usize, usize) {
        (self.pgrid.cols, self.pgrid.rows)
    }

    /// Congestion grid `(cols, rows)`.
    pub fn congestion_grid(&self) -> (usize, usize) {
        (self.cgrid.cols, self.cgrid.rows)
    }

    /// Centre of placement-grid cell `cell`.
    pub fn cell_center(&self, cell: usize) -> (f64, f64) {
        let r = cell / self.pgrid.cols;
        let c = cell % self.pgrid.cols;
        (
            self.pgrid.gw * c as f64 + self.pgrid.gw / 2.0,
            self.pgrid.gh * r as f64 + self.pgrid.gh / 2.0,
        )
    }

    /// Placement-grid cell of a point (clamped).
    pub fn cell_of(&self, x: f64, y: f64) -> usize {
        let (r, c) = self.pgrid.cell(x, y);
        r as usize * self.pgrid.cols + c as usize
    }

    /// Node indices of hard macros (ascending).
    pub fn hard_macros(&self) -> &[u32] {
        &self.hard_macros
    }

    /// Sets the placement blockages (`# Blockage : minx miny maxx maxy rate`).
    ///
    /// As circuit_training documents them (`placement_util`: rate 0.1 = "not macro overlap but
    /// allow stdcells", 0.99 = "no macros or stdcells", 1.0 = rectilinear floorplan), every
    /// blockage with a positive rate forbids hard-macro overlap: [`PlacementCost::node_mask`]
    /// masks each cell where the macro's footprint would overlap one with positive area
    /// (touching allowed). A rate of 0 blocks nothing. Blockages do not enter the wirelength,
    /// density or congestion costs (plc_client_os, which matches Google's costs, ignores them
    /// there) nor our force-directed placer.
    ///
    /// ```
    /// use a2perf_circuit::{generate, Blockage, GeneratorConfig, PlacementCost};
    /// let g = generate(&GeneratorConfig::small(), 0);
    /// let mut cost = PlacementCost::new(&g.netlist, g.settings.clone()).unwrap();
    /// let (w, h) = (g.settings.canvas_width, g.settings.canvas_height);
    /// // Block the whole canvas: no cell is legal for any hard macro.
    /// cost.set_blockages(&[Blockage { rect: [0.0, 0.0, w, h, 1.0] }]);
    /// let m = cost.hard_macros()[0] as usize;
    /// let (c, r) = cost.grid();
    /// let mut mask = vec![false; c * r];
    /// cost.node_mask(m, &mut mask);
    /// assert!(mask.iter().all(|legal| !legal));
    /// ```
    pub fn set_blockages(&mut self, blockages: &[Blockage]) {
        self.blockages = blockages.to_vec();
        self.macro_blockages = blockages
            .iter()
            .filter(|b| b.rect[4] > 0.0 && b.rect[..4].iter().all(|v| v.is_finite()))
            .map(|b| [b.rect[0], b.rect[1], b.rect[2], b.rect[3]])
            .collect();
    }

    /// The blockages in force.
    pub fn blockages(&self) -> &[Blockage] {
        &self.blockages
    }

    /// Applies a `.plc` placement (positions, orientations, fixed flags, and its header's
    /// blockages when it has any).
    pub fn apply_placement(&mut self, plc: &Placement) -> Result<(), CostError> {
        for e in &plc.entries {
            self.check_entry(e)?;
        }
        if !plc.header.blockages.is_empty() {
            self.set_blockages(&plc.header.blockages);
        }
        for e in &plc.entries {
            self.x[e.index] = e.x;
            self.y[e.index] = e.y;
            if let Some(o) = e.orientation
                && self.kind[e.index] == NodeKind::HardMacro
            {
                self.orient[e.index] = o;
                self.offsets_dirty = true;
            }
            self.fixed[e.index] = e.fixed || self.kind[e.index] == NodeKind::Port;
            self.placed[e.index] = true;
        }
        self.recompute();
        Ok(())
    }

    fn check_entry(&self, e: &PlcEntry) -> Result<(), CostError> {
        let bad = |reason: &str| CostError::BadNode {
            index: e.index,
            reason: reason.to_string(),
        };
        let Some(k) = self.kind.get(e.index) else {
            return Err(bad(&format!(
                "no such node (the netlist has {})",
                self.kind.len()
            )));
        };
        if k.is_pin() {
            return Err(bad("is a macro pin; pins move with their macro"));
        }
        Ok(())
    }

    /// The current placement as a `.plc` (ports, macros and standard cells).
    pub fn to_placement(&self, comments: Vec<String>) -> Placement {
        let entries = (0..self.kind.len())
            .filter(|&i| !self.kind[i].is_pin())
            .map(|i| PlcEntry {
                index: i,
                x: self.x[i],
                y: self.y[i],
                orientation: match self.kind[i] {
                    NodeKind::HardMacro | NodeKind::SoftMacro => Some(self.orient[i]),
                    _ => None,
                },
                fixed: self.fixed[i],
            })
            .collect();
        let mut p = Placement {
            comments,
            header: PlcHeader::default(),
            entries,
        };
        p.header = Placement::parse(&p.to_text())
            .map(|q| q.header)
            .unwrap_or_default();
        p
    }

    /// Re-derives pin `p`'s offset from its owner's orientation.
    #[inline]
    fn refresh_offset(&mut self, p: usize) {
        if self.pin_rot[p] {
            let o = self.pin_owner[p] as usize;
            (self.pin_rdx[p], self.pin_rdy[p]) =
                self.orient[o].apply(self.pin_ox[p], self.pin_oy[p]);
        }
    }

    #[inline]
    fn update_pin(&mut self, p: usize) {
        let o = self.pin_owner[p] as usize;
        let (px, py) = (self.x[o] + self.pin_rdx[p], self.y[o] + self.pin_rdy[p]);
        self.pin_x[p] = px;
        self.pin_y[p] = py;
        self.pin_cell[p] = self.cgrid.raw_cell(px, py);
    }

    fn net_hpwl(&self, n: usize) -> f64 {
        let (s, e) = (self.net_start[n] as usize, self.net_start[n + 1] as usize);
        let (mut x0, mut x1, mut y0, mut y1) = (
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::INFINITY,
            f64::NEG_INFINITY,
        );
        // Plain comparisons (NaN pins are ignored, as by f64::min/max) are much cheaper than the
        // NaN-aware f64::min/max sequences.
        for (&px, &py) in self.pin_x[s..e].iter().zip(&self.pin_y[s..e]) {
            if px < x0 {
                x0 = px;
            }
            if px > x1 {
                x1 = px;
            }
            if py < y0 {
                y0 = py;
            }
            if py > y1 {
                y1 = py;
            }
        }
        (x1 - x0).abs() + (y1 - y0).abs()
    }

    /// Adds (`sign` = 1) or removes (−1) net `n`'s routing demand.
    ///
    /// Cells are the unclamped (row, col) of each pin and a route's flat index is `row·C + col`
    /// with Python list semantics, exactly as plc_client_os: a pin on the right canvas edge
    /// (`col == C`) lands in the next row's first cell, negative indices count from the end;
    /// indices the reference would reject are skipped.
    fn route_net(&mut self, n: usize, sign: f64) {
        let (s, e) = (self.net_start[n] as usize, self.net_start[n + 1] as usize);
        if e - s == 2 {
            // Most nets have two pins: no set needed.
            let (a, b) = (self.pin_cell[s], self.pin_cell[s + 1]);
            if a != b {
                self.two_pin(a, b, sign * self.net_cw[n]);
            }
            return;
        }
        let w = sign * self.net_cw[n];
        // Only the set of distinct cells (and the driver's) matters: every edge of a net adds the
        // same `w`, so the order in which its edges are routed cannot change a cell's sum.
        // Fast path, all pins on the grid: distinct cells via generation stamps, no sorting.
        let (cols, rows) = (self.cgrid.cols, self.cgrid.rows);
        self.stamp_gen = self.stamp_gen.wrapping_add(1);
        if self.stamp_gen == 0 {
            self.stamp.iter_mut().for_each(|v| *v = 0);
            self.stamp_gen = 1;
        }
        let gen_ = self.stamp_gen;
        let mut cells = std::mem::take(&mut self.cells);
        cells.clear();
        let mut on_grid = true;
        for &c in &self.pin_cell[s..e] {
            if (c.0 as u64) >= rows as u64 || (c.1 as u64) >= cols as u64 {
                on_grid = false;
                break;
            }
            let k = c.0 as usize * cols + c.1 as usize;
            if self.stamp[k] != gen_ {
                self.stamp[k] = gen_;
                cells.push(c);
            }
        }
        if on_grid {
            // `cells[0]` is the driver's cell.
            let src = cells[0];
            match cells.len() {
                0 | 1 => {}
                2 => self.two_pin(src, cells[1], w),
                3 => {
                    let mut g = [cells[0], cells[1], cells[2]];
                    self.three_pin(&mut g, w);
                }
                _ => {
                    for &t in &cells[1..] {
                        self.two_pin(src, t, w);
                    }
                }
            }
            self.cells = cells;
            return;
        }
        self.cells = cells;
        let mut cells = std::mem::take(&mut self.cells);
        cells.clear();
        for p in s..e {
            cells.push(self.pin_cell[p]);
        }
        let src = cells[0];
        cells.sort_unstable();
        cells.dedup();
        match cells.len() {
            0 | 1 => {}
            2 => {
                let t = if cells[0] == src { cells[1] } else { cells[0] };
                self.two_pin(src, t, w);
            }
            3 => {
                let mut g = [cells[0], cells[1], cells[2]];
                self.three_pin(&mut g, w);
            }
            _ => {
                for &t in cells.iter() {
                    if t != src {
                        self.two_pin(src, t, w);
                    }
                }
            }
        }
        self.cells = cells;
    }

    /// Adds `w` to the H cells `(row, c)`, `c ∈ [c0, c1)`, at flat index `row·C + c` with Python
    /// list semantics (negative indices from the end, others out of range skipped).
    #[inline(always)]
    fn add_h(&mut self, row: i64, c0: i64, c1: i64, w: f64) {
        let (cols, rows) = (self.cgrid.cols as i64, self.cgrid.rows as i64);
        if (0..rows).contains(&row) && c0 >= 0 && c1 <= cols {
            // Inside the grid (the common case): one contiguous run.
            let base = (row * cols) as usize;
            if c0 < c1 {
                for v in &mut self.h_net[base + c0 as usize..base + c1 as usize] {
                    *v += w;
                }
            }
        } else {
            self.add_h_wrapped(row, c0, c1, w);
        }
    }

    #[inline(never)]
    fn add_h_wrapped(&mut self, row: i64, c0: i64, c1: i64, w: f64) {
        if c0 >= c1 {
            return;
        }
        let n = self.h_net.len() as i64;
        let base = row.saturating_mul(self.cgrid.cols as i64);
        let lo = c0.max((-n).saturating_sub(base));
        let hi = c1.min(n.saturating_sub(base));
        if lo >= hi {
            return;
        }
        // Now −n ≤ a < b ≤ n; the negative part comes first, as in ascending `c`.
        let (a, b) = (base + lo, base + hi);
        if a < 0 {
            for v in &mut self.h_net[(n + a) as usize..(n + b.min(0)) as usize] {
                *v += w;
            }
        }
        if b > 0 {
            for v in &mut self.h_net[a.max(0) as usize..b as usize] {
                *v += w;
            }
        }
    }

    /// Adds `w` to the V cells `(r, col)`, `r ∈ [r0, r1)`, with the same index semantics.
    #[inline(always)]
    fn add_v(&mut self, col: i64, r0: i64, r1: i64, w: f64) {
        let (cols, rows) = (self.cgrid.cols as i64, self.cgrid.rows as i64);
        if (0..cols).contains(&col) && r0 >= 0 && r1 <= rows {
            // Inside the grid (the common case).
            let base = (col * rows) as usize;
            for v in &mut self.v_net[base + r0 as usize..base + r1 as usize] {
                *v += w;
            }
        } else {
            self.add_v_wrapped(col, r0, r1, w);
        }
    }

    #[inline(never)]
    fn add_v_wrapped(&mut self, col: i64, r0: i64, r1: i64, w: f64) {
        if r0 >= r1 {
            return;
        }
        let cols = self.cgrid.cols as i64;
        let n = self.v_net.len() as i64;
        let ceil_div = |a: i64| -((-a).div_euclid(cols));
        // Rows whose flat index is in [−n, 0) (wrapped) precede those in [0, n).
        let parts = [
            (ceil_div(-n - col), (-1 - col).div_euclid(cols) + 1, n),
            (ceil_div(-col), (n - 1 - col).div_euclid(cols) + 1, 0),
        ];
        for (lo, hi, off) in parts {
            let (lo, hi) = (lo.max(r0), hi.min(r1));
            if lo >= hi {
                continue;
            }
            let rows = self.cgrid.rows as i64;
            for r in lo..hi {
                // Flat row-major index → the (row, col) it designates → column-major slot.
                let flat = r * cols + col + off;
                let (fr, fc) = (flat / cols, flat % cols);
                self.v_net[(fc * rows + fr) as usize] += w;
            }
        }
    }

    #[inline(always)]
    fn two_pin(&mut self, s: (i64, i64), t: (i64, i64), w: f64) {
        let (cols, rows) = (self.cgrid.cols, self.cgrid.rows);
        let inside = |c: (i64, i64)| (c.0 as u64) < rows as u64 && (c.1 as u64) < cols as u64;
        if inside(s) && inside(t) {
            // Both cells on the grid (the common case): no index wrapping to consider.
            let base = s.0 as usize * cols;
            let (c0, c1) = (s.1.min(t.1) as usize, s.1.max(t.1) as usize);
            for v in &mut self.h_net[base + c0..base + c1] {
                *v += w;
            }
            let (r0, r1) = (s.0.min(t.0) as usize, s.0.max(t.0) as usize);
            let base = t.1 as usize * rows;
            for v in &mut self.v_net[base + r0..base + r1] {
                *v += w;
            }
            return;
        }
        self.add_h(s.0, s.1.min(t.1), s.1.max(t.1), w);
        self.add_v(t.1, s.0.min(t.0), s.0.max(t.0), w);
    }

    /// The 3-pin L/T decomposition; cells are (row, col).
    fn three_pin(&mut self, g: &mut [(i64, i64); 3], w: f64) {
        g.sort_by_key(|&(r, c)| (c, r));
        let [(y1, x1), (y2, x2), (y3, x3)] = *g;
        if x1 < x2 && x2 < x3 && y1.min(y3) < y2 && y1.max(y3) > y2 {
            self.add_h(y1, x1, x2, w);
            self.add_h(y2, x2, x3, w);
            self.add_v(x2, y1.min(y2), y1.max(y2), w);
            self.add_v(x3, y2.min(y3), y2.max(y3), w);
        } else if x2 == x3 && x1 < x2 && y1 < y2.min(y3) {
            self.add_h(y1, x1, x2, w);
            self.add_v(x2, y1, y2.max(y3), w);
        } else if y2 == y3 {
            self.add_h(y1, x1, x2, w);
            self.add_h(y2, x2, x3, w);
            self.add_v(x2, y1.min(y2), y1.max(y2), w);
        } else {
            g.sort();
            let [(y1, x1), (y2, x2), (y3, x3)] = *g;
            let xmin = x1.min(x2).min(x3);
            let xmax = x1.max(x2).max(x3);
            self.add_h(y2, xmin, xmax, w);
            self.add_v(x1, y1.min(y2), y1.max(y2), w);
            self.add_v(x3, y2.min(y3), y2.max(y3), w);
        }
    }

    fn counts_in_density(&self, i: usize) -> bool {
        self.kind[i].has_area() && (self.placed[i] || self.kind[i] != NodeKind::HardMacro)
    }

    /// Adds (`sign` 1) or removes (−1) node `i`'s footprint from the density grid.
    fn add_density(&mut self, i: usize, sign: f64) {
        let g = self.pgrid;
        let (xmin, xmax) = (self.x[i] - self.w[i] / 2.0, self.x[i] + self.w[i] / 2.0);
        let (ymin, ymax) = (self.y[i] - self.h[i] / 2.0, self.y[i] + self.h[i] / 2.0);
        let Some((r0, c0, r1, c1)) = g.range(xmin, ymin, xmax, ymax) else {
            return;
        };
        for r in r0..=r1 {
            let (cy0, cy1) = (r as f64 * g.gh, (r + 1) as f64 * g.gh);
            let dy = ymax.min(cy1) - ymin.max(cy0);
            for c in c0..=c1 {
                let (cx0, cx1) = (c as f64 * g.gw, (c + 1) as f64 * g.gw);
                let dx = xmax.min(cx1) - xmin.max(cx0);
                if dx >= 0.0 && dy >= 0.0 {
                    self.occupied[r * g.cols + c] += sign * (dx * dy);
                }
            }
        }
    }

    /// Recomputes every cached quantity from the positions.
    pub fn recompute(&mut self) {
        if self.offsets_dirty {
            for p in 0..self.pin_owner.len() {
                self.refresh_offset(p);
            }
            self.offsets_dirty = false;
        }
        let g = self.cgrid;
        let (x, y) = (&self.x[..], &self.y[..]);
        for (((((&o, &dx), &dy), px), py), cell) in self
            .pin_owner
            .iter()
            .zip(&self.pin_rdx)
            .zip(&self.pin_rdy)
            .zip(&mut self.pin_x)
            .zip(&mut self.pin_y)
            .zip(&mut self.pin_cell)
        {
            let o = o as usize;
            *px = x[o] + dx;
            *py = y[o] + dy;
            *cell = g.raw_cell(*px, *py);
        }
        self.h_net.iter_mut().for_each(|v| *v = 0.0);
        self.v_net.iter_mut().for_each(|v| *v = 0.0);
        for n in 0..self.net_w.len() {
            self.net_hpwl[n] = self.net_hpwl(n);
            self.route_net(n, 1.0);
        }
        self.wl_total = self
            .net_w
            .iter()
            .zip(&self.net_hpwl)
            .map(|(w, h)| w * h)
            .sum();
        self.occupied.iter_mut().for_each(|v| *v = 0.0);
        for k in 0..self.area_nodes.len() {
            let i = self.area_nodes[k] as usize;
            if self.counts_in_density(i) {
                self.add_density(i, 1.0);
            }
        }
        self.macro_dirty = true;
    }

    /// Moves node `i`'s centre to `(x, y)`, updating all costs incrementally.
    pub fn set_position(&mut self, i: usize, x: f64, y: f64) {
        self.change_node(i, |me| {
            me.x[i] = x;
            me.y[i] = y;
        });
    }

    /// Changes node `i`'s orientation (hard macros), updating incrementally.
    pub fn set_orientation(&mut self, i: usize, o: Orientation) {
        self.change_node(i, |me| {
            me.orient[i] = o;
            for k in me.node_pin_start[i] as usize..me.node_pin_start[i + 1] as usize {
                let p = me.node_pins[k] as usize;
                me.refresh_offset(p);
            }
        });
    }

    /// Places node `i` at the centre of placement-grid `cell`.
    pub fn place_at_cell(&mut self, i: usize, cell: usize) {
        let (x, y) = self.cell_center(cell);
        self.change_node(i, |me| {
            me.x[i] = x;
            me.y[i] = y;
            me.placed[i] = true;
        });
    }

    /// Marks node `i` placed/unplaced (hard macros: whether they count in density and routing
    /// allocation).
    pub fn set_placed(&mut self, i: usize, placed: bool) {
        if self.placed[i] != placed {
            self.change_node(i, |me| me.placed[i] = placed);
        }
    }

    fn change_node(&mut self, i: usize, f: impl FnOnce(&mut Self)) {
        let (ns, ne) = (
            self.node_net_start[i] as usize,
            self.node_net_start[i + 1] as usize,
        );
        for k in ns..ne {
            let n = self.node_nets[k] as usize;
            self.route_net(n, -1.0);
        }
        let dens = self.counts_in_density(i);
        if dens {
            self.add_density(i, -1.0);
        }
        f(self);
        for k in self.node_pin_start[i] as usize..self.node_pin_start[i + 1] as usize {
            let p = self.node_pins[k] as usize;
            self.update_pin(p);
        }
        for k in ns..ne {
            let n = self.node_nets[k] as usize;
            let before = self.net_hpwl[n];
            self.net_hpwl[n] = self.net_hpwl(n);
            // Running total (exact sum restored by `recompute`).
            self.wl_total += self.net_w[n] * (self.net_hpwl[n] - before);
            self.route_net(n, 1.0);
        }
        if self.counts_in_density(i) {
            self.add_density(i, 1.0);
        }
        if self.kind[i] == NodeKind::HardMacro {
            self.macro_dirty = true;
        }
    }

    /// Σ w·HPWL over nets (maintained incrementally; exact after [`PlacementCost::recompute`]).
    pub fn wirelength(&self) -> f64 {
        self.wl_total
    }

    /// Σ net weights.
    pub fn net_count(&self) -> f64 {
        self.net_count
    }

    /// Wirelength cost.
    pub fn wirelength_cost(&self) -> f64 {
        self.wirelength()
            / ((self.settings.canvas_width + self.settings.canvas_height) * self.net_count)
    }

    /// Per-cell density (occupied area / cell area), row-major, into `out`.
    pub fn density_cells(&self, out: &mut Vec<f64>) {
        let area = self.pgrid.gw * self.pgrid.gh;
        out.clear();
        out.extend(self.occupied.iter().map(|a| a / area));
    }

    /// Density cost: 0.5 · mean of the top ⌊0.1·n⌋ cells (0.5 · mean of non-zero cells when
    /// ⌊0.1·n⌋ = 0, like plc_client_os).
    pub fn density_cost(&mut self) -> f64 {
        let area = self.pgrid.gw * self.pgrid.gh;
        let n = self.occupied.len();
        let k = (n as f64 * 0.1).floor() as usize;
        let mut buf = std::mem::take(&mut self.sort_buf);
        buf.clear();
        buf.extend(self.occupied.iter().map(|a| a / area));
        let out = if k == 0 {
            let nz: Vec<f64> = buf.iter().copied().filter(|v| *v != 0.0).collect();
            if nz.is_empty() {
                0.0
            } else {
                0.5 * (nz.iter().sum::<f64>() / nz.len() as f64)
            }
        } else {
            let mut tmp = std::mem::take(&mut self.scratch_f64);
            let v = top_mean(&buf, 0.1, &mut tmp);
            self.scratch_f64 = tmp;
            0.5 * v
        };
        self.sort_buf = buf;
        out
    }

    fn macro_route(&mut self) {
        let g = self.cgrid;
        self.h_macro.iter_mut().for_each(|v| *v = 0.0);
        self.v_macro.iter_mut().for_each(|v| *v = 0.0);
        let (halloc, valloc) = (self.settings.hrouting_alloc, self.settings.vrouting_alloc);
        let dist = |a0: f64, a1: f64, b0: f64, b1: f64| a1.min(b1) - a0.max(b0);
        for k in 0..self.hard_macros.len() {
            let i = self.hard_macros[k] as usize;
            if !self.placed[i] {
                continue;
            }
            let (xmin, xmax) = (self.x[i] - self.w[i] / 2.0, self.x[i] + self.w[i] / 2.0);
            let (ymin, ymax) = (self.y[i] - self.h[i] / 2.0, self.y[i] + self.h[i] / 2.0);
            let Some((r0, c0, r1, c1)) = g.range(xmin, ymin, xmax, ymax) else {
                continue;
            };
            let od = |r: usize, c: usize| {
                let dx = dist(xmin, xmax, c as f64 * g.gw, (c + 1) as f64 * g.gw);
                let dy = dist(ymin, ymax, r as f64 * g.gh, (r + 1) as f64 * g.gh);
                if dx > 0.0 && dy > 0.0 {
                    (dx, dy)
                } else {
                    (0.0, 0.0)
                }
            };
            let mut partial_v = false;
            let mut partial_h = false;
            for r in r0..=r1 {
                for c in c0..=c1 {
                    let (dx, dy) = od(r, c);
                    if r1 != r0 && (r == r0 || r == r1) && (dy - g.gh).abs() > 1e-5 {
                        partial_v = true;
                    }
                    if c1 != c0 && (c == c0 || c == c1) && (dx - g.gw).abs() > 1e-5 {
                        partial_h = true;
                    }
                    self.v_macro[r * g.cols + c] += dx * valloc;
                    self.h_macro[r * g.cols + c] += dy * halloc;
                }
            }
            if partial_v && r0 <= r1 {
                for c in c0..=c1 {
                    let (dx, _) = od(r1, c);
                    self.v_macro[r1 * g.cols + c] -= dx * valloc;
                }
            }
            if partial_h && c0 <= c1 {
                for r in r0..=r1 {
                    let (_, dy) = od(r, c1);
                    self.h_macro[r * g.cols + c1] -= dy * halloc;
                }
            }
        }
        let vr = g.gw * self.settings.vroutes_per_micron;
        let hr = g.gh * self.settings.hroutes_per_micron;
        self.v_macro.iter_mut().for_each(|v| *v /= vr);
        self.h_macro.iter_mut().for_each(|v| *v /= hr);
        self.macro_dirty = false;
    }

    /// Computes the total H and V congestion per congestion-grid cell (net routing normalised and
    /// smoothed, plus hard-macro allocation) into internal buffers and returns them `(H, V)`.
    pub fn congestion_maps(&mut self) -> (&[f64], &[f64]) {
        if self.macro_dirty {
            self.macro_route();
        }
        let g = self.cgrid;
        let vr = g.gw * self.settings.vroutes_per_micron;
        let hr = g.gh * self.settings.hroutes_per_micron;
        let k = self.settings.smooth_range.floor() as usize;
        let mut val = std::mem::take(&mut self.scratch_f64);
        smooth_demand(
            (&self.v_net, &self.h_net),
            (g.cols, g.rows, k),
            (vr, hr),
            &mut val,
            (&mut self.v_tot, &mut self.h_tot),
        );
        self.scratch_f64 = val;
        for (t, m) in self.v_tot.iter_mut().zip(&self.v_macro) {
            *t += m;
        }
        for (t, m) in self.h_tot.iter_mut().zip(&self.h_macro) {
            *t += m;
        }
        (&self.h_tot, &self.v_tot)
    }

    /// Hard-macro routing allocation maps `(H, V)` (normalised, unsmoothed).
    pub fn macro_congestion_maps(&mut self) -> (&[f64], &[f64]) {
        if self.macro_dirty {
            self.macro_route();
        }
        (&self.h_macro, &self.v_macro)
    }

    /// Congestion cost and the H-only / V-only top-5 % means.
    fn congestion_terms(&mut self) -> (f64, f64, f64) {
        self.congestion_maps();
        let mut buf = std::mem::take(&mut self.sort_buf);
        buf.clear();
        buf.extend_from_slice(&self.v_tot);
        buf.extend_from_slice(&self.h_tot);
        let mut tmp = std::mem::take(&mut self.scratch_f64);
        let all = top_mean(&buf, 0.05, &mut tmp);
        let h = top_mean(&self.h_tot, 0.05, &mut tmp);
        let v = top_mean(&self.v_tot, 0.05, &mut tmp);
        self.sort_buf = buf;
        self.scratch_f64 = tmp;
        (all, h, v)
    }

    /// Congestion cost.
    pub fn congestion_cost(&mut self) -> f64 {
        self.congestion_terms().0
    }

    /// Every cost term.
    pub fn costs(&mut self) -> CostBreakdown {
        let wirelength = self.wirelength();
        let wirelength_cost = self.wirelength_cost();
        let density_cost = self.density_cost();
        let (congestion_cost, h, v) = self.congestion_terms();
        let wt = self.settings.weights;
        let mut proxy = wt.wirelength * wirelength_cost;
        if wt.congestion > 0.0 {
            proxy += wt.congestion * congestion_cost;
        }
        if wt.density > 0.0 {
            proxy += wt.density * density_cost;
        }
        CostBreakdown {
            wirelength,
            net_count: self.net_count,
            wirelength_cost,
            density_cost,
            congestion_cost,
            h_congestion_cost: h,
            v_congestion_cost: v,
            proxy_cost: proxy,
        }
    }

    /// Raw occupied area per placement-grid cell.
    pub fn occupied_area(&self) -> &[f64] {
        &self.occupied
    }

    /// Legality mask of hard macro `i` on the placement grid (plc_client_os rule): a cell is legal
    /// iff the footprint centred on it lies inside the canvas and overlaps no *other* placed hard
    /// macro with positive area (touching allowed). Writes `true` for legal cells into `out`.
    pub fn node_mask(&self, i: usize, out: &mut [bool]) {
        let g = self.pgrid;
        let (w, h) = (self.w[i], self.h[i]);
        let (cw, ch) = (self.settings.canvas_width, self.settings.canvas_height);
        let inside = |t: f64, half: f64, lim: f64| (t + half).min(lim) - (t - half).max(0.0);
        for r in 0..g.rows {
            let ty = r as f64 * g.gh + g.gh / 2.0;
            let dy = inside(ty, h / 2.0, ch);
            for c in 0..g.cols {
                let tx = c as f64 * g.gw + g.gw / 2.0;
                let dx = inside(tx, w / 2.0, cw);
                let area = if dx >= 0.0 && dy >= 0.0 { dx * dy } else { 0.0 };
                out[r * g.cols + c] = (area - w * h).abs() <= 1e-8;
            }
        }
        let placed_macros = self
            .hard_macros
            .iter()
            .map(|&m| m as usize)
            .filter(|&m| m != i && self.placed[m])
            .map(|m| {
                [
                    self.x[m] - self.w[m] / 2.0,
                    self.y[m] - self.h[m] / 2.0,
                    self.x[m] + self.w[m] / 2.0,
                    self.y[m] + self.h[m] / 2.0,
                ]
            });
        for [pxmin, pymin, pxmax, pymax] in
            placed_macros.chain(self.macro_blockages.iter().copied())
        {
            // Candidate ranges from the separable predicate, widened by one and checked exactly.
            let c_lo = (((pxmin - w / 2.0) / g.gw - 0.5).floor() - 1.0).max(0.0) as usize;
            let c_hi = (((pxmax + w / 2.0) / g.gw - 0.5).ceil() + 1.0)
                .clamp(0.0, (g.cols - 1) as f64) as usize;
            let r_lo = (((pymin - h / 2.0) / g.gh - 0.5).floor() - 1.0).max(0.0) as usize;
            let r_hi = (((pymax + h / 2.0) / g.gh - 0.5).ceil() + 1.0)
                .clamp(0.0, (g.rows - 1) as f64) as usize;
            for r in r_lo..=r_hi {
                let ty = r as f64 * g.gh + g.gh / 2.0;
                let dy = pymax.min(ty + h / 2.0) - pymin.max(ty - h / 2.0);
                if dy <= 0.0 {
                    continue;
                }
                for c in c_lo..=c_hi {
                    let tx = c as f64 * g.gw + g.gw / 2.0;
                    let dx = pxmax.min(tx + w / 2.0) - pxmin.max(tx - w / 2.0);
                    if dx > 0.0 {
                        out[r * g.cols + c] = false;
                    }
                }
            }
        }
    }

    /// The mask rule evaluated directly for one cell (reference for tests).
    pub fn is_legal_cell(&self, i: usize, cell: usize) -> bool {
        let g = self.pgrid;
        let (w, h) = (self.w[i], self.h[i]);
        let (tx, ty) = self.cell_center(cell);
        let overlap = |a: [f64; 4], b: [f64; 4]| {
            let dx = a[2].min(b[2]) - a[0].max(b[0]);
            let dy = a[3].min(b[3]) - a[1].max(b[1]);
            if dx >= 0.0 && dy >= 0.0 { dx * dy } else { 0.0 }
        };
        let me = [tx - w / 2.0, ty - h / 2.0, tx + w / 2.0, ty + h / 2.0];
        let canvas = [
            0.0,
            0.0,
            self.settings.canvas_width,
            self.settings.canvas_height,
        ];
        let _ = g;
        if (overlap(canvas, me) - w * h).abs() > 1e-8 {
            return false;
        }
        if self.macro_blockages.iter().any(|b| overlap(*b, me) > 0.0) {
            return false;
        }
        self.hard_macros.iter().all(|&m| {
            let m = m as usize;
            if m == i || !self.placed[m] {
                return true;
            }
            let b = [
                self.x[m] - self.w[m] / 2.0,
                self.y[m] - self.h[m] / 2.0,
                self.x[m] + self.w[m] / 2.0,
                self.y[m] + self.h[m] / 2.0,
            ];
            overlap(b, me) <= 0.0
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    /// circuit_training's smoothing as it reads: each non-empty source adds its share to the
    /// cells of its window, sources in row-major order (the `congestion_maps` of before).
    fn smooth_reference(
        v_net: &[f64],
        h_net: &[f64],
        (cols, rows, k): (usize, usize, usize),
        (vr, hr): (f64, f64),
    ) -> (Vec<f64>, Vec<f64>) {
        let (mut v_tot, mut h_tot) = (vec![0.0; cols * rows], vec![0.0; cols * rows]);
        for r in 0..rows {
            for c in 0..cols {
                let raw = v_net[c * rows + r];
                if raw == 0.0 {
                    continue;
                }
                let (lp, rp) = (c.saturating_sub(k), (c + k).min(cols - 1));
                let val = (raw / vr) / (rp - lp + 1) as f64;
                for t in &mut v_tot[r * cols + lp..=r * cols + rp] {
                    *t += val;
                }
            }
        }
        for r in 0..rows {
            for c in 0..cols {
                let raw = h_net[r * cols + c];
                if raw == 0.0 {
                    continue;
                }
                let (lp, up) = (r.saturating_sub(k), (r + k).min(rows - 1));
                let val = (raw / hr) / (up - lp + 1) as f64;
                for rr in lp..=up {
                    h_tot[rr * cols + c] += val;
                }
            }
        }
        (v_tot, h_tot)
    }

    /// Demand values as routing leaves them: mostly empty cells, sums of net weights, and the
    /// tiny residues (either sign, and `-0.0`) that incremental removals leave behind.
    fn demand() -> impl Strategy<Value = f64> {
        prop_oneof![
            4 => Just(0.0),
            1 => Just(-0.0),
            4 => 0.0f64..50.0,
            1 => -1e-12f64..1e-12,
            1 => Just(1e-320),
            1 => Just(-1e-320),
        ]
    }

    #[test]
    fn floor_i64_is_the_saturated_floor() {
        let reference = |v: f64| v.floor().clamp(-1e12, 1e12) as i64;
        for v in [
            0.0,
            -0.0,
            0.5,
            -0.5,
            1.0,
            -1.0,
            -1.5,
            1e12,
            1e12 + 0.5,
            -1e12,
            -1e12 - 0.5,
            1e300,
            -1e300,
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::NAN,
            f64::MIN_POSITIVE,
            -f64::MIN_POSITIVE,
            4_503_599_627_370_495.5,
        ] {
            assert_eq!(floor_i64(v), reference(v), "{v}");
        }
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(200))]

        #[test]
        fn floor_i64_matches_floor_clamp_cast(v in proptest::num::f64::ANY) {
            prop_assert_eq!(floor_i64(v), v.floor().clamp(-1e12, 1e12) as i64);
        }

        /// The vectorized smoothing equals the reference's loops bit for bit.
        #[test]
        fn smoothing_matches_the_reference_loops_bit_for_bit(
            (cols, rows, nets) in (1usize..40, 1usize..40).prop_flat_map(|(c, r)| {
                (Just(c), Just(r), proptest::collection::vec((demand(), demand()), c * r))
            }),
            k in 0usize..12,
            vr in 0.1f64..20.0,
            hr in 0.1f64..20.0,
        ) {
            let (v_net, h_net): (Vec<f64>, Vec<f64>) = nets.into_iter().unzip();
            let (v_ref, h_ref) = smooth_reference(&v_net, &h_net, (cols, rows, k), (vr, hr));
            let (mut v_tot, mut h_tot, mut val) =
                (vec![f64::NAN; cols * rows], vec![f64::NAN; cols * rows], Vec::new());
            smooth_demand(
                (&v_net, &h_net),
                (cols, rows, k),
                (vr, hr),
                &mut val,
                (&mut v_tot, &mut h_tot),
            );
            let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
            prop_assert_eq!(bits(&v_tot), bits(&v_ref));
            prop_assert_eq!(bits(&h_tot), bits(&h_ref));
        }
    }
}
