//! Merging: reports of disjoint (task, algorithm) groups joined into one (`a2perf report
//! --from-reports`).

use std::collections::BTreeMap;
use std::path::PathBuf;

use super::model::{Report, ReportOptions, TableSettings};
use super::statistics::comparisons;
use crate::{PipelineError, Result};

/// Merges reports of disjoint (task, algorithm) groups into one, as if `a2perf report` had read
/// all their runs at once: groups and per-task settings are joined, and the IQMs and
/// probabilities of improvement are computed again over the joined groups (from the per-seed
/// returns each report keeps, with the bootstrap streams `a2perf report` uses), so a pair of
/// algorithms reported apart is compared too. `parts` name their source (a `report.json`) for
/// errors.
///
/// Refused: reports made with different bootstrap repetitions, a (task, algorithm) group in
/// two reports, and reports with the paper's findings (a finding is checked over a whole
/// report's runs: report the runs together instead).
///
/// ```
/// use a2perf_pipeline::report::{Report, merge_reports};
/// let empty = |reps| Report {
///     groups: vec![], iqm: vec![], probability_of_improvement: vec![], skipped_runs: vec![],
///     bootstrap_reps: reps, settings: vec![], paper: vec![], findings: vec![],
/// };
/// let merged = merge_reports(vec![("a".into(), empty(100)), ("b".into(), empty(100))]).unwrap();
/// assert_eq!(merged.bootstrap_reps, 100);
/// let err = merge_reports(vec![("a".into(), empty(100)), ("b".into(), empty(10))]).unwrap_err();
/// assert!(err.to_string().contains("bootstrap"));
/// ```
pub fn merge_reports(parts: Vec<(PathBuf, Report)>) -> Result<Report> {
    let Some((first_path, first)) = parts.first() else {
        return Err(PipelineError::Invalid("no report to merge".into()));
    };
    let reps = first.bootstrap_reps;
    let first_path = first_path.clone();
    let mut merged = Report {
        groups: Vec::new(),
        iqm: Vec::new(),
        probability_of_improvement: Vec::new(),
        skipped_runs: Vec::new(),
        bootstrap_reps: reps,
        settings: Vec::new(),
        paper: Vec::new(),
        findings: Vec::new(),
    };
    let mut owner: BTreeMap<(String, String), PathBuf> = BTreeMap::new();
    for (path, report) in parts {
        let bad = |reason: String| PipelineError::Corrupt {
            path: path.clone(),
            reason,
        };
        if report.bootstrap_reps != reps {
            return Err(bad(format!(
                "made with {} bootstrap repetitions, {} with {reps}: reports merged into one \
                 page must share them (rerun `a2perf report --bootstrap-reps N` on one)",
                report.bootstrap_reps,
                first_path.display()
            )));
        }
        if !report.findings.is_empty() {
            return Err(bad(
                "holds the paper's findings, which are checked over a whole report's runs: \
                 report those runs together (`a2perf report DIRS --paper ...`) instead of \
                 merging reports"
                    .into(),
            ));
        }
        for g in &report.groups {
            let key = (g.task.clone(), g.algorithm.clone());
            if let Some(other) = owner.get(&key) {
                return Err(bad(format!(
                    "task `{}`, algorithm `{}` is also in {}: each (task, algorithm) may come \
                     from one report only",
                    g.task,
                    g.algorithm,
                    other.display()
                )));
            }
            owner.insert(key, path.clone());
        }
        merged.groups.extend(report.groups);
        merged.skipped_runs.extend(report.skipped_runs);
        merged.paper.extend(report.paper);
        for s in report.settings {
            match merged.settings.iter_mut().find(|m| m.task == s.task) {
                None => merged.settings.push(s),
                Some(m) => merge_settings(m, s),
            }
        }
    }
    let opts = ReportOptions {
        bootstrap_reps: reps,
        seed: 0,
    };
    let (iqm, poi) = comparisons(&merged.groups, &opts);
    merged.iqm = iqm;
    merged.probability_of_improvement = poi;
    Ok(merged)
}

/// Joins the settings of one task from two reports: an equal profile or suite gains the other's
/// algorithms, a different one is listed beside it (the table then mixes settings, as one report
/// of both sets of runs would say).
fn merge_settings(into: &mut TableSettings, from: TableSettings) {
    for p in from.profiles {
        match into.profiles.iter_mut().find(|q| q.profile == p.profile) {
            Some(q) => q.algorithms.extend(p.algorithms),
            None => into.profiles.push(p),
        }
    }
    for s in from.suites {
        match into
            .suites
            .iter_mut()
            .find(|t| t.source == s.source && t.tasks == s.tasks)
        {
            Some(t) => t.algorithms.extend(s.algorithms),
            None => into.suites.push(s),
        }
    }
    for p in &mut into.profiles {
        p.algorithms.sort();
        p.algorithms.dedup();
    }
    for s in &mut into.suites {
        s.algorithms.sort();
        s.algorithms.dedup();
    }
}
