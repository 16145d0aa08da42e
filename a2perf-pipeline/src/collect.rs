//! `a2perf collect`: evaluates every checkpoint of trained runs, assigns expertise levels, and
//! rolls out novice, intermediate and expert policies into offline datasets with their training
//! sample cost.
//!
//! Layout of one dataset, `OUT/<dataset_id>/`:
//!
//! | file | contents |
//! |---|---|
//! | `samples.json` | (observation, action) pairs: the input of the `bc` baseline's `dataset` parameter |
//! | `episodes.json` | per episode: checkpoint used, seed, return, length |
//! | `a2perf_dataset.json` | [`DatasetInfo`]: level, checkpoints, training sample cost and how it was obtained |
//! | `data/` | the same episodes in Minari's layout (`arrow` storage), see [`super::minari`] |
//!
//! Each run directory also gets `collect/evaluation.json` (every checkpoint's returns and
//! training energy, as the original's `policies/evaluation.json`).

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use a2perf_baselines::dataset::{Dataset, DatasetError, Sample};
use a2perf_core::{
    ActMode, LearningCurve, Registry, RngStream, results::read_json, write_json_atomic,
};
use serde::{Deserialize, Serialize};

use super::stats::Summary;
use super::train::PhaseSystem;
use super::{
    CHECKPOINT_DIR, CURVE_JSON, LoadedRun, PipelineError, PolicySource, RegistryPolicies, Result,
    TRAIN_SYSTEM_FILE, located_rollout, progress,
};

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

/// Options of [`collect`].
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
}

impl Default for CollectOptions {
    fn default() -> Self {
        Self {
            eval_episodes: 100,
            dataset_episodes: 100,
            cost: CostRule::Measured,
            one_sigma: false,
            show_progress: false,
        }
    }
}

/// Evaluation of one checkpoint.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct CheckpointEval {
    /// Checkpoint file.
    pub checkpoint: PathBuf,
    /// Environment steps at which it was taken.
    pub env_steps: u64,
    /// Greedy returns.
    pub returns: Summary,
    /// Every return.
    pub rollout_returns: Vec<f64>,
    /// Energy of the whole training run (kWh), when measured.
    pub total_training_energy_kwh: Option<f64>,
    /// Energy attributed to training up to this checkpoint (kWh).
    pub training_energy_kwh: Option<f64>,
    /// Expertise level, once assigned.
    pub level: Option<Level>,
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

/// Outcome of [`collect`].
#[derive(Clone, Debug, Default)]
pub struct CollectSummary {
    /// Every checkpoint evaluation.
    pub evaluations: Vec<CheckpointEval>,
    /// The datasets written.
    pub datasets: Vec<DatasetInfo>,
    /// Levels with no checkpoint (no dataset written), per task.
    pub empty_levels: Vec<(String, Level)>,
}

/// Checkpoint files of a run, sorted by step.
pub fn checkpoints(run: &Path) -> Result<Vec<(u64, PathBuf)>> {
    let dir = run.join(CHECKPOINT_DIR);
    let mut out = Vec::new();
    if !dir.is_dir() {
        return Ok(out);
    }
    for e in std::fs::read_dir(&dir).map_err(super::io_err(&dir))? {
        let p = e.map_err(super::io_err(&dir))?.path();
        let name = p
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default();
        if let Some(step) = name
            .strip_prefix("step_")
            .and_then(|s| s.strip_suffix(".ckpt"))
            .and_then(|s| s.parse::<u64>().ok())
        {
            out.push((step, p));
        }
    }
    out.sort();
    Ok(out)
}

fn energy_kwh(system: &PhaseSystem) -> Option<f64> {
    [
        "energy_total_kwh",
        "total_energy_kwh",
        "energy_kwh",
        "energy_consumed_kwh",
    ]
    .iter()
    .find_map(|n| system.meters.value(n))
}

/// Wall-clock seconds at `steps`, interpolated on the curve's clock.
fn wall_at(curve: &LearningCurve, steps: u64) -> Option<f64> {
    let pts = &curve.points;
    let first = pts.first()?;
    if steps <= first.env_steps {
        return Some(first.wall_seconds * steps as f64 / first.env_steps.max(1) as f64);
    }
    for w in pts.windows(2) {
        if steps <= w[1].env_steps {
            let t =
                (steps - w[0].env_steps) as f64 / (w[1].env_steps - w[0].env_steps).max(1) as f64;
            return Some(w[0].wall_seconds + t * (w[1].wall_seconds - w[0].wall_seconds));
        }
    }
    pts.last().map(|p| p.wall_seconds)
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

/// Evaluates the checkpoints of `runs`, assigns levels per task and writes the datasets under
/// `out`.
pub fn collect(
    registry: &Registry,
    runs: &[PathBuf],
    out: &Path,
    opts: &CollectOptions,
) -> Result<CollectSummary> {
    collect_with(registry, runs, out, &mut RegistryPolicies(registry), opts)
}

/// [`collect`] with every checkpoint's policy taken from `policies` (for external agents, a
/// front end's loader of their own checkpoint files; see [`PolicySource`]). A rollout error
/// names the checkpoint, the episode and the step.
pub fn collect_with(
    registry: &Registry,
    runs: &[PathBuf],
    out: &Path,
    policies: &mut dyn PolicySource,
    opts: &CollectOptions,
) -> Result<CollectSummary> {
    collect_levels(
        registry,
        runs,
        out,
        policies,
        opts,
        &[Level::Novice, Level::Intermediate, Level::Expert],
    )
}

/// [`collect_with`], writing only the datasets of `levels` (every checkpoint is still evaluated
/// and levelled: the levels depend on all of them).
pub fn collect_levels(
    registry: &Registry,
    runs: &[PathBuf],
    out: &Path,
    policies: &mut dyn PolicySource,
    opts: &CollectOptions,
    levels: &[Level],
) -> Result<CollectSummary> {
    if opts.eval_episodes == 0 || opts.dataset_episodes == 0 {
        return Err(PipelineError::Invalid(
            "collect needs at least one evaluation and one dataset episode".into(),
        ));
    }
    let mut by_task: BTreeMap<String, Vec<(LoadedRun, Vec<CheckpointEval>)>> = BTreeMap::new();
    let mut summary = CollectSummary::default();
    for dir in runs {
        let run = LoadedRun::open(dir)?;
        run.require_complete()?;
        let ckpts = checkpoints(dir)?;
        if ckpts.is_empty() {
            return Err(PipelineError::Invalid(format!(
                "{}: no checkpoints (set training.checkpoint_interval)",
                dir.display()
            )));
        }
        let curve: LearningCurve = read_json(&dir.join(CURVE_JSON))?;
        let system: Option<PhaseSystem> = {
            let p = dir.join(TRAIN_SYSTEM_FILE);
            if p.is_file() {
                Some(read_json(&p)?)
            } else {
                None
            }
        };
        let total = system.as_ref().and_then(energy_kwh);
        let total_wall = system.as_ref().map(|s| s.wall_clock_s);
        let last_step = ckpts.last().map_or(1, |c| c.0).max(1);
        let mut env = run.make_env(registry)?;
        let spec = env.spec().clone();
        let seeds = RngStream::new(run.record.seed, "collect/evaluation");
        let bar = progress::bar(
            (ckpts.len() * opts.eval_episodes) as u64,
            "evaluate",
            opts.show_progress,
        );
        let mut evals = Vec::with_capacity(ckpts.len());
        for (step, path) in &ckpts {
            let mut policy = policies.policy(&run, path, &spec)?;
            let mut returns = Vec::with_capacity(opts.eval_episodes);
            for i in 0..opts.eval_episodes {
                let seed = seeds.derive_index(i as u64).next_u64();
                let ep = located_rollout(
                    env.as_mut(),
                    policy.as_mut(),
                    seed,
                    ActMode::Greedy,
                    false,
                    i,
                    || path.display().to_string(),
                )?;
                returns.push(ep.episode_return);
                bar.inc(1);
            }
            let energy = match opts.cost {
                CostRule::ProRata => total.map(|t| t * *step as f64 / last_step as f64),
                CostRule::Measured => match (total, total_wall, wall_at(&curve, *step)) {
                    (Some(t), Some(w), Some(at)) if w > 0.0 => Some(t * (at / w).clamp(0.0, 1.0)),
                    _ => None,
                },
            };
            evals.push(CheckpointEval {
                checkpoint: path.clone(),
                env_steps: *step,
                returns: Summary::of(&returns),
                rollout_returns: returns,
                total_training_energy_kwh: total,
                training_energy_kwh: energy,
                level: None,
            });
        }
        bar.finish_and_clear();
        by_task
            .entry(run.record.task.name.clone())
            .or_default()
            .push((run, evals));
    }

    for (task, mut entries) in by_task {
        let means: Vec<f64> = entries
            .iter()
            .flat_map(|(_, e)| e.iter().map(|c| c.returns.mean))
            .collect();
        let mu = super::stats::mean(&means);
        let sigma = Summary::of(&means).std;
        for (_, evals) in &mut entries {
            for e in evals.iter_mut() {
                e.level = level_of(e.returns.mean, mu, sigma, opts.one_sigma);
            }
        }
        for (run, evals) in &entries {
            let dir = run.dir.join("collect");
            std::fs::create_dir_all(&dir).map_err(super::io_err(&dir))?;
            write_json_atomic(&dir.join("evaluation.json"), evals)?;
        }
        let first = &entries[0].0;
        for &level in levels {
            let pool: Vec<(&LoadedRun, &CheckpointEval)> = entries
                .iter()
                .flat_map(|(r, e)| {
                    e.iter()
                        .filter(|c| c.level == Some(level))
                        .map(move |c| (r, c))
                })
                .collect();
            if pool.is_empty() {
                summary.empty_levels.push((task.clone(), level));
                continue;
            }
            let info = write_dataset(
                registry,
                policies,
                first,
                &task,
                level,
                &pool,
                out,
                opts,
                [mu, sigma],
            )?;
            summary.datasets.push(info);
        }
        for (_, evals) in entries {
            summary.evaluations.extend(evals);
        }
    }
    Ok(summary)
}

#[allow(clippy::too_many_arguments)]
fn write_dataset(
    registry: &Registry,
    source: &mut dyn PolicySource,
    run: &LoadedRun,
    task: &str,
    level: Level,
    pool: &[(&LoadedRun, &CheckpointEval)],
    out: &Path,
    opts: &CollectOptions,
    mu_sigma: [f64; 2],
) -> Result<DatasetInfo> {
    let id = dataset_id(task, &run.record.task.env_id, level);
    let dir = out.join(&id);
    if dir.join(DATASET_INFO_FILE).is_file() {
        // Ours, from an earlier collect: replace it whole so no stale episode survives.
        std::fs::remove_dir_all(&dir).map_err(super::io_err(&dir))?;
    } else if dir.read_dir().is_ok_and(|mut d| d.next().is_some()) {
        return Err(PipelineError::Invalid(format!(
            "{}: exists and was not written by `a2perf collect`; refusing to overwrite it",
            dir.display()
        )));
    }
    std::fs::create_dir_all(&dir).map_err(super::io_err(&dir))?;
    let mut env = run.make_env(registry)?;
    let spec = env.spec().clone();
    let mut rng = RngStream::new(0, &format!("collect/{task}/{}", level.name()));
    let mut policies: BTreeMap<usize, Box<dyn a2perf_core::Policy>> = BTreeMap::new();
    let mut samples: Vec<Sample> = Vec::new();
    let mut episodes = Vec::with_capacity(opts.dataset_episodes);
    let mut returns = Vec::with_capacity(opts.dataset_episodes);
    let bar = progress::bar(
        opts.dataset_episodes as u64,
        level.name(),
        opts.show_progress,
    );
    for e in 0..opts.dataset_episodes {
        // Checkpoints are drawn with replacement, as the original's `df.sample(replace=True)`.
        let k = rng.index(pool.len());
        let seed = rng.next_u64();
        let policy = match policies.entry(k) {
            std::collections::btree_map::Entry::Occupied(o) => o.into_mut(),
            std::collections::btree_map::Entry::Vacant(v) => {
                v.insert(source.policy(pool[k].0, &pool[k].1.checkpoint, &spec)?)
            }
        };
        let ep = located_rollout(
            env.as_mut(),
            policy.as_mut(),
            seed,
            ActMode::Explore,
            true,
            e,
            || pool[k].1.checkpoint.display().to_string(),
        )?;
        returns.push(ep.episode_return);
        let record = super::minari::EpisodeRecord {
            observations: ep
                .transitions
                .iter()
                .map(|t| t.observation.clone())
                .chain(ep.final_observation.clone())
                .collect(),
            actions: ep.transitions.iter().map(|t| t.action.clone()).collect(),
            rewards: ep.transitions.iter().map(|t| t.reward).collect(),
            terminations: ep.transitions.iter().map(|t| t.terminated).collect(),
            truncations: ep.transitions.iter().map(|t| t.truncated).collect(),
            seed,
        };
        let data_dir = dir.join("data");
        super::minari::write_episode(
            &data_dir,
            e,
            &record,
            &spec.observation_space,
            &spec.action_space,
        )
        .map_err(super::io_err(&data_dir))?;
        episodes.push(serde_json::json!({
            "id": e,
            "checkpoint": pool[k].1.checkpoint,
            "seed": seed,
            "return": ep.episode_return,
            "length": ep.length,
        }));
        samples.extend(ep.transitions.into_iter().map(Sample::from));
        bar.inc(1);
    }
    bar.finish_and_clear();
    let _ = env.close();
    let costs: Option<Vec<f64>> = pool.iter().map(|(_, c)| c.training_energy_kwh).collect();
    let mut used: Vec<PathBuf> = pool.iter().map(|(_, c)| c.checkpoint.clone()).collect();
    used.sort();
    used.dedup();
    let info = DatasetInfo {
        dataset_id: id,
        path: dir.clone(),
        task: task.into(),
        env_id: run.record.task.env_id.clone(),
        env_params: run.record.task.env_params.clone(),
        level,
        episodes: opts.dataset_episodes,
        steps: samples.len(),
        mean_return: super::stats::mean(&returns),
        checkpoints: used,
        training_sample_cost_kwh: costs.map(|c| super::stats::mean(&c)),
        cost_rule: opts.cost,
        level_mu_sigma: mu_sigma,
    };
    let samples_file = dir.join("samples.json");
    Dataset {
        env_id: Some(spec.id.clone()),
        samples,
    }
    .save_json(&samples_file)
    .map_err(|e| match e {
        DatasetError::Io { path, source } => PipelineError::Io { path, source },
        other => PipelineError::Corrupt {
            path: samples_file.clone(),
            reason: other.to_string(),
        },
    })?;
    write_json_atomic(&dir.join("episodes.json"), &episodes)?;
    write_json_atomic(&dir.join(DATASET_INFO_FILE), &info)?;
    let mut extra = serde_json::Map::new();
    extra.insert(
        "a2perf".into(),
        serde_json::to_value(&info).map_err(|e| PipelineError::Invalid(e.to_string()))?,
    );
    let data_dir = dir.join("data");
    super::minari::write_metadata(
        &data_dir,
        &info.dataset_id,
        &spec.observation_space,
        &spec.action_space,
        info.episodes,
        info.steps,
        &run.record.algorithm.name,
        extra,
    )
    .map_err(super::io_err(&data_dir))?;
    Ok(info)
}

/// `a2perf_dataset.json`.
pub const DATASET_INFO_FILE: &str = "a2perf_dataset.json";

/// Reads the provenance of the dataset holding `samples` (a `samples.json` path or its
/// directory), if it was written by `collect`.
pub fn dataset_info_for(samples: &Path) -> Result<Option<DatasetInfo>> {
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
