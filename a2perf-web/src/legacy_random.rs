//! The draws A2Perf made with numpy's legacy `RandomState` to pick its website pool, so that
//! `pool = "a2perf"` plays the same designs as the original for the same seed.
//!
//! `WebNavigationEnv.__init__` does, with `RandomState(seed)`: one `randint(0, 1000)` (the seed of
//! the page's JavaScript generator), then `choice(designs, num_websites, replace=False)`, which
//! is `permutation(len(designs))[:num_websites]`. numpy seeds a legacy `RandomState` from an
//! integer with the classic `init_genrand` of MT19937, draws bounded integers by masked
//! rejection on 32-bit outputs, and shuffles by Fisher–Yates from the end.

/// The 32-bit Mersenne Twister (MT19937) exactly as numpy's legacy `RandomState` runs it.
///
/// ```
/// // numpy: np.random.RandomState(5489).randint(0, 2**32, dtype=np.uint64) == 3499211612
/// let mut mt = a2perf_web::legacy_random::Mt19937::new(5489);
/// assert_eq!(mt.next_u32(), 3_499_211_612);
/// ```
#[derive(Clone, Debug)]
pub struct Mt19937 {
    state: [u32; 624],
    index: usize,
}

impl Mt19937 {
    /// `init_genrand(seed)` (numpy's `RandomState(seed)` for an integer seed < 2³²).
    pub fn new(seed: u32) -> Self {
        let mut state = [0u32; 624];
        state[0] = seed;
        for i in 1..624 {
            let prev = state[i - 1];
            state[i] = 1_812_433_253u32
                .wrapping_mul(prev ^ (prev >> 30))
                .wrapping_add(i as u32);
        }
        Self { state, index: 624 }
    }

    fn twist(&mut self) {
        for i in 0..624 {
            let y = (self.state[i] & 0x8000_0000) | (self.state[(i + 1) % 624] & 0x7fff_ffff);
            let mut next = self.state[(i + 397) % 624] ^ (y >> 1);
            if y & 1 == 1 {
                next ^= 0x9908_b0df;
            }
            self.state[i] = next;
        }
        self.index = 0;
    }

    /// The next 32-bit output (`genrand_int32`).
    pub fn next_u32(&mut self) -> u32 {
        if self.index >= 624 {
            self.twist();
        }
        let mut y = self.state[self.index];
        self.index += 1;
        y ^= y >> 11;
        y ^= (y << 7) & 0x9d2c_5680;
        y ^= (y << 15) & 0xefc6_0000;
        y ^ (y >> 18)
    }

    /// A uniform integer in `0..=max` by masked rejection (numpy's `random_interval`, also what
    /// the legacy `randint` uses for ranges below 2³²).
    pub fn interval(&mut self, max: u32) -> u32 {
        if max == 0 {
            return 0;
        }
        let mut mask = max;
        mask |= mask >> 1;
        mask |= mask >> 2;
        mask |= mask >> 4;
        mask |= mask >> 8;
        mask |= mask >> 16;
        loop {
            let v = self.next_u32() & mask;
            if v <= max {
                return v;
            }
        }
    }

    /// `randint(low, high)` of the legacy `RandomState` (`high` exclusive, `high > low`).
    pub fn randint(&mut self, low: u32, high: u32) -> u32 {
        low + self.interval(high - low - 1)
    }

    /// `permutation(n)`: `arange(n)` shuffled by the legacy Fisher–Yates.
    pub fn permutation(&mut self, n: usize) -> Vec<usize> {
        let mut out: Vec<usize> = (0..n).collect();
        for i in (1..n).rev() {
            let j = self.interval(i as u32) as usize;
            out.swap(i, j);
        }
        out
    }
}

/// Indices (into the design file, in pool order) of the `count` designs the original's
/// `WebNavigationEnv(seed=seed, num_websites=count)` draws from a file of `total` designs.
/// `None` when numpy would refuse the draw (seed ≥ 2³², `count > total`, or more than 2³² designs).
///
/// ```
/// // Reference: level 01, seed 0 → [708, 533, 298, 356, 833, 553, 27, 231, 306, 994].
/// let pool = a2perf_web::legacy_random::a2perf_pool_indices(0, 1000, 10).unwrap();
/// assert_eq!(pool, [708, 533, 298, 356, 833, 553, 27, 231, 306, 994]);
/// ```
pub fn a2perf_pool_indices(seed: u64, total: usize, count: usize) -> Option<Vec<usize>> {
    let seed = u32::try_from(seed).ok()?;
    if count > total || u32::try_from(total).is_err() {
        return None;
    }
    let mut mt = Mt19937::new(seed);
    // The page's JavaScript seed (`utils.create_environment`), drawn before the pool.
    let _js_seed = mt.randint(0, 1000);
    let mut perm = mt.permutation(total);
    perm.truncate(count);
    Some(perm)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn matches_numpy_reference_draws() {
        // numpy 2.x, `np.random.RandomState(s)`: randint(0, 1000), then choice(1000, 10, False).
        let mut mt = Mt19937::new(37);
        assert_eq!(mt.randint(0, 1000), 911);
        assert_eq!(
            mt.permutation(1000)[..10],
            [747, 685, 301, 911, 276, 983, 166, 648, 663, 11]
        );
        let mut mt = Mt19937::new(0);
        assert_eq!(mt.randint(0, 1000), 684);
        let mut mt = Mt19937::new(u32::MAX);
        assert_eq!(mt.randint(0, 1000), 419);
        assert_eq!(mt.permutation(7), [1, 3, 6, 0, 5, 4, 2]);
        // A pool larger than 2¹¹ draws with a wider mask.
        assert_eq!(
            a2perf_pool_indices(1234, 3000, 5).unwrap(),
            [1932, 85, 1772, 1211, 2677]
        );
        assert_eq!(a2perf_pool_indices(1 << 32, 1000, 1), None);
        assert_eq!(a2perf_pool_indices(0, 5, 6), None);
        assert_eq!(a2perf_pool_indices(0, 5, 5).map(|p| p.len()), Some(5));
    }
}
