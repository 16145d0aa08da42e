//! The ground floor: what can go wrong in a pipeline, and the run lock's vocabulary that its
//! errors carry. It imports nothing else of the crate, so every module can use it.

use std::path::{Path, PathBuf};

use a2perf_core::{RegistryError, RunError, results::ResultsError};
use serde::{Deserialize, Serialize};

/// Everything that can go wrong in a pipeline. Each variant names the file or run concerned.
#[derive(Debug, thiserror::Error)]
pub enum PipelineError {
    /// Reading or writing a file failed.
    #[error("{}: {source}", path.display())]
    Io {
        /// The file or directory.
        path: PathBuf,
        /// The error.
        source: std::io::Error,
    },
    /// A results file or checkpoint exists but cannot be used.
    #[error("{}: {reason}", path.display())]
    Corrupt {
        /// The file.
        path: PathBuf,
        /// Why.
        reason: String,
    },
    /// An environment or algorithm is unknown or badly parameterised.
    #[error(transparent)]
    Registry(#[from] RegistryError),
    /// Training or a rollout failed.
    #[error("{run}: {source}")]
    Run {
        /// The run directory.
        run: String,
        /// The error.
        source: RunError,
    },
    /// A rollout failed: the policy or the environment returned an error in this episode at
    /// this step (both counted from 0).
    #[error("{run}: episode {episode}, step {step} (counted from 0): {source}")]
    Rollout {
        /// The run directory (and the task, for generalization).
        run: String,
        /// Episode index.
        episode: usize,
        /// Step index within the episode (the policy call that failed, or the step after it).
        step: usize,
        /// The error.
        source: RunError,
    },
    /// A request that cannot be carried out (bad shard, no seeds, …).
    #[error("{0}")]
    Invalid(String),
    /// Cancelled (Ctrl-C); the state on disk is resumable.
    #[error("cancelled; rerun the same command to resume")]
    Cancelled,
    /// Run directories that another trainer holds (see [`run_lock`](crate::run_lock)): left alone, neither
    /// trained nor treated as complete.
    #[error("{}", .0.iter().map(ToString::to_string).collect::<Vec<_>>().join("; "))]
    Locked(Vec<LockedRun>),
}

impl From<ResultsError> for PipelineError {
    fn from(e: ResultsError) -> Self {
        match e {
            ResultsError::Io { path, source } => PipelineError::Io { path, source },
            ResultsError::Corrupt { path, reason } => PipelineError::Corrupt { path, reason },
        }
    }
}

/// Shorthand.
pub type Result<T, E = PipelineError> = std::result::Result<T, E>;

pub(crate) fn io_err(path: &Path) -> impl FnOnce(std::io::Error) -> PipelineError + '_ {
    move |source| PipelineError::Io {
        path: path.to_path_buf(),
        source,
    }
}

/// `train.lock`: the lock file of a run directory (see [`run_lock`](crate::run_lock)).
pub const TRAIN_LOCK_FILE: &str = "train.lock";

/// The process that holds a run directory's training lock, as it recorded itself.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct LockHolder {
    /// Its process id.
    pub pid: u32,
    /// The host it runs on.
    pub host: String,
}

impl LockHolder {
    /// This process.
    pub fn current() -> Self {
        Self {
            pid: std::process::id(),
            host: sysinfo::System::host_name().unwrap_or_else(|_| "unknown host".into()),
        }
    }
}

impl std::fmt::Display for LockHolder {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "pid {} on {}", self.pid, self.host)
    }
}

/// A run directory left alone because another trainer holds its lock.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct LockedRun {
    /// The run directory.
    pub run: PathBuf,
    /// The holder, as it recorded itself (`None` when it had not yet done so).
    pub holder: Option<LockHolder>,
}

impl std::fmt::Display for LockedRun {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let who = match &self.holder {
            Some(h) => format!("another trainer ({h})"),
            None => "another trainer (it has not recorded its pid and host yet)".into(),
        };
        write!(
            f,
            "{}: skipped: {who} holds its training lock ({TRAIN_LOCK_FILE}); run the same \
             command again once that process has stopped",
            self.run.display()
        )
    }
}
