//! Resumable training: resume points and the directory that keeps the newest of them.
//!
//! A [`ResumePoint`] is everything needed to continue a training run exactly: the context's part
//! ([`TrainingProgress`]: steps, the curve so far, when the next evaluation and checkpoint are
//! due, the wall clock) and the algorithm's own state, an opaque byte string that the algorithm
//! wrote and reads back through
//! [`TrainingContext::take_resume_state`](crate::TrainingContext::take_resume_state).
//!
//! On disk a resume point is a [`Checkpoint`] container (magic, versions, length, FNV-1a
//! checksum), so a torn or corrupted file is rejected before anything decodes it. Its payload,
//! little-endian:
//!
//! | bytes | content |
//! |---|---|
//! | 8 | magic `A2RESUME` |
//! | 4 | `u32` format version ([`RESUME_FORMAT_VERSION`]) |
//! | 8 × 3 | `u64` environment steps, next evaluation, next checkpoint |
//! | 1 + 8 | last checkpoint step (flag, `u64`) |
//! | 8 | wall clock in seconds, `f64` bits |
//! | 4 + 32·*n* | curve: `u32` *n*, then per point `u64` steps and `f64` bits of mean, std, seconds |
//! | 8 + *S* | `u64` *S* and the algorithm's state bytes |
//!
//! Floats are stored as raw bits, so a resumed curve is bit-identical to the one saved.

use std::path::{Path, PathBuf};

use crate::bytes::ByteReader;
use crate::checkpoint::Checkpoint;
use crate::curve::{CurvePoint, LearningCurve};
use crate::error::PolicyError;

/// Version of the resume-point payload written by [`ResumePoint::to_bytes`].
pub const RESUME_FORMAT_VERSION: u32 = 1;
const RESUME_MAGIC: &[u8; 8] = b"A2RESUME";
/// Name in the container's algorithm field, so a resume file is never taken for a policy.
const CONTAINER_NAME: &str = "resume-point";
/// Resume points kept on disk: the newest, and the one before as a fallback if the newest turns
/// out unreadable.
pub const RESUME_POINTS_KEPT: usize = 2;

/// The training context's part of a resume point.
#[derive(Clone, Debug, PartialEq)]
pub struct TrainingProgress {
    /// Environment steps consumed when the point was taken.
    pub env_steps: u64,
    /// The learning curve so far.
    pub curve: LearningCurve,
    /// Step at or after which the next evaluation is due.
    pub next_eval: u64,
    /// Step at or after which the next checkpoint is due.
    pub next_checkpoint: u64,
    /// Step of the last policy checkpoint written, if any.
    pub last_checkpoint: Option<u64>,
    /// Wall-clock seconds of training when the point was taken, counted over every segment
    /// (the curve's clock continues from here when training resumes).
    pub clock_s: f64,
}

/// A resumable checkpoint: where training stood and the algorithm's own state.
///
/// ```
/// use a2perf_core::{LearningCurve, ResumePoint, TrainingProgress};
/// let point = ResumePoint {
///     progress: TrainingProgress {
///         env_steps: 300,
///         curve: LearningCurve::default(),
///         next_eval: 400,
///         next_checkpoint: 600,
///         last_checkpoint: Some(300),
///         clock_s: 1.25,
///     },
///     state: vec![1, 2, 3],
/// };
/// let bytes = point.to_bytes();
/// assert_eq!(ResumePoint::from_bytes(&bytes).unwrap(), point);
/// assert!(ResumePoint::from_bytes(&bytes[..bytes.len() - 1]).is_err()); // torn write
/// ```
#[derive(Clone, Debug, PartialEq)]
pub struct ResumePoint {
    /// The context's progress.
    pub progress: TrainingProgress,
    /// The algorithm's state (its own format).
    pub state: Vec<u8>,
}

impl ResumePoint {
    /// Encodes the resume point in its checksummed container.
    pub fn to_bytes(&self) -> Vec<u8> {
        let mut out = Vec::with_capacity(128 + self.state.len());
        self.write_to(&mut out)
            .unwrap_or_else(|_| unreachable!("writing to a Vec cannot fail"));
        out
    }

    /// Writes [`Self::to_bytes`]'s encoding to `w` without gathering it in memory (the state
    /// can be hundreds of MB: a replay buffer); returns the bytes written.
    pub fn write_to(&self, w: &mut impl std::io::Write) -> std::io::Result<u64> {
        let p = &self.progress;
        let mut head = Vec::with_capacity(64 + 32 * p.curve.points.len());
        head.extend_from_slice(RESUME_MAGIC);
        head.extend_from_slice(&RESUME_FORMAT_VERSION.to_le_bytes());
        for v in [p.env_steps, p.next_eval, p.next_checkpoint] {
            head.extend_from_slice(&v.to_le_bytes());
        }
        head.push(u8::from(p.last_checkpoint.is_some()));
        head.extend_from_slice(&p.last_checkpoint.unwrap_or(0).to_le_bytes());
        head.extend_from_slice(&p.clock_s.to_bits().to_le_bytes());
        head.extend_from_slice(&(p.curve.points.len() as u32).to_le_bytes());
        for c in &p.curve.points {
            head.extend_from_slice(&c.env_steps.to_le_bytes());
            for f in [c.mean_return, c.std_return, c.wall_seconds] {
                head.extend_from_slice(&f.to_bits().to_le_bytes());
            }
        }
        head.extend_from_slice(&(self.state.len() as u64).to_le_bytes());
        crate::checkpoint::write_container(
            w,
            CONTAINER_NAME,
            RESUME_FORMAT_VERSION,
            &[&head, &self.state],
        )
    }

    /// Decodes and verifies a resume point (checksum, versions, every length).
    pub fn from_bytes(bytes: &[u8]) -> Result<Self, PolicyError> {
        let ckpt = Checkpoint::from_bytes(bytes)?;
        let bad = |m: String| PolicyError::BadCheckpoint(m);
        if ckpt.algorithm != CONTAINER_NAME {
            return Err(bad(format!(
                "not a resume point (the container holds `{}`)",
                ckpt.algorithm
            )));
        }
        if ckpt.format_version != RESUME_FORMAT_VERSION {
            return Err(bad(format!(
                "resume format version {} is not supported (this build reads {RESUME_FORMAT_VERSION})",
                ckpt.format_version
            )));
        }
        let mut r = ByteReader::new(&ckpt.payload);
        if r.take(8)? != RESUME_MAGIC {
            return Err(bad("not a resume point (bad magic bytes)".into()));
        }
        let version = r.u32()?;
        if version != RESUME_FORMAT_VERSION {
            return Err(bad(format!(
                "resume payload version {version} is not supported"
            )));
        }
        let env_steps = r.u64()?;
        let next_eval = r.u64()?;
        let next_checkpoint = r.u64()?;
        let has_last = r.u8()? != 0;
        let last = r.u64()?;
        let clock_s = r.f64()?;
        let n = r.u32()? as usize;
        if n > r.remaining() / 32 {
            return Err(bad("curve length exceeds the payload".into()));
        }
        let mut points = Vec::with_capacity(n);
        for _ in 0..n {
            points.push(CurvePoint {
                env_steps: r.u64()?,
                mean_return: r.f64()?,
                std_return: r.f64()?,
                wall_seconds: r.f64()?,
            });
        }
        let len = usize::try_from(r.u64()?).map_err(|_| bad("state length overflows".into()))?;
        let state = r.take(len)?.to_vec();
        if r.remaining() != 0 {
            return Err(bad("trailing bytes after the state".into()));
        }
        Ok(Self {
            progress: TrainingProgress {
                env_steps,
                curve: LearningCurve { points },
                next_eval,
                next_checkpoint,
                last_checkpoint: has_last.then_some(last),
                clock_s,
            },
            state,
        })
    }
}

/// How long writing one resume point took and how big it was.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ResumeWrite {
    /// Environment steps of the point.
    pub env_steps: u64,
    /// Size of the file in bytes.
    pub bytes: u64,
    /// Seconds from asking the algorithm for its state to the file being on disk (encoding,
    /// checksum, write, fsync, rename).
    pub seconds: f64,
}

/// The newest valid resume point of a directory, and what was wrong with newer ones.
#[derive(Debug, Default)]
pub struct NewestResume {
    /// The point and its file, if any file was valid.
    pub point: Option<(PathBuf, ResumePoint)>,
    /// One message per unreadable file that was skipped (the file is renamed `*.corrupt`).
    pub warnings: Vec<String>,
}

/// A directory of resume points, `step_<steps, 12 digits>.resume`, of which only the newest
/// [`RESUME_POINTS_KEPT`] are kept.
///
/// ```
/// use a2perf_core::{LearningCurve, ResumeDir, ResumePoint, TrainingProgress};
/// let tmp = std::env::temp_dir().join(format!("a2perf-resume-doc-{}", std::process::id()));
/// let dir = ResumeDir::new(&tmp);
/// for steps in [100, 200, 300] {
///     let progress = TrainingProgress {
///         env_steps: steps,
///         curve: LearningCurve::default(),
///         next_eval: steps,
///         next_checkpoint: steps + 100,
///         last_checkpoint: Some(steps),
///         clock_s: 0.0,
///     };
///     dir.save(&ResumePoint { progress, state: vec![steps as u8] }).unwrap();
/// }
/// let steps: Vec<u64> = dir.list().unwrap().iter().map(|(s, _)| *s).collect();
/// assert_eq!(steps, vec![200, 300]); // the oldest was pruned
/// // The newest is torn: the previous one is used, with a warning.
/// std::fs::write(dir.path_for(300), b"A2PERFCK\x01").unwrap();
/// let newest = dir.newest_valid().unwrap();
/// assert_eq!(newest.point.unwrap().1.progress.env_steps, 200);
/// assert!(newest.warnings[0].contains("step_000000000300.resume"));
/// # std::fs::remove_dir_all(&tmp).unwrap();
/// ```
#[derive(Clone, Debug)]
pub struct ResumeDir {
    dir: PathBuf,
}

impl ResumeDir {
    /// Resume points in `dir` (created on the first save).
    pub fn new(dir: impl Into<PathBuf>) -> Self {
        Self { dir: dir.into() }
    }

    /// The directory.
    pub fn path(&self) -> &Path {
        &self.dir
    }

    /// The file of the point at `env_steps`.
    pub fn path_for(&self, env_steps: u64) -> PathBuf {
        self.dir.join(format!("step_{env_steps:012}.resume"))
    }

    /// Writes `point` atomically and removes all but the newest [`RESUME_POINTS_KEPT`] points.
    /// Returns the size of the file written.
    pub fn save(&self, point: &ResumePoint) -> std::io::Result<u64> {
        std::fs::create_dir_all(&self.dir)?;
        // Written to the file piece by piece (three writes): the encoding is not gathered in
        // memory beside the state.
        let written =
            crate::results::write_atomic_with(&self.path_for(point.progress.env_steps), |f| {
                point.write_to(f)
            })?;
        let all = self.list()?;
        let excess = all.len().saturating_sub(RESUME_POINTS_KEPT);
        for (_, old) in &all[..excess] {
            std::fs::remove_file(old)?;
        }
        Ok(written)
    }

    /// The resume points on disk, oldest first.
    pub fn list(&self) -> std::io::Result<Vec<(u64, PathBuf)>> {
        let mut out = Vec::new();
        if !self.dir.is_dir() {
            return Ok(out);
        }
        for e in std::fs::read_dir(&self.dir)? {
            let p = e?.path();
            let step = p
                .file_name()
                .and_then(|n| n.to_str())
                .and_then(|n| n.strip_prefix("step_"))
                .and_then(|n| n.strip_suffix(".resume"))
                .and_then(|n| n.parse::<u64>().ok());
            if let Some(step) = step {
                out.push((step, p));
            }
        }
        out.sort();
        Ok(out)
    }

    /// The newest point that decodes, newest first. Unreadable files (torn, corrupt, from
    /// another format version) are renamed `*.corrupt`, so that they are neither retried nor
    /// pruned as if valid, and reported in [`NewestResume::warnings`]; leftover temporary files
    /// of an interrupted write are removed.
    pub fn newest_valid(&self) -> std::io::Result<NewestResume> {
        let mut found = NewestResume::default();
        if !self.dir.is_dir() {
            return Ok(found);
        }
        for e in std::fs::read_dir(&self.dir)? {
            let p = e?.path();
            let is_tmp = p
                .file_name()
                .and_then(|n| n.to_str())
                .is_some_and(|n| n.starts_with('.') && n.contains(".tmp-"));
            if is_tmp {
                std::fs::remove_file(&p)?;
            }
        }
        for (step, path) in self.list()?.into_iter().rev() {
            let decoded = std::fs::read(&path)
                .map_err(|e| PolicyError::BadCheckpoint(e.to_string()))
                .and_then(|b| ResumePoint::from_bytes(&b));
            match decoded {
                Ok(point) if point.progress.env_steps == step => {
                    found.point = Some((path, point));
                    break;
                }
                Ok(point) => found.warnings.push(format!(
                    "{}: holds step {} but is named for step {step}; skipped",
                    path.display(),
                    point.progress.env_steps
                )),
                Err(e) => {
                    let mut corrupt = path.clone().into_os_string();
                    corrupt.push(".corrupt");
                    std::fs::rename(&path, &corrupt)?;
                    found.warnings.push(format!(
                        "{}: {e}; skipped (kept as {})",
                        path.display(),
                        Path::new(&corrupt).display()
                    ));
                }
            }
        }
        if found.point.is_some() && !found.warnings.is_empty() {
            let step = found
                .point
                .as_ref()
                .map_or(0, |(_, p)| p.progress.env_steps);
            found
                .warnings
                .push(format!("fell back to the resume point at step {step}"));
        }
        Ok(found)
    }

    /// Removes every resume point (the directory itself included).
    pub fn clear(&self) -> std::io::Result<()> {
        match std::fs::remove_dir_all(&self.dir) {
            Err(e) if e.kind() != std::io::ErrorKind::NotFound => Err(e),
            _ => Ok(()),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn point(steps: u64, state: Vec<u8>) -> ResumePoint {
        ResumePoint {
            progress: TrainingProgress {
                env_steps: steps,
                curve: LearningCurve {
                    points: vec![CurvePoint {
                        env_steps: steps,
                        mean_return: 0.1 + 0.2,
                        std_return: f64::MIN_POSITIVE,
                        wall_seconds: 1e-300,
                    }],
                },
                next_eval: steps + 1,
                next_checkpoint: steps + 2,
                last_checkpoint: None,
                clock_s: 3.5,
            },
            state,
        }
    }

    #[test]
    fn round_trip_is_bit_exact_and_every_flipped_byte_is_caught() {
        let p = point(42, (0..200u8).collect());
        let bytes = p.to_bytes();
        let back = ResumePoint::from_bytes(&bytes).unwrap();
        assert_eq!(back, p);
        assert_eq!(
            back.progress.curve.points[0].mean_return.to_bits(),
            (0.1f64 + 0.2).to_bits()
        );
        for i in 0..bytes.len() {
            let mut b = bytes.clone();
            b[i] ^= 0x10;
            assert!(ResumePoint::from_bytes(&b).is_err(), "flip at byte {i}");
        }
        for n in 0..bytes.len() {
            assert!(ResumePoint::from_bytes(&bytes[..n]).is_err(), "cut at {n}");
        }
    }

    #[test]
    fn a_saved_point_is_its_encoding_written_piece_by_piece() {
        let tmp = tempfile::tempdir().unwrap();
        let dir = ResumeDir::new(tmp.path().join("resume"));
        // A state larger than any write buffer, with a pattern that catches misplaced pieces.
        let p = point(7, (0..3_000_000u32).map(|i| (i % 251) as u8).collect());
        let written = dir.save(&p).unwrap();
        let on_disk = std::fs::read(dir.path_for(7)).unwrap();
        assert_eq!(written, on_disk.len() as u64);
        assert!(on_disk == p.to_bytes(), "the file differs from to_bytes()");
        assert_eq!(ResumePoint::from_bytes(&on_disk).unwrap(), p);
        // No temporary file is left beside it.
        let names: Vec<_> = std::fs::read_dir(dir.path())
            .unwrap()
            .map(|e| e.unwrap().file_name())
            .collect();
        assert_eq!(
            names,
            [std::ffi::OsString::from("step_000000000007.resume")]
        );
    }

    #[test]
    fn a_policy_checkpoint_is_not_a_resume_point() {
        let c = Checkpoint {
            algorithm: "ppo".into(),
            format_version: 1,
            payload: vec![0; 8],
        };
        let err = ResumePoint::from_bytes(&c.to_bytes())
            .unwrap_err()
            .to_string();
        assert!(err.contains("not a resume point"), "{err}");
    }

    #[test]
    fn corrupt_points_fall_back_then_run_out() {
        let tmp = tempfile::tempdir().unwrap();
        let dir = ResumeDir::new(tmp.path().join("resume"));
        assert!(dir.newest_valid().unwrap().point.is_none());
        dir.save(&point(10, vec![1])).unwrap();
        dir.save(&point(20, vec![2])).unwrap();
        // A temporary file left by a write that was killed.
        std::fs::write(
            tmp.path().join("resume/.step_000000000030.resume.tmp-9"),
            b"x",
        )
        .unwrap();
        let mut bytes = std::fs::read(dir.path_for(20)).unwrap();
        let last = bytes.len() - 1;
        bytes[last] ^= 1;
        std::fs::write(dir.path_for(20), &bytes).unwrap();
        let found = dir.newest_valid().unwrap();
        let (path, p) = found.point.unwrap();
        assert_eq!((path, p.state), (dir.path_for(10), vec![1]));
        assert!(
            found.warnings[0].contains("checksum"),
            "{:?}",
            found.warnings
        );
        assert!(
            found.warnings[1].contains("fell back"),
            "{:?}",
            found.warnings
        );
        assert!(
            tmp.path()
                .join("resume/step_000000000020.resume.corrupt")
                .is_file()
        );
        assert!(
            !tmp.path()
                .join("resume/.step_000000000030.resume.tmp-9")
                .exists()
        );
        // The renamed file is not listed again; the next save prunes normally.
        assert_eq!(dir.list().unwrap().len(), 1);
        std::fs::write(dir.path_for(10), b"garbage").unwrap();
        let found = dir.newest_valid().unwrap();
        assert!(found.point.is_none());
        assert_eq!(found.warnings.len(), 1);
    }
}
