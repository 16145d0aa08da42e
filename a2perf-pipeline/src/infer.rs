//! `a2perf infer`: rollouts of the final policy, per-call inference time, and system meters.

use std::path::Path;
use std::time::Instant;

use a2perf_core::replay::Recorder;
use a2perf_core::{
    ActMode, Env, Observation, Policy, Registry, RngStream, Space, Step, Tensor, write_atomic,
    write_json_atomic,
};

// The result file's model belongs to the run directory; `infer::` still names it.
use crate::error::{PipelineError, Result, io_err};
use crate::phase::{MeterFactory, Phase, measured, no_meters};
use crate::progress;
pub use crate::run_dir::InferenceResults;
use crate::run_dir::{
    INFERENCE_EMISSIONS_FILE, INFERENCE_EPISODES_FILE, INFERENCE_FILE, LoadedRun, POLICY_FILE,
    PolicySource, RegistryPolicies, write_episode_logs,
};
use crate::spec::ObservationSource;
use crate::stats::Summary;

/// Options of [`infer_run`]; `None` fields take the run's recorded settings.
#[derive(Clone)]
pub struct InferOptions {
    /// Greedy rollouts.
    pub episodes: Option<usize>,
    /// Which observations the reported time is measured on.
    pub observation_source: Option<ObservationSource>,
    /// Calls timed on random observations (with `ObservationSource::Random`).
    pub timing_samples: Option<usize>,
    /// System meters for the rollout phase.
    pub meters: MeterFactory,
    /// Show a progress bar.
    pub show_progress: bool,
}

impl Default for InferOptions {
    fn default() -> Self {
        Self {
            episodes: None,
            observation_source: None,
            timing_samples: None,
            meters: no_meters(),
            show_progress: false,
        }
    }
}

/// Draws an observation from `space` (each box in its element type, see
/// [`Space::sample_tensor`]).
/// Discrete action spaces get an all-legal mask of `action_n` entries.
pub fn random_observation(
    space: &Space,
    action_n: Option<usize>,
    rng: &mut RngStream,
) -> Observation {
    fn fill(name: &str, space: &Space, rng: &mut RngStream, out: &mut Vec<Tensor>) {
        match space {
            Space::Box { .. } => out.extend(space.sample_tensor(name, rng)),
            Space::Discrete { n } => {
                out.push(Tensor::new(name, &[1], vec![rng.index((*n).max(1)) as i32]))
            }
            Space::Dict(items) => {
                for (k, s) in items {
                    fill(k, s, rng, out);
                }
            }
        }
    }
    let mut tensors = Vec::new();
    fill("obs", space, rng, &mut tensors);
    Observation {
        tensors,
        action_mask: action_n.map(|n| vec![true; n]),
    }
}

/// Runs the inference benchmark on a complete run directory and writes `inference.json`.
pub fn infer_run(registry: &Registry, dir: &Path, opts: &InferOptions) -> Result<InferenceResults> {
    infer_run_with(registry, dir, &mut RegistryPolicies(registry), opts)
}

/// [`infer_run`] with the run's final policy taken from `policies` (for an external agent, a
/// front end's policy; see [`PolicySource`]). Every `act` call is timed the same way (after the
/// policy's [`Policy::prepare`], outside the timer). A failed
/// rollout (an error naming its episode and step) writes nothing: no `inference.json`, and the
/// meters' `inference_emissions.csv` is left as it was.
pub fn infer_run_with(
    registry: &Registry,
    dir: &Path,
    policies: &mut dyn PolicySource,
    opts: &InferOptions,
) -> Result<InferenceResults> {
    let run = LoadedRun::open(dir)?;
    run.require_complete()?;
    let episodes = opts.episodes.unwrap_or(run.record.inference.episodes);
    if episodes == 0 {
        return Err(PipelineError::Invalid(
            "inference needs at least one episode".into(),
        ));
    }
    let source = opts
        .observation_source
        .unwrap_or(run.record.inference.observation_source);
    let random_n = match source {
        ObservationSource::Random => opts
            .timing_samples
            .unwrap_or(run.record.inference.timing_samples)
            .max(1),
        ObservationSource::Rollouts => 0,
    };
    let mut env = run.make_env(registry)?;
    let spec = env.spec().clone();
    let mut policy = policies.policy(&run, &dir.join(POLICY_FILE), &spec)?;
    let emissions = dir.join(INFERENCE_EMISSIONS_FILE);
    let emissions_before = std::fs::read(&emissions).ok();

    let bar = progress::bar(episodes as u64, "infer", opts.show_progress);
    let meters = (opts.meters)(Phase::Inference, dir, &run.record.metrics);
    // Every episode's seed and actions are logged, so that `verify` can replay them.
    let mut recorder = Recorder::new(env.as_mut());
    let (rollouts, system) = measured(meters, || -> Result<(Vec<f64>, Vec<usize>, Vec<f64>)> {
        let mut returns = Vec::with_capacity(episodes);
        let mut lengths = Vec::with_capacity(episodes);
        let mut times_ms = Vec::new();
        for i in 0..episodes {
            let seed = inference_episode_seed(run.record.seed, i);
            let (ret, len) = timed_rollout(&mut recorder, policy.as_mut(), seed, &mut times_ms)
                .map_err(|(step, source)| PipelineError::Rollout {
                    run: dir.display().to_string(),
                    episode: i,
                    step,
                    source,
                })?;
            returns.push(ret);
            lengths.push(len);
            bar.inc(1);
        }
        Ok((returns, lengths, times_ms))
    });
    bar.finish_and_clear();
    let logs = recorder.into_logs();
    let _ = env.close();
    let fatal = policies.errors_are_fatal();
    let finished = rollouts.and_then(|(returns, lengths, times_ms)| {
        let mut random_failures = 0;
        let random_time = if random_n > 0 {
            let action_n = match spec.action_space {
                Space::Discrete { n } => Some(n),
                _ => None,
            };
            let mut rng = RngStream::new(run.record.seed, "inference/random-observations");
            // Sampled before timing, as the original did, so only the call itself is measured.
            let samples: Vec<Observation> = (0..random_n)
                .map(|_| random_observation(&spec.observation_space, action_n, &mut rng))
                .collect();
            let mut times = Vec::with_capacity(random_n);
            for (k, obs) in samples.iter().enumerate() {
                let r = policy.prepare(obs).and_then(|()| {
                    let t = Instant::now();
                    policy.act(obs, ActMode::Greedy).map(|_| t.elapsed())
                });
                let dt = r.as_ref().map_or(0.0, |d| d.as_secs_f64() * 1e3);
                match r {
                    Ok(_) => times.push(dt),
                    Err(e) if fatal => {
                        return Err(PipelineError::Run {
                            run: format!(
                                "{} (timing call {k} on a random observation)",
                                dir.display()
                            ),
                            source: e.into(),
                        });
                    }
                    Err(_) => random_failures += 1,
                }
            }
            Some(Summary::of(&times))
        } else {
            None
        };
        let rollout_time = Summary::of(&times_ms);
        let results = InferenceResults {
            episodes,
            returns: Summary::of(&returns),
            rollout_returns: returns,
            episode_lengths: lengths,
            inference_time_ms: random_time.clone().unwrap_or_else(|| rollout_time.clone()),
            observation_source: source,
            rollout_call_time_ms: rollout_time,
            random_observation_time_ms: random_time,
            random_observation_failures: random_failures,
            system,
        };
        // The logs first: results on disk always have their proof beside them.
        write_episode_logs(dir, INFERENCE_EPISODES_FILE, &logs)?;
        write_json_atomic(&dir.join(INFERENCE_FILE), &results)?;
        Ok(results)
    });
    if finished.is_err() {
        // The meters appended a row for the failed phase; the run keeps its earlier file.
        match &emissions_before {
            Some(bytes) => write_atomic(&emissions, bytes).map_err(io_err(&emissions))?,
            None if emissions.exists() => {
                std::fs::remove_file(&emissions).map_err(io_err(&emissions))?
            }
            None => {}
        }
    }
    finished
}

/// The reset seed of inference episode `index` of a run with `run_seed` (what `verify` checks
/// the logged seeds against).
///
/// ```
/// use a2perf_pipeline::infer::inference_episode_seed;
/// assert_eq!(inference_episode_seed(0, 3), inference_episode_seed(0, 3));
/// assert_ne!(inference_episode_seed(0, 3), inference_episode_seed(1, 3));
/// ```
pub fn inference_episode_seed(run_seed: u64, index: usize) -> u64 {
    RngStream::new(run_seed, "inference/episodes")
        .derive_index(index as u64)
        .next_u64()
}

/// One greedy episode, timing every `act` call (milliseconds appended to `times_ms`; the
/// policy's `prepare` is not timed). An error comes with the step it happened at.
fn timed_rollout(
    env: &mut dyn Env,
    policy: &mut dyn Policy,
    seed: u64,
    times_ms: &mut Vec<f64>,
) -> std::result::Result<(f64, usize), (usize, a2perf_core::RunError)> {
    let limit = env.spec().max_episode_steps.unwrap_or(usize::MAX);
    let mut step = Step::default();
    env.reset_into(Some(seed), &mut step.observation)
        .map_err(|e| (0, e.into()))?;
    let mut ret = 0.0;
    let mut len = 0usize;
    loop {
        policy
            .prepare(&step.observation)
            .map_err(|e| (len, e.into()))?;
        let t = Instant::now();
        let action = policy
            .act(&step.observation, ActMode::Greedy)
            .map_err(|e| (len, e.into()))?;
        times_ms.push(t.elapsed().as_secs_f64() * 1e3);
        env.step_into(&action, &mut step)
            .map_err(|e| (len, e.into()))?;
        ret += step.reward;
        len += 1;
        if step.terminated || step.truncated || len >= limit {
            return Ok((ret, len));
        }
    }
}
