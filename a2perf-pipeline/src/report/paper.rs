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

use super::{Group, Report};
use crate::{PipelineError, Result};

/// The schema tag `tables.json` must carry.
pub const SCHEMA: &str = "a2perf-paper-tables/1";

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
        if self.schema != SCHEMA {
            return Err(format!(
                "schema `{}` is not supported (expected `{SCHEMA}`)",
                self.schema
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
        Ok(())
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
                                let ratio =
                                    match (RATIO_METRICS.contains(&m.key.as_str()), m.mean, c.mean)
                                    {
                                        (true, Some(ours), Some(p)) if p != 0.0 => Some(ours / p),
                                        _ => None,
                                    };
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
                                    verdict: None,
                                    gap: None,
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
