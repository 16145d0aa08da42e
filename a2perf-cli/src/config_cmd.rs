//! `a2perf config`: inspects experiment configs.

use std::io::Write;
use std::path::PathBuf;

use a2perf_core::{Experiment, Registry};
use anyhow::{Context, Result};
use clap::{Args, Subcommand};

/// Arguments of `a2perf config`.
#[derive(Args, Debug)]
pub struct ConfigArgs {
    #[command(subcommand)]
    command: ConfigCommand,
}

#[derive(Subcommand, Debug)]
enum ConfigCommand {
    /// Print the operative config: every value in force after includes, overrides and defaults.
    Show(ShowArgs),
}

#[derive(Args, Debug)]
struct ShowArgs {
    /// Experiment file (RON; see configs/README.md).
    file: PathBuf,
    /// Override a value, `dotted.path=value` (repeatable; the last one wins),
    /// e.g. `--set algorithm.learning_rate=1e-4`.
    #[arg(long = "set", value_name = "KEY=VALUE")]
    set: Vec<String>,
}

/// Runs `a2perf config ...`.
pub fn run(registry: &Registry, args: &ConfigArgs) -> Result<()> {
    match &args.command {
        ConfigCommand::Show(show) => {
            let experiment = Experiment::load(&show.file, &show.set, registry)?;
            let mut out = std::io::stdout().lock();
            match out
                .write_all(experiment.to_ron_string().as_bytes())
                .and_then(|()| out.flush())
            {
                // `a2perf config show x.ron | head` is not an error.
                Err(e) if e.kind() == std::io::ErrorKind::BrokenPipe => Ok(()),
                other => Ok(other.context("writing to stdout")?),
            }
        }
    }
}
