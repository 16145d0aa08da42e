//! `a2perf bench`: steps any registered environment with uniformly random legal actions.

use std::collections::BTreeMap;
use std::time::Instant;

use a2perf_core::{Env, Registry, RngStream, Step, Value};
use anyhow::{Context, Result, bail};
use clap::Args;
use serde::Serialize;

/// Arguments of `a2perf bench`.
#[derive(Args, Debug)]
pub struct BenchArgs {
    /// Environment id (see `a2perf list`).
    pub env_id: String,
    /// Number of environment steps to time.
    #[arg(long, default_value_t = 10_000)]
    pub steps: u64,
    /// Environment parameter, `key=value` (repeatable).
    #[arg(long = "set", value_name = "KEY=VALUE")]
    pub set: Vec<String>,
    /// Seed of the episodes and of the random actions.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Print one JSON object instead of a table.
    #[arg(long)]
    pub json: bool,
}

#[derive(Serialize, Debug)]
struct Percentiles {
    p50: f64,
    p90: f64,
    p99: f64,
}

#[derive(Serialize, Debug)]
struct BenchReport {
    env_id: String,
    steps: u64,
    episodes: u64,
    steps_per_second: f64,
    reset_time_us: Percentiles,
    step_latency_us: Percentiles,
    mean_step_us: f64,
    params: BTreeMap<String, Value>,
}

/// Parses `key=value` pairs into environment parameters.
pub fn parse_sets(sets: &[String]) -> Result<BTreeMap<String, Value>> {
    let mut out = BTreeMap::new();
    for s in sets {
        let Some((k, v)) = s.split_once('=') else {
            bail!("--set `{s}`: expected KEY=VALUE");
        };
        let k = k.trim();
        if k.is_empty() {
            bail!("--set `{s}`: empty key");
        }
        out.insert(k.to_string(), Value::parse_literal(v));
    }
    Ok(out)
}

fn percentiles(samples: &mut [f64]) -> Percentiles {
    samples.sort_by(f64::total_cmp);
    let at = |q: f64| -> f64 {
        if samples.is_empty() {
            return f64::NAN;
        }
        let i = ((samples.len() - 1) as f64 * q).round() as usize;
        samples[i]
    };
    Percentiles {
        p50: at(0.5),
        p90: at(0.9),
        p99: at(0.99),
    }
}

/// Runs the benchmark and prints the report.
pub fn run(registry: &Registry, args: &BenchArgs) -> Result<()> {
    if args.steps == 0 {
        bail!("--steps must be at least 1");
    }
    let params = parse_sets(&args.set)?;
    let mut env = registry
        .make_env(&args.env_id, &params)
        .with_context(|| format!("cannot build environment `{}`", args.env_id))?;
    let resolved = registry.env_params(&args.env_id, &params)?;
    let spec = env.spec().clone();
    let mut rng = RngStream::new(args.seed, "bench/actions");
    let seeds = RngStream::new(args.seed, "bench/episodes");
    let mut step = Step::default();
    let mut reset_us = Vec::new();
    let mut step_us = Vec::with_capacity(args.steps as usize);
    let mut episodes = 0u64;
    let mut episode_len = 0usize;
    let limit = spec.max_episode_steps.unwrap_or(usize::MAX);

    let mut reset = |env: &mut Box<dyn Env>, step: &mut Step, episodes: &mut u64| -> Result<()> {
        let t = Instant::now();
        env.reset_into(
            Some(seeds.derive_index(*episodes).next_u64()),
            &mut step.observation,
        )?;
        reset_us.push(t.elapsed().as_secs_f64() * 1e6);
        *episodes += 1;
        Ok(())
    };
    reset(&mut env, &mut step, &mut episodes)?;
    let total = Instant::now();
    let mut stepping = 0.0;
    for _ in 0..args.steps {
        let action = match spec
            .action_space
            .sample(&mut rng, step.observation.action_mask.as_deref())
        {
            Some(a) => a,
            None => {
                // No legal action left: the episode cannot continue.
                reset(&mut env, &mut step, &mut episodes)?;
                episode_len = 0;
                continue;
            }
        };
        let t = Instant::now();
        env.step_into(&action, &mut step)?;
        let dt = t.elapsed().as_secs_f64();
        stepping += dt;
        step_us.push(dt * 1e6);
        episode_len += 1;
        if step.done() || episode_len >= limit {
            reset(&mut env, &mut step, &mut episodes)?;
            episode_len = 0;
        }
    }
    let wall = total.elapsed().as_secs_f64();
    env.close()?;
    let n = step_us.len() as u64;
    let report = BenchReport {
        env_id: spec.id.clone(),
        steps: n,
        episodes,
        // Wall-clock rate, including resets and action sampling: what a training loop sees.
        steps_per_second: n as f64 / wall.max(1e-12),
        mean_step_us: stepping * 1e6 / n.max(1) as f64,
        reset_time_us: percentiles(&mut reset_us),
        step_latency_us: percentiles(&mut step_us),
        params: resolved.values().clone(),
    };
    if args.json {
        println!("{}", serde_json::to_string(&report)?);
    } else {
        println!("environment      {}", report.env_id);
        println!(
            "steps            {} in {} episodes",
            report.steps, report.episodes
        );
        println!("steps/s          {:.1}", report.steps_per_second);
        println!(
            "step latency µs  p50 {:.2}  p90 {:.2}  p99 {:.2}  mean {:.2}",
            report.step_latency_us.p50,
            report.step_latency_us.p90,
            report.step_latency_us.p99,
            report.mean_step_us
        );
        println!(
            "reset µs         p50 {:.2}  p90 {:.2}  p99 {:.2}",
            report.reset_time_us.p50, report.reset_time_us.p90, report.reset_time_us.p99
        );
        for (k, v) in &report.params {
            println!("  {k} = {v}");
        }
    }
    Ok(())
}
