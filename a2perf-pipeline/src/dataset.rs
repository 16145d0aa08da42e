//! The dataset vocabulary shared by planning and collection: expertise levels, the sample-cost
//! rule, a collected dataset's description (`a2perf_dataset.json`) and its provenance in a run
//! record. `collect` writes datasets; `plan` reads their description to train offline
//! algorithms from them.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use a2perf_core::results::{ResultsError, read_json};
use serde::{Deserialize, Serialize};

/// How a checkpoint's training sample cost is assigned.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum CostRule {
    /// The training energy measured over the whole run, times the fraction of the run's
    /// wall-clock time elapsed at the checkpoint (read from the training curve's clock).
    Measured,
    /// The original's rule: total energy × checkpoint step / last checkpoint step.
    ProRata,
}

/// Expertise level of a checkpoint.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Level {
    /// Low return.
    Novice,
    /// Around the mean.
    Intermediate,
    /// High return.
    Expert,
}

impl Level {
    /// `novice`, `intermediate` or `expert`.
    pub fn name(self) -> &'static str {
        match self {
            Level::Novice => "novice",
            Level::Intermediate => "intermediate",
            Level::Expert => "expert",
        }
    }
}

/// Assigns a level to a checkpoint's mean return given the mean `mu` and standard deviation
/// `sigma` of all checkpoints' mean returns. The original code's rule (default): novice
/// ≤ μ−2σ, intermediate within μ±σ, expert ≥ μ+2σ, others unassigned. With `one_sigma` (the
/// paper's wording): novice < μ−σ, intermediate within μ±σ, expert > μ+σ.
///
/// ```
/// use a2perf_pipeline::collect::{level_of, Level};
/// assert_eq!(level_of(0.0, 5.0, 2.0, false), Some(Level::Novice));
/// assert_eq!(level_of(2.0, 5.0, 2.0, false), None);
/// assert_eq!(level_of(2.0, 5.0, 2.0, true), Some(Level::Novice));
/// assert_eq!(level_of(3.5, 5.0, 2.0, false), Some(Level::Intermediate));
/// assert_eq!(level_of(9.0, 5.0, 2.0, false), Some(Level::Expert));
/// ```
pub fn level_of(ret: f64, mu: f64, sigma: f64, one_sigma: bool) -> Option<Level> {
    if one_sigma {
        if ret < mu - sigma {
            Some(Level::Novice)
        } else if ret > mu + sigma {
            Some(Level::Expert)
        } else {
            Some(Level::Intermediate)
        }
    } else if ret <= mu - 2.0 * sigma {
        Some(Level::Novice)
    } else if ret >= mu + 2.0 * sigma {
        Some(Level::Expert)
    } else if (mu - sigma..=mu + sigma).contains(&ret) {
        Some(Level::Intermediate)
    } else {
        None
    }
}

/// Options of [`collect`](crate::collect::collect).
#[derive(Clone, Debug)]
pub struct CollectOptions {
    /// Greedy episodes per checkpoint evaluation (the original: 100).
    pub eval_episodes: usize,
    /// Episodes per dataset.
    pub dataset_episodes: usize,
    /// Sample-cost rule.
    pub cost: CostRule,
    /// Use the one-σ level rule.
    pub one_sigma: bool,
    /// Show progress bars.
    pub show_progress: bool,
    /// Stops the collection before its next episode once cancelled (SIGTERM, Ctrl-C), with
    /// [`PipelineError::Cancelled`](crate::PipelineError::Cancelled). A dataset is written to a
    /// staging directory and moved into place whole, so an interrupted collection leaves no
    /// partial dataset; collecting again gives the same samples.
    pub cancel: a2perf_core::CancelToken,
}

impl Default for CollectOptions {
    fn default() -> Self {
        Self {
            eval_episodes: 100,
            dataset_episodes: 100,
            cost: CostRule::Measured,
            one_sigma: false,
            show_progress: false,
            cancel: a2perf_core::CancelToken::new(),
        }
    }
}

/// A collected dataset (`a2perf_dataset.json`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct DatasetInfo {
    /// Dataset id, `<Env>-<level>-v0`.
    pub dataset_id: String,
    /// Directory.
    pub path: PathBuf,
    /// Task name.
    pub task: String,
    /// Environment id.
    pub env_id: String,
    /// Environment parameters.
    pub env_params: BTreeMap<String, a2perf_core::Value>,
    /// Level.
    pub level: Level,
    /// Episodes.
    pub episodes: usize,
    /// Steps (samples).
    pub steps: usize,
    /// Mean return of the episodes.
    #[serde(deserialize_with = "a2perf_core::results::f64_or_nan")]
    pub mean_return: f64,
    /// Checkpoints the episodes were drawn from.
    pub checkpoints: Vec<PathBuf>,
    /// Training sample cost: mean training energy (kWh) of those checkpoints (as the original's
    /// `training_sample_cost.txt`); `None` when energy was not measured.
    pub training_sample_cost_kwh: Option<f64>,
    /// How the cost was assigned.
    pub cost_rule: CostRule,
    /// Mean and std of all checkpoints' mean returns used for the levels.
    pub level_mu_sigma: [f64; 2],
}

/// `<Env>[-<task suffix>]-<level>-v0`: the directory `collect` writes a task's dataset of one
/// level to.
pub(crate) fn dataset_id(task: &str, env_id: &str, level: Level) -> String {
    let base = match env_id.rfind("-v") {
        Some(i) if env_id[i + 2..].chars().all(|c| c.is_ascii_digit()) => &env_id[..i],
        _ => env_id,
    };
    let extra: String = task
        .strip_prefix(env_id)
        .unwrap_or("")
        .chars()
        .filter_map(|c| match c {
            c if c.is_ascii_alphanumeric() || c == '.' => Some(c),
            '[' | ']' => None,
            _ => Some('_'),
        })
        .collect();
    if extra.is_empty() {
        format!("{base}-{}-v0", level.name())
    } else {
        format!("{base}-{extra}-{}-v0", level.name())
    }
}

/// `a2perf_dataset.json`.
pub const DATASET_INFO_FILE: &str = "a2perf_dataset.json";

/// Reads the provenance of the dataset holding `samples` (a `samples.json` path or its
/// directory), if it was written by `collect`.
pub fn dataset_info_for(samples: &Path) -> Result<Option<DatasetInfo>, ResultsError> {
    let dir = if samples.is_dir() {
        samples.to_path_buf()
    } else {
        samples.parent().map(Path::to_path_buf).unwrap_or_default()
    };
    let p = dir.join(DATASET_INFO_FILE);
    if p.is_file() {
        Ok(Some(read_json(&p)?))
    } else {
        Ok(None)
    }
}

/// Where an offline algorithm's training data came from, and what producing it cost.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct DatasetProvenance {
    /// Dataset directory.
    pub path: String,
    /// Dataset id.
    pub dataset_id: String,
    /// Training sample cost: energy (kWh) spent training the policies that generated the data.
    pub training_sample_cost_kwh: Option<f64>,
    /// How the cost was obtained (`measured` or `pro_rata`).
    pub cost_method: String,
}

impl DatasetProvenance {
    /// The provenance of a dataset written by `collect`, used from `path`.
    pub fn from_info(info: &DatasetInfo, path: &str) -> Self {
        Self {
            path: path.into(),
            dataset_id: info.dataset_id.clone(),
            training_sample_cost_kwh: info.training_sample_cost_kwh,
            cost_method: match info.cost_rule {
                CostRule::Measured => "measured".into(),
                CostRule::ProRata => "pro_rata".into(),
            },
        }
    }
}
