//! The report's data: the tables' columns and cells ([`Report`], [`GroupReport`],
//! [`MetricValue`]), the comparisons between algorithms, the paper's cells beside ours
//! ([`PaperComparison`], [`Verdict`], [`FindingCheck`]) and the names under which the meters
//! record what the tables show. Every other part of the report reads or writes these; this file
//! imports none of them.

use a2perf_core::{MeterReport, Provenance, TimeSplit};
use serde::{Deserialize, Serialize};

use crate::spec::{ProfileRecord, SuiteSource};

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

/// The note of a metric whose value is NaN or infinite for the group's runs.
pub(crate) const NOT_FINITE: &str = "not finite for these runs";

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
    pub(crate) fn new(
        category: Category,
        key: &str,
        label: &str,
        unit: &str,
        higher: bool,
    ) -> Self {
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

    pub(crate) fn missing(mut self, why: impl Into<String>) -> Self {
        self.note = Some(why.into());
        self
    }

    pub(crate) fn scalar(mut self, value: f64, spread: Option<f64>) -> Self {
        if value.is_finite() {
            self.mean = Some(value);
            self.std = spread.filter(|s| s.is_finite());
        } else {
            self.note = Some(NOT_FINITE.into());
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
    /// Where the group's training wall time went, summed over its runs (when every run
    /// recorded it).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub time_split: Option<GroupTimeSplit>,
}

/// The training wall time of a group's runs, and how much of it each part claimed.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct GroupTimeSplit {
    /// Training wall seconds, summed over the runs.
    pub wall_s: f64,
    /// The parts' seconds, summed over the runs.
    pub parts: TimeSplit,
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
    pub paper: Vec<PaperComparison>,
    /// The paper's findings checked on these runs (`--paper` with findings in its tables).
    #[serde(default)]
    pub findings: Vec<FindingCheck>,
}

impl Report {
    /// The settings of task table `task`.
    pub fn settings_of(&self, task: &str) -> Option<&TableSettings> {
        self.settings.iter().find(|s| s.task == task)
    }

    /// The paper comparison of task table `task`.
    pub fn paper_of(&self, task: &str) -> Option<&PaperComparison> {
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

/// Options of [`build_report`](super::build_report).
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
    /// ([`PaperTask::ceilings`](super::paper::PaperTask::ceilings)): why, with the number.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub out_of_reach: Option<String>,
}

/// Metrics that get a verdict: higher is better, and the paper's ± is a spread over seeds.
pub const VERDICT_METRICS: &[&str] = &["returns", "generalization"];

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

/// Names under which the system meters report each quantity (first match wins).
pub(crate) const ENERGY_NAMES: &[&str] = &[
    "energy_total_kwh",
    "total_energy_kwh",
    "energy_kwh",
    "energy_consumed_kwh",
];

pub(crate) const PEAK_RAM_NAMES: &[&str] = &["peak_ram_gb", "ram_peak_gb"];

/// A system measurement looked up under any of `names`, with its provenance.
pub(crate) fn meter_value(
    report: &MeterReport,
    names: &[&str],
) -> Option<(Option<f64>, Provenance)> {
    names.iter().find_map(|n| {
        report
            .get(n)
            .map(|m| (m.value.filter(|v| v.is_finite()), m.provenance.clone()))
    })
}
