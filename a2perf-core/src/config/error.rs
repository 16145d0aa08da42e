//! Where a configuration value came from, and everything that can go wrong loading one.

use std::fmt;
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// Where a value or key was written: a position in a file, a `--set` override, or a default.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Location {
    /// A position in a file (1-based line and column; columns count characters).
    File {
        /// The file, as the user named it (includes are joined to the including file's folder).
        path: Arc<Path>,
        /// Line, from 1.
        line: u32,
        /// Column, from 1.
        column: u32,
    },
    /// A command-line override; holds the whole override, e.g. `algorithm.learning_rate=1e-4`.
    Override(Arc<str>),
    /// A default from the schema or a registry's parameter specs.
    Default,
}

impl Location {
    /// A position in `path`.
    pub fn file(path: &Arc<Path>, line: u32, column: u32) -> Self {
        Location::File {
            path: Arc::clone(path),
            line,
            column,
        }
    }
}

impl fmt::Display for Location {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Location::File { path, line, column } => {
                write!(f, "{}:{line}:{column}", path.display())
            }
            Location::Override(text) => write!(f, "--set {text}"),
            Location::Default => write!(f, "(default)"),
        }
    }
}

fn fmt_hint(h: &Option<String>) -> String {
    h.as_ref()
        .map(|h| format!(" (did you mean `{h}`?)"))
        .unwrap_or_default()
}

fn fmt_chain(files: &[PathBuf]) -> String {
    files
        .iter()
        .map(|p| format!("`{}`", p.display()))
        .collect::<Vec<_>>()
        .join(" -> ")
}

/// An error loading an experiment config. Every variant names the place it points at (file, line
/// and column, or the `--set` override) and the dotted key where there is one.
#[derive(Debug, thiserror::Error)]
pub enum ConfigError {
    /// A file could not be read (missing top-level file or missing include).
    #[error("{}cannot read `{}`: {source}{}",
        included_at.as_ref().map(|l| format!("{l}: include: ")).unwrap_or_default(),
        path.display(),
        if chain.len() > 1 { format!(" (include chain: {})", fmt_chain(chain)) } else { String::new() })]
    Read {
        /// The file that could not be read.
        path: PathBuf,
        /// Where the `include` naming it was written (`None` for the top-level file).
        included_at: Option<Location>,
        /// The files being loaded, outermost first, ending with `path`.
        chain: Vec<PathBuf>,
        /// The I/O error.
        source: std::io::Error,
    },
    /// Files that include each other.
    #[error("{location}: include cycle: {}", fmt_chain(chain))]
    IncludeCycle {
        /// The `include` entry that closes the cycle.
        location: Location,
        /// The files of the cycle, outermost first; the last one repeats an earlier one.
        chain: Vec<PathBuf>,
    },
    /// The text is not valid (subset of) RON.
    #[error("{location}: syntax error: {message}")]
    Syntax {
        /// Where the parser stopped.
        location: Location,
        /// What it expected.
        message: String,
    },
    /// A key the schema or the registry's parameter specs do not declare.
    #[error("{location}: unknown key `{key}`{}{}", fmt_hint(hint), known.as_ref().map(|k| format!("; known keys: {k}")).unwrap_or_default())]
    UnknownKey {
        /// Where the key was written.
        location: Location,
        /// Dotted path of the key, e.g. `algorithm.lerning_rate`.
        key: String,
        /// The closest known key.
        hint: Option<String>,
        /// The known keys at that level, comma-separated (only when no close match exists).
        known: Option<String>,
    },
    /// The same key twice in one struct or map.
    #[error("{location}: duplicate key `{key}` (first set at {first})")]
    DuplicateKey {
        /// The second occurrence.
        location: Location,
        /// Dotted path of the key.
        key: String,
        /// The first occurrence.
        first: Location,
    },
    /// A value of the wrong type.
    #[error("{location}: `{key}`: {reason}")]
    WrongType {
        /// Where the value was written.
        location: Location,
        /// Dotted path of the key.
        key: String,
        /// Expected and found types.
        reason: String,
    },
    /// A value of the right type that is not allowed (negative count, unknown environment, …).
    #[error("{location}: `{key}`: {reason}")]
    InvalidValue {
        /// Where the value was written.
        location: Location,
        /// Dotted path of the key.
        key: String,
        /// Why it is rejected.
        reason: String,
    },
    /// A required key is absent.
    #[error("{location}: missing key `{key}`: {reason}")]
    MissingKey {
        /// The struct that lacks the key.
        location: Location,
        /// Dotted path of the missing key.
        key: String,
        /// What it is for.
        reason: String,
    },
    /// The experiment lacks a section a pipeline needs (`env` or `algorithm`).
    #[error("experiment `{experiment}` has no `{section}` section: {reason}")]
    MissingSection {
        /// The experiment's name.
        experiment: String,
        /// The section.
        section: String,
        /// What to add.
        reason: String,
    },
    /// A malformed `--set` argument.
    #[error("--set {text}: {reason}")]
    BadOverride {
        /// The argument as given.
        text: String,
        /// What is wrong with it.
        reason: String,
    },
    /// Writing the operative config failed.
    #[error("cannot write `{}`: {source}", path.display())]
    Write {
        /// The file.
        path: PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
}

impl ConfigError {
    /// The dotted key the error is about, if any.
    pub fn key(&self) -> Option<&str> {
        match self {
            ConfigError::UnknownKey { key, .. }
            | ConfigError::DuplicateKey { key, .. }
            | ConfigError::WrongType { key, .. }
            | ConfigError::InvalidValue { key, .. }
            | ConfigError::MissingKey { key, .. } => Some(key),
            ConfigError::MissingSection { section, .. } => Some(section),
            _ => None,
        }
    }

    /// Where the error points, if it points at one place.
    pub fn location(&self) -> Option<&Location> {
        match self {
            ConfigError::IncludeCycle { location, .. }
            | ConfigError::Syntax { location, .. }
            | ConfigError::UnknownKey { location, .. }
            | ConfigError::DuplicateKey { location, .. }
            | ConfigError::WrongType { location, .. }
            | ConfigError::InvalidValue { location, .. }
            | ConfigError::MissingKey { location, .. } => Some(location),
            ConfigError::Read { included_at, .. } => included_at.as_ref(),
            ConfigError::BadOverride { .. }
            | ConfigError::MissingSection { .. }
            | ConfigError::Write { .. } => None,
        }
    }
}
