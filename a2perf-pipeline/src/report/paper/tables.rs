//! The paper's published tables as data: reading and checking `tables.json`, converting its
//! units to ours, and the paper's side of the findings.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

use a2perf_core::Value;
use serde::{Deserialize, Serialize};

use super::super::format::format_value;
use super::findings::{CellRef, CellSource, CellValue, FindingDef};
use crate::report::model::{Phase, RATIO_METRICS, VERDICT_METRICS, Verdict};
use crate::{PipelineError, Result};

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

/// What a unit measures.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Dimension {
    Energy,
    Power,
    Memory,
    Time,
}

/// A unit's dimension and its size in the dimension's base unit (kWh, W, bytes, seconds).
pub(super) fn unit_scale(unit: &str) -> Option<(Dimension, f64)> {
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
pub(super) fn report_unit(dim: Dimension, key: &str) -> &'static str {
    match dim {
        Dimension::Energy => "kWh",
        Dimension::Power => "W",
        Dimension::Memory => "GB",
        Dimension::Time if key == "wall_clock" => "Hours",
        Dimension::Time => "ms",
    }
}

/// The dimension of metric `key` (`None` when unitless or unknown).
pub(super) fn dimension_of(key: &str) -> Option<Dimension> {
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
    pub(super) fn in_unit(&self, our_unit: &str) -> Converted {
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

pub(super) struct Converted {
    pub(super) mean: Option<f64>,
    pub(super) std: Option<f64>,
    pub(super) conversion: Option<String>,
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

/// Ours / paper for the metrics of [`RATIO_METRICS`], when both are known.
pub(super) fn ratio_of(key: &str, ours: Option<f64>, paper: Option<f64>) -> Option<f64> {
    match (RATIO_METRICS.contains(&key), ours, paper) {
        (true, Some(o), Some(p)) if p != 0.0 => Some(o / p),
        _ => None,
    }
}

/// The verdict (and gap) for the metrics of [`VERDICT_METRICS`], when both means are known.
pub(super) fn verdict_of(
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
pub(super) fn finding_unit(key: &str) -> String {
    dimension_of(key)
        .map(|d| report_unit(d, key).to_string())
        .unwrap_or_default()
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
