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
//! A dataset is written into `OUT/.<dataset_id>.partial/` and renamed into place once complete,
//! so an interrupted collection (SIGTERM, a crash) never leaves a partial dataset where a
//! finished one is expected; the next collection replaces the stage.
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

use crate::dataset::dataset_id;
use crate::error::{PipelineError, Result, io_err};
use crate::phase::PhaseSystem;
use crate::rollout::located_rollout;
use crate::run_dir::{
    COLLECT_DIR, CURVE_JSON, EVALUATION_FILE, LoadedRun, PolicySource, RegistryPolicies,
    TRAIN_SYSTEM_FILE,
};
use crate::stats::Summary;
use crate::{minari, progress, stats};

// The dataset vocabulary and the run's checkpoint listing live with the plans and the run
// directory; `collect::` still names them for the front ends.
pub use crate::dataset::{
    CollectOptions, CostRule, DATASET_INFO_FILE, DatasetInfo, Level, dataset_info_for, level_of,
};
pub use crate::run_dir::checkpoints;

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
    #[serde(deserialize_with = "a2perf_core::results::vec_f64_or_nan")]
    pub rollout_returns: Vec<f64>,
    /// Energy of the whole training run (kWh), when measured.
    pub total_training_energy_kwh: Option<f64>,
    /// Energy attributed to training up to this checkpoint (kWh).
    pub training_energy_kwh: Option<f64>,
    /// Expertise level, once assigned.
    pub level: Option<Level>,
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
                if opts.cancel.is_cancelled() {
                    return Err(PipelineError::Cancelled);
                }
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
        let mu = stats::mean(&means);
        let sigma = Summary::of(&means).std;
        for (_, evals) in &mut entries {
            for e in evals.iter_mut() {
                e.level = level_of(e.returns.mean, mu, sigma, opts.one_sigma);
            }
        }
        for (run, evals) in &entries {
            let dir = run.dir.join(COLLECT_DIR);
            std::fs::create_dir_all(&dir).map_err(io_err(&dir))?;
            write_json_atomic(&dir.join(EVALUATION_FILE), evals)?;
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
    let stage = Stage::new(out, &id, &dir)?;
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
        if opts.cancel.is_cancelled() {
            return Err(PipelineError::Cancelled);
        }
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
        let record = minari::EpisodeRecord {
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
        let data_dir = stage.path.join("data");
        minari::write_episode(
            &data_dir,
            e,
            &record,
            &spec.observation_space,
            &spec.action_space,
        )
        .map_err(io_err(&data_dir))?;
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
        mean_return: stats::mean(&returns),
        checkpoints: used,
        training_sample_cost_kwh: costs.map(|c| stats::mean(&c)),
        cost_rule: opts.cost,
        level_mu_sigma: mu_sigma,
    };
    let samples_file = stage.path.join("samples.json");
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
    write_json_atomic(&stage.path.join("episodes.json"), &episodes)?;
    write_json_atomic(&stage.path.join(DATASET_INFO_FILE), &info)?;
    let mut extra = serde_json::Map::new();
    extra.insert(
        "a2perf".into(),
        serde_json::to_value(&info).map_err(|e| PipelineError::Invalid(e.to_string()))?,
    );
    let data_dir = stage.path.join("data");
    minari::write_metadata(
        &data_dir,
        &info.dataset_id,
        &spec.observation_space,
        &spec.action_space,
        info.episodes,
        info.steps,
        &run.record.algorithm.name,
        extra,
    )
    .map_err(io_err(&data_dir))?;
    stage.commit()?;
    Ok(info)
}

/// A dataset being written: its files go into the staging directory `OUT/.<id>.partial`, which
/// [`commit`](Stage::commit) moves to the dataset's directory whole, replacing an earlier
/// dataset of `a2perf collect`. Dropped before that (an error, a cancel), the stage is removed.
struct Stage {
    path: PathBuf,
    dir: PathBuf,
    /// Whether `dir` holds a finished dataset of ours, replaced on commit.
    replaces: bool,
}

impl Stage {
    /// A fresh stage for the dataset `id` under `out`, whose directory is `dir`. A non-empty
    /// `dir` that is not a finished dataset of ours is refused, before any episode is rolled out.
    fn new(out: &Path, id: &str, dir: &Path) -> Result<Self> {
        let replaces = dir.join(DATASET_INFO_FILE).is_file();
        if !replaces && dir.read_dir().is_ok_and(|mut d| d.next().is_some()) {
            return Err(PipelineError::Invalid(format!(
                "{}: exists without `{DATASET_INFO_FILE}`, so it is not a dataset `a2perf \
                 collect` finished; refusing to overwrite it (remove it to collect here)",
                dir.display()
            )));
        }
        // A stage left by a killed attempt is ours by its name: replaced, never trusted.
        let path = out.join(format!(".{id}.partial"));
        if path.exists() {
            std::fs::remove_dir_all(&path).map_err(io_err(&path))?;
        }
        std::fs::create_dir_all(&path).map_err(io_err(&path))?;
        Ok(Self {
            path,
            dir: dir.to_path_buf(),
            replaces,
        })
    }

    /// Moves the finished dataset into place, so no stale episode of an earlier one survives.
    fn commit(self) -> Result<()> {
        let dir = &self.dir;
        if self.replaces {
            std::fs::remove_dir_all(dir).map_err(io_err(dir))?;
        } else if dir.is_dir() {
            // Empty (checked in `new`).
            std::fs::remove_dir(dir).map_err(io_err(dir))?;
        }
        std::fs::rename(&self.path, dir).map_err(io_err(dir))
    }
}

impl Drop for Stage {
    fn drop(&mut self) {
        // Nothing is left after a commit; after a failure this is best effort (the next attempt
        // replaces a stage it finds).
        let _ = std::fs::remove_dir_all(&self.path);
    }
}
