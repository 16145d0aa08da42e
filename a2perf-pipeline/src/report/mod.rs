//! `a2perf report`: the paper's four-category tables per (task, algorithm), statistics between
//! algorithms, plots and a leaderboard entry.
//!
//! Every figure is computed from the run directories' files; nothing is re-run. A metric whose
//! inputs are missing (e.g. `infer` was not run, or the machine has no GPU) is reported as missing
//! with the reason, never as zero.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use a2perf_core::{LearningCurve, MeterReport, Provenance, RngStream, results::read_json};
use serde::{Deserialize, Serialize};

use super::generalize::GeneralizationResults;
use super::infer::InferenceResults;
use super::stats::{mean, percentile_sorted, sample_std};
use super::train::PhaseSystem;
use super::{
    CURVE_JSON, GENERALIZATION_FILE, INFERENCE_FILE, LoadedRun, PipelineError, Result,
    SYSTEM_INFO_FILE, SystemInfo, TRAIN_SYSTEM_FILE, find_runs, io_err,
};

pub mod html;
pub mod leaderboard;
pub mod paper;
pub mod render;
pub mod svg;

use super::plan::{GeneralizationSuite, ObservationSource, ProfileRecord, SuiteSource};

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

/// Everything loaded from one complete run directory.
#[derive(Clone, Debug)]
pub struct RunData {
    /// The run.
    pub run: LoadedRun,
    /// Its training curve.
    pub curve: LearningCurve,
    /// Training system measurements.
    pub train_system: Option<PhaseSystem>,
    /// Inference results (absent until `infer` ran).
    pub inference: Option<InferenceResults>,
    /// Generalization results (absent until `generalize` ran).
    pub generalization: Option<GeneralizationResults>,
    /// Machine it was trained on.
    pub system_info: Option<SystemInfo>,
}

/// Which observations the seeds' inference times were measured on (the profile times random
/// observation-space samples, as the original harness did; the default, the rollouts').
fn inference_time_note(runs: &[RunData]) -> String {
    let sources: Vec<ObservationSource> = runs
        .iter()
        .filter_map(|r| r.inference.as_ref().map(|i| i.observation_source))
        .collect();
    let all = |s: ObservationSource| !sources.is_empty() && sources.iter().all(|x| *x == s);
    if all(ObservationSource::Random) {
        "per call, on random observation-space samples (the original harness's method)".into()
    } else if sources.is_empty() || all(ObservationSource::Rollouts) {
        "per call, on the observations met in the rollouts".into()
    } else {
        "per call; the seeds differ in what was timed (rollout observations or random samples)"
            .into()
    }
}

fn read_opt<T: for<'de> Deserialize<'de>>(path: &Path) -> Result<Option<T>> {
    if path.is_file() {
        Ok(Some(read_json(path)?))
    } else {
        Ok(None)
    }
}

impl RunData {
    /// Loads a complete run; errors name the file at fault.
    pub fn load(dir: &Path) -> Result<Self> {
        let run = LoadedRun::open(dir)?;
        run.require_complete()?;
        Ok(Self {
            curve: read_json(&dir.join(CURVE_JSON))?,
            train_system: read_opt(&dir.join(TRAIN_SYSTEM_FILE))?,
            inference: read_opt(&dir.join(INFERENCE_FILE))?,
            generalization: read_opt(&dir.join(GENERALIZATION_FILE))?,
            system_info: read_opt(&dir.join(SYSTEM_INFO_FILE))?,
            run,
        })
    }
}

/// The runs of one (task, algorithm), or of one (task, algorithm, experiment) when several
/// experiments ran the same algorithm on the task.
#[derive(Clone, Debug)]
pub struct Group {
    /// Task name.
    pub task: String,
    /// Algorithm name (`algorithm:experiment` when needed to tell experiments apart).
    pub algorithm: String,
    /// Runs, sorted by seed.
    pub runs: Vec<RunData>,
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

fn table_settings(groups: &[Group]) -> Vec<TableSettings> {
    let mut out: Vec<TableSettings> = Vec::new();
    for g in groups {
        let i = match out.iter().position(|t| t.task == g.task) {
            Some(i) => i,
            None => {
                out.push(TableSettings {
                    task: g.task.clone(),
                    profiles: Vec::new(),
                    suites: Vec::new(),
                });
                out.len() - 1
            }
        };
        let table = &mut out[i];
        let add = |algos: &mut Vec<String>| {
            if !algos.contains(&g.algorithm) {
                algos.push(g.algorithm.clone());
            }
        };
        for r in &g.runs {
            let record = &r.run.record;
            let profile = record.task.profile.clone();
            match table.profiles.iter_mut().find(|u| u.profile == profile) {
                Some(u) => add(&mut u.algorithms),
                None => table.profiles.push(ProfileUse {
                    profile,
                    algorithms: vec![g.algorithm.clone()],
                }),
            }
            let suite = record.generalization.suite.as_ref();
            let source = suite.map(|s: &GeneralizationSuite| s.source);
            let tasks: Vec<String> = suite
                .map(|s| s.tasks.iter().map(|t| t.name.clone()).collect())
                .unwrap_or_default();
            match table
                .suites
                .iter_mut()
                .find(|u| u.source == source && u.tasks == tasks)
            {
                Some(u) => add(&mut u.algorithms),
                None => table.suites.push(SuiteUse {
                    source,
                    tasks,
                    algorithms: vec![g.algorithm.clone()],
                }),
            }
        }
    }
    out
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

/// Loads every complete run below `dirs` and groups them by (task, algorithm). Incomplete runs
/// are listed with the reason; a corrupt file in a complete run is an error naming the file.
pub fn load_groups(dirs: &[PathBuf]) -> Result<(Vec<Group>, Vec<SkippedRun>)> {
    let mut groups: BTreeMap<(String, String, String), Vec<RunData>> = BTreeMap::new();
    let mut skipped = Vec::new();
    let mut seen = std::collections::BTreeSet::new();
    for root in dirs {
        for dir in find_runs(root)? {
            let canon = dir.canonicalize().map_err(io_err(&dir))?;
            if !seen.insert(canon) {
                continue;
            }
            LoadedRun::open(&dir)?;
            if let Some(why) = incomplete_reason(&dir)? {
                skipped.push((dir.display().to_string(), why));
                continue;
            }
            let data = RunData::load(&dir)?;
            let key = (
                data.run.record.task.name.clone(),
                data.run.record.algorithm.name.clone(),
                data.run.record.experiment.clone(),
            );
            groups.entry(key).or_default().push(data);
        }
    }
    // Two experiments running one algorithm on one task (e.g. a hyperparameter sweep) stay
    // apart, labelled `algorithm:experiment`.
    let mut per_pair: BTreeMap<(String, String), usize> = BTreeMap::new();
    for (task, algorithm, _) in groups.keys() {
        *per_pair
            .entry((task.clone(), algorithm.clone()))
            .or_default() += 1;
    }
    let mut out = Vec::new();
    for ((task, algorithm, experiment), mut runs) in groups {
        let algorithm = if per_pair[&(task.clone(), algorithm.clone())] > 1 {
            format!("{algorithm}:{experiment}")
        } else {
            algorithm
        };
        runs.sort_by_key(|r| r.run.record.seed);
        // The same seed twice (e.g. two sweeps merged) would double-count it.
        let mut seeds = std::collections::BTreeSet::new();
        let mut kept = Vec::new();
        for r in runs {
            if seeds.insert(r.run.record.seed) {
                kept.push(r);
            } else {
                skipped.push((
                    r.run.dir.display().to_string(),
                    format!("duplicate seed {} of {task}/{algorithm}", r.run.record.seed),
                ));
            }
        }
        out.push(Group {
            task,
            algorithm,
            runs: kept,
        });
    }
    if out.is_empty() {
        return Err(PipelineError::Invalid(format!(
            "no complete runs found under {}",
            dirs.iter()
                .map(|d| d.display().to_string())
                .collect::<Vec<_>>()
                .join(", ")
        )));
    }
    Ok((out, skipped))
}

/// Why the run in `dir` cannot be reported (`None`: its training completed): failed and
/// interrupted runs say so, with their status note.
fn incomplete_reason(dir: &Path) -> Result<Option<String>> {
    use a2perf_core::RunState;
    let status = a2perf_core::RunDir::new(dir).status()?;
    Ok(match status {
        Some(s) if s.state.is_complete() => None,
        Some(s) => {
            let note = s.note.trim();
            let note = note
                .strip_prefix("failed: ")
                .or_else(|| note.strip_prefix("interrupted: "))
                .unwrap_or(note);
            let state = match s.state {
                RunState::Failed => "training failed",
                RunState::Interrupted => "training interrupted",
                _ => "training incomplete (running, or killed while running)",
            };
            Some(if note.is_empty() {
                state.to_string()
            } else {
                format!("{state}: {note}")
            })
        }
        None => Some("training never started (no status.json)".into()),
    })
}

/// A run directory left out of a report, and why.
pub type SkippedRun = (String, String);

/// Percentile-bootstrap 95% interval of the mean of `values`.
pub fn bootstrap_mean_ci(values: &[f64], reps: usize, rng: &mut RngStream) -> Option<[f64; 2]> {
    if values.is_empty() || reps == 0 || values.iter().any(|v| !v.is_finite()) {
        return None;
    }
    let n = values.len();
    let mut means = Vec::with_capacity(reps);
    for _ in 0..reps {
        let mut s = 0.0;
        for _ in 0..n {
            s += values[rng.index(n)];
        }
        means.push(s / n as f64);
    }
    means.sort_by(f64::total_cmp);
    Some([
        percentile_sorted(&means, 2.5),
        percentile_sorted(&means, 97.5),
    ])
}

/// A system measurement looked up under any of `names`, with its provenance.
fn meter_value(report: &MeterReport, names: &[&str]) -> Option<(Option<f64>, Provenance)> {
    names.iter().find_map(|n| {
        report
            .get(n)
            .map(|m| (m.value.filter(|v| v.is_finite()), m.provenance.clone()))
    })
}

fn per_seed(
    metric: MetricValue,
    values: Vec<Option<f64>>,
    missing_why: &str,
    notes: Vec<String>,
    reps: usize,
    rng: &mut RngStream,
) -> MetricValue {
    let mut m = metric;
    if values.is_empty() || values.iter().any(Option::is_none) {
        let have = values.iter().filter(|v| v.is_some()).count();
        return m.missing(format!("{missing_why} ({have} of {} runs)", values.len()));
    }
    let v: Vec<f64> = values.into_iter().flatten().collect();
    m.mean = Some(mean(&v));
    m.std = Some(sample_std(&v));
    m.ci95 = bootstrap_mean_ci(&v, reps, rng);
    m.per_seed = v;
    let mut notes = notes;
    notes.sort();
    notes.dedup();
    if !notes.is_empty() {
        m.note = Some(notes.join("; "));
    }
    m
}

/// A system metric across the runs of a group, with provenance notes.
#[allow(clippy::too_many_arguments)]
fn system_metric(
    metric: MetricValue,
    systems: &[Option<&PhaseSystem>],
    names: &[&str],
    scale: f64,
    reps: usize,
    rng: &mut RngStream,
) -> MetricValue {
    let mut values = Vec::new();
    let mut notes = Vec::new();
    let mut absent = None;
    for s in systems {
        match s.and_then(|s| meter_value(&s.meters, names)) {
            Some((Some(v), prov)) => {
                values.push(Some(v * scale));
                if let Provenance::Estimated(how) = prov {
                    notes.push(format!("estimated: {how}"));
                }
                if let Some(s) = s
                    && s.concurrent_runs > 1
                {
                    notes.push(format!(
                        "process-wide while {} runs shared the process",
                        s.concurrent_runs
                    ));
                }
            }
            Some((None, Provenance::Absent(why))) => {
                absent = Some(why);
                values.push(None);
            }
            _ => values.push(None),
        }
    }
    if let Some(why) = absent {
        return metric.missing(format!("absent: {why}"));
    }
    per_seed(metric, values, "not measured", notes, reps, rng)
}

/// Mean total power of a phase: its energy over its wall-clock time.
fn power_metric(
    metric: MetricValue,
    systems: &[Option<&PhaseSystem>],
    reps: usize,
    rng: &mut RngStream,
) -> MetricValue {
    let mut derived = Vec::with_capacity(systems.len());
    for s in systems {
        derived.push(s.map(|s| {
            let mut meters = MeterReport::default();
            if let Some((Some(e), prov)) = meter_value(&s.meters, ENERGY_NAMES) {
                meters.measurements.push(a2perf_core::Measurement {
                    name: "derived_power_w".into(),
                    value: Some(e * 3.6e6 / s.wall_clock_s.max(1e-9)),
                    unit: "W".into(),
                    provenance: prov,
                });
            }
            PhaseSystem {
                meters,
                ..s.clone()
            }
        }));
    }
    let refs: Vec<Option<&PhaseSystem>> = derived.iter().map(Option::as_ref).collect();
    let mut m = system_metric(metric, &refs, &["derived_power_w"], 1.0, reps, rng);
    if m.mean.is_some() {
        let note = m.note.take().map(|n| format!("; {n}")).unwrap_or_default();
        m.note = Some(format!("energy / wall-clock time{note}"));
    }
    m
}

fn group_report(group: &Group, opts: &ReportOptions) -> GroupReport {
    use Category::*;
    let first = &group.runs[0].run.record;
    let mut rng = RngStream::new(
        opts.seed,
        &format!("report/bootstrap/{}/{}", group.task, group.algorithm),
    );
    let reps = opts.bootstrap_reps;
    let runs = &group.runs;
    let mut metrics = Vec::new();

    // Data cost.
    let cost: Vec<Option<f64>> = runs
        .iter()
        .map(|r| {
            r.run
                .record
                .dataset
                .as_ref()
                .and_then(|d| d.training_sample_cost_kwh)
        })
        .collect();
    let train_energy: Vec<Option<f64>> = runs
        .iter()
        .map(|r| {
            r.train_system
                .as_ref()
                .and_then(|s| meter_value(&s.meters, ENERGY_NAMES))
                .and_then(|(v, _)| v)
        })
        .collect();
    let sample_cost = MetricValue::new(
        DataCost,
        "training_sample_cost",
        "Training sample cost",
        "kWh",
        false,
    );
    if runs.iter().all(|r| r.run.record.dataset.is_none()) {
        metrics.push(sample_cost.missing("not applicable: trained online, no dataset"));
        metrics.push(
            MetricValue::new(
                DataCost,
                "total_energy",
                "Sample cost + training energy",
                "kWh",
                false,
            )
            .missing("not applicable: trained online, no dataset"),
        );
    } else {
        let methods: Vec<String> = runs
            .iter()
            .filter_map(|r| {
                r.run
                    .record
                    .dataset
                    .as_ref()
                    .map(|d| format!("cost method: {}", d.cost_method))
            })
            .collect();
        metrics.push(per_seed(
            sample_cost,
            cost.clone(),
            "no sample cost recorded",
            methods,
            reps,
            &mut rng,
        ));
        let total: Vec<Option<f64>> = cost
            .iter()
            .zip(&train_energy)
            .map(|(c, e)| Some((*c)? + (*e)?))
            .collect();
        metrics.push(per_seed(
            MetricValue::new(
                DataCost,
                "total_energy",
                "Sample cost + training energy",
                "kWh",
                false,
            ),
            total,
            "sample cost or training energy missing",
            Vec::new(),
            reps,
            &mut rng,
        ));
    }

    // Application.
    let returns: Vec<Option<f64>> = runs
        .iter()
        .map(|r| r.inference.as_ref().map(|i| i.returns.mean))
        .collect();
    let episodes = runs
        .iter()
        .find_map(|r| r.inference.as_ref().map(|i| i.episodes))
        .unwrap_or(first.inference.episodes);
    metrics.push(per_seed(
        MetricValue::new(
            Application,
            "returns",
            "Returns",
            &format!("{episodes} eps."),
            true,
        ),
        returns,
        "run `a2perf infer` first",
        Vec::new(),
        reps,
        &mut rng,
    ));
    let gen_sum: Vec<Option<f64>> = runs
        .iter()
        .map(|r| {
            r.generalization
                .as_ref()
                .and_then(|g| g.sum_of_mean_returns)
        })
        .collect();
    let gen_eps = runs
        .iter()
        .find_map(|r| r.generalization.as_ref().map(|g| g.episodes))
        .unwrap_or(first.generalization.episodes);
    let failed_task = runs.iter().find_map(|r| {
        r.generalization.as_ref().and_then(|g| {
            g.tasks.iter().find_map(|t| {
                t.error
                    .as_ref()
                    .map(|e| format!("task {} failed: {e}", t.name))
            })
        })
    });
    metrics.push(per_seed(
        MetricValue::new(
            Application,
            "generalization",
            "Generalization",
            &format!("{gen_eps} eps. [all tasks]"),
            true,
        ),
        gen_sum,
        failed_task
            .as_deref()
            .unwrap_or("run `a2perf generalize` first"),
        Vec::new(),
        reps,
        &mut rng,
    ));

    // Reliability.
    let mut rel = reliability(runs);
    if runs
        .iter()
        .any(|r| r.run.record.metrics.reliability_definition != "a2perf")
    {
        for m in &mut rel {
            let why = "the config asks for the chan2019 definitions; this table uses A2Perf's \
                       (score curves.csv with `a2perf metrics reliability --definition chan2019`)";
            m.note = Some(match m.note.take() {
                Some(n) => format!("{n}; {why}"),
                None => why.into(),
            });
        }
    }
    metrics.extend(rel);

    // System, training.
    let train: Vec<Option<&PhaseSystem>> = runs.iter().map(|r| r.train_system.as_ref()).collect();
    metrics.push(system_metric(
        MetricValue::new(SystemTraining, "energy", "Energy consumed", "kWh", false),
        &train,
        ENERGY_NAMES,
        1.0,
        reps,
        &mut rng,
    ));
    metrics.push(power_metric(
        MetricValue::new(SystemTraining, "power", "Mean power", "W", false),
        &train,
        reps,
        &mut rng,
    ));
    metrics.push(system_metric(
        MetricValue::new(SystemTraining, "gpu_power", "GPU power", "W", false),
        &train,
        GPU_POWER_NAMES,
        1.0,
        reps,
        &mut rng,
    ));
    metrics.push(system_metric(
        MetricValue::new(SystemTraining, "mean_ram", "Mean RAM usage", "GB", false),
        &train,
        MEAN_RAM_NAMES,
        1.0,
        reps,
        &mut rng,
    ));
    metrics.push(system_metric(
        MetricValue::new(SystemTraining, "peak_ram", "Peak RAM usage", "GB", false),
        &train,
        PEAK_RAM_NAMES,
        1.0,
        reps,
        &mut rng,
    ));
    metrics.push(per_seed(
        MetricValue::new(
            SystemTraining,
            "wall_clock",
            "Wall-clock time",
            "Hours",
            false,
        ),
        train
            .iter()
            .map(|s| s.map(|s| s.wall_clock_s / 3600.0))
            .collect(),
        "no train_system.json",
        Vec::new(),
        reps,
        &mut rng,
    ));

    // System, inference.
    let inf: Vec<Option<&PhaseSystem>> = runs
        .iter()
        .map(|r| r.inference.as_ref().map(|i| &i.system))
        .collect();
    metrics.push(per_seed(
        MetricValue::new(
            SystemInference,
            "inference_time",
            "Inference time",
            "ms",
            false,
        ),
        runs.iter()
            .map(|r| {
                r.inference
                    .as_ref()
                    .map(|i| i.inference_time_ms.mean)
                    .filter(|v| v.is_finite())
            })
            .collect(),
        "run `a2perf infer` first",
        vec![inference_time_note(runs)],
        reps,
        &mut rng,
    ));
    metrics.push(power_metric(
        MetricValue::new(SystemInference, "inference_power", "Mean power", "W", false),
        &inf,
        reps,
        &mut rng,
    ));
    metrics.push(system_metric(
        MetricValue::new(
            SystemInference,
            "inference_gpu_power",
            "GPU power",
            "W",
            false,
        ),
        &inf,
        GPU_POWER_NAMES,
        1.0,
        reps,
        &mut rng,
    ));
    metrics.push(system_metric(
        MetricValue::new(
            SystemInference,
            "inference_energy",
            "Energy consumed",
            "kWh",
            false,
        ),
        &inf,
        ENERGY_NAMES,
        1.0,
        reps,
        &mut rng,
    ));
    metrics.push(system_metric(
        MetricValue::new(
            SystemInference,
            "inference_mean_ram",
            "Mean RAM usage",
            "GB",
            false,
        ),
        &inf,
        MEAN_RAM_NAMES,
        1.0,
        reps,
        &mut rng,
    ));
    metrics.push(system_metric(
        MetricValue::new(
            SystemInference,
            "inference_peak_ram",
            "Peak RAM usage",
            "GB",
            false,
        ),
        &inf,
        PEAK_RAM_NAMES,
        1.0,
        reps,
        &mut rng,
    ));

    GroupReport {
        task: group.task.clone(),
        env_id: first.task.env_id.clone(),
        domain: first.domain.clone(),
        algorithm: group.algorithm.clone(),
        seeds: runs.iter().map(|r| r.run.record.seed).collect(),
        metrics,
    }
}

/// Names under which the system meters report each quantity (first match wins).
const ENERGY_NAMES: &[&str] = &[
    "energy_total_kwh",
    "total_energy_kwh",
    "energy_kwh",
    "energy_consumed_kwh",
];
const GPU_POWER_NAMES: &[&str] = &["gpu_power_w"];
const MEAN_RAM_NAMES: &[&str] = &["mean_ram_gb", "ram_mean_gb"];
const PEAK_RAM_NAMES: &[&str] = &["peak_ram_gb", "ram_peak_gb"];

fn reliability(runs: &[RunData]) -> Vec<MetricValue> {
    use Category::Reliability;
    use a2perf_metrics::a2perf as rel;
    let curves: std::result::Result<Vec<a2perf_metrics::Curve>, String> = runs
        .iter()
        .map(|r| {
            let (steps, values): (Vec<f64>, Vec<f64>) = r
                .curve
                .points
                .iter()
                .map(|p| (p.env_steps as f64, p.mean_return))
                .unzip();
            a2perf_metrics::Curve::new(steps, values)
                .map_err(|e| format!("{}: {e}", r.run.dir.join(CURVE_JSON).display()))
        })
        .collect();
    let mk = |key: &str, label: &str, unit: &str, higher: bool| {
        MetricValue::new(Reliability, key, label, unit, higher)
    };
    let mut out = Vec::new();
    let spread =
        |m: MetricValue, r: std::result::Result<rel::Spread, rel::ReliabilityError>| match r {
            Ok(s) => m.scalar(s.mean, Some(s.std)),
            Err(e) => m.missing(e.to_string()),
        };
    let scalar = |m: MetricValue, r: std::result::Result<f64, rel::ReliabilityError>| match r {
        Ok(v) => m.scalar(v, None),
        Err(e) => m.missing(e.to_string()),
    };
    let specs = [
        (
            "dispersion_across_runs",
            "Dispersion across runs",
            "IQR",
            false,
        ),
        (
            "dispersion_within_runs",
            "Dispersion within runs",
            "IQR",
            false,
        ),
        ("short_term_risk", "Short-term risk", "CVaR", false),
        ("long_term_risk", "Long-term risk", "CVaR", false),
        ("risk_across_runs", "Risk across runs", "CVaR", true),
    ];
    match &curves {
        Ok(curves) => {
            let across = if curves.len() < 3 {
                Err(format!("needs at least 3 runs, have {}", curves.len()))
            } else {
                Ok(())
            };
            for (key, label, unit, higher) in specs {
                let m = mk(key, label, unit, higher);
                out.push(match key {
                    "dispersion_across_runs" => match &across {
                        Err(why) => m.missing(why.clone()),
                        Ok(()) => spread(m, rel::dispersion_across_runs(curves)),
                    },
                    "dispersion_within_runs" => spread(m, rel::dispersion_within_runs(curves)),
                    "short_term_risk" => scalar(m, rel::short_term_risk(curves)),
                    "long_term_risk" => scalar(m, rel::long_term_risk(curves)),
                    _ => scalar(m, rel::risk_across_runs(curves)),
                });
            }
        }
        Err(why) => {
            for (key, label, unit, higher) in specs {
                out.push(mk(key, label, unit, higher).missing(why.clone()));
            }
        }
    }
    let pooled: Option<Vec<f64>> = runs
        .iter()
        .map(|r| r.inference.as_ref().map(|i| i.rollout_returns.clone()))
        .collect::<Option<Vec<_>>>()
        .map(|v| v.concat());
    let rollouts = [
        (
            "dispersion_across_rollouts",
            "Dispersion across rollouts",
            "IQR",
            false,
        ),
        ("risk_across_rollouts", "Risk across rollouts", "CVaR", true),
    ];
    for (key, label, unit, higher) in rollouts {
        let m = mk(key, label, unit, higher);
        out.push(match &pooled {
            None => m.missing("run `a2perf infer` first"),
            Some(p) if key == "dispersion_across_rollouts" => {
                scalar(m, rel::dispersion_across_rollouts(p))
            }
            Some(p) => scalar(m, rel::risk_across_rollouts(p)),
        });
    }
    out
}

/// Interquartile mean: the mean of the middle 50% (25% trimmed at each end, integer
/// truncation, as rliable/scipy `trim_mean`).
pub fn iqm(values: &[f64]) -> f64 {
    let mut v = values.to_vec();
    v.sort_by(f64::total_cmp);
    let cut = v.len() / 4;
    mean(&v[cut..v.len() - cut])
}

/// P(X > Y) on one task: Mann–Whitney, ties one half.
pub fn prob_improvement(x: &[f64], y: &[f64]) -> f64 {
    let mut s = 0.0;
    for a in x {
        for b in y {
            s += if a > b {
                1.0
            } else if a == b {
                0.5
            } else {
                0.0
            };
        }
    }
    s / (x.len() * y.len()) as f64
}

fn comparisons(
    groups: &[GroupReport],
    opts: &ReportOptions,
) -> (Vec<IqmEntry>, Vec<ImprovementEntry>) {
    let scores: BTreeMap<(String, String), Vec<f64>> = groups
        .iter()
        .filter_map(|g| {
            let m = g.metric("returns")?;
            (m.mean.is_some() && !m.per_seed.is_empty())
                .then(|| ((g.algorithm.clone(), g.task.clone()), m.per_seed.clone()))
        })
        .collect();
    let mut iqms = Vec::new();
    for ((algo, task), s) in &scores {
        let mut rng = RngStream::new(opts.seed, &format!("report/iqm/{task}/{algo}"));
        let mut boot = Vec::with_capacity(opts.bootstrap_reps);
        let mut buf = vec![0.0; s.len()];
        for _ in 0..opts.bootstrap_reps {
            for b in buf.iter_mut() {
                *b = s[rng.index(s.len())];
            }
            boot.push(iqm(&buf));
        }
        boot.sort_by(f64::total_cmp);
        iqms.push(IqmEntry {
            task: task.clone(),
            algorithm: algo.clone(),
            iqm: iqm(s),
            ci95: [
                percentile_sorted(&boot, 2.5),
                percentile_sorted(&boot, 97.5),
            ],
            runs: s.len(),
        });
    }
    iqms.sort_by(|a, b| (&a.task, &a.algorithm).cmp(&(&b.task, &b.algorithm)));
    let algos: std::collections::BTreeSet<&String> = scores.keys().map(|(a, _)| a).collect();
    let mut poi = Vec::new();
    for x in &algos {
        for y in &algos {
            if x == y {
                continue;
            }
            let tasks: Vec<&String> = scores
                .keys()
                .filter(|(a, t)| a == *x && scores.contains_key(&((*y).clone(), t.clone())))
                .map(|(_, t)| t)
                .collect();
            if tasks.is_empty() {
                continue;
            }
            let pairs: Vec<(&Vec<f64>, &Vec<f64>)> = tasks
                .iter()
                .map(|t| {
                    (
                        &scores[&((*x).clone(), (*t).clone())],
                        &scores[&((*y).clone(), (*t).clone())],
                    )
                })
                .collect();
            let point = mean(
                &pairs
                    .iter()
                    .map(|(a, b)| prob_improvement(a, b))
                    .collect::<Vec<_>>(),
            );
            // Stratified bootstrap: runs are resampled within each task and algorithm.
            let mut rng = RngStream::new(opts.seed, &format!("report/poi/{x}/{y}"));
            let mut boot = Vec::with_capacity(opts.bootstrap_reps);
            let (mut ba, mut bb) = (Vec::new(), Vec::new());
            for _ in 0..opts.bootstrap_reps {
                let mut acc = 0.0;
                for (a, b) in &pairs {
                    ba.clear();
                    bb.clear();
                    ba.extend((0..a.len()).map(|_| a[rng.index(a.len())]));
                    bb.extend((0..b.len()).map(|_| b[rng.index(b.len())]));
                    acc += prob_improvement(&ba, &bb);
                }
                boot.push(acc / pairs.len() as f64);
            }
            boot.sort_by(f64::total_cmp);
            poi.push(ImprovementEntry {
                x: (*x).clone(),
                y: (*y).clone(),
                tasks: tasks.iter().map(|t| (*t).clone()).collect(),
                probability: point,
                ci95: [
                    percentile_sorted(&boot, 2.5),
                    percentile_sorted(&boot, 97.5),
                ],
            });
        }
    }
    (iqms, poi)
}

/// Merges reports of disjoint (task, algorithm) groups into one, as if `a2perf report` had read
/// all their runs at once: groups and per-task settings are joined, and the IQMs and
/// probabilities of improvement are computed again over the joined groups (from the per-seed
/// returns each report keeps, with the bootstrap streams `a2perf report` uses), so a pair of
/// algorithms reported apart is compared too. `parts` name their source (a `report.json`) for
/// errors.
///
/// Refused: reports made with different bootstrap repetitions, a (task, algorithm) group in
/// two reports, and reports with the paper's findings (a finding is checked over a whole
/// report's runs: report the runs together instead).
///
/// ```
/// use a2perf_pipeline::report::{Report, merge_reports};
/// let empty = |reps| Report {
///     groups: vec![], iqm: vec![], probability_of_improvement: vec![], skipped_runs: vec![],
///     bootstrap_reps: reps, settings: vec![], paper: vec![], findings: vec![],
/// };
/// let merged = merge_reports(vec![("a".into(), empty(100)), ("b".into(), empty(100))]).unwrap();
/// assert_eq!(merged.bootstrap_reps, 100);
/// let err = merge_reports(vec![("a".into(), empty(100)), ("b".into(), empty(10))]).unwrap_err();
/// assert!(err.to_string().contains("bootstrap"));
/// ```
pub fn merge_reports(parts: Vec<(PathBuf, Report)>) -> Result<Report> {
    let Some((first_path, first)) = parts.first() else {
        return Err(PipelineError::Invalid("no report to merge".into()));
    };
    let reps = first.bootstrap_reps;
    let first_path = first_path.clone();
    let mut merged = Report {
        groups: Vec::new(),
        iqm: Vec::new(),
        probability_of_improvement: Vec::new(),
        skipped_runs: Vec::new(),
        bootstrap_reps: reps,
        settings: Vec::new(),
        paper: Vec::new(),
        findings: Vec::new(),
    };
    let mut owner: BTreeMap<(String, String), PathBuf> = BTreeMap::new();
    for (path, report) in parts {
        let bad = |reason: String| PipelineError::Corrupt {
            path: path.clone(),
            reason,
        };
        if report.bootstrap_reps != reps {
            return Err(bad(format!(
                "made with {} bootstrap repetitions, {} with {reps}: reports merged into one \
                 page must share them (rerun `a2perf report --bootstrap-reps N` on one)",
                report.bootstrap_reps,
                first_path.display()
            )));
        }
        if !report.findings.is_empty() {
            return Err(bad(
                "holds the paper's findings, which are checked over a whole report's runs: \
                 report those runs together (`a2perf report DIRS --paper ...`) instead of \
                 merging reports"
                    .into(),
            ));
        }
        for g in &report.groups {
            let key = (g.task.clone(), g.algorithm.clone());
            if let Some(other) = owner.get(&key) {
                return Err(bad(format!(
                    "task `{}`, algorithm `{}` is also in {}: each (task, algorithm) may come \
                     from one report only",
                    g.task,
                    g.algorithm,
                    other.display()
                )));
            }
            owner.insert(key, path.clone());
        }
        merged.groups.extend(report.groups);
        merged.skipped_runs.extend(report.skipped_runs);
        merged.paper.extend(report.paper);
        for s in report.settings {
            match merged.settings.iter_mut().find(|m| m.task == s.task) {
                None => merged.settings.push(s),
                Some(m) => merge_settings(m, s),
            }
        }
    }
    let opts = ReportOptions {
        bootstrap_reps: reps,
        seed: 0,
    };
    let (iqm, poi) = comparisons(&merged.groups, &opts);
    merged.iqm = iqm;
    merged.probability_of_improvement = poi;
    Ok(merged)
}

/// Joins the settings of one task from two reports: an equal profile or suite gains the other's
/// algorithms, a different one is listed beside it (the table then mixes settings, as one report
/// of both sets of runs would say).
fn merge_settings(into: &mut TableSettings, from: TableSettings) {
    for p in from.profiles {
        match into.profiles.iter_mut().find(|q| q.profile == p.profile) {
            Some(q) => q.algorithms.extend(p.algorithms),
            None => into.profiles.push(p),
        }
    }
    for s in from.suites {
        match into
            .suites
            .iter_mut()
            .find(|t| t.source == s.source && t.tasks == s.tasks)
        {
            Some(t) => t.algorithms.extend(s.algorithms),
            None => into.suites.push(s),
        }
    }
    for p in &mut into.profiles {
        p.algorithms.sort();
        p.algorithms.dedup();
    }
    for s in &mut into.suites {
        s.algorithms.sort();
        s.algorithms.dedup();
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
    let reports: Vec<GroupReport> = groups.iter().map(|g| group_report(g, opts)).collect();
    let (iqm, poi) = comparisons(&reports, opts);
    let mut report = Report {
        groups: reports,
        iqm,
        probability_of_improvement: poi,
        skipped_runs: skipped,
        bootstrap_reps: opts.bootstrap_reps,
        settings: table_settings(&groups),
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
    let (report, groups) = build_report_with_paper(dirs, opts, paper)?;
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
    a2perf_core::write_json_atomic(
        &out.join("leaderboard.json"),
        &leaderboard::leaderboard(&report, &groups),
    )?;
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
