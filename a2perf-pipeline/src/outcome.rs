//! What training did: each run's outcome ([`RunOutcome`], [`RunReport`], which a training
//! child process hands its parent as JSON) and the summary of a whole grid ([`TrainSummary`]).

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::error::{LockHolder, LockedRun, Result};
use crate::pool::Slot;

/// What happened to one run.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum RunOutcome {
    /// Trained to completion now (possibly continuing an interrupted run).
    Completed,
    /// Already complete on disk; not redone.
    Skipped,
    /// Stopped by the cancel token (or never started because of it); the directory is marked
    /// `interrupted`, and a rerun continues it.
    Cancelled,
    /// Training failed; the directory is marked `failed` with the reason.
    Failed(String),
    /// Left alone: another trainer holds the run directory's training lock (see
    /// [`run_lock`](crate::run_lock)); the holder as it recorded itself.
    Locked(Option<LockHolder>),
    /// Not started: something it needs (the dataset it trains on, or a run that dataset is
    /// collected from) did not come to be; the reason names it. The directory is left as it
    /// was, and a rerun trains the run.
    Blocked(String),
}

/// Outcome of [`train`](crate::train::train).
#[derive(Clone, Debug, Default)]
pub struct TrainSummary {
    /// Run directories with their outcome, in grid order.
    pub runs: Vec<(PathBuf, RunOutcome)>,
    /// Runs that continued from a resume point, and its environment steps.
    pub resumed: Vec<(PathBuf, u64)>,
    /// Things a user should know (fallbacks past corrupt resume points, runs restarted from
    /// scratch, environments that did not replay exactly), per run directory. The library never
    /// prints them; front ends do.
    pub warnings: Vec<(PathBuf, String)>,
}

impl TrainSummary {
    /// Run directories with the given outcome.
    pub fn with(&self, outcome: &RunOutcome) -> Vec<&Path> {
        self.runs
            .iter()
            .filter(|(_, o)| o == outcome)
            .map(|(p, _)| p.as_path())
            .collect()
    }

    /// Runs left alone because another trainer holds them, with the holder.
    pub fn locked(&self) -> Vec<LockedRun> {
        self.runs
            .iter()
            .filter_map(|(p, o)| match o {
                RunOutcome::Locked(holder) => Some(LockedRun {
                    run: p.clone(),
                    holder: holder.clone(),
                }),
                _ => None,
            })
            .collect()
    }

    /// Runs not started because something they need did not come to be, and why.
    pub fn blocked(&self) -> Vec<(&Path, &str)> {
        self.with_reason(|o| match o {
            RunOutcome::Blocked(why) => Some(why),
            _ => None,
        })
    }

    /// Adds what the pool did with the run in `dir`: its report, or [`RunOutcome::Blocked`]
    /// with `blocked_by(task)` as the reason, or [`RunOutcome::Cancelled`] when it never
    /// started. A run whose training stopped with an error (not a failed run: a problem that
    /// stops everything) returns that error.
    pub(crate) fn add(
        &mut self,
        dir: PathBuf,
        slot: Slot<Result<RunReport>>,
        blocked_by: impl Fn(usize) -> String,
    ) -> Result<()> {
        let outcome = match slot {
            Slot::Done(report) => {
                let report = report?;
                if let Some(step) = report.resumed_from {
                    self.resumed.push((dir.clone(), step));
                }
                self.warnings
                    .extend(report.warnings.into_iter().map(|w| (dir.clone(), w)));
                report.outcome
            }
            Slot::Blocked { by } => RunOutcome::Blocked(blocked_by(by)),
            Slot::NotRun => RunOutcome::Cancelled,
        };
        self.runs.push((dir, outcome));
        Ok(())
    }

    /// Failed runs and why.
    pub fn failures(&self) -> Vec<(&Path, &str)> {
        self.with_reason(|o| match o {
            RunOutcome::Failed(why) => Some(why),
            _ => None,
        })
    }

    /// Runs whose outcome `reason` gives a reason for, with it.
    fn with_reason(&self, reason: fn(&RunOutcome) -> Option<&String>) -> Vec<(&Path, &str)> {
        self.runs
            .iter()
            .filter_map(|(p, o)| reason(o).map(|why| (p.as_path(), why.as_str())))
            .collect()
    }
}

/// What [`train_run`](crate::train::train_run) did to one run (a child process of [`Isolation::Children`](crate::isolate::Isolation::Children) hands it to
/// its parent as JSON).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RunReport {
    /// How the run ended.
    pub outcome: RunOutcome,
    /// The resume point's environment steps, when the run continued from one.
    pub resumed_from: Option<u64>,
    /// Warnings for the user (see [`TrainSummary::warnings`]).
    pub warnings: Vec<String>,
}
