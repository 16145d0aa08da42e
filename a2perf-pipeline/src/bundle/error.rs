//! What a bundle's members are called, and why a bundle could not be made or read.

use super::archive::ArchiveError;

/// `bundle.json`: the bundle's [`BundleInfo`](super::BundleInfo).
pub const INFO_FILE: &str = "bundle.json";
/// The folder of the runs' members: `runs/<experiment>/<run>/…`.
pub const RUNS_DIR: &str = "runs";

/// Why a bundle could not be made or read (a verification's failed checks are not errors: they
/// are in its [`Verification`](super::Verification)).
#[derive(Debug, thiserror::Error)]
pub enum BundleError {
    /// The archive itself: truncated, tampered with, unsafe or too large.
    #[error(transparent)]
    Archive(#[from] ArchiveError),
    /// A run directory could not be read.
    #[error(transparent)]
    Pipeline(#[from] crate::PipelineError),
    /// The runs or the bundle do not have what a bundle needs.
    #[error("{0}")]
    Invalid(String),
}

impl From<a2perf_core::results::ResultsError> for BundleError {
    fn from(e: a2perf_core::results::ResultsError) -> Self {
        BundleError::Pipeline(e.into())
    }
}
