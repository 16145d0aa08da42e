//! `a2perf bundle` and `a2perf verify`: the clap front end of `a2perf_pipeline::bundle`.

use std::path::PathBuf;

use a2perf_core::Registry;
use a2perf_pipeline::bundle::{self, VerifyOptions};
use anyhow::Result;
use clap::Args;

/// Arguments of `a2perf bundle`.
#[derive(Args, Debug)]
pub struct BundleArgs {
    /// Run directories or experiment directories (their complete runs are bundled).
    #[arg(required = true)]
    pub dirs: Vec<PathBuf>,
    /// The bundle file to write (e.g. `ppo-ariane.a2perf`).
    #[arg(short = 'o', long)]
    pub output: PathBuf,
}

/// Arguments of `a2perf verify`.
#[derive(Args, Debug)]
pub struct VerifyArgs {
    /// The bundle file.
    pub bundle: PathBuf,
    /// Also retrain every built-in run from its config and seed and check that the final
    /// policy is byte-identical (as long as the original training).
    #[arg(long)]
    pub retrain: bool,
}

/// `a2perf bundle`.
pub fn bundle(registry: &Registry, args: &BundleArgs) -> Result<()> {
    let s = bundle::pack(registry, &args.dirs, &args.output)?;
    println!(
        "bundle: {} runs, {} members, {} bytes -> {}",
        s.info.runs.len(),
        s.members,
        s.bytes,
        args.output.display()
    );
    Ok(())
}

/// `a2perf verify`: every check printed; an error when one fails.
pub fn verify(registry: &Registry, args: &VerifyArgs) -> Result<()> {
    let opts = VerifyOptions {
        retrain: args.retrain,
    };
    let v = bundle::verify(registry, &args.bundle, &opts)?;
    for c in &v.checks {
        println!("{c}");
    }
    let failed = v.failures().count();
    if failed > 0 {
        anyhow::bail!(
            "{}: {failed} of {} checks fail",
            args.bundle.display(),
            v.checks.len()
        );
    }
    println!(
        "verified: {} ({} checks hold)",
        args.bundle.display(),
        v.checks.len()
    );
    Ok(())
}

/// Splits report inputs into directories and bundle files: each bundle is verified (any failed
/// check is an error naming it) and its runs extracted below `into`. Returns every directory
/// to report on, and the extracted (verified) run directories.
pub fn open_bundles(
    inputs: &[PathBuf],
    into: &std::path::Path,
) -> Result<(Vec<PathBuf>, Vec<PathBuf>)> {
    let registry = a2perf_pipeline::registry::full_registry();
    let mut dirs = Vec::new();
    let mut verified = Vec::new();
    for (i, input) in inputs.iter().enumerate() {
        if !input.is_file() {
            dirs.push(input.clone());
            continue;
        }
        let b = bundle::Bundle::read(input, &bundle::ArchiveLimits::default())?;
        let v = b.verify(&registry, &VerifyOptions::default());
        if !v.holds() {
            let failed: Vec<String> = v.failures().map(ToString::to_string).collect();
            anyhow::bail!(
                "{}: the bundle does not verify:\n{}",
                input.display(),
                failed.join("\n")
            );
        }
        let runs = b.extract(&into.join(format!("bundle{i}")))?;
        println!(
            "verified: {} ({} runs, {} checks hold)",
            input.display(),
            runs.len(),
            v.checks.len()
        );
        dirs.extend(runs.iter().cloned());
        verified.extend(runs);
    }
    Ok((dirs, verified))
}
