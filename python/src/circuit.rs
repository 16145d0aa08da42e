//! The exact circuit placement cost with circuit_training's `plc_client` method names (the engine
//! of `a2perf_rs.circuit.PlacementCost`).
//!
//! Settings start as `a2perf circuit cost` starts them: from the `.plc` header when a placement is
//! given (`CostSettings::from_header`), else the CT environment's values; `set_*` calls override
//! them as the CLI's flags do. Getters return the cost of the current placement recomputed from
//! scratch (as the CLI computes it) whenever a node moved since the last computation, so results
//! equal the CLI's bit for bit.

use std::sync::{Mutex, MutexGuard};

use a2perf_circuit::{
    CostSettings, CostWeights, Netlist, NetlistError, NodeKind, Orientation, Placement, PlcError,
    SoftMacroRule,
};
use numpy::PyArray1;
use pyo3::exceptions::{PyIndexError, PyRuntimeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::PyDict;

use crate::errors::{file_error, guard};

fn netlist_error(e: NetlistError) -> PyErr {
    match &e {
        NetlistError::Io { path, .. } => file_error(path, e.to_string()),
        NetlistError::Syntax { .. } => PyValueError::new_err(e.to_string()),
    }
}

fn plc_error(e: PlcError) -> PyErr {
    match &e {
        PlcError::Io { path, .. } => file_error(path, e.to_string()),
        PlcError::Syntax { .. } => PyValueError::new_err(e.to_string()),
    }
}

fn read_plc(path: &str) -> PyResult<Placement> {
    guard("reading the placement", || {
        Placement::from_file(path).map_err(plc_error)
    })
}

struct CostState {
    netlist: Netlist,
    settings: CostSettings,
    cost: a2perf_circuit::PlacementCost,
    /// The settings changed: the cost model is rebuilt (keeping the placement) before use.
    rebuild: bool,
    /// A node moved since the last full computation.
    stale: bool,
}

impl CostState {
    /// The cost model, rebuilt with the current settings and recomputed if needed.
    fn fresh(&mut self) -> PyResult<&mut a2perf_circuit::PlacementCost> {
        if self.rebuild {
            let placement = self.cost.to_placement(Vec::new());
            let placed: Vec<bool> = (0..self.cost.num_nodes())
                .map(|i| self.cost.is_placed(i))
                .collect();
            let blockages = self.cost.blockages().to_vec();
            let mut cost = a2perf_circuit::PlacementCost::new(&self.netlist, self.settings.clone())
                .map_err(|e| PyValueError::new_err(e.to_string()))?;
            cost.apply_placement(&placement)
                .map_err(|e| PyValueError::new_err(e.to_string()))?;
            cost.set_blockages(&blockages);
            for (i, p) in placed.into_iter().enumerate() {
                if !p {
                    cost.set_placed(i, false);
                }
            }
            self.cost = cost;
            self.rebuild = false;
            self.stale = true;
        }
        if self.stale {
            self.cost.recompute();
            self.stale = false;
        }
        Ok(&mut self.cost)
    }

    fn node(&self, index: i64) -> PyResult<usize> {
        let n = self.netlist.nodes.len();
        usize::try_from(index)
            .ok()
            .filter(|i| *i < n)
            .ok_or_else(|| {
                PyIndexError::new_err(format!(
                    "node index {index} is out of range (the netlist has {n} nodes)"
                ))
            })
    }

    fn movable(&self, index: i64) -> PyResult<usize> {
        let i = self.node(index)?;
        if self.netlist.nodes[i].kind.is_pin() {
            return Err(PyValueError::new_err(format!(
                "node {i} ({}) is a macro pin; pins move with their macro",
                self.netlist.nodes[i].name
            )));
        }
        Ok(i)
    }

    fn set(&mut self, f: impl FnOnce(&mut CostSettings)) -> PyResult<()> {
        let mut s = self.settings.clone();
        f(&mut s);
        s.validate()
            .map_err(|e| PyValueError::new_err(e.to_string()))?;
        self.settings = s;
        self.rebuild = true;
        Ok(())
    }
}

fn finite(what: &str, v: f64) -> PyResult<f64> {
    if v.is_finite() {
        Ok(v)
    } else {
        Err(PyValueError::new_err(format!(
            "{what} must be finite, got {v}"
        )))
    }
}

fn positive(what: &str, v: f64) -> PyResult<f64> {
    if v.is_finite() && v > 0.0 {
        Ok(v)
    } else {
        Err(PyValueError::new_err(format!(
            "{what} must be positive, got {v}"
        )))
    }
}

fn count(what: &str, v: i64) -> PyResult<usize> {
    usize::try_from(v)
        .ok()
        .filter(|v| *v >= 1)
        .ok_or_else(|| PyValueError::new_err(format!("{what} must be at least 1, got {v}")))
}

/// `PlacementCost(netlist_path, plc_path=None, soft_macro_rule="name_prefix")`.
#[pyclass(module = "a2perf_rs._native", name = "PlacementCost")]
pub struct PyPlacementCost {
    state: Mutex<CostState>,
}

impl PyPlacementCost {
    fn state(&self) -> PyResult<MutexGuard<'_, CostState>> {
        self.state.lock().map_err(|_| {
            PyRuntimeError::new_err("the placement cost is unusable after an earlier failure")
        })
    }

    fn with<T>(&self, what: &str, f: impl FnOnce(&mut CostState) -> PyResult<T>) -> PyResult<T> {
        let mut st = self.state()?;
        guard(what, || f(&mut st))
    }
}

#[pymethods]
impl PyPlacementCost {
    #[new]
    #[pyo3(signature = (netlist_path, plc_path=None, soft_macro_rule="name_prefix"))]
    fn new(
        py: Python<'_>,
        netlist_path: std::path::PathBuf,
        plc_path: Option<std::path::PathBuf>,
        soft_macro_rule: &str,
    ) -> PyResult<Self> {
        let rule = match soft_macro_rule {
            "name_prefix" => SoftMacroRule::NamePrefix,
            "type_case" => SoftMacroRule::TypeCase,
            other => {
                return Err(PyValueError::new_err(format!(
                    "soft_macro_rule must be `name_prefix` (Google: soft iff the name starts with \
                     Grp) or `type_case` (plc_client_os: lower-case `macro`), got `{other}`"
                )));
            }
        };
        py.detach(|| {
            guard("loading the netlist", || {
                let netlist = Netlist::from_file(&netlist_path, rule).map_err(netlist_error)?;
                let plc = plc_path
                    .as_ref()
                    .map(|p| read_plc(&p.to_string_lossy()))
                    .transpose()?;
                let header = plc.as_ref().map(|p| p.header.clone()).unwrap_or_default();
                let settings = CostSettings::from_header(&netlist, &header);
                let mut cost = a2perf_circuit::PlacementCost::new(&netlist, settings.clone())
                    .map_err(|e| PyValueError::new_err(e.to_string()))?;
                if let (Some(p), Some(path)) = (&plc, &plc_path) {
                    cost.apply_placement(p).map_err(|e| {
                        PyValueError::new_err(format!(
                            "{}: placement does not fit the netlist: {e}",
                            path.display()
                        ))
                    })?;
                }
                Ok(Self {
                    state: Mutex::new(CostState {
                        netlist,
                        settings,
                        cost,
                        rebuild: false,
                        stale: false,
                    }),
                })
            })
        })
    }

    /// Wirelength cost `WL / ((W + H) · net_count)` (plc_client's `get_cost`).
    fn get_cost(&self) -> PyResult<f64> {
        self.get_wirelength_cost()
    }

    /// Wirelength cost `WL / ((W + H) · net_count)`.
    fn get_wirelength_cost(&self) -> PyResult<f64> {
        self.with("get_wirelength_cost", |s| Ok(s.fresh()?.wirelength_cost()))
    }

    /// Σ w·HPWL over nets.
    fn get_wirelength(&self) -> PyResult<f64> {
        self.with("get_wirelength", |s| Ok(s.fresh()?.wirelength()))
    }

    /// Density cost: 0.5 · mean of the top 10 % cell densities.
    fn get_density_cost(&self) -> PyResult<f64> {
        self.with("get_density_cost", |s| Ok(s.fresh()?.density_cost()))
    }

    /// Congestion cost: mean of the top 5 % of the H and V routing congestion.
    fn get_congestion_cost(&self) -> PyResult<f64> {
        self.with("get_congestion_cost", |s| Ok(s.fresh()?.congestion_cost()))
    }

    /// Every term as `a2perf circuit cost --json` reports it: `wirelength`, `net_count`,
    /// `wirelength_cost`, `density_cost`, `congestion_cost`, `h_congestion_cost`,
    /// `v_congestion_cost`, `proxy_cost` (with the proxy weights in force).
    fn costs<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let c = self.with("costs", |s| Ok(s.fresh()?.costs()))?;
        let d = PyDict::new(py);
        for (k, v) in [
            ("wirelength", c.wirelength),
            ("net_count", c.net_count),
            ("wirelength_cost", c.wirelength_cost),
            ("density_cost", c.density_cost),
            ("congestion_cost", c.congestion_cost),
            ("h_congestion_cost", c.h_congestion_cost),
            ("v_congestion_cost", c.v_congestion_cost),
            ("proxy_cost", c.proxy_cost),
        ] {
            d.set_item(k, v)?;
        }
        Ok(d)
    }

    /// The proxy cost with the weights in force (default 1.0 · wirelength + 1.0 · density +
    /// 0.5 · congestion).
    fn get_proxy_cost(&self) -> PyResult<f64> {
        self.with("get_proxy_cost", |s| Ok(s.fresh()?.costs().proxy_cost))
    }

    /// Sets the proxy weights.
    fn set_proxy_weights(&self, wirelength: f64, density: f64, congestion: f64) -> PyResult<()> {
        self.with("set_proxy_weights", |s| {
            s.set(|c| {
                c.weights = CostWeights {
                    wirelength,
                    density,
                    congestion,
                }
            })
        })
    }

    /// Moves node `node_index` (a macro, standard cell or port) so that its centre is at `(x, y)`.
    fn update_node_coords(&self, node_index: i64, x: f64, y: f64) -> PyResult<()> {
        let (x, y) = (finite("x", x)?, finite("y", y)?);
        self.with("update_node_coords", |s| {
            let i = s.movable(node_index)?;
            s.cost.set_position(i, x, y);
            s.stale = true;
            Ok(())
        })
    }

    /// Centre of node `node_index`.
    fn get_node_location(&self, node_index: i64) -> PyResult<(f64, f64)> {
        self.with("get_node_location", |s| {
            let i = s.node(node_index)?;
            let node = &s.netlist.nodes[i];
            if node.kind.is_pin() {
                // A pin sits at its macro's centre plus its (oriented) offset.
                let m = node.macro_index.unwrap_or(i);
                let (mx, my) = s.cost.position(m);
                if node.kind == NodeKind::HardMacroPin {
                    let (dx, dy) = s.cost.orientation(m).apply(node.x_offset, node.y_offset);
                    return Ok((mx + dx, my + dy));
                }
                return Ok((mx, my));
            }
            Ok(s.cost.position(i))
        })
    }

    /// Places node `node_index` at the centre of placement-grid cell `cell` (row-major).
    fn place_node(&self, node_index: i64, cell: i64) -> PyResult<()> {
        self.with("place_node", |s| {
            let i = s.movable(node_index)?;
            let c = s.fresh()?;
            let (cols, rows) = c.grid();
            let cell = usize::try_from(cell)
                .ok()
                .filter(|c| *c < cols * rows)
                .ok_or_else(|| {
                    PyIndexError::new_err(format!(
                        "cell {cell} is outside the {cols}x{rows} placement grid"
                    ))
                })?;
            c.place_at_cell(i, cell);
            s.stale = true;
            Ok(())
        })
    }

    /// Marks node `node_index` unplaced (it then counts in neither density nor routing allocation).
    fn unplace_node(&self, node_index: i64) -> PyResult<()> {
        self.with("unplace_node", |s| {
            let i = s.movable(node_index)?;
            s.fresh()?.set_placed(i, false);
            s.stale = true;
            Ok(())
        })
    }

    /// Sets a hard macro's orientation (`N`, `S`, `E`, `W`, `FN`, `FS`, `FE`, `FW`).
    fn update_macro_orientation(&self, node_index: i64, orientation: &str) -> PyResult<()> {
        let o = Orientation::parse(orientation).ok_or_else(|| {
            PyValueError::new_err(format!(
                "orientation `{orientation}` is not one of N, S, E, W, FN, FS, FE, FW"
            ))
        })?;
        self.with("update_macro_orientation", |s| {
            let i = s.node(node_index)?;
            if s.netlist.nodes[i].kind != NodeKind::HardMacro {
                return Err(PyValueError::new_err(format!(
                    "node {i} ({}) is not a hard macro",
                    s.netlist.nodes[i].name
                )));
            }
            s.fresh()?.set_orientation(i, o);
            s.stale = true;
            Ok(())
        })
    }

    /// A macro's orientation.
    fn get_macro_orientation(&self, node_index: i64) -> PyResult<String> {
        self.with("get_macro_orientation", |s| {
            let i = s.node(node_index)?;
            Ok(s.cost.orientation(i).as_str().to_string())
        })
    }

    /// Applies the node lines (positions, orientations, fixed flags) and blockages of a `.plc`.
    fn restore_placement(&self, plc_path: std::path::PathBuf) -> PyResult<()> {
        let plc = read_plc(&plc_path.to_string_lossy())?;
        self.with("restore_placement", |s| {
            s.fresh()?.apply_placement(&plc).map_err(|e| {
                PyValueError::new_err(format!(
                    "{}: placement does not fit the netlist: {e}",
                    plc_path.display()
                ))
            })?;
            s.stale = false;
            Ok(())
        })
    }

    /// Writes the current placement as a `.plc` file.
    fn save_placement(&self, path: std::path::PathBuf) -> PyResult<()> {
        let text = self.with("save_placement", |s| {
            Ok(s.fresh()?.to_placement(Vec::new()).to_text())
        })?;
        std::fs::write(&path, text)
            .map_err(|e| pyo3::exceptions::PyOSError::new_err(format!("{}: {e}", path.display())))
    }

    /// Sets the canvas size (µm).
    fn set_canvas_size(&self, width: f64, height: f64) -> PyResult<()> {
        let (w, h) = (
            positive("canvas width", width)?,
            positive("canvas height", height)?,
        );
        self.with("set_canvas_size", |s| {
            s.set(|c| {
                c.canvas_width = w;
                c.canvas_height = h;
            })
        })
    }

    /// Sets the placement grid (columns, rows).
    fn set_placement_grid(&self, cols: i64, rows: i64) -> PyResult<()> {
        let (c, r) = (count("grid columns", cols)?, count("grid rows", rows)?);
        self.with("set_placement_grid", |s| {
            s.set(|x| {
                x.grid_cols = c;
                x.grid_rows = r;
            })
        })
    }

    /// Sets the routing tracks per µm (horizontal, vertical).
    fn set_routes_per_micron(&self, hroutes: f64, vroutes: f64) -> PyResult<()> {
        let (h, v) = (
            positive("horizontal routes per micron", hroutes)?,
            positive("vertical routes per micron", vroutes)?,
        );
        self.with("set_routes_per_micron", |s| {
            s.set(|c| {
                c.hroutes_per_micron = h;
                c.vroutes_per_micron = v;
            })
        })
    }

    /// Sets the tracks used per µm of hard macro (horizontal, vertical).
    fn set_macro_routing_allocation(&self, hrouting: f64, vrouting: f64) -> PyResult<()> {
        let (h, v) = (finite("hrouting", hrouting)?, finite("vrouting", vrouting)?);
        self.with("set_macro_routing_allocation", |s| {
            s.set(|c| {
                c.hrouting_alloc = h;
                c.vrouting_alloc = v;
            })
        })
    }

    /// Sets the congestion smoothing range.
    fn set_congestion_smooth_range(&self, smooth_range: f64) -> PyResult<()> {
        let k = finite("smooth range", smooth_range)?;
        self.with("set_congestion_smooth_range", |s| {
            s.set(|c| c.smooth_range = k)
        })
    }

    /// Makes every soft macro a square of the same area (as the CT environment does).
    fn make_soft_macros_square(&self) -> PyResult<()> {
        self.with("make_soft_macros_square", |s| {
            s.set(|c| c.make_soft_macros_square = true)
        })
    }

    /// Canvas `(width, height)`.
    fn get_canvas_width_height(&self) -> PyResult<(f64, f64)> {
        self.with("get_canvas_width_height", |s| {
            Ok((s.settings.canvas_width, s.settings.canvas_height))
        })
    }

    /// Placement grid `(columns, rows)`.
    fn get_grid_num_columns_rows(&self) -> PyResult<(usize, usize)> {
        self.with("get_grid_num_columns_rows", |s| {
            Ok((s.settings.grid_cols, s.settings.grid_rows))
        })
    }

    /// Routing tracks per µm `(horizontal, vertical)`.
    fn get_routes_per_micron(&self) -> PyResult<(f64, f64)> {
        self.with("get_routes_per_micron", |s| {
            Ok((s.settings.hroutes_per_micron, s.settings.vroutes_per_micron))
        })
    }

    /// Macro routing allocation `(horizontal, vertical)`.
    fn get_macro_routing_allocation(&self) -> PyResult<(f64, f64)> {
        self.with("get_macro_routing_allocation", |s| {
            Ok((s.settings.hrouting_alloc, s.settings.vrouting_alloc))
        })
    }

    /// Congestion smoothing range.
    fn get_congestion_smooth_range(&self) -> PyResult<f64> {
        self.with("get_congestion_smooth_range", |s| {
            Ok(s.settings.smooth_range)
        })
    }

    /// Every setting in force, as the CLI's JSON `settings`.
    fn settings<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        let text = self.with("settings", |s| {
            serde_json::to_string(&s.settings).map_err(|e| PyValueError::new_err(e.to_string()))
        })?;
        py.import("json")?.call_method1("loads", (text,))
    }

    /// Number of nodes (macros, pins, ports, standard cells).
    fn num_nodes(&self) -> PyResult<usize> {
        self.with("num_nodes", |s| Ok(s.netlist.nodes.len()))
    }

    /// Node indices of hard and soft macros, ascending (plc_client's `get_macro_indices`).
    fn get_macro_indices(&self) -> PyResult<Vec<usize>> {
        self.with("get_macro_indices", |s| {
            Ok(s.netlist
                .nodes
                .iter()
                .enumerate()
                .filter(|(_, n)| matches!(n.kind, NodeKind::HardMacro | NodeKind::SoftMacro))
                .map(|(i, _)| i)
                .collect())
        })
    }

    /// Node indices of hard macros, ascending.
    fn get_hard_macro_indices(&self) -> PyResult<Vec<usize>> {
        self.with("get_hard_macro_indices", |s| {
            Ok(s.netlist.indices_of(NodeKind::HardMacro))
        })
    }

    /// Name of node `node_index`.
    fn get_node_name(&self, node_index: i64) -> PyResult<String> {
        self.with("get_node_name", |s| {
            let i = s.node(node_index)?;
            Ok(s.netlist.nodes[i].name.clone())
        })
    }

    /// Type of node `node_index` as plc_client names it: `MACRO` (hard), `macro` (soft),
    /// `MACRO_PIN`, `macro_pin`, `PORT` or `STDCELL`.
    fn get_node_type(&self, node_index: i64) -> PyResult<&'static str> {
        self.with("get_node_type", |s| {
            let i = s.node(node_index)?;
            Ok(s.netlist.nodes[i].kind.type_name())
        })
    }

    /// Width and height of node `node_index` (soft macros after squaring, if requested).
    fn get_node_width_height(&self, node_index: i64) -> PyResult<(f64, f64)> {
        self.with("get_node_width_height", |s| {
            let i = s.node(node_index)?;
            Ok(s.fresh()?.size(i))
        })
    }

    /// Total area of macros and standard cells.
    fn get_area(&self) -> PyResult<f64> {
        self.with("get_area", |s| Ok(s.netlist.total_area()))
    }

    /// Per-cell density of the placement grid (row-major).
    fn get_grid_cells_density<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray1<f64>>> {
        let v = self.with("get_grid_cells_density", |s| {
            let mut out = Vec::new();
            s.fresh()?.density_cells(&mut out);
            Ok(out)
        })?;
        Ok(PyArray1::from_vec(py, v))
    }

    /// Horizontal routing congestion per cell (row-major).
    fn get_horizontal_routing_congestion<'py>(
        &self,
        py: Python<'py>,
    ) -> PyResult<Bound<'py, PyArray1<f64>>> {
        let v = self.with("congestion", |s| {
            Ok(s.fresh()?.congestion_maps().0.to_vec())
        })?;
        Ok(PyArray1::from_vec(py, v))
    }

    /// Vertical routing congestion per cell (row-major).
    fn get_vertical_routing_congestion<'py>(
        &self,
        py: Python<'py>,
    ) -> PyResult<Bound<'py, PyArray1<f64>>> {
        let v = self.with("congestion", |s| {
            Ok(s.fresh()?.congestion_maps().1.to_vec())
        })?;
        Ok(PyArray1::from_vec(py, v))
    }

    /// The netlist's name and content hash (as results record them).
    fn netlist_info(&self) -> PyResult<(String, String)> {
        self.with("netlist_info", |s| {
            Ok((s.netlist.name.clone(), s.netlist.content_hash.clone()))
        })
    }
}

/// Adds `PlacementCost` to the module.
pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PyPlacementCost>()?;
    Ok(())
}
