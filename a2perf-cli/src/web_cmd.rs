//! `a2perf web`: look at generated websites and at A2Perf's original design files.

use std::path::PathBuf;

use a2perf_core::RngStream;
use a2perf_web::{Limits, Vocabulary, Website, generate, load_designs, report};
use anyhow::{Context, Result, bail};
use clap::{Args, Subcommand};

/// Arguments of `a2perf web`.
#[derive(Args, Debug)]
pub struct WebArgs {
    #[command(subcommand)]
    command: WebCommand,
}

#[derive(Subcommand, Debug)]
enum WebCommand {
    /// Write a generated website's pages as one static HTML file (next buttons work; open it in a
    /// browser).
    Render {
        /// Difficulty level (1–3).
        #[arg(long)]
        difficulty: u8,
        /// Generator seed (the same seed as the environment's `seed` parameter).
        #[arg(long, default_value_t = 0)]
        seed: u64,
        /// Which website of the seed's pool (0 = first).
        #[arg(long, default_value_t = 0)]
        index: usize,
        /// Seed of the episode content (profile values, prices).
        #[arg(long, default_value_t = 0)]
        episode_seed: u64,
        /// Show only the first page, as the agent sees it (default: every page at once).
        #[arg(long)]
        first_page_only: bool,
        /// Output file.
        #[arg(short = 'o', long)]
        output: PathBuf,
    },
    /// Report how many designs of an A2Perf design file are solvable, and their recomputed levels.
    Report {
        /// A2Perf design JSON (e.g. `environment_generation/data/01.json`).
        designs: PathBuf,
    },
}

/// Runs `a2perf web …`.
pub fn run(args: &WebArgs) -> Result<()> {
    match &args.command {
        WebCommand::Render {
            difficulty,
            seed,
            index,
            episode_seed,
            first_page_only,
            output,
        } => {
            if !(1..=3).contains(difficulty) {
                bail!("--difficulty {difficulty}: must be 1, 2 or 3");
            }
            if *index > 100_000 {
                bail!("--index {index}: must be at most 100000");
            }
            let generated = generate(*difficulty, *seed, index + 1, &Limits::default());
            let g = generated
                .last()
                .context("the generator returned no website")?;
            let site = Website::build(
                &g.design,
                &mut RngStream::new(*episode_seed, "web-render"),
                Vocabulary::standard(),
            );
            std::fs::write(output, site.to_html(!first_page_only))
                .with_context(|| format!("cannot write {}", output.display()))?;
            println!(
                "wrote {}: level {difficulty}, generator index {}, {} page(s), {} field(s), difficulty {:.3} (success probability {:.3})",
                output.display(),
                g.index,
                site.pages.len(),
                site.fields.len(),
                g.difficulty,
                (-g.difficulty).exp()
            );
            Ok(())
        }
        WebCommand::Report { designs } => {
            let list = load_designs(designs)?;
            let r = report(&list, &Limits::default());
            println!("{}: {} designs", designs.display(), r.total);
            println!(
                "  solvable here (cc fixed, ≤ 25 steps, pages ≤ 250 elements): {}",
                r.solvable
            );
            println!(
                "  solvable in the original (no cc, ≤ 25 steps):                 {}",
                r.original_solvable
            );
            println!(
                "  containing cc:                                                 {}",
                r.with_cc
            );
            println!(
                "  needing more than 25 steps:                                    {}",
                r.too_many_steps
            );
            println!(
                "  with a page over 250 elements:                                 {}",
                r.too_many_elements
            );
            println!(
                "  solvable by recomputed level: too easy {}, level 1 {}, level 2 {}, level 3 {}",
                r.solvable_by_level[0],
                r.solvable_by_level[1],
                r.solvable_by_level[2],
                r.solvable_by_level[3]
            );
            Ok(())
        }
    }
}
