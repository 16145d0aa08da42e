//! The `a2perf` command: lists, benchmarks and (as the pipelines land) trains, infers and reports.

use anyhow::Result;
use clap::{Parser, Subcommand};

mod bench;
mod registry;

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
    // DOMAIN-SUBCOMMANDS (helpers add their variants above this line)
}

fn main() {
    let cli = Cli::parse();
    if let Err(err) = run(cli) {
        eprintln!("error: {err:#}");
        std::process::exit(1);
    }
}

fn run(cli: Cli) -> Result<()> {
    let registry = registry::full_registry();
    match cli.command {
        Command::List => {
            registry::print_list(&registry);
            Ok(())
        }
        Command::Bench(args) => bench::run(&registry, &args),
        // DOMAIN-DISPATCH (helpers add their match arms above this line)
    }
}
