//! One table column per (task, algorithm) group: one function per metric family of the paper
//! (data cost, application, reliability, system in training and in inference), in table order.

use a2perf_core::RngStream;

use super::statistics::OverSeeds;
use super::{Group, GroupReport, MetricValue, ReportOptions};

mod application;
mod data_cost;
mod reliability;
pub(super) mod system;

/// The column of `group`: every metric of every family.
pub(super) fn group_report(group: &Group, opts: &ReportOptions) -> GroupReport {
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
    }
}

/// The bootstrap settings and stream of a column's per-seed metrics.
struct Seeds {
    reps: usize,
    rng: RngStream,
}

impl Seeds {
    /// A metric with one value per run: its statistics over the seeds, or missing (saying how
    /// many runs have it) when any run lacks it. `notes` (deduplicated) say how it was obtained.
    fn metric(
        &mut self,
        metric: MetricValue,
        values: Vec<Option<f64>>,
        missing_why: &str,
        mut notes: Vec<String>,
    ) -> MetricValue {
        let mut m = metric;
        if values.is_empty() || values.iter().any(Option::is_none) {
            let have = values.iter().filter(|v| v.is_some()).count();
            return m.missing(format!("{missing_why} ({have} of {} runs)", values.len()));
        }
        let v: Vec<f64> = values.into_iter().flatten().collect();
        let stats = OverSeeds::of(&v, self.reps, &mut self.rng);
        m.mean = Some(stats.mean);
        m.std = Some(stats.std);
        m.ci95 = stats.ci95;
        m.per_seed = v;
        notes.sort();
        notes.dedup();
        if !notes.is_empty() {
            m.note = Some(notes.join("; "));
        }
        m
    }
}
