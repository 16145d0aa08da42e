//! Loading: the complete run directories below the report's inputs, grouped by (task,
//! algorithm), and the settings (profiles, generalization suites) each task table's runs used.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

use a2perf_core::{LearningCurve, results::read_json};
use serde::Deserialize;

use super::model::{ProfileUse, SuiteUse, TableSettings};
use crate::generalize::GeneralizationResults;
use crate::infer::InferenceResults;
use crate::spec::GeneralizationSuite;
use crate::train::PhaseSystem;
use crate::{
    CURVE_JSON, GENERALIZATION_FILE, INFERENCE_FILE, LoadedRun, PipelineError, Result,
    SYSTEM_INFO_FILE, SystemInfo, TRAIN_SEGMENTS_FILE, TRAIN_SYSTEM_FILE, find_runs, io_err,
};

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
    /// Where its training's wall time went, over every segment; `None` when a segment did not
    /// record it (killed, or trained before it was recorded).
    pub time_split: Option<a2perf_core::TimeSplit>,
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
            time_split: read_opt::<crate::run_dir::TrainSegments>(&dir.join(TRAIN_SEGMENTS_FILE))?
                .and_then(|s| {
                    s.segments
                        .iter()
                        .try_fold(a2perf_core::TimeSplit::default(), |sum, seg| {
                            seg.time_split.map(|t| sum.plus(&t))
                        })
                }),
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

/// Loads every complete run below `dirs` and groups them by (task, algorithm). Incomplete runs
/// are listed with the reason; a corrupt file in a complete run is an error naming the file.
pub fn load_groups(dirs: &[PathBuf]) -> Result<(Vec<Group>, Vec<SkippedRun>)> {
    let mut groups: BTreeMap<(String, String, String), Vec<RunData>> = BTreeMap::new();
    let mut skipped = Vec::new();
    let mut seen = BTreeSet::new();
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
        let mut seeds = BTreeSet::new();
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

/// Per task table: the profiles and generalization suites its runs used, in order of first use.
pub(super) fn table_settings(groups: &[Group]) -> Vec<TableSettings> {
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
