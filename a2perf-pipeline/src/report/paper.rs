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

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

use a2perf_core::Value;
use serde::{Deserialize, Serialize};

use super::format::format_value;
use super::{Group, Report};
use crate::{PipelineError, Result};

pub mod findings;
pub mod summary;

use findings::{CellRef, CellSource, CellValue, FindingDef};

/// The schema tag `tables.json` files are written with.
pub const SCHEMA: &str = "a2perf-paper-tables/2";

/// The schema tags this version reads: `/1` files have no findings and no paper names per cell.
pub const SCHEMAS_READ: &[&str] = &["a2perf-paper-tables/1", SCHEMA];

/// `tables.json`: the paper's task tables.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PaperTables {
    /// [`SCHEMA`].
    pub schema: String,
    /// Which paper, which version, and how the figures were obtained.
    pub paper: PaperInfo,
    /// One entry per task table of the paper.
    pub tasks: Vec<PaperTask>,
    /// The paper's findings, each with a definition over the tables' cells.
    #[serde(default)]
    pub findings: Vec<FindingDef>,
}

/// The paper a `tables.json` transcribes.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PaperInfo {
    /// Title.
    pub title: String,
    /// The version the figures come from (e.g. `arXiv 2503.03056v1`).
    pub version: String,
    /// Where that version was read.
    #[serde(default)]
    pub url: Option<String>,
    /// Other versions, and where they disagree with the one used.
    #[serde(default)]
    pub other_versions: Vec<String>,
    /// How the figures were obtained, and what is missing.
    #[serde(default)]
    pub note: Option<String>,
}

/// One task table of the paper.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PaperTask {
    /// Short id (`dog_pace`, `web_level1_websites5`).
    pub id: String,
    /// What the table is about.
    pub title: String,
    /// Our domain name (`quadruped_locomotion`).
    pub domain: String,
    /// The table's number in the paper (`Table 5`), or `null` if unknown.
    pub table: Option<String>,
    /// Our environment id the table matches.
    pub env_id: String,
    /// Environment parameters a run must have to match (e.g. `{"num_websites": 5}`); the others
    /// are free.
    #[serde(default)]
    pub params: BTreeMap<String, Value>,
    /// Algorithm (our registered name, `ppo`) → metric key (as in `report.json`) → value.
    pub algorithms: BTreeMap<String, BTreeMap<String, PaperValue>>,
    /// Remarks on the whole table.
    #[serde(default)]
    pub note: Option<String>,
    /// Ours, not the paper's: for a metric key (`returns`), the best value measured as reachable
    /// in this project's environment, and how it was measured. A paper cell whose mean − std is
    /// above it trails here whatever the agent, and the report says so with the number.
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub ceilings: BTreeMap<String, Ceiling>,
}

impl PaperTask {
    /// For a cell of metric `key` with `verdict` against the paper's `mean ± std`: why it is
    /// out of reach here, when it trails and the task's ceiling for `key` is below the paper's
    /// mean − std (see [`Ceiling::out_of_reach`]).
    pub fn out_of_reach(
        &self,
        key: &str,
        verdict: Option<Verdict>,
        mean: Option<f64>,
        std: Option<f64>,
    ) -> Option<String> {
        match (verdict, mean) {
            (Some(Verdict::Trails), Some(mean)) => self.ceilings.get(key)?.out_of_reach(mean, std),
            _ => None,
        }
    }
}

/// The best value of a metric measured as reachable here ([`PaperTask::ceilings`]).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Ceiling {
    /// The value, in the unit of the paper's cells of that metric.
    pub value: f64,
    /// What reaches it and how it was measured (command, date).
    pub how: String,
}

impl Ceiling {
    /// Why a paper cell of `mean ± std` is out of reach, when its mean − std is above the
    /// ceiling.
    ///
    /// ```
    /// use a2perf_pipeline::report::paper::Ceiling;
    /// let c = Ceiling { value: -0.98, how: "the best of every placement".into() };
    /// assert!(c.out_of_reach(-0.97, Some(0.002)).unwrap().contains("-0.98"));
    /// assert_eq!(c.out_of_reach(-0.97, Some(0.05)), None);
    /// ```
    pub fn out_of_reach(&self, mean: f64, std: Option<f64>) -> Option<String> {
        let floor = mean - std.unwrap_or(0.0);
        (floor > self.value).then(|| {
            format!(
                "out of reach here: {} is {}, below the paper's mean − std {}",
                self.how,
                self.value,
                format_value(floor)
            )
        })
    }
}

/// One published figure.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PaperValue {
    /// The published mean, `null` when it could not be found.
    pub mean: Option<f64>,
    /// The published ± (the paper's spread), `null` when none is given or found.
    pub std: Option<f64>,
    /// The unit as published (`kWh`, `GB`, `Hours`, `ms`, `100 eps.`).
    pub unit: String,
    /// The unit the figure really is in, when the published label is known to be wrong (the
    /// original timed inference in seconds and labelled it ms); conversions start from it.
    #[serde(default)]
    pub measured_unit: Option<String>,
    /// Where it was typed in from: paper version, table and row.
    pub source: Option<String>,
    /// Why it is missing, or anything else a reader must know.
    #[serde(default)]
    pub note: Option<String>,
    /// The metric's name as the paper prints it (`Peak RAM Usage`).
    #[serde(default)]
    pub paper_metric: Option<String>,
    /// The phase the paper lists it under.
    #[serde(default)]
    pub phase: Option<Phase>,
}

/// The two halves of each of the paper's tables.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Phase {
    /// Data cost, application, training reliability and training system metrics.
    Training,
    /// Rollout reliability and inference system metrics.
    Inference,
}

impl Phase {
    /// The phase a metric key of our report belongs to in the paper's layout (returns and
    /// generalization are listed under training, though we roll them out after it).
    pub fn of_key(key: &str) -> Phase {
        if key.starts_with("inference_") || key.ends_with("_rollouts") {
            Phase::Inference
        } else {
            Phase::Training
        }
    }

    /// `training` or `inference`.
    pub fn as_str(self) -> &'static str {
        match self {
            Phase::Training => "training",
            Phase::Inference => "inference",
        }
    }
}

/// What a unit measures.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Dimension {
    Energy,
    Power,
    Memory,
    Time,
}

/// A unit's dimension and its size in the dimension's base unit (kWh, W, bytes, seconds).
fn unit_scale(unit: &str) -> Option<(Dimension, f64)> {
    use Dimension::*;
    Some(match unit {
        "kWh" => (Energy, 1.0),
        "Wh" => (Energy, 1e-3),
        "MWh" => (Energy, 1e3),
        "J" => (Energy, 1.0 / 3.6e6),
        "W" => (Power, 1.0),
        "kW" => (Power, 1e3),
        "mW" => (Power, 1e-3),
        "B" => (Memory, 1.0),
        "MB" => (Memory, 1e6),
        "GB" => (Memory, 1e9),
        "TB" => (Memory, 1e12),
        "MiB" => (Memory, 1_048_576.0),
        "GiB" => (Memory, 1_073_741_824.0),
        "TiB" => (Memory, 1_099_511_627_776.0),
        "s" => (Time, 1.0),
        "ms" => (Time, 1e-3),
        "us" | "µs" => (Time, 1e-6),
        "min" => (Time, 60.0),
        "h" | "hours" | "Hours" => (Time, 3600.0),
        _ => return None,
    })
}

/// The unit our report gives a dimension in; findings compute in it.
fn report_unit(dim: Dimension, key: &str) -> &'static str {
    match dim {
        Dimension::Energy => "kWh",
        Dimension::Power => "W",
        Dimension::Memory => "GB",
        Dimension::Time if key == "wall_clock" => "Hours",
        Dimension::Time => "ms",
    }
}

/// The dimension of metric `key` (`None` when unitless or unknown).
fn dimension_of(key: &str) -> Option<Dimension> {
    METRICS
        .iter()
        .find(|(k, _)| *k == key)
        .and_then(|(_, d)| *d)
}

fn units_of(dim: Dimension) -> &'static str {
    match dim {
        Dimension::Energy => "kWh, Wh, MWh, J",
        Dimension::Power => "W, kW, mW",
        Dimension::Memory => "GB, GiB, MB, MiB, TB, TiB, B",
        Dimension::Time => "Hours, h, min, s, ms, us",
    }
}

/// Metric keys a `tables.json` may give, with the dimension of their unit (`None`: unitless,
/// the unit is free text such as `100 eps.` or `IQR`).
const METRICS: &[(&str, Option<Dimension>)] = &[
    ("training_sample_cost", Some(Dimension::Energy)),
    ("total_energy", Some(Dimension::Energy)),
    ("returns", None),
    ("generalization", None),
    ("dispersion_across_runs", None),
    ("dispersion_within_runs", None),
    ("short_term_risk", None),
    ("long_term_risk", None),
    ("risk_across_runs", None),
    ("dispersion_across_rollouts", None),
    ("risk_across_rollouts", None),
    ("energy", Some(Dimension::Energy)),
    ("power", Some(Dimension::Power)),
    ("gpu_power", Some(Dimension::Power)),
    ("mean_ram", Some(Dimension::Memory)),
    ("peak_ram", Some(Dimension::Memory)),
    ("wall_clock", Some(Dimension::Time)),
    ("inference_time", Some(Dimension::Time)),
    ("inference_power", Some(Dimension::Power)),
    ("inference_gpu_power", Some(Dimension::Power)),
    ("inference_energy", Some(Dimension::Energy)),
    ("inference_mean_ram", Some(Dimension::Memory)),
    ("inference_peak_ram", Some(Dimension::Memory)),
];

/// Metrics whose ratio ours / paper the comparison reports: energy, RAM and wall-clock time.
pub const RATIO_METRICS: &[&str] = &[
    "energy",
    "mean_ram",
    "peak_ram",
    "wall_clock",
    "inference_energy",
    "inference_mean_ram",
    "inference_peak_ram",
];

impl PaperTables {
    /// Reads and checks `path`; errors name the file and the problem.
    pub fn load(path: &Path) -> Result<Self> {
        let text = std::fs::read_to_string(path).map_err(crate::io_err(path))?;
        Self::from_json(&text, path)
    }

    /// Parses and checks JSON text; `path` names it in errors.
    pub fn from_json(text: &str, path: &Path) -> Result<Self> {
        let corrupt = |reason: String| PipelineError::Corrupt {
            path: PathBuf::from(path),
            reason,
        };
        let tables: PaperTables = serde_json::from_str(text).map_err(|e| corrupt(e.to_string()))?;
        tables.check().map_err(corrupt)?;
        Ok(tables)
    }

    /// The structural rules of the format (see `docs/paper/README.md`).
    fn check(&self) -> std::result::Result<(), String> {
        if !SCHEMAS_READ.contains(&self.schema.as_str()) {
            return Err(format!(
                "schema `{}` is not supported (expected one of `{}`)",
                self.schema,
                SCHEMAS_READ.join("`, `")
            ));
        }
        if self.tasks.is_empty() {
            return Err("no tasks".into());
        }
        let mut ids = BTreeSet::new();
        for (i, t) in self.tasks.iter().enumerate() {
            if t.id.trim().is_empty() {
                return Err(format!("task {i}: empty `id`"));
            }
            if !ids.insert(t.id.as_str()) {
                return Err(format!("task `{}` is listed twice", t.id));
            }
            if let Some(other) = self.tasks[..i]
                .iter()
                .find(|o| o.env_id == t.env_id && o.params == t.params)
            {
                return Err(format!(
                    "tasks `{}` and `{}` match the same runs ({} with the same params)",
                    other.id, t.id, t.env_id
                ));
            }
            if t.algorithms.is_empty() {
                return Err(format!("task `{}`: no algorithms", t.id));
            }
            for (algo, metrics) in &t.algorithms {
                for (key, v) in metrics {
                    let at = format!("task `{}`, {algo} / {key}", t.id);
                    v.check(key).map_err(|why| format!("{at}: {why}"))?;
                }
            }
        }
        self.check_findings()
    }

    /// Findings have unique ids and read only cells the tables have.
    fn check_findings(&self) -> std::result::Result<(), String> {
        let mut ids = BTreeSet::new();
        for f in &self.findings {
            f.check()?;
            if !ids.insert(f.id.as_str()) {
                return Err(format!("finding `{}` is listed twice", f.id));
            }
            for cell in f
                .cells()
                .map_err(|why| format!("finding `{}`: {why}", f.id))?
            {
                if self.value(&cell).is_none() {
                    return Err(format!(
                        "finding `{}`: cell `{cell}` is not in the tables",
                        f.id
                    ));
                }
            }
        }
        Ok(())
    }

    /// The published value of `cell`.
    pub fn value(&self, cell: &CellRef) -> Option<&PaperValue> {
        self.tasks
            .iter()
            .find(|t| t.id == cell.task)?
            .algorithms
            .get(&cell.algorithm)?
            .get(&cell.metric)
    }

    /// The task table a run on `env_id` with resolved `params` belongs to.
    pub fn matching(&self, env_id: &str, params: &BTreeMap<String, Value>) -> Option<&PaperTask> {
        self.tasks.iter().find(|t| {
            t.env_id == env_id
                && t.params
                    .iter()
                    .all(|(k, want)| params.get(k).is_some_and(|have| same_value(have, want)))
        })
    }
}

/// Equal values, numbers compared by value (`5` matches `5.0`).
fn same_value(a: &Value, b: &Value) -> bool {
    match (a.as_f64(), b.as_f64()) {
        (Some(x), Some(y)) => x == y,
        _ => a == b,
    }
}

impl PaperValue {
    fn check(&self, key: &str) -> std::result::Result<(), String> {
        let Some((_, dim)) = METRICS.iter().find(|(k, _)| *k == key) else {
            let known = METRICS.iter().map(|(k, _)| *k);
            let hint = a2perf_core::did_you_mean(key, known.clone())
                .map(|h| format!(" (did you mean `{h}`?)"))
                .unwrap_or_default();
            return Err(format!(
                "unknown metric{hint}; known: {}",
                known.collect::<Vec<_>>().join(", ")
            ));
        };
        if let Some(dim) = dim {
            for (field, unit) in [
                ("unit", Some(&self.unit)),
                ("measured_unit", self.measured_unit.as_ref()),
            ] {
                let Some(unit) = unit else { continue };
                match unit_scale(unit) {
                    Some((d, _)) if d == *dim => {}
                    _ => {
                        return Err(format!(
                            "{}`{unit}` is not a unit of this metric (expected one of {})",
                            if field == "unit" {
                                "unit "
                            } else {
                                "measured_unit "
                            },
                            units_of(*dim)
                        ));
                    }
                }
            }
        } else if self.measured_unit.is_some() {
            return Err("`measured_unit` is only for metrics with physical units".into());
        }
        for (name, v) in [("mean", self.mean), ("std", self.std)] {
            if v.is_some_and(|v| !v.is_finite()) {
                return Err(format!("`{name}` is not a finite number"));
            }
        }
        if self.std.is_some_and(|s| s < 0.0) {
            return Err("`std` is negative".into());
        }
        if self.mean.is_some() && self.source.as_deref().is_none_or(|s| s.trim().is_empty()) {
            return Err(
                "a published value needs its `source` (paper version, table and row)".into(),
            );
        }
        if self.mean.is_none() && self.note.as_deref().is_none_or(|s| s.trim().is_empty()) {
            return Err("a missing value (`mean: null`) needs a `note` saying why".into());
        }
        if let Some(phase) = self.phase
            && phase != Phase::of_key(key)
        {
            return Err(format!(
                "`phase` is `{}` but this metric is a {} metric",
                phase.as_str(),
                Phase::of_key(key).as_str()
            ));
        }
        if self
            .paper_metric
            .as_deref()
            .is_some_and(|m| m.trim().is_empty())
        {
            return Err("empty `paper_metric`".into());
        }
        Ok(())
    }

    /// The value in `our_unit`, with a label of the conversion when one was needed.
    fn in_unit(&self, our_unit: &str) -> Converted {
        let from = self.measured_unit.as_deref().unwrap_or(&self.unit);
        let mut labels = Vec::new();
        if from != self.unit {
            labels.push(format!("published as {}, measured in {from}", self.unit));
        }
        let factor = match (unit_scale(from), unit_scale(our_unit)) {
            (Some((a, fa)), Some((b, fb))) if a == b => {
                let factor = fa / fb;
                if from != our_unit {
                    labels.push(format!("{from} → {our_unit} (×{})", short(factor)));
                }
                Some(factor)
            }
            (None, None) => Some(1.0),
            _ => {
                labels.push(format!(
                    "published in {from}, not convertible to {our_unit}"
                ));
                None
            }
        };
        Converted {
            mean: factor.and_then(|f| self.mean.map(|m| m * f)),
            std: factor.and_then(|f| self.std.map(|s| s * f)),
            conversion: (!labels.is_empty()).then(|| labels.join("; ")),
        }
    }
}

struct Converted {
    mean: Option<f64>,
    std: Option<f64>,
    conversion: Option<String>,
}

/// A conversion factor, short but exact enough to check by hand.
fn short(x: f64) -> String {
    let s = format!("{x:.6}");
    let s = s.trim_end_matches('0').trim_end_matches('.');
    if s == "0" {
        format!("{x:e}")
    } else {
        s.to_string()
    }
}

/// The paper's figures beside one task table of a report.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PaperComparison {
    /// Our task (the report table).
    pub task: String,
    /// The paper task it matches.
    pub paper_task: String,
    /// Its title.
    pub paper_title: String,
    /// The paper's table number, if known.
    pub table: Option<String>,
    /// The paper version the figures come from.
    pub version: String,
    /// One column per algorithm of our table, in table order.
    pub columns: Vec<PaperColumn>,
    /// Algorithms the paper reports on this task that our table does not have.
    pub not_run: Vec<String>,
    /// The paper task's remarks.
    pub note: Option<String>,
}

/// The paper's column for one of our algorithms.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PaperColumn {
    /// Our algorithm label (as in the table's header).
    pub algorithm: String,
    /// Whether the paper reports this algorithm on the task.
    pub in_paper: bool,
    /// One cell per metric of the paper's entry, keyed like our metrics.
    pub cells: Vec<PaperCell>,
}

impl PaperColumn {
    /// The cell of metric `key`.
    pub fn cell(&self, key: &str) -> Option<&PaperCell> {
        self.cells.iter().find(|c| c.key == key)
    }
}

/// The paper's value of one metric, in our unit, and the ratio ours / paper.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PaperCell {
    /// Metric key.
    pub key: String,
    /// Paper mean in our unit (`None` when not published/found or not convertible).
    pub mean: Option<f64>,
    /// Paper ± in our unit.
    pub std: Option<f64>,
    /// Our unit (the row's).
    pub unit: String,
    /// The value as published, with its unit, when a conversion was applied.
    pub published: Option<String>,
    /// The conversion applied (`GiB → GB (×1.073742)`), if any.
    pub conversion: Option<String>,
    /// Ours / paper, for energy, RAM and wall-clock time, when both are known.
    pub ratio: Option<f64>,
    /// Where the paper's figure was typed in from.
    pub source: Option<String>,
    /// Why it is missing, or remarks.
    pub note: Option<String>,
    /// For return and generalization cells: how our mean stands against the paper's
    /// (`None` for the other metrics, or when either side is missing).
    #[serde(default)]
    pub verdict: Option<Verdict>,
    /// For a `trails` verdict: the paper's mean minus ours (positive).
    #[serde(default)]
    pub gap: Option<f64>,
    /// The metric's name as the paper prints it, when `tables.json` gives it.
    #[serde(default)]
    pub paper_metric: Option<String>,
    /// The phase the paper lists the metric under.
    #[serde(default)]
    pub phase: Option<Phase>,
    /// For a `trails` verdict on a cell the task's ceiling puts out of reach
    /// ([`PaperTask::ceilings`]): why, with the number.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub out_of_reach: Option<String>,
}

/// Metrics that get a verdict: higher is better, and the paper's ± is a spread over seeds.
pub const VERDICT_METRICS: &[&str] = &["returns", "generalization"];

/// Ours / paper for the metrics of [`RATIO_METRICS`], when both are known.
fn ratio_of(key: &str, ours: Option<f64>, paper: Option<f64>) -> Option<f64> {
    match (RATIO_METRICS.contains(&key), ours, paper) {
        (true, Some(o), Some(p)) if p != 0.0 => Some(o / p),
        _ => None,
    }
}

/// The verdict (and gap) for the metrics of [`VERDICT_METRICS`], when both means are known.
fn verdict_of(
    key: &str,
    ours: Option<f64>,
    paper_mean: Option<f64>,
    paper_std: Option<f64>,
) -> (Option<Verdict>, Option<f64>) {
    match (VERDICT_METRICS.contains(&key), ours, paper_mean) {
        (true, Some(o), Some(p)) => {
            let (v, gap) = Verdict::judge(o, p, paper_std);
            (Some(v), gap)
        }
        _ => (None, None),
    }
}

impl Verdict {
    /// How `ours` stands against the paper's `mean ± std`, with the gap when it trails.
    ///
    /// ```
    /// use a2perf_pipeline::report::paper::Verdict;
    /// assert_eq!(Verdict::judge(1.2, 1.0, Some(0.5)), (Verdict::Beats, None));
    /// assert_eq!(Verdict::judge(0.6, 1.0, Some(0.5)), (Verdict::Within, None));
    /// assert_eq!(Verdict::judge(0.25, 1.0, Some(0.5)), (Verdict::Trails, Some(0.75)));
    /// assert_eq!(Verdict::judge(0.9, 1.0, None).0, Verdict::Trails);
    /// ```
    pub fn judge(ours: f64, paper_mean: f64, paper_std: Option<f64>) -> (Verdict, Option<f64>) {
        if ours > paper_mean {
            (Verdict::Beats, None)
        } else if ours >= paper_mean - paper_std.unwrap_or(0.0) {
            (Verdict::Within, None)
        } else {
            (Verdict::Trails, Some(paper_mean - ours))
        }
    }

    /// `beats`, `within` or `trails`.
    pub fn as_str(self) -> &'static str {
        match self {
            Verdict::Beats => "beats",
            Verdict::Within => "within",
            Verdict::Trails => "trails",
        }
    }
}

/// How our mean stands against the paper's `mean ± std`, for metrics where higher is better
/// (returns, generalization).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Verdict {
    /// Ours is above the paper's mean.
    Beats,
    /// Ours is at or below the paper's mean but within its ± std.
    Within,
    /// Ours is below the paper's mean minus its std (or below its mean when it prints no std).
    Trails,
}

/// One of the paper's findings, checked on a report's runs.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct FindingCheck {
    /// The finding's id (`F1`).
    pub id: String,
    /// The claim, as stated in `tables.json`.
    pub claim: String,
    /// The paper's numbers the claim rests on.
    pub paper: String,
    /// Our numbers, computed from the same cells of our runs.
    pub ours: String,
    /// Whether the claim holds on our runs; `None` when our runs lack a cell it needs.
    pub holds: Option<bool>,
    /// Why it could not be checked, or remarks.
    #[serde(default)]
    pub note: Option<String>,
    /// Whether the definition holds on the paper's own figures (a check of the definition:
    /// `false` means it does not capture the claim as the paper's numbers show it).
    #[serde(default)]
    pub paper_holds: Option<bool>,
}

/// Pairs every table of `report` that matches a paper task with the paper's figures.
/// `groups` are the report's groups in the same order as `report.groups`.
pub fn compare(report: &Report, groups: &[Group], tables: &PaperTables) -> Vec<PaperComparison> {
    let mut out = Vec::new();
    let tasks: BTreeSet<&str> = report.groups.iter().map(|g| g.task.as_str()).collect();
    for task in tasks {
        let in_task: Vec<(&super::GroupReport, &Group)> = report
            .groups
            .iter()
            .zip(groups)
            .filter(|(g, _)| g.task == task)
            .collect();
        let Some((_, first)) = in_task.first() else {
            continue;
        };
        let record = &first.runs[0].run.record;
        let Some(paper) = tables.matching(&record.task.env_id, &record.task.env_params) else {
            continue;
        };
        let mut ours_algos = BTreeSet::new();
        let columns = in_task
            .iter()
            .map(|(gr, g)| {
                let name = &g.runs[0].run.record.algorithm.name;
                ours_algos.insert(name.clone());
                let entry = paper.algorithms.get(name);
                let cells = entry
                    .map(|metrics| {
                        gr.metrics
                            .iter()
                            .filter_map(|m| metrics.get(&m.key).map(|v| (m, v)))
                            .map(|(m, v)| {
                                let c = v.in_unit(&m.unit);
                                let ratio = ratio_of(&m.key, m.mean, c.mean);
                                let (verdict, gap) = verdict_of(&m.key, m.mean, c.mean, c.std);
                                let out_of_reach =
                                    paper.out_of_reach(&m.key, verdict, c.mean, c.std);
                                PaperCell {
                                    key: m.key.clone(),
                                    mean: c.mean,
                                    std: c.std,
                                    unit: m.unit.clone(),
                                    published: c.conversion.as_ref().and(v.mean).map(|mean| {
                                        let pm =
                                            v.std.map(|s| format!(" ± {s}")).unwrap_or_default();
                                        format!("{mean}{pm} {}", v.unit)
                                    }),
                                    conversion: c.conversion,
                                    ratio,
                                    source: v.source.clone(),
                                    note: v.note.clone(),
                                    verdict,
                                    gap,
                                    paper_metric: v.paper_metric.clone(),
                                    phase: v.phase,
                                    out_of_reach,
                                }
                            })
                            .collect()
                    })
                    .unwrap_or_default();
                PaperColumn {
                    algorithm: gr.algorithm.clone(),
                    in_paper: entry.is_some(),
                    cells,
                }
            })
            .collect();
        out.push(PaperComparison {
            task: task.to_string(),
            paper_task: paper.id.clone(),
            paper_title: paper.title.clone(),
            table: paper.table.clone(),
            version: tables.paper.version.clone(),
            columns,
            not_run: paper
                .algorithms
                .keys()
                .filter(|a| !ours_algos.contains(*a))
                .cloned()
                .collect(),
            note: paper.note.clone(),
        });
    }
    out
}

/// The paper's figures as a side findings are evaluated on, in our report's units.
pub struct PaperSide<'a>(pub &'a PaperTables);

impl CellSource for PaperSide<'_> {
    fn value(&self, cell: &CellRef) -> std::result::Result<CellValue, String> {
        let v = self
            .0
            .value(cell)
            .ok_or_else(|| "not in the paper's tables".to_string())?;
        let c = match dimension_of(&cell.metric) {
            Some(dim) => v.in_unit(report_unit(dim, &cell.metric)),
            None => v.in_unit(&v.unit),
        };
        match c.mean {
            Some(mean) => Ok(CellValue { mean, std: c.std }),
            None => Err(v.note.clone().unwrap_or_else(|| "not published".into())),
        }
    }

    fn unit(&self, cell: &CellRef) -> String {
        finding_unit(&cell.metric)
    }
}

/// The unit findings compute metric `key` in (empty when unitless).
fn finding_unit(key: &str) -> String {
    dimension_of(key)
        .map(|d| report_unit(d, key).to_string())
        .unwrap_or_default()
}

/// A report's runs as a side findings are evaluated on: a cell `task/algorithm/metric` is the
/// metric of the report table that matches paper task `task`, column of algorithm `algorithm`
/// (our registered name).
pub struct OursSide<'a> {
    /// (paper task, algorithm) → the group and its number of runs, or why there is none.
    groups: BTreeMap<(String, String), std::result::Result<RanGroup<'a>, String>>,
}

/// A report group and its number of runs.
type RanGroup<'a> = (&'a super::GroupReport, usize);

impl<'a> OursSide<'a> {
    /// Pairs every (paper task, algorithm) with the report group that ran it.
    pub fn new(report: &'a Report, groups: &[Group], tables: &PaperTables) -> Self {
        let mut out = BTreeMap::new();
        for (gr, g) in report.groups.iter().zip(groups) {
            let Some(first) = g.runs.first() else {
                continue;
            };
            let record = &first.run.record;
            let Some(task) = tables.matching(&record.task.env_id, &record.task.env_params) else {
                continue;
            };
            let key = (task.id.clone(), record.algorithm.name.clone());
            match out.get(&key) {
                None => {
                    out.insert(key, Ok((gr, g.runs.len())));
                }
                Some(Ok((other, _))) => {
                    let why = format!(
                        "two report columns run {} on it ({} and {}); compare them one at a time",
                        record.algorithm.name, other.algorithm, gr.algorithm
                    );
                    out.insert(key, Err(why));
                }
                Some(Err(_)) => {}
            }
        }
        Self { groups: out }
    }

    /// The report group of `algorithm` on paper task `task`, and its number of runs.
    pub fn group(&self, task: &str, algorithm: &str) -> std::result::Result<RanGroup<'a>, String> {
        match self.groups.get(&(task.to_string(), algorithm.to_string())) {
            Some(found) => found.clone(),
            None => Err(format!("no {algorithm} runs on this task")),
        }
    }
}

impl CellSource for OursSide<'_> {
    fn value(&self, cell: &CellRef) -> std::result::Result<CellValue, String> {
        let (gr, _) = self.group(&cell.task, &cell.algorithm)?;
        let m = gr
            .metric(&cell.metric)
            .ok_or_else(|| "not a metric of our report".to_string())?;
        let Some(mean) = m.mean else {
            return Err(m.note.clone().unwrap_or_else(|| "missing".into()));
        };
        let factor = match dimension_of(&cell.metric) {
            None => 1.0,
            Some(dim) => match (
                unit_scale(&m.unit),
                unit_scale(report_unit(dim, &cell.metric)),
            ) {
                (Some((a, fa)), Some((b, fb))) if a == b => fa / fb,
                _ => return Err(format!("our unit `{}` is not convertible", m.unit)),
            },
        };
        Ok(CellValue {
            mean: mean * factor,
            std: m.std.map(|s| s * factor),
        })
    }

    fn unit(&self, cell: &CellRef) -> String {
        finding_unit(&cell.metric)
    }
}

/// Checks every finding of `tables` on the report's runs (and on the paper's own figures).
pub fn check_findings(
    report: &Report,
    groups: &[Group],
    tables: &PaperTables,
) -> Vec<FindingCheck> {
    let ours = OursSide::new(report, groups, tables);
    let paper = PaperSide(tables);
    tables
        .findings
        .iter()
        .map(|f| {
            let on_paper = f.evaluate(&paper);
            let on_ours = f.evaluate(&ours);
            let mut notes: Vec<String> = f.note.iter().cloned().collect();
            if !on_ours.missing.is_empty() {
                notes.push(format!(
                    "missing in our runs: {}",
                    on_ours.missing.join("; ")
                ));
            }
            if on_paper.holds != Some(true) {
                notes.push(format!(
                    "the definition does not hold on the paper's own figures{}",
                    if on_paper.missing.is_empty() {
                        String::new()
                    } else {
                        format!(" ({})", on_paper.missing.join("; "))
                    }
                ));
            }
            FindingCheck {
                id: f.id.clone(),
                claim: f.claim.clone(),
                paper: on_paper.text,
                ours: on_ours.text,
                holds: on_ours.holds,
                note: (!notes.is_empty()).then(|| notes.join("; ")),
                paper_holds: on_paper.holds,
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn value(mean: Option<f64>, std: Option<f64>, unit: &str) -> PaperValue {
        PaperValue {
            mean,
            std,
            unit: unit.into(),
            measured_unit: None,
            source: Some("Table 1, row 'x'".into()),
            note: Some("n".into()),
            paper_metric: None,
            phase: None,
        }
    }

    #[test]
    fn conversions_are_exact_and_labelled() {
        let c = value(Some(2.0), Some(0.5), "GiB").in_unit("GB");
        assert_eq!(c.mean, Some(2.0 * 1.073_741_824));
        assert_eq!(c.std, Some(0.5 * 1.073_741_824));
        assert_eq!(c.conversion.as_deref(), Some("GiB → GB (×1.073742)"));
        let c = value(Some(90.0), None, "min").in_unit("Hours");
        assert_eq!(c.mean, Some(1.5));
        let same = value(Some(3.0), None, "kWh").in_unit("kWh");
        assert_eq!((same.mean, same.conversion), (Some(3.0), None));
        let mut secs = value(Some(0.2), None, "ms");
        secs.measured_unit = Some("s".into());
        let c = secs.in_unit("ms");
        assert_eq!(c.mean, Some(200.0));
        assert_eq!(
            c.conversion.as_deref(),
            Some("published as ms, measured in s; s → ms (×1000)")
        );
        let free = value(Some(5.0), None, "100 eps.").in_unit("20 eps.");
        assert_eq!((free.mean, free.conversion), (Some(5.0), None));
    }

    #[test]
    fn values_follow_the_rules() {
        assert!(value(Some(1.0), None, "kWh").check("energy").is_ok());
        assert!(value(None, None, "kWh").check("energy").is_ok());
        let e = value(Some(1.0), None, "GB").check("energy").unwrap_err();
        assert!(e.contains("unit `GB` is not a unit of this metric"), "{e}");
        let e = value(Some(1.0), None, "kWh").check("enrgy").unwrap_err();
        assert!(e.contains("did you mean `energy`"), "{e}");
        let mut v = value(Some(1.0), None, "kWh");
        v.source = None;
        assert!(
            v.check("energy")
                .unwrap_err()
                .contains("needs its `source`")
        );
        let mut v = value(None, None, "kWh");
        v.note = None;
        assert!(v.check("energy").unwrap_err().contains("needs a `note`"));
        assert!(value(Some(f64::NAN), None, "kWh").check("energy").is_err());
        assert!(value(Some(1.0), Some(-1.0), "kWh").check("energy").is_err());
    }

    #[test]
    fn numbers_match_by_value() {
        assert!(same_value(&Value::Int(5), &Value::Float(5.0)));
        assert!(!same_value(&Value::Int(5), &Value::Int(10)));
        assert!(!same_value(&Value::Str("5".into()), &Value::Int(5)));
    }
}
