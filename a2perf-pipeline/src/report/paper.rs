//! The paper's published tables as data (`docs/paper/tables.json`) and their comparison with a
//! report: `a2perf report --paper FILE` puts the paper's value beside ours per algorithm, and
//! the ratio ours / paper for energy, RAM and wall-clock time.
//!
//! The file format is documented in `docs/paper/README.md`. Every published figure carries the
//! table and row it was typed in from; a figure that could not be found is `null` with a note
//! saying why. Units are kept as published and converted explicitly (and labelled) when they
//! differ from ours: the paper's hours against our hours, GiB against GB (10⁹ bytes), ms
//! against s.
//!
//! ```
//! use a2perf_pipeline::report::paper::PaperTables;
//! let text = r#"{
//!   "schema": "a2perf-paper-tables/1",
//!   "paper": {"title": "A2Perf", "version": "arXiv 2503.03056v1"},
//!   "tasks": [{
//!     "id": "dog_pace", "title": "Quadruped locomotion, dog pace", "domain": "quadruped_locomotion",
//!     "table": null, "env_id": "QuadrupedLocomotion-DogPace-v0", "params": {},
//!     "algorithms": {"ppo": {"peak_ram": {"mean": 2.0, "std": null, "unit": "GiB",
//!                                         "source": "Table 9, row 'Peak RAM Usage (GiB)'"}}}
//!   }]
//! }"#;
//! let tables = PaperTables::from_json(text, "tables.json".as_ref()).unwrap();
//! let v = &tables.tasks[0].algorithms["ppo"]["peak_ram"];
//! assert_eq!(v.mean, Some(2.0));
//!
//! let bad = text.replace("\"GiB\"", "\"furlongs\"");
//! let err = PaperTables::from_json(&bad, "tables.json".as_ref()).unwrap_err().to_string();
//! assert!(err.starts_with("tables.json: task `dog_pace`, ppo / peak_ram: unit `furlongs`"), "{err}");
//! ```

pub mod compare;
pub mod findings;
pub mod tables;

pub use super::model::{
    FindingCheck, PaperCell, PaperColumn, PaperComparison, Phase, RATIO_METRICS, VERDICT_METRICS,
    Verdict,
};
pub use compare::{
    ComparisonCell, ComparisonFile, FindingOutcome, OursSide, SuiteTotals, check_findings, compare,
    comparison,
};
pub use tables::{
    Ceiling, PaperInfo, PaperSide, PaperTables, PaperTask, PaperValue, SCHEMA, SCHEMAS_READ,
};
