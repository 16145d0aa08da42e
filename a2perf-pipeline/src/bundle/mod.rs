//! Bundles: one file that carries a run's results and the proof behind them.
//!
//! [`Archive`] is the container (a gzip-compressed tar with a SHA-256 manifest, read without
//! trusting a byte of it).

mod archive;

pub use archive::{
    Archive, ArchiveError, ArchiveLimits, FORMAT, FORMAT_VERSION, MANIFEST, Manifest,
    ManifestEntry, gzip, sha256_hex,
};
