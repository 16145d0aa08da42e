//! `a2perf bench`: steps any registered environment with uniformly random legal actions.

use std::collections::BTreeMap;

use a2perf_core::{Registry, Value};
use a2perf_pipeline::bench::bench_env;
use anyhow::{Context, Result, bail};
use clap::Args;

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

/// Runs the benchmark and prints the report.
pub fn run(registry: &Registry, args: &BenchArgs) -> Result<()> {
    if args.steps == 0 {
        bail!("--steps must be at least 1");
    }
    let params = parse_sets(&args.set)?;
    let report = bench_env(registry, &args.env_id, &params, args.steps, args.seed)
        .with_context(|| format!("cannot benchmark environment `{}`", args.env_id))?;
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
