//! The leaderboard entry: results with everything needed to reproduce and compare them
//! (hardware, software, seeds and every hyperparameter), as the paper's community benchmarking
//! section asks.

use std::collections::BTreeMap;

use serde::Serialize;

use super::load::Group;
use super::model::Report;
use crate::{RunRecord, SystemInfo};

/// One (task, algorithm) entry.
#[derive(Debug, Serialize)]
pub struct LeaderboardEntry<'a> {
    /// Task name.
    pub task: &'a str,
    /// Environment id.
    pub env_id: &'a str,
    /// Domain.
    pub domain: &'a str,
    /// Algorithm.
    pub algorithm: &'a str,
    /// Seeds.
    pub seeds: Vec<u64>,
    /// Settings and resolved parameters of the first run (all runs of a group share them
    /// except the seed; differing runs are listed in `inconsistent_settings`).
    pub run: &'a RunRecord,
    /// Run directories whose settings differ from the first run's (other than the seed).
    pub inconsistent_settings: Vec<String>,
    /// Metric key → {mean, std, ci95, unit, higher_is_better, note}.
    pub metrics: BTreeMap<&'a str, &'a super::MetricValue>,
    /// Every run came from a bundle that verified (absent when not).
    #[serde(skip_serializing_if = "std::ops::Not::not")]
    pub verified: bool,
}

/// `leaderboard.json`.
#[derive(Debug, Serialize)]
pub struct Leaderboard<'a> {
    /// Format tag.
    pub format: &'static str,
    /// Machines the runs were trained on (deduplicated).
    pub hardware_and_software: Vec<SystemInfo>,
    /// Entries.
    pub entries: Vec<LeaderboardEntry<'a>>,
    /// IQM of returns.
    pub iqm: &'a [super::IqmEntry],
    /// Probability of improvement.
    pub probability_of_improvement: &'a [super::ImprovementEntry],
}

/// Assembles the leaderboard entry of a report.
pub fn leaderboard<'a>(report: &'a Report, groups: &'a [Group]) -> Leaderboard<'a> {
    let mut machines: Vec<SystemInfo> = Vec::new();
    for g in groups {
        for r in &g.runs {
            if let Some(info) = &r.system_info
                && !machines.contains(info)
            {
                machines.push(info.clone());
            }
        }
    }
    let mut entries = Vec::new();
    for (gr, g) in report.groups.iter().zip(groups) {
        let first = &g.runs[0].run.record;
        let inconsistent = g
            .runs
            .iter()
            .filter(|r| {
                let mut a = r.run.record.clone();
                a.seed = first.seed;
                a != *first
            })
            .map(|r| r.run.dir.display().to_string())
            .collect();
        entries.push(LeaderboardEntry {
            task: &gr.task,
            env_id: &gr.env_id,
            domain: &gr.domain,
            algorithm: &gr.algorithm,
            seeds: gr.seeds.clone(),
            run: first,
            inconsistent_settings: inconsistent,
            metrics: gr.metrics.iter().map(|m| (m.key.as_str(), m)).collect(),
            verified: gr.verified,
        });
    }
    Leaderboard {
        format: "a2perf-leaderboard-v1",
        hardware_and_software: machines,
        entries,
        iqm: &report.iqm,
        probability_of_improvement: &report.probability_of_improvement,
    }
}
