//! Our report beside the paper: the paper's cell for each of ours with a verdict, the findings
//! checked on our runs, and `comparison.json` (every cell of the paper's tables beside ours, the
//! findings' outcomes and the runs' totals).

use std::collections::{BTreeMap, BTreeSet};

use serde::{Deserialize, Serialize};

use super::findings::{CellRef, CellSource, CellValue};
use super::tables::{
    PaperSide, PaperTables, dimension_of, finding_unit, ratio_of, report_unit, unit_scale,
    verdict_of,
};
use crate::report::load::Group;
use crate::report::model::{
    ENERGY_NAMES, FindingCheck, GroupReport, PEAK_RAM_NAMES, PaperCell, PaperColumn,
    PaperComparison, Phase, Report, Verdict, meter_value,
};

/// Pairs every table of `report` that matches a paper task with the paper's figures.
/// `groups` are the report's groups in the same order as `report.groups`.
pub fn compare(report: &Report, groups: &[Group], tables: &PaperTables) -> Vec<PaperComparison> {
    let mut out = Vec::new();
    let tasks: BTreeSet<&str> = report.groups.iter().map(|g| g.task.as_str()).collect();
    for task in tasks {
        let in_task: Vec<(&GroupReport, &Group)> = report
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

/// A report's runs as a side findings are evaluated on: a cell `task/algorithm/metric` is the
/// metric of the report table that matches paper task `task`, column of algorithm `algorithm`
/// (our registered name).
pub struct OursSide<'a> {
    /// (paper task, algorithm) → the group and its number of runs, or why there is none.
    groups: BTreeMap<(String, String), std::result::Result<RanGroup<'a>, String>>,
}

/// A report group and its number of runs.
type RanGroup<'a> = (&'a GroupReport, usize);

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

/// The file `a2perf report --paper` writes as `comparison.json`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ComparisonFile {
    /// One entry per cell of the paper's tables: task by task, then by algorithm and metric key.
    pub cells: Vec<ComparisonCell>,
    /// One entry per finding.
    pub findings: Vec<FindingOutcome>,
    /// What the report's runs cost in total.
    pub suite: SuiteTotals,
}

/// One cell of the paper's tables and ours.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ComparisonCell {
    /// The paper's task id.
    pub task: String,
    /// `training` or `inference`, as the paper lists the metric.
    pub phase: String,
    /// The metric's name as the paper prints it.
    pub metric: String,
    /// Algorithm (our registered name, the paper's lower-cased column).
    pub algorithm: String,
    /// The paper's mean (`null`: N/A in the paper).
    pub paper_mean: Option<f64>,
    /// The paper's ±.
    pub paper_std: Option<f64>,
    /// Our mean over seeds (`null`: not run, or not measured; see `ours_note`).
    pub ours_mean: Option<f64>,
    /// Our spread.
    pub ours_std: Option<f64>,
    /// For returns and generalization: how ours stands against the paper's mean ± std.
    pub verdict: Option<Verdict>,
    /// The unit both means are in: the paper's as printed (free text for returns and the
    /// reliability metrics).
    pub unit: String,
    /// Our metric key.
    pub key: String,
    /// Ours / paper, for energy, RAM and wall-clock time.
    pub ratio: Option<f64>,
    /// Why ours is missing.
    pub ours_note: Option<String>,
    /// For a `trails` verdict the task's measured ceiling explains: why, with the number.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub out_of_reach: Option<String>,
}

/// One finding's outcome.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct FindingOutcome {
    /// `F1`.
    pub id: String,
    /// Whether the claim holds on our runs (`null`: a cell it needs is missing).
    pub holds: Option<bool>,
    /// The paper's numbers.
    pub paper: String,
    /// Ours.
    pub ours: String,
    /// Why it could not be checked, or how it is judged.
    pub note: Option<String>,
}

/// Totals over every run of the report.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SuiteTotals {
    /// Training plus inference wall-clock time of every run, in hours (generalization records
    /// no wall-clock time).
    pub wall_hours: f64,
    /// Training plus inference energy of every run where recorded, kWh.
    pub energy_kwh: f64,
    /// The largest peak RAM of any run's training or inference, GB.
    pub peak_ram_gb: Option<f64>,
    /// Distinct seeds.
    pub seeds: usize,
    /// Runs.
    pub runs: usize,
    /// Runs whose energy was not recorded (left out of `energy_kwh`).
    pub runs_without_energy: usize,
    /// The paper's training energy (Energy Consumed) for the report's (task, algorithm) groups
    /// that match a paper cell, each per-seed mean times our number of runs of the group, kWh.
    pub paper_energy_kwh_same_runs: f64,
    /// Our training energy of those same runs, kWh.
    pub ours_energy_kwh_same_runs: f64,
    /// Ours / paper over those runs (`null` when no run matches).
    pub energy_ratio_same_runs: Option<f64>,
}

/// Builds `comparison.json` for `report` (whose findings are already checked).
pub fn comparison(report: &Report, groups: &[Group], tables: &PaperTables) -> ComparisonFile {
    let ours = OursSide::new(report, groups, tables);
    let paper = PaperSide(tables);
    let mut cells = Vec::new();
    let mut paper_energy = 0.0;
    let mut ours_energy = 0.0;
    let mut matched_energy = false;
    for task in &tables.tasks {
        for (algorithm, metrics) in &task.algorithms {
            for (key, v) in metrics {
                let cell = CellRef {
                    task: task.id.clone(),
                    algorithm: algorithm.clone(),
                    metric: key.clone(),
                };
                // Both sides in the paper's printed unit: findings work in ours, so convert
                // back when they differ.
                let back = finding_unit(key);
                let to_printed = if back.is_empty() {
                    Some(1.0)
                } else {
                    unit_scale(&back)
                        .zip(unit_scale(&v.unit))
                        .filter(|((a, _), (b, _))| a == b)
                        .map(|((_, fa), (_, fb))| fa / fb)
                };
                let scale = |x: f64| to_printed.map(|f| x * f);
                let theirs = paper.value(&cell).ok();
                let mine = ours.value(&cell);
                let (ours_mean, ours_std, ours_note) = match &mine {
                    Ok(c) => (scale(c.mean), c.std.and_then(scale), None),
                    Err(why) => (None, None, Some(why.clone())),
                };
                let paper_mean = theirs.and_then(|c| scale(c.mean));
                let paper_std = theirs.and_then(|c| c.std.and_then(scale));
                let verdict = verdict_of(key, ours_mean, paper_mean, paper_std).0;
                let out_of_reach = task.out_of_reach(key, verdict, paper_mean, paper_std);
                let ratio = ratio_of(key, ours_mean, paper_mean);
                if key == "energy"
                    && let (Ok((gr, runs)), Some(p)) = (ours.group(&task.id, algorithm), theirs)
                {
                    let per_seed = gr.metric("energy").map(|m| m.per_seed.clone());
                    if let Some(per_seed) = per_seed.filter(|s| s.len() == runs) {
                        matched_energy = true;
                        paper_energy += p.mean * runs as f64;
                        ours_energy += per_seed.iter().sum::<f64>();
                    }
                }
                cells.push(ComparisonCell {
                    task: task.id.clone(),
                    phase: v.phase.unwrap_or(Phase::of_key(key)).as_str().to_string(),
                    metric: v.paper_metric.clone().unwrap_or_else(|| key.clone()),
                    algorithm: algorithm.clone(),
                    paper_mean,
                    paper_std,
                    ours_mean,
                    ours_std,
                    verdict,
                    unit: v.unit.clone(),
                    key: key.clone(),
                    ratio,
                    ours_note,
                    out_of_reach,
                });
            }
        }
    }
    let findings = report
        .findings
        .iter()
        .map(|f| FindingOutcome {
            id: f.id.clone(),
            holds: f.holds,
            paper: f.paper.clone(),
            ours: f.ours.clone(),
            note: f.note.clone(),
        })
        .collect();
    let mut suite = totals(groups);
    suite.paper_energy_kwh_same_runs = paper_energy;
    suite.ours_energy_kwh_same_runs = ours_energy;
    suite.energy_ratio_same_runs =
        (matched_energy && paper_energy != 0.0).then_some(ours_energy / paper_energy);
    ComparisonFile {
        cells,
        findings,
        suite,
    }
}

/// Wall-clock time, energy, peak RAM and seeds over every run.
fn totals(groups: &[Group]) -> SuiteTotals {
    let mut wall_s = 0.0;
    let mut energy = 0.0;
    let mut peak: Option<f64> = None;
    let mut seeds = BTreeSet::new();
    let mut runs = 0;
    let mut without_energy = 0;
    for r in groups.iter().flat_map(|g| &g.runs) {
        runs += 1;
        seeds.insert(r.run.record.seed);
        let phases = [
            r.train_system.as_ref(),
            r.inference.as_ref().map(|i| &i.system),
        ];
        let mut recorded = false;
        for s in phases.into_iter().flatten() {
            wall_s += s.wall_clock_s;
            if let Some((Some(e), _)) = meter_value(&s.meters, ENERGY_NAMES) {
                energy += e;
                recorded = true;
            }
            if let Some((Some(p), _)) = meter_value(&s.meters, PEAK_RAM_NAMES) {
                peak = Some(peak.map_or(p, |q| q.max(p)));
            }
        }
        if !recorded {
            without_energy += 1;
        }
    }
    SuiteTotals {
        wall_hours: wall_s / 3600.0,
        energy_kwh: energy,
        peak_ram_gb: peak,
        seeds: seeds.len(),
        runs,
        runs_without_energy: without_energy,
        paper_energy_kwh_same_runs: 0.0,
        ours_energy_kwh_same_runs: 0.0,
        energy_ratio_same_runs: None,
    }
}
