//! The `a2perf` command: a thin clap layer over `a2perf_pipeline` and the domain crates.

use a2perf_pipeline::registry;
use anyhow::Result;
use clap::{Parser, Subcommand};

mod bench;
mod bundle_cmd;
mod circuit_cmd;
mod config_cmd;
mod list;
mod locomotion_cmd;
mod metrics_cmd;
mod pipeline_cmd;
mod submit_cmd;
mod web_cmd;

/// A2Perf: a benchmark for autonomous agents on chip placement, web navigation and quadruped
/// locomotion, scored on data cost, application performance, system resources and reliability.
#[derive(Parser, Debug)]
#[command(name = "a2perf", version, about, long_about = None)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand, Debug)]
enum Command {
    /// List the registered environments and algorithms.
    List,
    /// Step an environment with uniformly random legal actions and report its speed.
    Bench(bench::BenchArgs),
    /// Inspect experiment configs (`config show FILE [--set key=value ...]`).
    Config(config_cmd::ConfigArgs),
    /// Web navigation: render generated websites, report on design files.
    Web(web_cmd::WebArgs),
    /// Quadruped locomotion: render rollouts.
    Locomotion(locomotion_cmd::LocomotionArgs),
    /// Chip placement: placement cost, netlist generation, placement pictures.
    Circuit(circuit_cmd::CircuitArgs),
    /// Score your own logs: reliability metrics and IQM confidence intervals.
    Metrics(metrics_cmd::MetricsArgs),
    /// Train one run per (task, algorithm, seed); resumable (SIGTERM/Ctrl-C write a resume point,
    /// exit code 75; rerun to continue), shardable (`--shard i/N`), one trainer per run (a run
    /// another process is training is left to it: exit code 73).
    #[command(after_help = EXIT_CODES)]
    Train(pipeline_cmd::TrainArgs),
    /// Roll out trained policies and time their inference (RAM, power, energy too).
    Infer(pipeline_cmd::InferArgs),
    /// Roll out trained policies on every task of their domain's generalization suite.
    Generalize(pipeline_cmd::GeneralizeArgs),
    /// The paper's tables, radar plots, curves and a leaderboard entry from result directories.
    Report(pipeline_cmd::ReportArgs),
    /// Train, infer, generalize and report in one go (e.g. `a2perf run configs/quickstart.ron`).
    #[command(after_help = EXIT_CODES)]
    Run(pipeline_cmd::RunArgs),
    /// Evaluate checkpoints, assign expertise levels and collect offline datasets (SIGTERM or
    /// Ctrl-C stop it at the next episode without leaving a partial dataset; exit code 75).
    Collect(pipeline_cmd::CollectArgs),
    /// Train, infer, generalize and report an A2Perf participant folder (train.py,
    /// inference.py, requirements.txt) under the harness's meters, in a venv of its own.
    Submit(submit_cmd::SubmitArgs),
    /// Pack complete runs into one file that carries their results and the proof behind them
    /// (every evaluated episode's seed and actions); see docs/bundles.md.
    Bundle(bundle_cmd::BundleArgs),
    /// Check a bundle: its manifest, a replay of every logged episode, the stated means, and
    /// for built-in algorithms a re-run of the checkpoint. Exit code 1 when a check fails.
    Verify(bundle_cmd::VerifyArgs),
}

/// The exit codes of `train` and `run`, shown by their `--help`.
const EXIT_CODES: &str = "\
Exit codes:
  0   every run is complete
  1   an error (a run failed, a bad config, an unwritable output)
  73  runs left alone because another trainer holds them (each run directory holds an exclusive
      lock while it is trained; the message names the holder's pid and host): rerun once it
      has stopped
  75  interrupted by SIGTERM or Ctrl-C: rerun the same command to continue";

fn main() {
    let cli = Cli::parse();
    if let Err(err) = run(cli) {
        if locked(&err) {
            eprintln!("error: {}", error_chain(&err));
            std::process::exit(pipeline_cmd::EXIT_LOCKED);
        }
        if interrupted(&err) {
            eprintln!(
                "interrupted: rerun the same command to continue (exit code {})",
                pipeline_cmd::EXIT_INTERRUPTED
            );
            std::process::exit(pipeline_cmd::EXIT_INTERRUPTED);
        }
        eprintln!("error: {}", error_chain(&err));
        std::process::exit(1);
    }
}

/// Whether the pipelines left runs alone because other trainers hold them.
fn locked(err: &anyhow::Error) -> bool {
    err.chain().any(|c| {
        matches!(
            c.downcast_ref::<a2perf_pipeline::PipelineError>(),
            Some(a2perf_pipeline::PipelineError::Locked(_))
        )
    })
}

/// Whether the pipelines stopped because SIGTERM or Ctrl-C asked them to.
fn interrupted(err: &anyhow::Error) -> bool {
    err.chain().any(|c| {
        matches!(
            c.downcast_ref::<a2perf_pipeline::PipelineError>(),
            Some(a2perf_pipeline::PipelineError::Cancelled)
        )
    })
}

/// The error and its causes joined by `: `, leaving out a cause whose text the layer above
/// already printed: the library errors (thiserror) include their source in their own message,
/// and anyhow's `{:#}` would repeat it.
fn error_chain(err: &anyhow::Error) -> String {
    let mut out = String::new();
    let mut above = String::new();
    for cause in err.chain() {
        let msg = cause.to_string();
        if !above.contains(&msg) {
            if !out.is_empty() {
                out.push_str(": ");
            }
            out.push_str(&msg);
        }
        above = msg;
    }
    out
}

fn run(cli: Cli) -> Result<()> {
    let registry = registry::full_registry();
    match cli.command {
        Command::List => Ok(list::print_list(&registry)?),
        Command::Bench(args) => bench::run(&registry, &args),
        Command::Config(args) => config_cmd::run(&registry, &args),
        Command::Web(args) => web_cmd::run(&args),
        Command::Locomotion(args) => locomotion_cmd::run(&registry, &args),
        Command::Circuit(args) => circuit_cmd::run(&args),
        Command::Metrics(args) => metrics_cmd::run(&args),
        Command::Train(args) => pipeline_cmd::train(&registry, &args),
        Command::Infer(args) => pipeline_cmd::infer(&registry, &args),
        Command::Generalize(args) => pipeline_cmd::generalize(&registry, &args),
        Command::Report(args) => pipeline_cmd::report(&args),
        Command::Run(args) => pipeline_cmd::run(&registry, &args),
        Command::Collect(args) => pipeline_cmd::collect(&registry, &args),
        Command::Submit(args) => submit_cmd::submit(&registry, &args),
        Command::Bundle(args) => bundle_cmd::bundle(&registry, &args),
        Command::Verify(args) => bundle_cmd::verify(&registry, &args),
    }
}
