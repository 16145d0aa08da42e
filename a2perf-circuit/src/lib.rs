//! # a2perf-circuit
//!
//! Google Circuit Training's macro-placement task, open and fast:
//!
//! - [`Netlist`]: the protobuf-text netlist format (plain or gzipped), with implicit nets and
//!   attributes rounded to `f32` as Google's binary does; [`Placement`]: `.plc` files.
//! - [`PlacementCost`]: wirelength, density and congestion exactly as the reference, with
//!   incremental updates when one node moves, and the legality mask (which honours `.plc`
//!   blockages; they do not enter the costs, as in the reference).
//! - [`placer`]: a deterministic force-directed standard-cell placer (ours; Google's is closed).
//! - [`analytical`]: a deterministic analytical global placer (ours) with circuit_training's
//!   DREAMPlace parameters: Nesterov, weighted-average wirelength, electrostatic density.
//! - [`generator`]: seeded synthetic netlists for tasks that need no files.
//! - [`env`](mod@env): the `CircuitTraining-*` environments and [`register`].
//! - [`render`]: an SVG picture of a placement.
//!
//! ```
//! use a2perf_circuit::{generate, GeneratorConfig, PlacementCost};
//! let g = generate(&GeneratorConfig::small(), 1);
//! let mut cost = PlacementCost::new(&g.netlist, g.settings.clone()).unwrap();
//! let c = cost.costs();
//! assert!(c.wirelength_cost > 0.0 && c.proxy_cost.is_finite());
//! ```
//!
//! It deliberately does not reproduce Google's closed standard-cell placer or DREAMPlace itself
//! (ours follow their published schedules and parameters), so episode rewards are ours; the cost function itself matches the reference exactly. It does not
//! read the real CT Ariane netlist (unavailable); `CircuitTraining-Ariane-v0` takes it as a file.

#![warn(missing_docs)]

pub mod analytical;
pub mod cost;
pub mod env;
pub mod generator;
pub mod netlist;
pub mod placer;
pub mod plc;
pub mod render;

pub use cost::{CostBreakdown, CostError, CostSettings, CostWeights, PlacementCost};
pub use env::{CircuitEnv, CircuitEnvConfig, InitialLocations, StdCellPlacer, register};
pub use generator::{GeneratedCircuit, GeneratorConfig, generate};
pub use netlist::{
    AttrValue, Net, Netlist, NetlistError, Node, NodeKind, Orientation, SoftMacroRule,
};
pub use plc::{Blockage, Placement, PlcEntry, PlcError, PlcHeader};
