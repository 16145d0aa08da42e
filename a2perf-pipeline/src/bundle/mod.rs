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
mod error;
mod pack;
mod verify;

pub use archive::{
    Archive, ArchiveError, ArchiveLimits, FORMAT, FORMAT_VERSION, MANIFEST, Manifest,
    ManifestEntry, gzip, sha256_hex,
};
pub use error::{BundleError, INFO_FILE, RUNS_DIR};
pub use pack::{BundleInfo, EnvIdentity, IdentityFile, PackSummary, pack};
pub use verify::{Bundle, Check, Outcome, Verification, VerifyOptions, verify};
