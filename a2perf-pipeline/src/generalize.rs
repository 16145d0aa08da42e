//! `a2perf generalize`: greedy returns of a trained policy on every task of its generalization
//! suite (the one recorded in `run.json`: the config's, its profile's or the registry's for the
//! domain), and their sum.

use std::path::Path;

use a2perf_core::replay::Recorder;
use a2perf_core::{ActMode, Registry, RngStream, write_json_atomic};

// The result file's model belongs to the run directory; `generalize::` still names it.
use crate::error::{PipelineError, Result};
use crate::progress;
use crate::rollout::located_rollout;
use crate::run_dir::{
    GENERALIZATION_FILE, LoadedRun, POLICY_FILE, PolicySource, RegistryPolicies,
    generalization_episodes_file, write_episode_logs,
};
pub use crate::run_dir::{GeneralizationResults, TaskResult};
use crate::spec::{GeneralizationTask, SuiteSource};

/// The reset seed of episode `index` on generalization task `task` of a run with `run_seed`
/// (what `verify` checks the logged seeds against).
///
/// ```
/// use a2perf_pipeline::generalize::generalization_episode_seed;
/// assert_ne!(
///     generalization_episode_seed(0, "a", 0),
///     generalization_episode_seed(0, "b", 0)
/// );
/// ```
pub fn generalization_episode_seed(run_seed: u64, task: &str, index: usize) -> u64 {
    RngStream::new(run_seed, &format!("generalization/{task}"))
        .derive_index(index as u64)
        .next_u64()
}

/// The generalization suite of `run`: the one its `run.json` records, else the registry's for
/// its domain (runs recorded before suites were configurable).
pub fn generalization_suite(
    registry: &Registry,
    run: &LoadedRun,
) -> (SuiteSource, Vec<GeneralizationTask>) {
    match &run.record.generalization.suite {
        Some(s) => (s.source, s.tasks.clone()),
        None => (
            SuiteSource::Registry,
            registry
                .generalization(&run.record.domain)
                .iter()
                .map(GeneralizationTask::from)
                .collect(),
        ),
    }
}

/// Rolls the final policy of a complete run out on every task of its generalization suite and
/// writes `generalization.json`. The suite is the one `run.json` records; a run recorded without
/// one uses the registry's suite for its domain.
pub fn generalize_run(
    registry: &Registry,
    dir: &Path,
    episodes: Option<usize>,
    show_progress: bool,
) -> Result<GeneralizationResults> {
    // Refused up front: per task, the refusal would only be recorded as every task's failure.
    LoadedRun::open(dir)?.require_builtin("generalize")?;
    generalize_run_with(
        registry,
        dir,
        &mut RegistryPolicies(registry),
        episodes,
        show_progress,
    )
}

/// [`generalize_run`] with the policy for each task taken from `policies` (for an external
/// agent, a front end's policy; see [`PolicySource`]). A task whose policy or rollout fails is
/// recorded as failed (its `error`) and the others go on — unless the source's errors are
/// fatal: then the rollout error (naming the task, episode and step) is returned and nothing is
/// written.
pub fn generalize_run_with(
    registry: &Registry,
    dir: &Path,
    policies: &mut dyn PolicySource,
    episodes: Option<usize>,
    show_progress: bool,
) -> Result<GeneralizationResults> {
    let run = LoadedRun::open(dir)?;
    run.require_complete()?;
    let episodes = episodes.unwrap_or(run.record.generalization.episodes);
    if episodes == 0 {
        return Err(PipelineError::Invalid(
            "generalization needs at least one episode per task".into(),
        ));
    }
    let (source, suite) = generalization_suite(registry, &run);
    if suite.is_empty() {
        return Err(PipelineError::Invalid(format!(
            "domain `{}` has no generalization suite registered (list one in the config's \
             `generalization.tasks`)",
            run.record.domain
        )));
    }
    let bar = progress::bar((suite.len() * episodes) as u64, "generalize", show_progress);
    let mut tasks = Vec::with_capacity(suite.len());
    for task in &suite {
        let mut result = TaskResult {
            name: task.name.clone(),
            env_id: task.env_id.clone(),
            params: task.params.clone(),
            returns: Vec::new(),
            mean_return: None,
            error: None,
        };
        let outcome = (|| -> Result<Vec<f64>> {
            let mut env = registry.make_env(&task.env_id, &task.params)?;
            let spec = env.spec().clone();
            let mut policy = policies.policy(&run, &dir.join(POLICY_FILE), &spec)?;
            let mut recorder = Recorder::new(env.as_mut());
            let mut returns = Vec::with_capacity(episodes);
            for i in 0..episodes {
                let seed = generalization_episode_seed(run.record.seed, &task.name, i);
                let ep = located_rollout(
                    &mut recorder,
                    policy.as_mut(),
                    seed,
                    ActMode::Greedy,
                    false,
                    i,
                    || format!("{} on {}", dir.display(), task.name),
                )?;
                returns.push(ep.episode_return);
                bar.inc(1);
            }
            let logs = recorder.into_logs();
            let _ = env.close();
            write_episode_logs(dir, &generalization_episodes_file(&task.name), &logs)?;
            Ok(returns)
        })();
        match outcome {
            Ok(returns) => {
                let mean = returns.iter().sum::<f64>() / returns.len() as f64;
                if mean.is_finite() {
                    result.mean_return = Some(mean);
                } else {
                    // JSON has no NaN: say why there is no mean rather than write one that
                    // reads back as a task that could not be run.
                    result.error = Some(format!(
                        "the mean return is not finite ({mean}): the environment paid a \
                         non-finite reward"
                    ));
                }
                result.returns = returns;
            }
            Err(e @ PipelineError::Rollout { .. }) if policies.errors_are_fatal() => {
                bar.finish_and_clear();
                return Err(e);
            }
            Err(e) => result.error = Some(e.to_string()),
        }
        tasks.push(result);
    }
    bar.finish_and_clear();
    let sum = tasks.iter().map(|t| t.mean_return).sum::<Option<f64>>();
    let results = GeneralizationResults {
        domain: run.record.domain.clone(),
        source: Some(source),
        episodes,
        tasks,
        sum_of_mean_returns: sum,
    };
    write_json_atomic(&dir.join(GENERALIZATION_FILE), &results)?;
    Ok(results)
}
