//! The environment micro-benchmark behind `a2perf bench` and `a2perf_rs.bench`: steps a
//! registered environment with uniformly random legal actions and times every step.

use std::collections::BTreeMap;
use std::time::Instant;

use a2perf_core::{Env, EnvError, Registry, RegistryError, RngStream, Step, Value};
use serde::Serialize;

/// p50 / p90 / p99 of a set of timings (nearest rank).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Percentiles {
    /// Median.
    pub p50: f64,
    /// 90th percentile.
    pub p90: f64,
    /// 99th percentile.
    pub p99: f64,
}

impl Percentiles {
    /// The percentiles of `samples` (sorted in place); NaN when there are none.
    ///
    /// ```
    /// use a2perf_pipeline::bench::Percentiles;
    /// let p = Percentiles::of(&mut [3.0, 1.0, 2.0]);
    /// assert_eq!((p.p50, p.p99), (2.0, 3.0));
    /// ```
    pub fn of(samples: &mut [f64]) -> Self {
        samples.sort_by(f64::total_cmp);
        let at = |q: f64| -> f64 {
            if samples.is_empty() {
                return f64::NAN;
            }
            let i = ((samples.len() - 1) as f64 * q).round() as usize;
            samples[i]
        };
        Self {
            p50: at(0.5),
            p90: at(0.9),
            p99: at(0.99),
        }
    }
}

/// What [`bench_env`] measured.
#[derive(Clone, Debug, Serialize)]
pub struct BenchReport {
    /// The environment.
    pub env_id: String,
    /// Steps timed.
    pub steps: u64,
    /// Episodes started.
    pub episodes: u64,
    /// Wall-clock steps per second, resets and action sampling included (what a training loop
    /// sees).
    pub steps_per_second: f64,
    /// Time of one reset, µs.
    pub reset_time_us: Percentiles,
    /// Time of one `step_into`, µs.
    pub step_latency_us: Percentiles,
    /// Mean time of one `step_into`, µs.
    pub mean_step_us: f64,
    /// Every parameter of the environment in force.
    pub params: BTreeMap<String, Value>,
    /// The timed loop unit by unit, µs, in order: a step (sampling its action included) or the
    /// reset that followed the end of an episode, each its own unit, as a vector env with
    /// next-step autoreset spends them (the reset in the call after the episode's last step).
    /// Pairing two loops' timelines unit by unit bounds what a lockstep pair of them could do.
    /// Not serialised: `a2perf bench --json` stays one short object.
    #[serde(skip)]
    pub timeline_us: Vec<f64>,
}

/// Why a benchmark could not run.
#[derive(Debug, thiserror::Error)]
pub enum BenchError {
    /// `steps` was 0.
    #[error("the number of steps must be at least 1")]
    NoSteps,
    /// Unknown environment or bad parameters.
    #[error(transparent)]
    Registry(#[from] RegistryError),
    /// The environment failed.
    #[error("{env_id}: {source}")]
    Env {
        /// The environment.
        env_id: String,
        /// Its error.
        source: EnvError,
    },
}

/// Builds `env_id` with `params` and times `steps` steps with uniformly random legal actions
/// (episodes seeded from `seed`, actions from `seed` too); same arguments ⇒ same trajectory.
///
/// ```
/// use a2perf_pipeline::bench::bench_env;
/// let reg = a2perf_pipeline::registry::full_registry();
/// let r = bench_env(&reg, "WebNavigation-Difficulty-01-v0", &Default::default(), 50, 0).unwrap();
/// assert_eq!(r.steps, 50);
/// assert!(r.step_latency_us.p50 > 0.0 && r.steps_per_second > 0.0);
/// // One unit per step and per reset after the first.
/// assert_eq!(r.timeline_us.len() as u64, r.steps + r.episodes - 1);
/// ```
pub fn bench_env(
    registry: &Registry,
    env_id: &str,
    params: &BTreeMap<String, Value>,
    steps: u64,
    seed: u64,
) -> Result<BenchReport, BenchError> {
    if steps == 0 {
        return Err(BenchError::NoSteps);
    }
    let mut env = registry.make_env(env_id, params)?;
    let resolved = registry.env_params(env_id, params)?;
    let env_err = |source| BenchError::Env {
        env_id: env_id.to_string(),
        source,
    };
    let spec = env.spec().clone();
    let mut rng = RngStream::new(seed, "bench/actions");
    let seeds = RngStream::new(seed, "bench/episodes");
    let mut step = Step::default();
    let mut reset_us = Vec::new();
    let mut timeline_us = Vec::with_capacity(usize::try_from(steps).unwrap_or(0) * 11 / 10);
    let mut step_us = Vec::with_capacity(usize::try_from(steps).unwrap_or(0));
    let mut episodes = 0u64;
    let mut episode_len = 0usize;
    let limit = spec.max_episode_steps.unwrap_or(usize::MAX);

    let mut reset = |env: &mut Box<dyn Env>, step: &mut Step, episodes: &mut u64| {
        let t = Instant::now();
        env.reset_into(
            Some(seeds.derive_index(*episodes).next_u64()),
            &mut step.observation,
        )
        .map_err(env_err)?;
        let us = t.elapsed().as_secs_f64() * 1e6;
        reset_us.push(us);
        *episodes += 1;
        Ok::<f64, BenchError>(us)
    };
    reset(&mut env, &mut step, &mut episodes)?;
    let total = Instant::now();
    let mut stepping = 0.0;
    for _ in 0..steps {
        let unit = Instant::now();
        let action = match spec
            .action_space
            .sample(&mut rng, step.observation.action_mask.as_deref())
        {
            Some(a) => a,
            None => {
                // No legal action left: the episode cannot continue.
                timeline_us.push(reset(&mut env, &mut step, &mut episodes)?);
                episode_len = 0;
                continue;
            }
        };
        let t = Instant::now();
        env.step_into(&action, &mut step).map_err(env_err)?;
        let dt = t.elapsed().as_secs_f64();
        stepping += dt;
        step_us.push(dt * 1e6);
        timeline_us.push(unit.elapsed().as_secs_f64() * 1e6);
        episode_len += 1;
        if step.done() || episode_len >= limit {
            timeline_us.push(reset(&mut env, &mut step, &mut episodes)?);
            episode_len = 0;
        }
    }
    let wall = total.elapsed().as_secs_f64();
    env.close().map_err(env_err)?;
    let n = step_us.len() as u64;
    Ok(BenchReport {
        env_id: spec.id.clone(),
        steps: n,
        episodes,
        steps_per_second: n as f64 / wall.max(1e-12),
        mean_step_us: stepping * 1e6 / n.max(1) as f64,
        reset_time_us: Percentiles::of(&mut reset_us),
        step_latency_us: Percentiles::of(&mut step_us),
        params: resolved.values().clone(),
        timeline_us,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_timeline_holds_every_step_and_every_reset_in_order_within_the_wall_time() {
        let reg = crate::registry::full_registry();
        let id = "QuadrupedLocomotion-DogPace-v0";
        let r = bench_env(&reg, id, &BTreeMap::new(), 200, 3).unwrap();
        // Random actions topple the robot within a few dozen steps: resets are in the timeline.
        assert!(r.episodes > 2, "{} episodes", r.episodes);
        assert_eq!(r.timeline_us.len() as u64, r.steps + r.episodes - 1);
        assert!(r.timeline_us.iter().all(|&us| us > 0.0));
        let units: f64 = r.timeline_us.iter().sum();
        let wall_us = r.steps as f64 / r.steps_per_second * 1e6;
        // The units are timed inside the loop, which the wall time encloses; each step unit
        // holds that step's `step_into`.
        assert!(units <= wall_us, "{units} > {wall_us}");
        assert!(units >= r.mean_step_us * r.steps as f64, "{units}");
        let json = serde_json::to_value(&r).unwrap();
        assert!(
            json.get("timeline_us").is_none(),
            "the CLI's JSON stays short"
        );
    }
}
