//! Results on disk: atomic writes and run directories that know whether they completed.
//!
//! Layout: `EXPERIMENT/RUN/…` with one run directory per (task, algorithm, seed). A run directory
//! holds `status.json` (`{"state": "running" | "interrupted" | "failed" | "complete", …}`); files
//! are written with [`write_atomic`] (temp file + rename), so a killed run loses at most the work
//! in flight.

use std::io::Write;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

/// Errors reading or writing results.
#[derive(Debug, thiserror::Error)]
pub enum ResultsError {
    /// An i/o error on a named path.
    #[error("{path}: {source}")]
    Io {
        /// The path.
        path: PathBuf,
        /// The error.
        source: std::io::Error,
    },
    /// A results file exists but cannot be decoded.
    #[error("{path}: corrupt results file: {reason}")]
    Corrupt {
        /// The path.
        path: PathBuf,
        /// Why.
        reason: String,
    },
}

/// Writes `bytes` to `path` atomically: a temporary file in the same directory, flushed and synced,
/// then renamed over the target.
///
/// ```
/// let dir = std::env::temp_dir().join(format!("a2perf-doc-{}", std::process::id()));
/// std::fs::create_dir_all(&dir).unwrap();
/// let p = dir.join("x.json");
/// a2perf_core::write_atomic(&p, b"{}").unwrap();
/// assert_eq!(std::fs::read(&p).unwrap(), b"{}");
/// # std::fs::remove_dir_all(&dir).unwrap();
/// ```
pub fn write_atomic(path: &Path, bytes: &[u8]) -> std::io::Result<()> {
    write_atomic_with(path, |f| f.write_all(bytes))
}

/// [`write_atomic`] for content written piece by piece: `write` fills the temporary file, which
/// then replaces `path` (so a large file need not be gathered in memory first).
pub(crate) fn write_atomic_with<T>(
    path: &Path,
    write: impl FnOnce(&mut std::fs::File) -> std::io::Result<T>,
) -> std::io::Result<T> {
    let dir = path
        .parent()
        .filter(|p| !p.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    let name = path.file_name().ok_or_else(|| {
        std::io::Error::new(std::io::ErrorKind::InvalidInput, "path has no file name")
    })?;
    let tmp = dir.join(format!(
        ".{}.tmp-{}",
        name.to_string_lossy(),
        std::process::id()
    ));
    let written = (|| -> std::io::Result<T> {
        let mut f = std::fs::File::create(&tmp)?;
        let out = write(&mut f)?;
        f.sync_all()?;
        Ok(out)
    })()
    .inspect_err(|_| {
        let _ = std::fs::remove_file(&tmp);
    })?;
    std::fs::rename(&tmp, path).inspect_err(|_| {
        let _ = std::fs::remove_file(&tmp);
    })?;
    Ok(written)
}

/// Serialises `value` as pretty JSON and writes it atomically.
pub fn write_json_atomic<T: Serialize>(path: &Path, value: &T) -> Result<(), ResultsError> {
    let bytes = serde_json::to_vec_pretty(value).map_err(|e| ResultsError::Corrupt {
        path: path.to_path_buf(),
        reason: e.to_string(),
    })?;
    write_atomic(path, &bytes).map_err(|source| ResultsError::Io {
        path: path.to_path_buf(),
        source,
    })
}

/// Serialises `value` as compact JSON (no whitespace) straight into the file, atomically: for
/// large files such as datasets, where pretty-printing one number per line makes the file many
/// times larger and the whole text need not be held in memory.
///
/// ```
/// let dir = std::env::temp_dir().join(format!("a2perf-doc-compact-{}", std::process::id()));
/// std::fs::create_dir_all(&dir).unwrap();
/// let p = dir.join("x.json");
/// a2perf_core::write_json_compact_atomic(&p, &vec![1, 2, 3]).unwrap();
/// assert_eq!(std::fs::read(&p).unwrap(), b"[1,2,3]");
/// # std::fs::remove_dir_all(&dir).unwrap();
/// ```
pub fn write_json_compact_atomic<T: Serialize>(path: &Path, value: &T) -> Result<(), ResultsError> {
    write_atomic_with(path, |f| {
        let mut w = std::io::BufWriter::new(f);
        serde_json::to_writer(&mut w, value).map_err(std::io::Error::from)?;
        w.flush()
    })
    .map_err(|source| ResultsError::Io {
        path: path.to_path_buf(),
        source,
    })
}

/// Reads and decodes a JSON results file.
pub fn read_json<T: for<'de> Deserialize<'de>>(path: &Path) -> Result<T, ResultsError> {
    let bytes = std::fs::read(path).map_err(|source| ResultsError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    serde_json::from_slice(&bytes).map_err(|e| ResultsError::Corrupt {
        path: path.to_path_buf(),
        reason: e.to_string(),
    })
}

/// Reads a `f64` written by [`write_json_atomic`] that may have been NaN or infinite: JSON has
/// no such numbers, so they are written as `null`, and this reads `null` back as NaN (an
/// infinity's sign is not kept). For fields a run's numbers go into unchecked (returns and
/// their summaries), so that a run whose environment paid a NaN reward stays readable:
/// `#[serde(deserialize_with = "a2perf_core::results::f64_or_nan")]`.
///
/// ```
/// #[derive(serde::Serialize, serde::Deserialize)]
/// struct Point {
///     #[serde(deserialize_with = "a2perf_core::results::f64_or_nan")]
///     mean_return: f64,
/// }
/// let text = serde_json::to_string(&Point { mean_return: f64::NAN }).unwrap();
/// assert_eq!(text, r#"{"mean_return":null}"#);
/// let back: Point = serde_json::from_str(&text).unwrap();
/// assert!(back.mean_return.is_nan());
/// ```
pub fn f64_or_nan<'de, D: serde::Deserializer<'de>>(d: D) -> Result<f64, D::Error> {
    Ok(Option::<f64>::deserialize(d)?.unwrap_or(f64::NAN))
}

/// [`f64_or_nan`] for every element of a list.
///
/// ```
/// #[derive(serde::Deserialize)]
/// struct Returns {
///     #[serde(deserialize_with = "a2perf_core::results::vec_f64_or_nan")]
///     returns: Vec<f64>,
/// }
/// let r: Returns = serde_json::from_str(r#"{"returns":[1.5,null]}"#).unwrap();
/// assert_eq!(r.returns[0], 1.5);
/// assert!(r.returns[1].is_nan());
/// ```
pub fn vec_f64_or_nan<'de, D: serde::Deserializer<'de>>(d: D) -> Result<Vec<f64>, D::Error> {
    Ok(Vec::<Option<f64>>::deserialize(d)?
        .into_iter()
        .map(|v| v.unwrap_or(f64::NAN))
        .collect())
}

/// State of a run directory.
///
/// ```
/// use a2perf_core::RunState;
/// let s: RunState = serde_json::from_str("\"interrupted\"").unwrap();
/// assert_eq!(s, RunState::Interrupted);
/// assert!(!s.is_complete());
/// ```
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum RunState {
    /// Started and not finished: in progress, or killed (`kill -9`, power loss) while running.
    Running,
    /// Stopped on request (SIGTERM, Ctrl-C) at a safe point; rerunning continues it.
    Interrupted,
    /// Training failed (the note says why); rerunning tries again.
    Failed,
    /// Finished; all results present.
    Complete,
}

impl RunState {
    /// Whether training finished.
    pub fn is_complete(self) -> bool {
        self == RunState::Complete
    }
}

/// Contents of `status.json`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RunStatus {
    /// State.
    pub state: RunState,
    /// Free-form note (e.g. the phase reached).
    #[serde(default)]
    pub note: String,
}

/// One run's directory.
#[derive(Clone, Debug)]
pub struct RunDir {
    path: PathBuf,
}

impl RunDir {
    /// The run directory at `path` (not created yet).
    pub fn new(path: impl Into<PathBuf>) -> Self {
        Self { path: path.into() }
    }

    /// Its path.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// A file inside it.
    pub fn file(&self, name: &str) -> PathBuf {
        self.path.join(name)
    }

    /// Creates the directory and marks it running.
    pub fn begin(&self) -> Result<(), ResultsError> {
        std::fs::create_dir_all(&self.path).map_err(|source| ResultsError::Io {
            path: self.path.clone(),
            source,
        })?;
        self.set_status(RunState::Running, "")
    }

    /// Writes `status.json`.
    pub fn set_status(&self, state: RunState, note: &str) -> Result<(), ResultsError> {
        write_json_atomic(
            &self.file("status.json"),
            &RunStatus {
                state,
                note: note.into(),
            },
        )
    }

    /// The recorded status; `None` when the run never started.
    pub fn status(&self) -> Result<Option<RunStatus>, ResultsError> {
        let p = self.file("status.json");
        if !p.exists() {
            return Ok(None);
        }
        read_json(&p).map(Some)
    }

    /// Whether the run completed (so a rerun skips it).
    pub fn is_complete(&self) -> Result<bool, ResultsError> {
        Ok(self
            .status()?
            .is_some_and(|s| s.state == RunState::Complete))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_failed_piecewise_write_keeps_the_old_file_and_leaves_no_temporary() {
        let tmp = tempfile::tempdir().unwrap();
        let p = tmp.path().join("state.bin");
        write_atomic(&p, b"old").unwrap();
        let err = write_atomic_with(&p, |f| {
            f.write_all(b"half of the new")?;
            Err::<(), _>(std::io::Error::other("disk full"))
        })
        .unwrap_err();
        assert_eq!(err.to_string(), "disk full");
        assert_eq!(std::fs::read(&p).unwrap(), b"old");
        assert_eq!(std::fs::read_dir(tmp.path()).unwrap().count(), 1);
        assert_eq!(
            write_atomic_with(&p, |f| f.write_all(b"new").map(|()| 3)).unwrap(),
            3
        );
        assert_eq!(std::fs::read(&p).unwrap(), b"new");
    }

    #[test]
    fn run_dir_records_completion() {
        let tmp = tempfile::tempdir().unwrap();
        let run = RunDir::new(tmp.path().join("run"));
        assert!(!run.is_complete().unwrap());
        run.begin().unwrap();
        assert_eq!(run.status().unwrap().unwrap().state, RunState::Running);
        assert!(!run.is_complete().unwrap());
        run.set_status(RunState::Complete, "done").unwrap();
        assert!(run.is_complete().unwrap());
    }

    #[test]
    fn old_status_files_still_read() {
        let tmp = tempfile::tempdir().unwrap();
        let run = RunDir::new(tmp.path());
        std::fs::write(run.file("status.json"), br#"{"state": "running"}"#).unwrap();
        assert_eq!(run.status().unwrap().unwrap().state, RunState::Running);
        for state in [RunState::Interrupted, RunState::Failed] {
            run.set_status(state, "why").unwrap();
            let back = run.status().unwrap().unwrap();
            assert_eq!((back.state, back.note.as_str()), (state, "why"));
            assert!(!run.is_complete().unwrap());
        }
    }

    #[test]
    fn corrupt_status_is_an_error_naming_the_file() {
        let tmp = tempfile::tempdir().unwrap();
        let run = RunDir::new(tmp.path());
        std::fs::write(run.file("status.json"), b"{not json").unwrap();
        let err = run.status().unwrap_err().to_string();
        assert!(err.contains("status.json"), "{err}");
    }

    #[test]
    fn atomic_write_replaces_and_leaves_no_temp_files() {
        let tmp = tempfile::tempdir().unwrap();
        let p = tmp.path().join("a.txt");
        write_atomic(&p, b"one").unwrap();
        write_atomic(&p, b"two").unwrap();
        assert_eq!(std::fs::read(&p).unwrap(), b"two");
        assert_eq!(std::fs::read_dir(tmp.path()).unwrap().count(), 1);
    }
}
