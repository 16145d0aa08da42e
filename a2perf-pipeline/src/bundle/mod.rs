//! Bundles: one file that carries a run's results and the proof behind them.
//!
//! [`Archive`] is the container (a gzip-compressed tar with a SHA-256 manifest, read without
//! trusting a byte of it). [`pack`] fills one from complete runs: per run, under
//! `runs/<experiment>/<run>/`, the record, operative config, curves, results, system figures,
//! the identity of every environment used ([`IDENTITY_FILE`]), the episode logs and, for a
//! built-in algorithm, the final checkpoint; `bundle.json` names the binary that packed it.
//! [`Bundle::verify`] replays every logged episode and recomputes what the results state;
//! nothing in a bundle is executed. `docs/bundles.md` describes the format and what a
//! verification proves.
//!
//! [`IDENTITY_FILE`]: crate::run_dir::IDENTITY_FILE

mod archive;
mod pack;
mod verify;

pub use archive::{
    Archive, ArchiveError, ArchiveLimits, FORMAT, FORMAT_VERSION, MANIFEST, Manifest,
    ManifestEntry, gzip, sha256_hex,
};
pub use pack::{BundleInfo, EnvIdentity, IdentityFile, PackSummary, pack};
pub use verify::{Bundle, Check, Outcome, Verification, VerifyOptions, verify};

/// `bundle.json`: the bundle's [`BundleInfo`].
pub const INFO_FILE: &str = "bundle.json";
/// The folder of the runs' members: `runs/<experiment>/<run>/…`.
pub const RUNS_DIR: &str = "runs";

/// Why a bundle could not be made or read (a verification's failed checks are not errors: they
/// are in its [`Verification`]).
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
