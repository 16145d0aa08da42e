//! The baselines' resumable training state: a small binary codec in which every float is stored
//! as its raw bits, so a resumed run continues bit-identically.
//!
//! A state starts with the magic `A2ST`, the algorithm's name and its state format version;
//! then each algorithm writes its fields in a fixed order (see `ppo.rs`, `ddqn.rs`, `sac.rs`,
//! `bc.rs`). Every length is checked on reading: a state written by another configuration (other
//! network sizes, another number of environments) is refused with
//! [`RunError::Resume`](a2perf_core::RunError::Resume), never silently misread.

use a2perf_core::bytes::{ByteReader, Truncated};
use a2perf_core::{Action, EpisodeSnapshot, RngState, RngStream, RunError, VecEnv, VecEnvSnapshot};

const MAGIC: &[u8; 4] = b"A2ST";

/// Writes a training state.
pub(crate) struct StateWriter {
    buf: Vec<u8>,
}

impl StateWriter {
    /// A state of `algorithm`, format `version`.
    pub(crate) fn new(algorithm: &str, version: u32) -> Self {
        let mut w = Self { buf: Vec::new() };
        w.buf.extend_from_slice(MAGIC);
        w.str(algorithm);
        w.u32(version);
        w
    }

    pub(crate) fn finish(self) -> Vec<u8> {
        self.buf
    }

    pub(crate) fn u32(&mut self, v: u32) {
        self.buf.extend_from_slice(&v.to_le_bytes());
    }

    pub(crate) fn u64(&mut self, v: u64) {
        self.buf.extend_from_slice(&v.to_le_bytes());
    }

    pub(crate) fn usize(&mut self, v: usize) {
        self.u64(v as u64);
    }

    pub(crate) fn bool(&mut self, v: bool) {
        self.buf.push(u8::from(v));
    }

    pub(crate) fn f32(&mut self, v: f32) {
        self.u32(v.to_bits());
    }

    pub(crate) fn f64(&mut self, v: f64) {
        self.u64(v.to_bits());
    }

    pub(crate) fn str(&mut self, s: &str) {
        self.usize(s.len());
        self.buf.extend_from_slice(s.as_bytes());
    }

    pub(crate) fn f32s(&mut self, v: &[f32]) {
        self.usize(v.len());
        self.buf.reserve(4 * v.len());
        for x in v {
            self.buf.extend_from_slice(&x.to_bits().to_le_bytes());
        }
    }

    pub(crate) fn f64s(&mut self, v: &[f64]) {
        self.usize(v.len());
        for x in v {
            self.f64(*x);
        }
    }

    pub(crate) fn u8s(&mut self, v: &[u8]) {
        self.usize(v.len());
        self.buf.extend_from_slice(v);
    }

    pub(crate) fn u16s(&mut self, v: &[u16]) {
        self.usize(v.len());
        for x in v {
            self.buf.extend_from_slice(&x.to_le_bytes());
        }
    }

    pub(crate) fn u32s(&mut self, v: &[u32]) {
        self.usize(v.len());
        for x in v {
            self.u32(*x);
        }
    }

    pub(crate) fn u64s(&mut self, v: &[u64]) {
        self.usize(v.len());
        for x in v {
            self.u64(*x);
        }
    }

    pub(crate) fn usizes(&mut self, v: &[usize]) {
        self.usize(v.len());
        for x in v {
            self.usize(*x);
        }
    }

    pub(crate) fn bools(&mut self, v: &[bool]) {
        self.usize(v.len());
        self.buf.extend(v.iter().map(|b| u8::from(*b)));
    }

    pub(crate) fn rng(&mut self, r: &RngStream) {
        let s = r.state();
        self.u64(s.seed);
        self.u64(s.key);
        self.u64(s.word_pos[0]);
        self.u64(s.word_pos[1]);
        self.bool(s.spare_normal_bits.is_some());
        self.u64(s.spare_normal_bits.unwrap_or(0));
    }

    /// Every environment's current episode (reset seed number, actions since, running return).
    pub(crate) fn envs(&mut self, venv: &VecEnv) {
        let snap = venv.snapshot();
        self.usize(snap.envs.len());
        for e in &snap.envs {
            self.u64(e.episodes);
            self.u64(e.running_return_bits);
            self.u64(e.observation_hash);
            self.usize(e.actions.len());
            for a in &e.actions {
                match a {
                    Action::Discrete(d) => {
                        self.bool(false);
                        self.usize(*d);
                    }
                    Action::Continuous(v) => {
                        self.bool(true);
                        self.f32s(v);
                    }
                }
            }
        }
    }
}

/// Reads a training state written by [`StateWriter`].
pub(crate) struct StateReader<'a> {
    bytes: ByteReader<'a>,
}

pub(crate) fn resume_err(m: impl Into<String>) -> RunError {
    RunError::Resume(m.into())
}

fn truncated(e: Truncated) -> RunError {
    resume_err(format!("the training state is {e}"))
}

impl<'a> StateReader<'a> {
    /// Checks the magic, the algorithm and the version.
    pub(crate) fn new(bytes: &'a [u8], algorithm: &str, version: u32) -> Result<Self, RunError> {
        let mut r = Self {
            bytes: ByteReader::new(bytes),
        };
        if r.take(4)? != MAGIC {
            return Err(resume_err(
                "the resume state is not an a2perf-baselines training state (bad magic)",
            ));
        }
        let name = r.str()?;
        if name != algorithm {
            return Err(resume_err(format!(
                "the resume state was written by `{name}`, not `{algorithm}`"
            )));
        }
        let v = r.u32()?;
        if v != version {
            // Format 1 predates typed observations: its observation hashes and stored
            // observations were taken over float32 ids.
            let why = if v == 1 {
                " (it was written before integer observations were stored as integers; \
                 start the run again)"
            } else {
                ""
            };
            return Err(resume_err(format!(
                "{algorithm} training state format {v} is not supported (this build reads \
                 {version}){why}"
            )));
        }
        Ok(r)
    }

    /// Fails unless every byte was read.
    pub(crate) fn finish(self) -> Result<(), RunError> {
        if self.bytes.remaining() == 0 {
            Ok(())
        } else {
            Err(resume_err(format!(
                "{} unexpected bytes at the end of the training state",
                self.bytes.remaining()
            )))
        }
    }

    fn take(&mut self, n: usize) -> Result<&'a [u8], RunError> {
        self.bytes.take(n).map_err(truncated)
    }

    pub(crate) fn u32(&mut self) -> Result<u32, RunError> {
        self.bytes.u32().map_err(truncated)
    }

    pub(crate) fn u64(&mut self) -> Result<u64, RunError> {
        self.bytes.u64().map_err(truncated)
    }

    pub(crate) fn usize(&mut self) -> Result<usize, RunError> {
        usize::try_from(self.u64()?).map_err(|_| resume_err("a length overflows"))
    }

    pub(crate) fn bool(&mut self) -> Result<bool, RunError> {
        match self.take(1)?[0] {
            0 => Ok(false),
            1 => Ok(true),
            b => Err(resume_err(format!("invalid flag byte {b}"))),
        }
    }

    pub(crate) fn f32(&mut self) -> Result<f32, RunError> {
        self.bytes.f32().map_err(truncated)
    }

    pub(crate) fn f64(&mut self) -> Result<f64, RunError> {
        self.bytes.f64().map_err(truncated)
    }

    pub(crate) fn str(&mut self) -> Result<String, RunError> {
        let n = self.len_of(1)?;
        String::from_utf8(self.take(n)?.to_vec()).map_err(|_| resume_err("a name is not UTF-8"))
    }

    /// A length prefix, checked against what is left (`width` bytes per element).
    fn len_of(&mut self, width: usize) -> Result<usize, RunError> {
        let n = self.usize()?;
        if n.saturating_mul(width) > self.bytes.remaining() {
            return Err(resume_err("a length exceeds the training state"));
        }
        Ok(n)
    }

    /// A float vector of exactly `out.len()` values, into `out`.
    pub(crate) fn f32s_into(&mut self, what: &str, out: &mut [f32]) -> Result<(), RunError> {
        let n = self.len_of(4)?;
        if n != out.len() {
            return Err(resume_err(format!(
                "{what}: {n} values saved, this configuration has {}",
                out.len()
            )));
        }
        for (o, c) in out.iter_mut().zip(self.take(4 * n)?.chunks_exact(4)) {
            *o = f32::from_bits(u32::from_le_bytes([c[0], c[1], c[2], c[3]]));
        }
        Ok(())
    }

    pub(crate) fn f32s(&mut self) -> Result<Vec<f32>, RunError> {
        let n = self.len_of(4)?;
        Ok(self
            .take(4 * n)?
            .chunks_exact(4)
            .map(|c| f32::from_bits(u32::from_le_bytes([c[0], c[1], c[2], c[3]])))
            .collect())
    }

    /// A `f64` vector of exactly `out.len()` values, into `out`.
    pub(crate) fn f64s_into(&mut self, what: &str, out: &mut [f64]) -> Result<(), RunError> {
        let n = self.len_of(8)?;
        if n != out.len() {
            return Err(resume_err(format!(
                "{what}: {n} values saved, this configuration has {}",
                out.len()
            )));
        }
        for o in out.iter_mut() {
            *o = self.f64()?;
        }
        Ok(())
    }

    pub(crate) fn u8s(&mut self) -> Result<Vec<u8>, RunError> {
        let n = self.len_of(1)?;
        Ok(self.take(n)?.to_vec())
    }

    pub(crate) fn u16s(&mut self) -> Result<Vec<u16>, RunError> {
        let n = self.len_of(2)?;
        Ok(self
            .take(2 * n)?
            .chunks_exact(2)
            .map(|c| u16::from_le_bytes([c[0], c[1]]))
            .collect())
    }

    pub(crate) fn u32s(&mut self) -> Result<Vec<u32>, RunError> {
        let n = self.len_of(4)?;
        (0..n).map(|_| self.u32()).collect()
    }

    pub(crate) fn u64s(&mut self) -> Result<Vec<u64>, RunError> {
        let n = self.len_of(8)?;
        (0..n).map(|_| self.u64()).collect()
    }

    pub(crate) fn usizes(&mut self) -> Result<Vec<usize>, RunError> {
        let n = self.len_of(8)?;
        (0..n).map(|_| self.usize()).collect()
    }

    pub(crate) fn bools(&mut self) -> Result<Vec<bool>, RunError> {
        let n = self.len_of(1)?;
        (0..n).map(|_| self.bool()).collect()
    }

    pub(crate) fn rng(&mut self) -> Result<RngStream, RunError> {
        let seed = self.u64()?;
        let key = self.u64()?;
        let word_pos = [self.u64()?, self.u64()?];
        let has_spare = self.bool()?;
        let spare = self.u64()?;
        Ok(RngStream::from_state(&RngState {
            seed,
            key,
            word_pos,
            spare_normal_bits: has_spare.then_some(spare),
        }))
    }

    /// Restores `venv` to the saved episodes (replaying their actions) and returns the current
    /// observations; environments that did not replay exactly are reported through `warn`.
    pub(crate) fn envs<'v>(
        &mut self,
        venv: &'v mut VecEnv,
        warn: &mut dyn FnMut(String),
    ) -> Result<&'v [a2perf_core::VecStep], RunError> {
        let n = self.len_of(25)?;
        let mut snap = VecEnvSnapshot {
            envs: Vec::with_capacity(n),
        };
        for _ in 0..n {
            let episodes = self.u64()?;
            let running_return_bits = self.u64()?;
            let observation_hash = self.u64()?;
            let k = self.len_of(1)?;
            let mut actions = Vec::with_capacity(k);
            for _ in 0..k {
                actions.push(if self.bool()? {
                    Action::Continuous(self.f32s()?)
                } else {
                    Action::Discrete(self.usize()?)
                });
            }
            snap.envs.push(EpisodeSnapshot {
                episodes,
                actions,
                running_return_bits,
                observation_hash,
            });
        }
        let (outs, restarted) = venv
            .restore(&snap)
            .map_err(|e| resume_err(format!("restoring the environments: {e}")))?;
        if !restarted.is_empty() {
            warn(format!(
                "environments {restarted:?} did not replay their episode exactly (the \
                 environment is not a function of its seed and actions); they started a new \
                 episode, so this resumed run is not bit-identical to an uninterrupted one"
            ));
        }
        Ok(outs)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn values_round_trip_bit_exactly_and_lengths_are_checked() {
        let mut rng = RngStream::new(3, "t");
        rng.normal();
        let mut w = StateWriter::new("ppo", 7);
        w.f32s(&[1.5, -0.0, f32::MIN_POSITIVE]);
        w.f64s(&[0.1 + 0.2]);
        w.rng(&rng);
        w.usizes(&[3, 9]);
        w.bools(&[true, false]);
        let bytes = w.finish();
        let mut r = StateReader::new(&bytes, "ppo", 7).unwrap();
        let mut f = [0.0f32; 3];
        r.f32s_into("params", &mut f).unwrap();
        assert_eq!(f[1].to_bits(), (-0.0f32).to_bits());
        let mut d = [0.0f64; 1];
        r.f64s_into("stats", &mut d).unwrap();
        assert_eq!(d[0].to_bits(), (0.1f64 + 0.2).to_bits());
        let mut back = r.rng().unwrap();
        assert_eq!(back.normal().to_bits(), rng.normal().to_bits());
        assert_eq!(r.usizes().unwrap(), vec![3, 9]);
        assert_eq!(r.bools().unwrap(), vec![true, false]);
        r.finish().unwrap();

        let mut r = StateReader::new(&bytes, "ppo", 7).unwrap();
        let err = r
            .f32s_into("params", &mut [0.0; 4])
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("params: 3 values saved, this configuration has 4"),
            "{err}"
        );
        let err = StateReader::new(&bytes, "sac", 7)
            .err()
            .unwrap()
            .to_string();
        assert!(err.contains("written by `ppo`"), "{err}");
        let err = StateReader::new(&bytes, "ppo", 8)
            .err()
            .unwrap()
            .to_string();
        assert!(err.contains("format 7"), "{err}");
        let mut r = StateReader::new(&bytes[..bytes.len() - 3], "ppo", 7).unwrap();
        r.f32s_into("params", &mut f).unwrap();
        r.f64s_into("stats", &mut d).unwrap();
        assert!(r.rng().is_ok());
        assert!(r.usizes().is_ok());
        assert!(r.bools().is_err(), "truncated");
    }
}
