//! Seeded random streams.
//!
//! Every random number in the benchmark comes from a [`RngStream`], a ChaCha8 generator whose key is
//! derived from an experiment seed and a *purpose* string (`"env/reset"`, `"ppo/minibatch"`, …).
//! Two streams with different purposes are independent; the same (seed, purpose) always produces the
//! same numbers, on every machine, regardless of thread scheduling.

use rand_chacha::ChaCha8Rng;
use rand_core::{Rng, SeedableRng};
use serde::{Deserialize, Serialize};

/// A deterministic random stream keyed by `(seed, purpose)`.
///
/// ```
/// use a2perf_core::RngStream;
/// let mut a = RngStream::new(7, "demo");
/// let mut b = RngStream::new(7, "demo");
/// assert_eq!(a.next_u64(), b.next_u64());
/// let x = a.uniform();
/// assert!((0.0..1.0).contains(&x));
/// ```
///
/// A stream's exact position can be saved and restored ([`state`](RngStream::state),
/// [`from_state`](RngStream::from_state), or serde, which goes through [`RngState`]), so that
/// resumed training draws exactly the numbers an uninterrupted run would have drawn.
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(into = "RngState", from = "RngState")]
pub struct RngStream {
    rng: ChaCha8Rng,
    seed: u64,
    key: u64,
    spare_normal: Option<f64>,
}

/// The exact position of an [`RngStream`]: its key and how far it has advanced.
///
/// ```
/// use a2perf_core::RngStream;
/// let mut a = RngStream::new(7, "demo");
/// a.next_u32();
/// a.normal(); // leaves a cached spare normal, which is part of the state
/// let json = serde_json::to_string(&a.state()).unwrap();
/// let mut b = RngStream::from_state(&serde_json::from_str(&json).unwrap());
/// assert_eq!(a.normal().to_bits(), b.normal().to_bits());
/// assert_eq!(a.next_u64(), b.next_u64());
/// ```
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct RngState {
    /// Experiment seed.
    pub seed: u64,
    /// Key derived from the purpose (and sub-purposes).
    pub key: u64,
    /// Position in the ChaCha stream, in 32-bit words (a 68-bit number, as two halves so that
    /// every serde format can hold it).
    pub word_pos: [u64; 2],
    /// Bits of the cached second normal sample of the polar method, if any.
    pub spare_normal_bits: Option<u64>,
}

impl From<RngStream> for RngState {
    fn from(r: RngStream) -> Self {
        r.state()
    }
}

impl From<RngState> for RngStream {
    fn from(s: RngState) -> Self {
        RngStream::from_state(&s)
    }
}

/// SplitMix64 finaliser: a cheap, well-mixed, stable 64-bit hash step.
fn mix64(mut z: u64) -> u64 {
    z = z.wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// Stable hash of a purpose string (FNV-1a folded through SplitMix64); never changes between
/// releases, so recorded results stay reproducible.
fn purpose_key(purpose: &str) -> u64 {
    mix64(crate::hash::fnv1a64(purpose.as_bytes()))
}

impl RngStream {
    /// The stream for `purpose` under experiment `seed`.
    pub fn new(seed: u64, purpose: &str) -> Self {
        Self::from_key(seed, purpose_key(purpose))
    }

    fn from_key(seed: u64, key: u64) -> Self {
        let mut bytes = [0u8; 32];
        let words = [
            mix64(seed),
            mix64(seed ^ key),
            mix64(key.rotate_left(17)),
            mix64(seed.wrapping_add(key.rotate_left(41))),
        ];
        for (chunk, w) in bytes.chunks_exact_mut(8).zip(words) {
            chunk.copy_from_slice(&w.to_le_bytes());
        }
        Self {
            rng: ChaCha8Rng::from_seed(bytes),
            seed,
            key,
            spare_normal: None,
        }
    }

    /// The stream's exact position (see [`RngState`]).
    pub fn state(&self) -> RngState {
        let pos = self.rng.get_word_pos();
        RngState {
            seed: self.seed,
            key: self.key,
            word_pos: [pos as u64, (pos >> 64) as u64],
            spare_normal_bits: self.spare_normal.map(f64::to_bits),
        }
    }

    /// The stream at a saved position: it continues exactly where [`state`](Self::state) was
    /// taken.
    pub fn from_state(state: &RngState) -> Self {
        let mut s = Self::from_key(state.seed, state.key);
        s.rng
            .set_word_pos(u128::from(state.word_pos[0]) | (u128::from(state.word_pos[1]) << 64));
        s.spare_normal = state.spare_normal_bits.map(f64::from_bits);
        s
    }

    /// A child stream for a sub-purpose, e.g. one per environment index.
    ///
    /// The child depends only on this stream's (seed, purpose) and `sub`, not on how many numbers
    /// were drawn from the parent.
    pub fn derive(&self, sub: &str) -> Self {
        Self::from_key(self.seed, mix64(self.key ^ purpose_key(sub)))
    }

    /// A child stream indexed by a number (environment index, episode index, …).
    pub fn derive_index(&self, index: u64) -> Self {
        Self::from_key(
            self.seed,
            mix64(self.key ^ mix64(index ^ 0xA5A5_5A5A_0F0F_F0F0)),
        )
    }

    /// The next 32 random bits.
    pub fn next_u32(&mut self) -> u32 {
        self.rng.next_u32()
    }

    /// The next 64 random bits.
    pub fn next_u64(&mut self) -> u64 {
        self.rng.next_u64()
    }

    /// Uniform in `[0, 1)` with 53 bits of precision.
    pub fn uniform(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
    }

    /// Uniform in `[0, 1)` as `f32` (24 bits).
    pub fn uniform_f32(&mut self) -> f32 {
        (self.next_u32() >> 8) as f32 * (1.0 / (1u32 << 24) as f32)
    }

    /// Uniform in `[low, high)`.
    pub fn range(&mut self, low: f64, high: f64) -> f64 {
        low + (high - low) * self.uniform()
    }

    /// Uniform integer in `0..n` without modulo bias. Returns 0 when `n == 0`.
    pub fn below(&mut self, n: u64) -> u64 {
        if n <= 1 {
            return 0;
        }
        // Lemire's nearly-divisionless method.
        let mut m = u128::from(self.next_u64()) * u128::from(n);
        let mut low = m as u64;
        if low < n {
            let threshold = n.wrapping_neg() % n;
            while low < threshold {
                m = u128::from(self.next_u64()) * u128::from(n);
                low = m as u64;
            }
        }
        (m >> 64) as u64
    }

    /// Uniform index in `0..n` (`usize` convenience for [`below`](Self::below)).
    pub fn index(&mut self, n: usize) -> usize {
        self.below(n as u64) as usize
    }

    /// `true` with probability `p`.
    pub fn bernoulli(&mut self, p: f64) -> bool {
        self.uniform() < p
    }

    /// Standard normal sample (Marsaglia polar method; the spare is cached).
    pub fn normal(&mut self) -> f64 {
        if let Some(z) = self.spare_normal.take() {
            return z;
        }
        loop {
            let u = 2.0 * self.uniform() - 1.0;
            let v = 2.0 * self.uniform() - 1.0;
            let s = u * u + v * v;
            if s > 0.0 && s < 1.0 {
                let f = (-2.0 * s.ln() / s).sqrt();
                self.spare_normal = Some(v * f);
                return u * f;
            }
        }
    }

    /// In-place Fisher–Yates shuffle.
    pub fn shuffle<T>(&mut self, items: &mut [T]) {
        for i in (1..items.len()).rev() {
            let j = self.index(i + 1);
            items.swap(i, j);
        }
    }

    /// Index drawn with probability proportional to `weights` (non-negative, not all zero).
    /// Returns `None` when the weights sum to zero or are not finite.
    pub fn weighted_index(&mut self, weights: &[f64]) -> Option<usize> {
        let total: f64 = weights.iter().sum();
        if !(total.is_finite() && total > 0.0) {
            return None;
        }
        let mut target = self.uniform() * total;
        let mut last_positive = None;
        for (i, w) in weights.iter().enumerate() {
            if *w > 0.0 {
                last_positive = Some(i);
                if target < *w {
                    return Some(i);
                }
                target -= *w;
            }
        }
        last_positive
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn same_seed_and_purpose_give_same_stream() {
        let mut a = RngStream::new(3, "x");
        let mut b = RngStream::new(3, "x");
        for _ in 0..100 {
            assert_eq!(a.next_u64(), b.next_u64());
        }
    }

    #[test]
    fn purposes_and_seeds_are_independent() {
        let a: Vec<u64> = (0..4)
            .map(|_| 0)
            .scan(RngStream::new(3, "x"), |r, _: u64| Some(r.next_u64()))
            .collect();
        let b: Vec<u64> = (0..4)
            .map(|_| 0)
            .scan(RngStream::new(3, "y"), |r, _: u64| Some(r.next_u64()))
            .collect();
        let c: Vec<u64> = (0..4)
            .map(|_| 0)
            .scan(RngStream::new(4, "x"), |r, _: u64| Some(r.next_u64()))
            .collect();
        assert_ne!(a, b);
        assert_ne!(a, c);
    }

    #[test]
    fn derive_does_not_depend_on_parent_position() {
        let parent = RngStream::new(1, "p");
        let mut used = parent.clone();
        used.next_u64();
        assert_eq!(parent.derive("c").next_u64(), used.derive("c").next_u64());
        assert_ne!(
            parent.derive_index(0).next_u64(),
            parent.derive_index(1).next_u64()
        );
    }

    #[test]
    fn below_is_in_range_and_covers_values() {
        let mut r = RngStream::new(0, "below");
        let mut seen = [false; 7];
        for _ in 0..1000 {
            let v = r.below(7) as usize;
            assert!(v < 7);
            seen[v] = true;
        }
        assert!(seen.iter().all(|s| *s));
        assert_eq!(r.below(0), 0);
    }

    #[test]
    fn normal_has_roughly_unit_moments() {
        let mut r = RngStream::new(0, "normal");
        let n = 20_000;
        let xs: Vec<f64> = (0..n).map(|_| r.normal()).collect();
        let mean = xs.iter().sum::<f64>() / n as f64;
        let var = xs.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / n as f64;
        assert!(mean.abs() < 0.05, "mean {mean}");
        assert!((var - 1.0).abs() < 0.05, "var {var}");
    }

    proptest::proptest! {
        /// Whatever was drawn before, a stream restored from its state continues with exactly
        /// the numbers the original draws next.
        #[test]
        fn restored_state_continues_the_stream(seed in 0u64..1000, words in 0usize..300, normals in 0usize..5) {
            let mut a = RngStream::new(seed, "prop").derive_index(3);
            for _ in 0..words {
                a.next_u32();
            }
            for _ in 0..normals {
                a.normal();
            }
            let mut b = RngStream::from_state(&a.state());
            proptest::prop_assert_eq!(a.state(), b.state());
            for _ in 0..40 {
                proptest::prop_assert_eq!(a.normal().to_bits(), b.normal().to_bits());
                proptest::prop_assert_eq!(a.next_u64(), b.next_u64());
                proptest::prop_assert_eq!(a.next_u32(), b.next_u32());
            }
        }
    }

    #[test]
    fn weighted_index_respects_zero_weights() {
        let mut r = RngStream::new(0, "w");
        for _ in 0..200 {
            let i = r.weighted_index(&[0.0, 1.0, 0.0, 2.0]).unwrap();
            assert!(i == 1 || i == 3);
        }
        assert_eq!(r.weighted_index(&[0.0, 0.0]), None);
    }
}
