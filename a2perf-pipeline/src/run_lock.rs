//! One trainer per run directory.
//!
//! Whatever trains a run — `a2perf train`, `a2perf run`, a Python `TrainingRun` — first takes an
//! exclusive advisory lock (`flock`) on the run's [`TRAIN_LOCK_FILE`], and keeps it until it
//! stops. A second trainer of the same directory, in this process or another one on a machine
//! sharing the file system's locks, does not wait: it gets [`PipelineError::Locked`] naming the
//! holder's pid and host, which the trainer writes into the file once it holds the lock.
//!
//! The kernel releases the lock when the process ends, however it ends (`kill -9` included), so
//! a lock file left behind never blocks anyone: only the lock means something, the file's
//! contents are for messages.
//!
//! ```
//! use a2perf_pipeline::{PipelineError, run_lock::TrainingLock};
//! let dir = tempfile::tempdir().unwrap();
//! let first = TrainingLock::acquire(dir.path()).unwrap();
//! match TrainingLock::acquire(dir.path()) {
//!     Err(PipelineError::Locked(runs)) => {
//!         assert_eq!(runs[0].holder.as_ref().map(|h| h.pid), Some(std::process::id()));
//!     }
//!     other => panic!("expected the lock to be held, got {other:?}"),
//! }
//! drop(first);
//! assert!(TrainingLock::acquire(dir.path()).is_ok());
//! ```

use std::fs::{File, OpenOptions, TryLockError};
use std::io::{Read, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use crate::error::{PipelineError, Result, io_err};

// The lock's vocabulary is on the ground floor, since errors carry it.
pub use crate::error::{LockHolder, LockedRun, TRAIN_LOCK_FILE};

/// The exclusive training lock of one run directory, held until dropped (or the process ends).
#[derive(Debug)]
pub struct TrainingLock {
    file: File,
    path: PathBuf,
}

impl TrainingLock {
    /// Takes the training lock of the run directory `dir` (creating the directory when it does
    /// not exist) and records this process in it. When another trainer holds it, returns
    /// [`PipelineError::Locked`] at once, with the holder it recorded.
    pub fn acquire(dir: &Path) -> Result<Self> {
        std::fs::create_dir_all(dir).map_err(io_err(dir))?;
        let path = dir.join(TRAIN_LOCK_FILE);
        // Never truncated on open: the holder's record must survive a rival's attempt.
        let mut file = OpenOptions::new()
            .read(true)
            .write(true)
            .create(true)
            .truncate(false)
            .open(&path)
            .map_err(io_err(&path))?;
        // A lock held with no holder recorded is either a trainer that has just taken it or one
        // that has just released it while a child process forked by another thread of the
        // releasing process still shares the file (until that child's exec closes it): both
        // resolve within moments, so such a lock is tried again for a while before giving up.
        let deadline = Instant::now() + Duration::from_secs(2);
        loop {
            match file.try_lock() {
                Ok(()) => break,
                Err(TryLockError::WouldBlock) => {
                    let holder = read_holder(&mut file);
                    if holder.is_some() || Instant::now() >= deadline {
                        return Err(PipelineError::Locked(vec![LockedRun {
                            run: dir.to_path_buf(),
                            holder,
                        }]));
                    }
                }
                Err(TryLockError::Error(source)) => {
                    return Err(PipelineError::Io { path, source });
                }
            }
        }
        // Written in place, never replaced by a rename: the lock belongs to this inode.
        let record =
            serde_json::to_vec(&LockHolder::current()).map_err(|e| PipelineError::Corrupt {
                path: path.clone(),
                reason: e.to_string(),
            })?;
        file.set_len(0)
            .and_then(|()| file.seek(SeekFrom::Start(0)))
            .and_then(|_| file.write_all(&record))
            .and_then(|()| file.flush())
            .map_err(io_err(&path))?;
        Ok(Self { file, path })
    }

    /// The lock file.
    pub fn path(&self) -> &Path {
        &self.path
    }
}

impl Drop for TrainingLock {
    fn drop(&mut self) {
        // An emptied file tells a reader that nobody trains the run now; the lock itself is
        // released when the file is closed, right after.
        let _ = self.file.set_len(0);
    }
}

/// The holder's record. A holder that has just taken the lock may not have written it yet, so
/// an empty or partial record is read again for a moment before giving up.
fn read_holder(file: &mut File) -> Option<LockHolder> {
    let deadline = Instant::now() + Duration::from_millis(200);
    loop {
        let mut text = String::new();
        let parsed = file
            .seek(SeekFrom::Start(0))
            .and_then(|_| file.read_to_string(&mut text))
            .ok()
            .and_then(|_| serde_json::from_str::<LockHolder>(&text).ok());
        if parsed.is_some() || Instant::now() >= deadline {
            return parsed;
        }
        std::thread::sleep(Duration::from_millis(20));
    }
}
