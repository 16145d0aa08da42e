//! `a2perf locomotion …`: tools for the quadruped locomotion domain.

use std::collections::BTreeMap;
use std::path::PathBuf;

use a2perf_core::{Registry, Value};
use a2perf_locomotion::env::{EnvConfig, LocomotionEnv};
use a2perf_locomotion::render::{RenderPolicy, record_rollout, rollout_html};
use anyhow::{Context, Result, bail};
use clap::{Args, Subcommand, ValueEnum};

/// Quadruped locomotion tools.
#[derive(Args, Debug)]
pub struct LocomotionArgs {
    #[command(subcommand)]
    command: LocomotionCommand,
}

#[derive(Subcommand, Debug)]
enum LocomotionCommand {
    /// Write a rollout (reference and robot side by side) as a self-contained HTML animation.
    Render(RenderArgs),
}

#[derive(Clone, Copy, Debug, ValueEnum)]
enum PolicyArg {
    /// Zero action offsets (hold the default pose).
    Zero,
    /// Open-loop PD targets at the reference's next joint angles.
    Reference,
}

#[derive(Args, Debug)]
struct RenderArgs {
    /// Environment id (QuadrupedLocomotion-DogPace-v0, -DogTrot-v0, -DogSpin-v0, -Gait-v0).
    #[arg(long, default_value = "QuadrupedLocomotion-DogPace-v0")]
    env: String,
    /// Environment parameter `key=value` (e.g. `motion_file=dog_pace.txt`, `gait=bound`); repeatable.
    #[arg(long = "param", value_name = "KEY=VALUE")]
    params: Vec<String>,
    /// Actions to roll out.
    #[arg(long, value_enum, default_value = "reference")]
    policy: PolicyArg,
    /// Maximum control steps.
    #[arg(long, default_value_t = 300)]
    steps: usize,
    /// Episode seed.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Output HTML file.
    #[arg(long, short, default_value = "locomotion.html")]
    out: PathBuf,
}

/// Runs a `locomotion` subcommand.
pub fn run(registry: &Registry, args: &LocomotionArgs) -> Result<()> {
    match &args.command {
        LocomotionCommand::Render(a) => render(registry, a),
    }
}

fn render(registry: &Registry, a: &RenderArgs) -> Result<()> {
    let entry = registry.env(&a.env)?;
    if entry.domain != a2perf_locomotion::registry::DOMAIN {
        bail!("`{}` is not a quadruped locomotion environment", a.env);
    }
    let mut given = BTreeMap::new();
    for p in &a.params {
        let (k, v) = p
            .split_once('=')
            .with_context(|| format!("--param `{p}` is not KEY=VALUE"))?;
        given.insert(k.trim().to_string(), Value::parse_literal(v));
    }
    let resolved = registry.env_params(&a.env, &given)?;
    let default_gait = match a.env.as_str() {
        "QuadrupedLocomotion-DogPace-v0" => Some(a2perf_locomotion::gait::Gait::Pace),
        "QuadrupedLocomotion-DogTrot-v0" => Some(a2perf_locomotion::gait::Gait::Trot),
        "QuadrupedLocomotion-DogSpin-v0" => Some(a2perf_locomotion::gait::Gait::Spin),
        _ => None,
    };
    let config: EnvConfig =
        a2perf_locomotion::registry::config_from_params(&a.env, default_gait, &resolved)?;
    let mut env = LocomotionEnv::new(config)?;
    let policy = match a.policy {
        PolicyArg::Zero => RenderPolicy::Zero,
        PolicyArg::Reference => RenderPolicy::Reference,
    };
    let rollout = record_rollout(&mut env, policy, a.steps, a.seed)?;
    let html = rollout_html(&rollout);
    let tmp = a.out.with_extension("html.tmp");
    std::fs::write(&tmp, html).with_context(|| format!("writing {}", tmp.display()))?;
    std::fs::rename(&tmp, &a.out).with_context(|| format!("writing {}", a.out.display()))?;
    println!(
        "wrote {} ({} steps, return {:.2}, clip {})",
        a.out.display(),
        rollout.frames.len() - 1,
        rollout.total_reward,
        rollout.clip
    );
    Ok(())
}
