//! What can go wrong with policies and training runs.

use crate::env::EnvError;

/// Errors raised by policies (inference, checkpoint encoding and decoding).
#[derive(Debug, thiserror::Error)]
pub enum PolicyError {
    /// The observation does not fit the policy (wrong shape or missing tensor).
    #[error("observation does not fit the policy: {0}")]
    BadObservation(String),
    /// No legal action exists (all masked out).
    #[error("no legal action available")]
    NoLegalAction,
    /// A checkpoint could not be decoded.
    #[error("invalid checkpoint: {0}")]
    BadCheckpoint(String),
}

impl From<crate::bytes::Truncated> for PolicyError {
    fn from(e: crate::bytes::Truncated) -> Self {
        PolicyError::BadCheckpoint(format!("the data is {e}"))
    }
}

/// Errors raised while training or rolling out.
#[derive(Debug, thiserror::Error)]
pub enum RunError {
    /// The environment failed.
    #[error(transparent)]
    Env(#[from] EnvError),
    /// The policy failed.
    #[error(transparent)]
    Policy(#[from] PolicyError),
    /// Writing a checkpoint or result failed.
    #[error("i/o error: {0}")]
    Io(#[from] std::io::Error),
    /// A hyperparameter is invalid for this environment.
    #[error("invalid hyperparameter `{name}`: {reason}")]
    InvalidHyperparameter {
        /// Name of the hyperparameter.
        name: String,
        /// Why it is invalid.
        reason: String,
    },
    /// The algorithm does not support this environment's spaces.
    #[error("unsupported environment: {0}")]
    Unsupported(String),
    /// Training diverged (non-finite loss or parameters).
    #[error("training diverged: {0}")]
    Diverged(String),
    /// The algorithm cannot continue from the resume state it was given (another format
    /// version, another configuration, a changed dataset). Pipelines then train from scratch.
    #[error("cannot resume: {0}")]
    Resume(String),
    /// Training was cancelled (Ctrl-C, SIGTERM). When the algorithm opted in to resumption and
    /// the sink keeps resume points, one was written first.
    #[error("cancelled")]
    Cancelled,
}
