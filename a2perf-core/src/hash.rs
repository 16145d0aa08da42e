//! FNV-1a (64-bit): the project's one stable hash.
//!
//! Provenance records (netlists, motion clips, website pools, datasets), checkpoint checksums,
//! observation hashes and the random streams' purpose keys are all FNV-1a over bytes. Unlike
//! `std`'s hashers its value never changes between Rust releases or platforms, so hashes written
//! into result files stay comparable. Numbers are fed as their little-endian bytes.
//!
//! ```
//! use a2perf_core::hash::{Fnv1a, fnv1a64};
//! let mut h = Fnv1a::new();
//! h.write(b"a2");
//! h.write(b"perf");
//! assert_eq!(h.finish(), fnv1a64(b"a2perf"));
//! assert_eq!(fnv1a64(b""), Fnv1a::OFFSET_BASIS);
//! assert_eq!(fnv1a64(b"a"), 0xaf63_dc4c_8601_ec8c); // the published FNV-1a test vector
//! ```

/// An FNV-1a 64-bit hash in progress.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Fnv1a(u64);

impl Fnv1a {
    /// The FNV-1a 64-bit offset basis (the hash of no bytes).
    pub const OFFSET_BASIS: u64 = 0xcbf2_9ce4_8422_2325;
    /// The FNV 64-bit prime.
    pub const PRIME: u64 = 0x0000_0100_0000_01B3;

    /// A hash of no bytes yet.
    pub const fn new() -> Self {
        Self(Self::OFFSET_BASIS)
    }

    /// Feeds `bytes`.
    #[inline]
    pub fn write(&mut self, bytes: &[u8]) {
        for b in bytes {
            self.0 = (self.0 ^ u64::from(*b)).wrapping_mul(Self::PRIME);
        }
    }

    /// Feeds the eight little-endian bytes of `x`.
    #[inline]
    pub fn write_u64(&mut self, x: u64) {
        self.write(&x.to_le_bytes());
    }

    /// The hash of everything fed so far.
    pub const fn finish(self) -> u64 {
        self.0
    }
}

impl Default for Fnv1a {
    fn default() -> Self {
        Self::new()
    }
}

/// FNV-1a 64 of `bytes`.
pub fn fnv1a64(bytes: &[u8]) -> u64 {
    let mut h = Fnv1a::new();
    h.write(bytes);
    h.finish()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn published_test_vectors() {
        // From the FNV reference test suite (64-bit FNV-1a).
        assert_eq!(fnv1a64(b""), 0xcbf2_9ce4_8422_2325);
        assert_eq!(fnv1a64(b"a"), 0xaf63_dc4c_8601_ec8c);
        assert_eq!(fnv1a64(b"foobar"), 0x8594_4171_f739_67e8);
    }

    #[test]
    fn split_writes_and_words_match_one_write() {
        let mut h = Fnv1a::new();
        h.write_u64(0x0102_0304_0506_0708);
        h.write(b"xy");
        let mut bytes = 0x0102_0304_0506_0708_u64.to_le_bytes().to_vec();
        bytes.extend_from_slice(b"xy");
        assert_eq!(h.finish(), fnv1a64(&bytes));
        assert_ne!(fnv1a64(b"ab"), fnv1a64(b"ba"));
    }
}
