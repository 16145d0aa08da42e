//! The bundle container: a gzip-compressed tar whose first member, `manifest.json`, lists every
//! other member with its size and SHA-256.
//!
//! A bundle comes from someone else, so reading one trusts nothing: the whole archive is read
//! into memory (nothing is ever written to disk while reading), every member must be a regular
//! file with a plain relative path, the declared size of a member and the decompressed size of
//! the whole archive are capped before any byte is kept, and the manifest must name exactly the
//! members present with their exact sizes and hashes. Writing is deterministic: the same members
//! give the same bytes (zero times, owners and modes; gzip without a timestamp).
//!
//! ```
//! use a2perf_pipeline::bundle::{Archive, ArchiveLimits};
//! let mut a = Archive::default();
//! a.insert("run/run.json", b"{}".to_vec()).unwrap();
//! let bytes = a.to_bytes().unwrap();
//! let back = Archive::from_bytes(&bytes, "x.a2perf", &ArchiveLimits::default()).unwrap();
//! assert_eq!(back.get("run/run.json"), Some(&b"{}"[..]));
//! ```

use std::collections::BTreeMap;
use std::io::{Read, Write};
use std::path::{Component, Path, PathBuf};

use serde::{Deserialize, Serialize};
use sha2::{Digest, Sha256};

/// The manifest's member name; always the archive's first member.
pub const MANIFEST: &str = "manifest.json";
/// The `format` field of every manifest.
pub const FORMAT: &str = "a2perf-bundle";
/// The manifest version this code writes and reads.
pub const FORMAT_VERSION: u32 = 1;

/// Why a bundle could not be written or read. Every variant names the bundle file.
#[derive(Debug, thiserror::Error)]
pub enum ArchiveError {
    /// Reading or writing the file failed.
    #[error("{}: {source}", path.display())]
    Io {
        /// The bundle.
        path: PathBuf,
        /// The error.
        source: std::io::Error,
    },
    /// The bytes are not a complete gzip-compressed tar (truncated, corrupted or another format).
    #[error("{}: not a readable bundle archive: {reason}", path.display())]
    Malformed {
        /// The bundle.
        path: PathBuf,
        /// What the decoder said.
        reason: String,
    },
    /// A member that a bundle may not hold: a link, a device, a directory entry, a path that is
    /// absolute, has `..` or is not UTF-8, or a name given twice.
    #[error("{}: member {member:?} refused: {reason}", path.display())]
    UnsafeMember {
        /// The bundle.
        path: PathBuf,
        /// The member's name as the archive gives it.
        member: String,
        /// Why it is refused.
        reason: String,
    },
    /// A member, or the archive decompressed, is larger than the limit.
    #[error("{}: {what} exceeds the limit of {limit} bytes", path.display())]
    TooLarge {
        /// The bundle.
        path: PathBuf,
        /// The member or "the decompressed archive".
        what: String,
        /// The limit in force.
        limit: u64,
    },
    /// The manifest is missing, unreadable, or disagrees with the members.
    #[error("{}: manifest: {reason}", path.display())]
    Manifest {
        /// The bundle.
        path: PathBuf,
        /// What disagrees.
        reason: String,
    },
    /// A member name given to the writer that a reader would refuse.
    #[error("member {member:?} cannot be stored: {reason}")]
    BadName {
        /// The name.
        member: String,
        /// Why.
        reason: String,
    },
}

/// Caps applied while reading a bundle, before any byte of a member is kept.
#[derive(Clone, Debug)]
pub struct ArchiveLimits {
    /// Largest member (declared size in its tar header).
    pub max_member_bytes: u64,
    /// Largest decompressed archive (tar stream) in total.
    pub max_total_bytes: u64,
    /// Most members.
    pub max_members: usize,
}

impl Default for ArchiveLimits {
    /// 256 MiB per member, 1 GiB decompressed, 100,000 members: a paper-suite run with its
    /// recorded actions is a few MB.
    fn default() -> Self {
        Self {
            max_member_bytes: 256 << 20,
            max_total_bytes: 1 << 30,
            max_members: 100_000,
        }
    }
}

/// One member as the manifest lists it.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct ManifestEntry {
    /// Relative path inside the bundle (`/`-separated).
    pub path: String,
    /// Size in bytes.
    pub size: u64,
    /// SHA-256 of the bytes, lowercase hex.
    pub sha256: String,
}

/// `manifest.json`.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct Manifest {
    /// Always [`FORMAT`].
    pub format: String,
    /// [`FORMAT_VERSION`].
    pub version: u32,
    /// Every other member, in archive order.
    pub members: Vec<ManifestEntry>,
}

/// The members of a bundle, by path (sorted, so writing is deterministic).
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Archive {
    members: BTreeMap<String, Vec<u8>>,
}

/// SHA-256 of bytes as lowercase hex.
///
/// ```
/// assert_eq!(
///     a2perf_pipeline::bundle::sha256_hex(b"abc"),
///     "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad"
/// );
/// ```
pub fn sha256_hex(bytes: &[u8]) -> String {
    let digest = Sha256::digest(bytes);
    let mut s = String::with_capacity(64);
    for b in digest {
        s.push_str(&format!("{b:02x}"));
    }
    s
}

/// Checks a member name: relative, `/`-separated plain components, no `.`/`..`, no backslash,
/// not the manifest's name.
fn check_name(name: &str) -> Result<(), String> {
    if name.is_empty() {
        return Err("empty path".into());
    }
    if name == MANIFEST {
        return Err("the manifest's own name".into());
    }
    if name.contains('\\') || name.contains('\0') {
        return Err("backslash or NUL in the path".into());
    }
    if name.starts_with('/') {
        return Err("absolute path".into());
    }
    for part in name.split('/') {
        match part {
            "" => return Err("empty path component".into()),
            "." | ".." => return Err(format!("path component {part:?}")),
            _ => {}
        }
    }
    // Belt and braces: the platform's own parser must agree that it is plain and relative.
    if !Path::new(name)
        .components()
        .all(|c| matches!(c, Component::Normal(_)))
    {
        return Err("not a plain relative path".into());
    }
    Ok(())
}

impl Archive {
    /// Adds (or replaces) a member.
    pub fn insert(&mut self, name: &str, bytes: Vec<u8>) -> Result<(), ArchiveError> {
        check_name(name).map_err(|reason| ArchiveError::BadName {
            member: name.to_string(),
            reason,
        })?;
        self.members.insert(name.to_string(), bytes);
        Ok(())
    }

    /// A member's bytes.
    pub fn get(&self, name: &str) -> Option<&[u8]> {
        self.members.get(name).map(Vec::as_slice)
    }

    /// Member names, sorted.
    pub fn names(&self) -> impl Iterator<Item = &str> {
        self.members.keys().map(String::as_str)
    }

    /// Members, sorted by name.
    pub fn iter(&self) -> impl Iterator<Item = (&str, &[u8])> {
        self.members.iter().map(|(k, v)| (k.as_str(), v.as_slice()))
    }

    /// Number of members (the manifest not counted).
    pub fn len(&self) -> usize {
        self.members.len()
    }

    /// Whether there is no member.
    pub fn is_empty(&self) -> bool {
        self.members.is_empty()
    }

    /// The manifest of the current members.
    pub fn manifest(&self) -> Manifest {
        Manifest {
            format: FORMAT.into(),
            version: FORMAT_VERSION,
            members: self
                .members
                .iter()
                .map(|(path, bytes)| ManifestEntry {
                    path: path.clone(),
                    size: bytes.len() as u64,
                    sha256: sha256_hex(bytes),
                })
                .collect(),
        }
    }

    /// The archive's bytes: gzip(tar(manifest, members…)), deterministic.
    pub fn to_bytes(&self) -> Result<Vec<u8>, ArchiveError> {
        let io = |source| ArchiveError::Io {
            path: PathBuf::from("<memory>"),
            source,
        };
        let manifest = serde_json::to_vec_pretty(&self.manifest()).map_err(|e| io(e.into()))?;
        let gz = flate2::GzBuilder::new()
            .mtime(0)
            .write(Vec::new(), flate2::Compression::default());
        let mut tar = tar::Builder::new(gz);
        tar.mode(tar::HeaderMode::Deterministic);
        let mut append = |name: &str, bytes: &[u8]| -> std::io::Result<()> {
            let mut h = tar::Header::new_ustar();
            h.set_size(bytes.len() as u64);
            h.set_mode(0o644);
            h.set_mtime(0);
            h.set_uid(0);
            h.set_gid(0);
            h.set_entry_type(tar::EntryType::Regular);
            tar.append_data(&mut h, name, bytes)
        };
        append(MANIFEST, &manifest).map_err(io)?;
        for (name, bytes) in &self.members {
            append(name, bytes).map_err(io)?;
        }
        let gz = tar.into_inner().map_err(io)?;
        gz.finish().map_err(io)
    }

    /// Writes the archive to `path` atomically (a temporary file beside it, then a rename).
    pub fn write(&self, path: &Path) -> Result<(), ArchiveError> {
        let bytes = self.to_bytes()?;
        a2perf_core::write_atomic(path, &bytes).map_err(|source| ArchiveError::Io {
            path: path.to_path_buf(),
            source,
        })
    }

    /// Reads and checks a bundle file.
    pub fn read(path: &Path, limits: &ArchiveLimits) -> Result<Self, ArchiveError> {
        let mut file = std::fs::File::open(path).map_err(|source| ArchiveError::Io {
            path: path.to_path_buf(),
            source,
        })?;
        // The compressed file itself is capped too, so a huge file is refused before reading.
        let len = file
            .metadata()
            .map_err(|source| ArchiveError::Io {
                path: path.to_path_buf(),
                source,
            })?
            .len();
        if len > limits.max_total_bytes {
            return Err(ArchiveError::TooLarge {
                path: path.to_path_buf(),
                what: "the bundle file".into(),
                limit: limits.max_total_bytes,
            });
        }
        let mut bytes = Vec::with_capacity(len as usize);
        file.read_to_end(&mut bytes)
            .map_err(|source| ArchiveError::Io {
                path: path.to_path_buf(),
                source,
            })?;
        Self::from_bytes(&bytes, path, limits)
    }

    /// Reads and checks a bundle from bytes; `path` only names it in errors.
    pub fn from_bytes(
        bytes: &[u8],
        path: impl AsRef<Path>,
        limits: &ArchiveLimits,
    ) -> Result<Self, ArchiveError> {
        let path = path.as_ref();
        let malformed = |e: &dyn std::fmt::Display| ArchiveError::Malformed {
            path: path.to_path_buf(),
            reason: e.to_string(),
        };
        let decoder = flate2::read::GzDecoder::new(bytes);
        let capped = Capped {
            inner: decoder,
            left: limits.max_total_bytes,
            hit: false,
        };
        let mut tar = tar::Archive::new(capped);
        let mut members: Vec<(String, Vec<u8>)> = Vec::new();
        let entries = tar.entries().map_err(|e| malformed(&e))?;
        for entry in entries {
            let mut entry = match entry {
                Ok(e) => e,
                Err(e) => return Err(read_error(path, limits, &e)),
            };
            let raw_name = String::from_utf8_lossy(&entry.path_bytes()).into_owned();
            let unsafe_member = |reason: String| ArchiveError::UnsafeMember {
                path: path.to_path_buf(),
                member: raw_name.clone(),
                reason,
            };
            let kind = entry.header().entry_type();
            if kind != tar::EntryType::Regular {
                return Err(unsafe_member(format!(
                    "entry type {kind:?}: only regular files are allowed"
                )));
            }
            let name = std::str::from_utf8(&entry.path_bytes())
                .map_err(|_| unsafe_member("path is not UTF-8".into()))?
                .to_string();
            if name != MANIFEST || !members.is_empty() {
                check_name(&name).map_err(unsafe_member)?;
            }
            if members.iter().any(|(n, _)| *n == name) {
                return Err(unsafe_member("given twice".into()));
            }
            if members.len() > limits.max_members {
                return Err(ArchiveError::TooLarge {
                    path: path.to_path_buf(),
                    what: "the member count".into(),
                    limit: limits.max_members as u64,
                });
            }
            let declared = entry.header().size().map_err(|e| malformed(&e))?;
            if declared > limits.max_member_bytes {
                return Err(ArchiveError::TooLarge {
                    path: path.to_path_buf(),
                    what: format!("member {name:?} (declares {declared} bytes)"),
                    limit: limits.max_member_bytes,
                });
            }
            let mut data = Vec::with_capacity(declared as usize);
            if let Err(e) = entry.read_to_end(&mut data) {
                return Err(read_error(path, limits, &e));
            }
            if data.len() as u64 != declared {
                return Err(malformed(&format!(
                    "member {name:?} holds {} of its {declared} bytes",
                    data.len()
                )));
            }
            members.push((name, data));
        }
        // A tar stream that ends without its two zero blocks still parses as complete in some
        // readers; the gzip trailer (CRC and length) is what proves the stream is whole.
        let mut rest = tar.into_inner();
        let mut sink = [0u8; 512];
        loop {
            match rest.read(&mut sink) {
                Ok(0) => break,
                Ok(_) => {}
                Err(e) => return Err(read_error(path, limits, &e)),
            }
        }
        Self::from_members(members, path)
    }

    /// Checks the manifest against the members read.
    fn from_members(members: Vec<(String, Vec<u8>)>, path: &Path) -> Result<Self, ArchiveError> {
        let manifest_err = |reason: String| ArchiveError::Manifest {
            path: path.to_path_buf(),
            reason,
        };
        let mut iter = members.into_iter();
        let (first, manifest_bytes) = iter
            .next()
            .ok_or_else(|| manifest_err("the archive is empty".into()))?;
        if first != MANIFEST {
            return Err(manifest_err(format!(
                "the first member is {first:?}, not {MANIFEST}"
            )));
        }
        let manifest: Manifest = serde_json::from_slice(&manifest_bytes)
            .map_err(|e| manifest_err(format!("not a manifest: {e}")))?;
        if manifest.format != FORMAT || manifest.version != FORMAT_VERSION {
            return Err(manifest_err(format!(
                "format {:?} version {} (this program reads {FORMAT:?} version {FORMAT_VERSION})",
                manifest.format, manifest.version
            )));
        }
        let mut archive = Archive::default();
        let mut listed = manifest.members.iter();
        for (name, bytes) in iter {
            let entry = listed
                .next()
                .ok_or_else(|| manifest_err(format!("member {name:?} is not listed")))?;
            if entry.path != name {
                return Err(manifest_err(format!(
                    "lists {:?} where the archive holds {name:?}",
                    entry.path
                )));
            }
            if entry.size != bytes.len() as u64 {
                return Err(manifest_err(format!(
                    "{name}: size {} listed, {} found",
                    entry.size,
                    bytes.len()
                )));
            }
            let found = sha256_hex(&bytes);
            if entry.sha256 != found {
                return Err(manifest_err(format!(
                    "{name}: sha256 {} listed, {found} found",
                    entry.sha256
                )));
            }
            archive.members.insert(name, bytes);
        }
        if let Some(missing) = listed.next() {
            return Err(manifest_err(format!(
                "member {:?} is listed but missing",
                missing.path
            )));
        }
        Ok(archive)
    }
}

/// Turns a read error into "too large" when the decompression cap caused it.
fn read_error(path: &Path, limits: &ArchiveLimits, e: &std::io::Error) -> ArchiveError {
    if e.kind() == std::io::ErrorKind::FileTooLarge {
        ArchiveError::TooLarge {
            path: path.to_path_buf(),
            what: "the decompressed archive".into(),
            limit: limits.max_total_bytes,
        }
    } else {
        ArchiveError::Malformed {
            path: path.to_path_buf(),
            reason: e.to_string(),
        }
    }
}

/// A reader that fails once more than `left` bytes came through: the decompression bomb stops
/// at the cap, whatever the headers declare.
struct Capped<R> {
    inner: R,
    left: u64,
    hit: bool,
}

impl<R: Read> Read for Capped<R> {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        if self.hit {
            return Err(std::io::ErrorKind::FileTooLarge.into());
        }
        // Ask for one byte past the cap so that reaching it exactly is not an error.
        let want = buf.len().min(self.left.saturating_add(1) as usize);
        let n = self.inner.read(&mut buf[..want])?;
        if n as u64 > self.left {
            self.hit = true;
            return Err(std::io::ErrorKind::FileTooLarge.into());
        }
        self.left -= n as u64;
        Ok(n)
    }
}

/// Writes raw tar bytes as a gzip stream (for tests that build hostile archives by hand).
#[doc(hidden)]
pub fn gzip(bytes: &[u8]) -> Vec<u8> {
    let mut gz = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::fast());
    // Writing to a Vec cannot fail.
    let _ = gz.write_all(bytes);
    gz.finish().unwrap_or_default()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample() -> Archive {
        let mut a = Archive::default();
        a.insert("exp/run__ppo__seed0/run.json", b"{\"seed\":0}".to_vec())
            .unwrap();
        a.insert("exp/run__ppo__seed0/episodes.json", vec![7u8; 10_000])
            .unwrap();
        a
    }

    fn limits() -> ArchiveLimits {
        ArchiveLimits::default()
    }

    /// A raw tar with one member whose header says what the test wants (bypassing the writer's
    /// own checks).
    fn raw_tar(members: &[(&str, tar::EntryType, &[u8])]) -> Vec<u8> {
        let mut b = tar::Builder::new(Vec::new());
        for (name, kind, data) in members {
            let mut h = tar::Header::new_gnu();
            h.set_size(data.len() as u64);
            h.set_entry_type(*kind);
            h.set_mode(0o644);
            if *kind == tar::EntryType::Symlink {
                h.set_size(0);
                let _ = h.set_link_name("/etc/passwd");
            }
            // Write the name straight into the header so `..` and absolute paths get through.
            let field = &mut h.as_old_mut().name;
            field.fill(0);
            field[..name.len()].copy_from_slice(name.as_bytes());
            h.set_cksum();
            let body: &[u8] = if *kind == tar::EntryType::Symlink {
                &[]
            } else {
                data
            };
            b.append(&h, body).unwrap();
        }
        b.into_inner().unwrap()
    }

    fn manifest_for(members: &[(&str, &[u8])]) -> Vec<u8> {
        let m = Manifest {
            format: FORMAT.into(),
            version: FORMAT_VERSION,
            members: members
                .iter()
                .map(|(p, d)| ManifestEntry {
                    path: (*p).into(),
                    size: d.len() as u64,
                    sha256: sha256_hex(d),
                })
                .collect(),
        };
        serde_json::to_vec(&m).unwrap()
    }

    #[test]
    fn round_trip_is_exact_and_deterministic() {
        let a = sample();
        let bytes = a.to_bytes().unwrap();
        assert_eq!(bytes, sample().to_bytes().unwrap());
        let back = Archive::from_bytes(&bytes, "b.a2perf", &limits()).unwrap();
        assert_eq!(back, a);
    }

    #[test]
    fn writer_refuses_unsafe_names() {
        let mut a = Archive::default();
        for bad in [
            "../x",
            "/etc/passwd",
            "a/../b",
            "a//b",
            "",
            "./a",
            "a\\b",
            MANIFEST,
        ] {
            assert!(a.insert(bad, vec![]).is_err(), "{bad:?} accepted");
        }
    }

    #[test]
    fn truncated_archive_fails() {
        let bytes = sample().to_bytes().unwrap();
        for cut in [10, bytes.len() / 2, bytes.len() - 4] {
            let e = Archive::from_bytes(&bytes[..cut], "t.a2perf", &limits()).unwrap_err();
            assert!(matches!(e, ArchiveError::Malformed { .. }), "{cut}: {e}");
            assert!(e.to_string().contains("t.a2perf"));
        }
    }

    #[test]
    fn edited_member_fails_its_hash() {
        let run = b"{\"seed\":0}";
        let forged = b"{\"seed\":1}";
        let tar = raw_tar(&[
            (
                MANIFEST,
                tar::EntryType::Regular,
                &manifest_for(&[("run.json", run)]),
            ),
            ("run.json", tar::EntryType::Regular, forged),
        ]);
        let e = Archive::from_bytes(&gzip(&tar), "e.a2perf", &limits()).unwrap_err();
        assert!(e.to_string().contains("sha256"), "{e}");
    }

    #[test]
    fn missing_extra_and_swapped_members_fail() {
        let (a, b) = (&b"a"[..], &b"b"[..]);
        let m = manifest_for(&[("a.json", a), ("b.json", b)]);
        let missing = raw_tar(&[
            (MANIFEST, tar::EntryType::Regular, &m),
            ("a.json", tar::EntryType::Regular, a),
        ]);
        let e = Archive::from_bytes(&gzip(&missing), "m.a2perf", &limits()).unwrap_err();
        assert!(e.to_string().contains("missing"), "{e}");
        let swapped = raw_tar(&[
            (MANIFEST, tar::EntryType::Regular, &m),
            ("a.json", tar::EntryType::Regular, b),
            ("b.json", tar::EntryType::Regular, a),
        ]);
        let e = Archive::from_bytes(&gzip(&swapped), "s.a2perf", &limits()).unwrap_err();
        assert!(e.to_string().contains("sha256"), "{e}");
        let extra = raw_tar(&[
            (MANIFEST, tar::EntryType::Regular, &m),
            ("a.json", tar::EntryType::Regular, a),
            ("b.json", tar::EntryType::Regular, b),
            ("c.json", tar::EntryType::Regular, b),
        ]);
        let e = Archive::from_bytes(&gzip(&extra), "x.a2perf", &limits()).unwrap_err();
        assert!(e.to_string().contains("not listed"), "{e}");
        let no_manifest = raw_tar(&[("a.json", tar::EntryType::Regular, a)]);
        let e = Archive::from_bytes(&gzip(&no_manifest), "n.a2perf", &limits()).unwrap_err();
        assert!(matches!(e, ArchiveError::Manifest { .. }), "{e}");
    }

    #[test]
    fn traversal_absolute_and_links_are_refused() {
        let m = manifest_for(&[]);
        for (name, kind) in [
            ("../evil", tar::EntryType::Regular),
            ("/tmp/evil", tar::EntryType::Regular),
            ("a/../../evil", tar::EntryType::Regular),
            ("link", tar::EntryType::Symlink),
            ("hard", tar::EntryType::Link),
            ("dir/", tar::EntryType::Directory),
        ] {
            let tar = raw_tar(&[(MANIFEST, tar::EntryType::Regular, &m), (name, kind, b"x")]);
            let e = Archive::from_bytes(&gzip(&tar), "u.a2perf", &limits()).unwrap_err();
            assert!(
                matches!(e, ArchiveError::UnsafeMember { .. }),
                "{name}: {e}"
            );
        }
    }

    #[test]
    fn declared_giant_member_is_refused_before_reading() {
        let m = manifest_for(&[]);
        let mut tar = raw_tar(&[
            (MANIFEST, tar::EntryType::Regular, &m),
            ("big.bin", tar::EntryType::Regular, b""),
        ]);
        // Patch the second header's size field to 8 GiB (octal), keeping a valid checksum.
        let at = tar
            .windows(7)
            .position(|w| w == b"big.bin")
            .expect("header");
        let mut h = tar::Header::new_gnu();
        h.as_mut_bytes().copy_from_slice(&tar[at..at + 512]);
        h.set_size(8 << 30);
        h.set_cksum();
        tar[at..at + 512].copy_from_slice(h.as_bytes());
        let e = Archive::from_bytes(&gzip(&tar), "g.a2perf", &limits()).unwrap_err();
        assert!(matches!(e, ArchiveError::TooLarge { .. }), "{e}");
    }

    #[test]
    fn decompression_bomb_stops_at_the_cap() {
        let mut a = Archive::default();
        a.insert("zeros.bin", vec![0u8; 4 << 20]).unwrap();
        let bytes = a.to_bytes().unwrap();
        assert!(bytes.len() < 64 << 10, "zeros compress well");
        let tight = ArchiveLimits {
            max_total_bytes: 1 << 20,
            ..ArchiveLimits::default()
        };
        let e = Archive::from_bytes(&bytes, "z.a2perf", &tight).unwrap_err();
        assert!(matches!(e, ArchiveError::TooLarge { .. }), "{e}");
    }
}
