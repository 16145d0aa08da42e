//! `a2perf report`: the paper's four-category tables per (task, algorithm), statistics between
//! algorithms, plots and a leaderboard entry.
//!
//! Every figure is computed from the run directories' files; nothing is re-run. A metric whose
//! inputs are missing (e.g. `infer` was not run, or the machine has no GPU) is reported as missing
//! with the reason, never as zero.
//!
//! The parts: [`load`] finds and groups the runs; `families` computes one table column per
//! (task, algorithm) group, one function per metric family; [`statistics`] compares the
//! algorithms (IQM, probability of improvement), with all arithmetic from `a2perf_metrics`;
//! [`merge`] joins reports made apart; [`render`], [`html`], [`svg`] and [`leaderboard`] write
//! them out, and [`paper`] sets the paper's figures beside them.

use std::path::{Path, PathBuf};

use a2perf_core::RngStream;

use super::{Result, io_err};
use families::{application, data_cost, reliability, system};
use statistics::Seeds;

mod families;
pub mod format;
pub mod html;
pub mod leaderboard;
pub mod load;
pub mod merge;
pub mod model;
pub mod paper;
pub mod render;
pub mod statistics;
pub mod svg;

pub use load::{Group, RunData, SkippedRun, load_groups};
pub use merge::merge_reports;
pub use model::{
    Category, GroupReport, GroupTimeSplit, ImprovementEntry, IqmEntry, MetricValue, ProfileUse,
    Report, ReportOptions, SuiteUse, TableSettings,
};

/// One page for several report directories (each `report.json` and `curves.csv`, e.g. the
/// per-domain reports under `docs/results/`), merged by [`merge_reports`]: returns the
/// merged report, whose `report.json` the page's numbers refer to, and the page. As in
/// [`html::page_from_report_dir`], run links and inference-time distributions are left out.
pub fn page_from_report_dirs(dirs: &[PathBuf]) -> Result<(Report, String)> {
    let mut parts = Vec::with_capacity(dirs.len());
    let mut runs = Vec::new();
    for dir in dirs {
        let path = dir.join("report.json");
        let report: Report = a2perf_core::results::read_json(&path)?;
        runs.extend(html::runs_of_report_dir(dir, &report)?);
        parts.push((path, report));
    }
    let merged = merge_reports(parts)?;
    let page = html::page(&merged, &runs);
    Ok((merged, page))
}

/// Runs proven by bundles that verified (see [`crate::bundle::Bundle::extract`]), and what the
/// report does with them.
#[derive(Clone, Debug, Default)]
pub struct VerifiedRuns {
    /// The run directories extracted from verified bundles.
    pub runs: Vec<PathBuf>,
    /// Restrict `leaderboard.json` to the verified groups.
    pub only: bool,
}

impl VerifiedRuns {
    /// Marks each group of `report` whose runs (`groups`, in the same order) are all verified.
    fn mark(&self, report: &mut Report, groups: &[Group]) {
        for (gr, g) in report.groups.iter_mut().zip(groups) {
            gr.verified =
                !g.runs.is_empty() && g.runs.iter().all(|r| self.runs.contains(&r.run.dir));
        }
    }
}

/// Computes the report of the runs below `dirs`.
pub fn build_report(dirs: &[PathBuf], opts: &ReportOptions) -> Result<(Report, Vec<Group>)> {
    build_report_with_paper(dirs, opts, None)
}

/// [`build_report`], with the paper's figures beside every table that matches a task of
/// `paper` (see [`paper`]).
pub fn build_report_with_paper(
    dirs: &[PathBuf],
    opts: &ReportOptions,
    paper: Option<&paper::PaperTables>,
) -> Result<(Report, Vec<Group>)> {
    let (groups, skipped) = load_groups(dirs)?;
    let reports: Vec<GroupReport> = groups.iter().map(|g| group_report(g, opts)).collect();
    let (iqm, poi) = statistics::comparisons(&reports, opts);
    let mut report = Report {
        groups: reports,
        iqm,
        probability_of_improvement: poi,
        skipped_runs: skipped,
        bootstrap_reps: opts.bootstrap_reps,
        settings: load::table_settings(&groups),
        paper: Vec::new(),
        findings: Vec::new(),
    };
    if let Some(tables) = paper {
        report.paper = paper::compare(&report, &groups, tables);
        report.findings = paper::check_findings(&report, &groups, tables);
    }
    Ok((report, groups))
}

/// Builds the report and writes every output into `out`: `report.md`, `index.html`, `report.tex`,
/// `metrics.csv`, `report.json`, `leaderboard.json`, `curves.csv` and `scores.csv` (the inputs
/// of `a2perf metrics reliability` and `a2perf metrics iqm`) and
/// `plots/{radar,curves}_<task>.svg`.
pub fn write_report(dirs: &[PathBuf], out: &Path, opts: &ReportOptions) -> Result<Report> {
    write_report_with_paper(dirs, out, opts, None)
}

/// [`write_report`], with the paper's figures beside every table that matches a task of
/// `paper`; `paper_comparison.csv` lists them one row per (task, algorithm, metric), and
/// `comparison.json` every cell of the paper's tables beside ours, the findings' outcomes and
/// the runs' totals ([`paper::ComparisonFile`]).
pub fn write_report_with_paper(
    dirs: &[PathBuf],
    out: &Path,
    opts: &ReportOptions,
    paper: Option<&paper::PaperTables>,
) -> Result<Report> {
    write_report_verified(dirs, out, opts, paper, &VerifiedRuns::default())
}

/// [`write_report_with_paper`], marking the groups whose runs are all in `verified` and, with
/// [`VerifiedRuns::only`], leaving the others out of `leaderboard.json`.
pub fn write_report_verified(
    dirs: &[PathBuf],
    out: &Path,
    opts: &ReportOptions,
    paper: Option<&paper::PaperTables>,
    verified: &VerifiedRuns,
) -> Result<Report> {
    let (mut report, groups) = build_report_with_paper(dirs, opts, paper)?;
    verified.mark(&mut report, &groups);
    std::fs::create_dir_all(out.join("plots")).map_err(io_err(out))?;
    let write = |name: &str, text: &str| -> Result<()> {
        let p = out.join(name);
        a2perf_core::write_atomic(&p, text.as_bytes()).map_err(io_err(&p))
    };
    write("report.md", &render::markdown(&report))?;
    write(
        "index.html",
        &html::page(&report, &html::RunView::of_groups(&groups, out)),
    )?;
    write("report.tex", &render::latex(&report))?;
    write("metrics.csv", &render::csv(&report))?;
    let curves = groups.iter().flat_map(|g| {
        g.runs.iter().map(move |r| {
            (
                g.task.as_str(),
                g.algorithm.as_str(),
                r.run.record.seed,
                &r.curve,
            )
        })
    });
    write("curves.csv", &render::curves_csv(curves))?;
    write("scores.csv", &render::scores_csv(&report))?;
    if let Some(tables) = paper {
        write("paper_comparison.csv", &render::paper_csv(&report))?;
        a2perf_core::write_json_atomic(
            &out.join("comparison.json"),
            &paper::comparison(&report, &groups, tables),
        )?;
    }
    a2perf_core::write_json_atomic(&out.join("report.json"), &report)?;
    let mut board = leaderboard::leaderboard(&report, &groups);
    if verified.only {
        board.entries.retain(|e| e.verified);
    }
    a2perf_core::write_json_atomic(&out.join("leaderboard.json"), &board)?;
    let tasks: std::collections::BTreeSet<&str> =
        report.groups.iter().map(|g| g.task.as_str()).collect();
    for task in tasks {
        let stem = crate::run_dir::path_safe(task);
        let in_task: Vec<&GroupReport> = report.groups.iter().filter(|g| g.task == task).collect();
        write(
            &format!("plots/radar_{stem}.svg"),
            &svg::radar(task, &in_task),
        )?;
        let task_groups: Vec<(&str, Vec<&a2perf_core::LearningCurve>)> = groups
            .iter()
            .filter(|g| g.task == task)
            .map(|g| {
                (
                    g.algorithm.as_str(),
                    g.runs.iter().map(|r| &r.curve).collect(),
                )
            })
            .collect();
        write(
            &format!("plots/curves_{stem}.svg"),
            &svg::curves(task, &task_groups),
        )?;
    }
    Ok(report)
}

/// The column of `group`: every metric of every family.
fn group_report(group: &Group, opts: &ReportOptions) -> GroupReport {
    let first = &group.runs[0].run.record;
    let runs = &group.runs;
    // One stream for the whole column, drawn from in table order.
    let mut seeds = Seeds {
        reps: opts.bootstrap_reps,
        rng: RngStream::new(
            opts.seed,
            &format!("report/bootstrap/{}/{}", group.task, group.algorithm),
        ),
    };
    let mut metrics = data_cost::metrics(runs, &mut seeds);
    metrics.extend(application::metrics(runs, &mut seeds));
    metrics.extend(reliability::metrics(runs));
    metrics.extend(system::training(runs, &mut seeds));
    metrics.extend(system::inference(runs, &mut seeds));
    GroupReport {
        task: group.task.clone(),
        env_id: first.task.env_id.clone(),
        domain: first.domain.clone(),
        algorithm: group.algorithm.clone(),
        seeds: runs.iter().map(|r| r.run.record.seed).collect(),
        metrics,
        verified: false,
        time_split: group_time_split(runs),
    }
}

/// The group's training time split, summed over its runs: `None` unless every run recorded
/// both its split and its training wall clock.
fn group_time_split(runs: &[RunData]) -> Option<model::GroupTimeSplit> {
    runs.iter().try_fold(
        model::GroupTimeSplit {
            wall_s: 0.0,
            parts: a2perf_core::TimeSplit::default(),
        },
        |sum, r| {
            Some(model::GroupTimeSplit {
                wall_s: sum.wall_s + r.train_system.as_ref()?.wall_clock_s,
                parts: sum.parts.plus(&r.time_split?),
            })
        },
    )
}
