//! What training did: each run's outcome ([`RunOutcome`], [`RunReport`], which a training
//! child process hands its parent as JSON) and the summary of a whole grid ([`TrainSummary`]).

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::error::{LockHolder, LockedRun};

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

    /// Failed runs and why.
    pub fn failures(&self) -> Vec<(&Path, &str)> {
        self.runs
            .iter()
            .filter_map(|(p, o)| match o {
                RunOutcome::Failed(why) => Some((p.as_path(), why.as_str())),
                _ => None,
            })
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
