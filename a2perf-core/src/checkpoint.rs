//! Checkpoints: serialised policies and the self-checking container they (and resume points)
//! are stored in.
//!
//! The container, little-endian:
//!
//! | bytes | content |
//! |---|---|
//! | 8 | magic `A2PERFCK` |
//! | 4 | `u32` container version (1) |
//! | 4 + *n* | `u32` *n* and the algorithm's name, UTF-8 |
//! | 4 | `u32` payload format version (the algorithm's) |
//! | 8 | `u64` payload length *P* |
//! | 8 | `u64` FNV-1a checksum of the payload |
//! | *P* | the payload |

use crate::error::PolicyError;
use crate::hash::Fnv1a;

/// A serialised policy: which algorithm made it, its payload format version and the bytes.
///
/// On disk a checkpoint is a small self-checking container (magic, versions, length, checksum), so
/// truncated or corrupted files are rejected with a clear error before any algorithm decodes them.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Checkpoint {
    /// Registered algorithm name, used to find the loader.
    pub algorithm: String,
    /// Version of the algorithm's payload format.
    pub format_version: u32,
    /// Algorithm-specific bytes.
    pub payload: Vec<u8>,
}

const CHECKPOINT_MAGIC: &[u8; 8] = b"A2PERFCK";
const CONTAINER_VERSION: u32 = 1;

fn fnv1a64(parts: &[&[u8]]) -> u64 {
    let mut h = Fnv1a::new();
    for p in parts {
        h.write(p);
    }
    h.finish()
}

/// The checkpoint container around a payload given in parts (concatenated), so that large
/// payloads are copied once.
pub(crate) fn encode_container(algorithm: &str, format_version: u32, parts: &[&[u8]]) -> Vec<u8> {
    let len: usize = parts.iter().map(|p| p.len()).sum();
    let mut out = Vec::with_capacity(40 + algorithm.len() + len);
    write_container(&mut out, algorithm, format_version, parts)
        .unwrap_or_else(|_| unreachable!("writing to a Vec cannot fail"));
    out
}

/// Writes the container of `parts` (their concatenation is the payload) to `w` without
/// gathering the payload in one buffer; returns the bytes written.
pub(crate) fn write_container(
    w: &mut impl std::io::Write,
    algorithm: &str,
    format_version: u32,
    parts: &[&[u8]],
) -> std::io::Result<u64> {
    let name = algorithm.as_bytes();
    let len: usize = parts.iter().map(|p| p.len()).sum();
    let mut head = Vec::with_capacity(40 + name.len());
    head.extend_from_slice(CHECKPOINT_MAGIC);
    head.extend_from_slice(&CONTAINER_VERSION.to_le_bytes());
    head.extend_from_slice(&(name.len() as u32).to_le_bytes());
    head.extend_from_slice(name);
    head.extend_from_slice(&format_version.to_le_bytes());
    head.extend_from_slice(&(len as u64).to_le_bytes());
    head.extend_from_slice(&fnv1a64(parts).to_le_bytes());
    w.write_all(&head)?;
    for p in parts {
        w.write_all(p)?;
    }
    Ok((head.len() + len) as u64)
}

impl Checkpoint {
    /// Encodes the checkpoint container.
    ///
    /// ```
    /// use a2perf_core::Checkpoint;
    /// let c = Checkpoint { algorithm: "ppo".into(), format_version: 2, payload: vec![1, 2, 3] };
    /// assert_eq!(Checkpoint::from_bytes(&c.to_bytes()).unwrap(), c);
    /// let mut bad = c.to_bytes();
    /// let last = bad.len() - 1;
    /// bad[last] ^= 1;
    /// assert!(Checkpoint::from_bytes(&bad).is_err());
    /// ```
    pub fn to_bytes(&self) -> Vec<u8> {
        encode_container(&self.algorithm, self.format_version, &[&self.payload])
    }

    /// Decodes and verifies a checkpoint container.
    pub fn from_bytes(bytes: &[u8]) -> Result<Self, PolicyError> {
        let bad = |m: &str| PolicyError::BadCheckpoint(m.to_string());
        let mut r = crate::bytes::ByteReader::new(bytes);
        if r.take(8)? != CHECKPOINT_MAGIC {
            return Err(bad("not an a2perf checkpoint (bad magic bytes)"));
        }
        let container = r.u32()?;
        if container != CONTAINER_VERSION {
            return Err(PolicyError::BadCheckpoint(format!(
                "container version {container} is not supported (expected {CONTAINER_VERSION})"
            )));
        }
        let name_len = r.u32()?;
        if name_len > 256 {
            return Err(bad("algorithm name is implausibly long"));
        }
        let algorithm = std::str::from_utf8(r.take(name_len as usize)?)
            .map_err(|_| bad("algorithm name is not UTF-8"))?
            .to_string();
        let format_version = r.u32()?;
        let len = r.u64()?;
        let sum = r.u64()?;
        let len = usize::try_from(len).map_err(|_| bad("payload length overflows"))?;
        let payload = r.take(len)?.to_vec();
        if r.remaining() != 0 {
            return Err(bad("trailing bytes after payload"));
        }
        if fnv1a64(&[&payload]) != sum {
            return Err(bad("checksum mismatch: the file is corrupt"));
        }
        Ok(Self {
            algorithm,
            format_version,
            payload,
        })
    }
}
