//! `a2perf report`: the paper's four-category tables per (task, algorithm), statistics between
//! algorithms, plots and a leaderboard entry.
//!
//! Every figure is computed from the run directories' files; nothing is re-run. A metric whose
//! inputs are missing (e.g. `infer` was not run, or the machine has no GPU) is reported as missing
//! with the reason, never as zero.
//!
//! The parts: [`load`] finds and groups the runs; `families` computes one table column per
//! (task, algorithm) group, one function per metric family; [`statistics`] compares the
//! algorithms (IQM, probability of improvement), with all arithmetic from `a2perf_metrics`;
//! [`merge`] joins reports made apart; [`render`], [`html`], [`svg`] and [`leaderboard`] write
//! them out, and [`paper`] sets the paper's figures beside them.

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use super::plan::{ProfileRecord, SuiteSource};
use super::{Result, io_err};

mod families;
pub mod format;
pub mod html;
pub mod leaderboard;
pub mod load;
pub mod merge;
pub mod paper;
pub mod render;
pub mod statistics;
pub mod svg;

pub use load::{Group, RunData, SkippedRun, load_groups};
pub use merge::merge_reports;

/// The four metric families of the paper (system split into training and inference).
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Category {
    /// Training sample cost of offline data.
    DataCost,
    /// Returns and generalization.
    Application,
    /// The seven reliability metrics.
    Reliability,
    /// Energy, power, RAM and wall-clock of training.
    SystemTraining,
    /// Inference time, power, energy and RAM.
    SystemInference,
}

impl Category {
    /// Display name.
    pub fn label(self) -> &'static str {
        match self {
            Category::DataCost => "Data cost",
            Category::Application => "Application",
            Category::Reliability => "Reliability",
            Category::SystemTraining => "System (training)",
            Category::SystemInference => "System (inference)",
        }
    }
}

/// One metric of one (task, algorithm) group.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct MetricValue {
    /// Family.
    pub category: Category,
    /// Machine name, e.g. `dispersion_across_runs`.
    pub key: String,
    /// Display name.
    pub label: String,
    /// Unit (`kWh`, `GB`, `IQR`, `CVaR`, …).
    pub unit: String,
    /// `true` when larger is better.
    pub higher_is_better: bool,
    /// Per-seed values, when the metric is defined per run.
    pub per_seed: Vec<f64>,
    /// Mean over seeds, or the group-level value.
    pub mean: Option<f64>,
    /// Sample standard deviation over seeds (ddof 1), or the metric's own spread.
    pub std: Option<f64>,
    /// 95% percentile-bootstrap confidence interval of the mean over seeds.
    pub ci95: Option<[f64; 2]>,
    /// Why the value is missing, or how it was obtained when estimated.
    pub note: Option<String>,
}

impl MetricValue {
    fn new(category: Category, key: &str, label: &str, unit: &str, higher: bool) -> Self {
        Self {
            category,
            key: key.into(),
            label: label.into(),
            unit: unit.into(),
            higher_is_better: higher,
            per_seed: Vec::new(),
            mean: None,
            std: None,
            ci95: None,
            note: None,
        }
    }

    fn missing(mut self, why: impl Into<String>) -> Self {
        self.note = Some(why.into());
        self
    }

    fn scalar(mut self, value: f64, spread: Option<f64>) -> Self {
        if value.is_finite() {
            self.mean = Some(value);
            self.std = spread.filter(|s| s.is_finite());
        } else {
            self.note = Some("not finite for these runs".into());
        }
        self
    }
}

/// Report of one (task, algorithm) group.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct GroupReport {
    /// Task name.
    pub task: String,
    /// Environment id.
    pub env_id: String,
    /// Domain.
    pub domain: String,
    /// Algorithm.
    pub algorithm: String,
    /// Seeds of the complete runs.
    pub seeds: Vec<u64>,
    /// The metrics, in table order.
    pub metrics: Vec<MetricValue>,
    /// Every run of the group came from a bundle that verified (see [`crate::bundle`]);
    /// absent (false) otherwise, so reports made without bundles are unchanged.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub verified: bool,
}

impl GroupReport {
    /// The metric called `key`.
    pub fn metric(&self, key: &str) -> Option<&MetricValue> {
        self.metrics.iter().find(|m| m.key == key)
    }
}

/// Interquartile mean of one algorithm on one task, with its 95% bootstrap interval.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct IqmEntry {
    /// Task.
    pub task: String,
    /// Algorithm.
    pub algorithm: String,
    /// IQM of the per-seed mean returns.
    pub iqm: f64,
    /// 95% percentile-bootstrap interval.
    pub ci95: [f64; 2],
    /// Number of runs.
    pub runs: usize,
}

/// P(X > Y): the probability that a run of algorithm `x` beats a run of `y`, averaged over the
/// tasks both were run on (rliable's Mann–Whitney form; ties count one half).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ImprovementEntry {
    /// Algorithm X.
    pub x: String,
    /// Algorithm Y.
    pub y: String,
    /// Tasks both were run on.
    pub tasks: Vec<String>,
    /// Probability of improvement of X over Y.
    pub probability: f64,
    /// 95% stratified-bootstrap interval.
    pub ci95: [f64; 2],
}

/// The whole report (`report.json`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Report {
    /// One entry per (task, algorithm).
    pub groups: Vec<GroupReport>,
    /// IQM of per-seed mean returns per (task, algorithm).
    pub iqm: Vec<IqmEntry>,
    /// Probability of improvement between every ordered pair of algorithms.
    pub probability_of_improvement: Vec<ImprovementEntry>,
    /// Run directories left out, and why.
    pub skipped_runs: Vec<(String, String)>,
    /// Bootstrap repetitions used for every interval.
    pub bootstrap_reps: usize,
    /// Per task table: the profiles and generalization suites its runs used (absent in
    /// reports written before profiles existed).
    #[serde(default)]
    pub settings: Vec<TableSettings>,
    /// The paper's figures beside the tables that match a paper task (`--paper`).
    #[serde(default)]
    pub paper: Vec<paper::PaperComparison>,
    /// The paper's findings checked on these runs (`--paper` with findings in its tables).
    #[serde(default)]
    pub findings: Vec<paper::FindingCheck>,
}

impl Report {
    /// The settings of task table `task`.
    pub fn settings_of(&self, task: &str) -> Option<&TableSettings> {
        self.settings.iter().find(|s| s.task == task)
    }

    /// The paper comparison of task table `task`.
    pub fn paper_of(&self, task: &str) -> Option<&paper::PaperComparison> {
        self.paper.iter().find(|p| p.task == task)
    }
}

/// What a task table's runs were run with: the profile (and its switches) and the
/// generalization suite. More than one of either means the table mixes settings.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TableSettings {
    /// Task.
    pub task: String,
    /// Each distinct profile, with the algorithms whose runs used it.
    pub profiles: Vec<ProfileUse>,
    /// Each distinct generalization suite, with the algorithms whose runs used it.
    pub suites: Vec<SuiteUse>,
}

/// A profile used by runs of a table.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ProfileUse {
    /// The profile with its switches; `None`: no profile (the corrected defaults).
    pub profile: Option<ProfileRecord>,
    /// Algorithms (table columns) whose runs used it.
    pub algorithms: Vec<String>,
}

/// A generalization suite used by runs of a table.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SuiteUse {
    /// Where it came from; `None`: not recorded (older runs, which used the registry's suite
    /// at `generalize` time).
    pub source: Option<SuiteSource>,
    /// Its task names, in order (empty when not recorded).
    pub tasks: Vec<String>,
    /// Algorithms (table columns) whose runs used it.
    pub algorithms: Vec<String>,
}

impl TableSettings {
    /// Whether runs with different profiles (or different switches of one profile) share the
    /// table.
    pub fn mixed_profiles(&self) -> bool {
        self.profiles.len() > 1
    }

    /// Whether runs with different generalization suites share the table (their
    /// generalization sums are over different tasks).
    pub fn mixed_suites(&self) -> bool {
        self.suites.len() > 1
    }
}

/// Options of [`build_report`].
#[derive(Clone, Debug)]
pub struct ReportOptions {
    /// Bootstrap repetitions for confidence intervals.
    pub bootstrap_reps: usize,
    /// Seed of the bootstrap streams.
    pub seed: u64,
}

impl Default for ReportOptions {
    fn default() -> Self {
        Self {
            bootstrap_reps: 10_000,
            seed: 0,
        }
    }
}

/// Runs proven by bundles that verified (see [`crate::bundle::Bundle::extract`]), and what the
/// report does with them.
#[derive(Clone, Debug, Default)]
pub struct VerifiedRuns {
    /// The run directories extracted from verified bundles.
    pub runs: Vec<PathBuf>,
    /// Restrict `leaderboard.json` to the verified groups.
    pub only: bool,
}

impl VerifiedRuns {
    /// Marks each group of `report` whose runs (`groups`, in the same order) are all verified.
    fn mark(&self, report: &mut Report, groups: &[Group]) {
        for (gr, g) in report.groups.iter_mut().zip(groups) {
            gr.verified =
                !g.runs.is_empty() && g.runs.iter().all(|r| self.runs.contains(&r.run.dir));
        }
    }
}

/// Computes the report of the runs below `dirs`.
pub fn build_report(dirs: &[PathBuf], opts: &ReportOptions) -> Result<(Report, Vec<Group>)> {
    build_report_with_paper(dirs, opts, None)
}

/// [`build_report`], with the paper's figures beside every table that matches a task of
/// `paper` (see [`paper`]).
pub fn build_report_with_paper(
    dirs: &[PathBuf],
    opts: &ReportOptions,
    paper: Option<&paper::PaperTables>,
) -> Result<(Report, Vec<Group>)> {
    let (groups, skipped) = load_groups(dirs)?;
    let reports: Vec<GroupReport> = groups
        .iter()
        .map(|g| families::group_report(g, opts))
        .collect();
    let (iqm, poi) = statistics::comparisons(&reports, opts);
    let mut report = Report {
        groups: reports,
        iqm,
        probability_of_improvement: poi,
        skipped_runs: skipped,
        bootstrap_reps: opts.bootstrap_reps,
        settings: load::table_settings(&groups),
        paper: Vec::new(),
        findings: Vec::new(),
    };
    if let Some(tables) = paper {
        report.paper = paper::compare(&report, &groups, tables);
        report.findings = paper::check_findings(&report, &groups, tables);
    }
    Ok((report, groups))
}

/// Builds the report and writes every output into `out`: `report.md`, `index.html`, `report.tex`,
/// `metrics.csv`, `report.json`, `leaderboard.json`, `curves.csv` and `scores.csv` (the inputs
/// of `a2perf metrics reliability` and `a2perf metrics iqm`) and
/// `plots/{radar,curves}_<task>.svg`.
pub fn write_report(dirs: &[PathBuf], out: &Path, opts: &ReportOptions) -> Result<Report> {
    write_report_with_paper(dirs, out, opts, None)
}

/// [`write_report`], with the paper's figures beside every table that matches a task of
/// `paper`; `paper_comparison.csv` lists them one row per (task, algorithm, metric), and
/// `comparison.json` every cell of the paper's tables beside ours, the findings' outcomes and
/// the runs' totals ([`paper::summary::ComparisonFile`]).
pub fn write_report_with_paper(
    dirs: &[PathBuf],
    out: &Path,
    opts: &ReportOptions,
    paper: Option<&paper::PaperTables>,
) -> Result<Report> {
    write_report_verified(dirs, out, opts, paper, &VerifiedRuns::default())
}

/// [`write_report_with_paper`], marking the groups whose runs are all in `verified` and, with
/// [`VerifiedRuns::only`], leaving the others out of `leaderboard.json`.
pub fn write_report_verified(
    dirs: &[PathBuf],
    out: &Path,
    opts: &ReportOptions,
    paper: Option<&paper::PaperTables>,
    verified: &VerifiedRuns,
) -> Result<Report> {
    let (mut report, groups) = build_report_with_paper(dirs, opts, paper)?;
    verified.mark(&mut report, &groups);
    std::fs::create_dir_all(out.join("plots")).map_err(io_err(out))?;
    let write = |name: &str, text: &str| -> Result<()> {
        let p = out.join(name);
        a2perf_core::write_atomic(&p, text.as_bytes()).map_err(io_err(&p))
    };
    write("report.md", &render::markdown(&report))?;
    write(
        "index.html",
        &html::page(&report, &html::RunView::of_groups(&groups, out)),
    )?;
    write("report.tex", &render::latex(&report))?;
    write("metrics.csv", &render::csv(&report))?;
    write("curves.csv", &render::curves_csv(&groups))?;
    write("scores.csv", &render::scores_csv(&report))?;
    if let Some(tables) = paper {
        write("paper_comparison.csv", &render::paper_csv(&report))?;
        a2perf_core::write_json_atomic(
            &out.join("comparison.json"),
            &paper::summary::comparison(&report, &groups, tables),
        )?;
    }
    a2perf_core::write_json_atomic(&out.join("report.json"), &report)?;
    let mut board = leaderboard::leaderboard(&report, &groups);
    if verified.only {
        board.entries.retain(|e| e.verified);
    }
    a2perf_core::write_json_atomic(&out.join("leaderboard.json"), &board)?;
    let tasks: std::collections::BTreeSet<&str> =
        report.groups.iter().map(|g| g.task.as_str()).collect();
    for task in tasks {
        let stem = super::plan::path_safe(task);
        let in_task: Vec<&GroupReport> = report.groups.iter().filter(|g| g.task == task).collect();
        write(
            &format!("plots/radar_{stem}.svg"),
            &svg::radar(task, &in_task),
        )?;
        let task_groups: Vec<&Group> = groups.iter().filter(|g| g.task == task).collect();
        write(
            &format!("plots/curves_{stem}.svg"),
            &svg::curves(task, &task_groups),
        )?;
    }
    Ok(report)
}
