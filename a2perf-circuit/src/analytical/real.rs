//! The float type of the placer's kernels (the wirelength and density maps): `f32`, as
//! DREAMPlace computes by default (`dtype` `float32` in its `params.json`, which
//! circuit_training's `get_dreamplace_params` leaves as it is), or `f64`, which the tests use
//! to check gradients against finite differences. Positions, the optimizer and every sum that
//! a stopping test reads stay `f64`.

use rustdct::rustfft::FftNum;
use rustdct::rustfft::num_traits::Float;

mod sealed {
    pub trait Sealed {}
    impl Sealed for f32 {}
    impl Sealed for f64 {}
}

/// `f32` or `f64`: what the kernels need beyond [`Float`].
pub trait Real:
    Float
    + FftNum
    + Default
    + std::ops::AddAssign
    + std::ops::SubAssign
    + std::ops::MulAssign
    + std::fmt::Debug
    + sealed::Sealed
{
    /// The largest `|x|` whose `e^x` [`Real::exp_clamped`] gives as a normal number.
    const EXP_LIMIT: f64;

    /// `x` rounded to this type.
    fn of(x: f64) -> Self;

    /// This value as an `f64` (exact).
    fn widen(self) -> f64;

    /// `e^x` within 2 ulp for `|x| ≤ EXP_LIMIT`; 0 below `−EXP_LIMIT`, `e^EXP_LIMIT` above it;
    /// NaN stays NaN. Straight-line code (no branch, no call), so that a loop over a slice of
    /// exponents vectorizes, and the same bits on every x86-64 CPU.
    ///
    /// ```
    /// use a2perf_circuit::analytical::real::Real;
    /// for x in [0.0f32, -0.5, 1.0, -37.25, 80.0, -80.0] {
    ///     let (ours, libm) = (x.exp_clamped(), x.exp());
    ///     assert!((ours - libm).abs() <= 4.0 * f32::EPSILON * libm, "{x}");
    /// }
    /// assert_eq!((-100.0f32).exp_clamped(), 0.0);
    /// assert_eq!((-800.0f64).exp_clamped(), 0.0);
    /// ```
    fn exp_clamped(self) -> Self;
}

/// `Real` for one float type: `$bits`/`$int` its bit and signed integer types, `$mant` its
/// mantissa bits, `$bias` its exponent bias, `$limit` the clamp of the exponent, `$hi`/`$lo`
/// the bits of ln 2 split so that `n·ln2_hi` is exact, `$c` the Taylor coefficients `1/k!`
/// from the highest degree down to 0.
macro_rules! real_impl {
    ($t:ident, $bits:ty, $int:ty, $mant:expr, $bias:expr, $limit:expr, $hi:expr, $lo:expr, $c:expr) => {
        impl Real for $t {
            const EXP_LIMIT: f64 = $limit;

            #[inline(always)]
            fn of(x: f64) -> Self {
                x as $t
            }

            #[inline(always)]
            fn widen(self) -> f64 {
                self as f64
            }

            #[inline(always)]
            fn exp_clamped(self) -> Self {
                let x = self;
                const LN2_HI: $t = $t::from_bits($hi);
                const LN2_LO: $t = $t::from_bits($lo);
                // 1.5·2^mant: adding it rounds to an integer held in the low mantissa bits.
                const SHIFT: $t = (3u64 << ($mant - 1)) as $t;
                const C: &[$t] = &$c;
                const LIMIT: $t = $limit as $t;
                // `clamp` keeps a NaN.
                let xc = x.clamp(-LIMIT, LIMIT);
                let t = xc * std::$t::consts::LOG2_E + SHIFT;
                let n = t - SHIFT;
                let r = (xc - n * LN2_HI) - n * LN2_LO;
                let mut p = C[0];
                for c in &C[1..] {
                    // Fused: exact on every build (the FMA instruction, or the C library's
                    // `fma` on CPUs without it), one rounding instead of two.
                    p = p.mul_add(r, *c);
                }
                // |n| stays below the bias, so 2ⁿ is a normal number; the mantissa of `t`
                // holds 2^(mant − 1) + n.
                let ni = (t.to_bits() & ((1 << $mant) - 1)) as $int - (1 << ($mant - 1));
                let scale = $t::from_bits(((ni + $bias) as $bits) << $mant);
                let y = p * scale;
                if x < -LIMIT { 0.0 } else { y }
            }
        }
    };
}

// Degree 13 (remainder below 2⁻⁵⁸ for |r| ≤ ln2/2); fdlibm's split of ln 2.
real_impl!(
    f64,
    u64,
    i64,
    52,
    1023,
    708.0,
    0x3fe6_2e42_fee0_0000,
    0x3dea_39ef_3579_3c76,
    [
        1.0 / 6_227_020_800.0,
        1.0 / 479_001_600.0,
        1.0 / 39_916_800.0,
        1.0 / 3_628_800.0,
        1.0 / 362_880.0,
        1.0 / 40_320.0,
        1.0 / 5_040.0,
        1.0 / 720.0,
        1.0 / 120.0,
        1.0 / 24.0,
        1.0 / 6.0,
        0.5,
        1.0,
        1.0,
    ]
);

// Degree 7 (remainder below 2⁻²⁷); the high part of ln 2 has 12 trailing zero bits.
real_impl!(
    f32,
    u32,
    i32,
    23,
    127,
    87.0,
    0x3f31_7200,
    0x35bf_be8e,
    [
        1.0 / 5_040.0,
        1.0 / 720.0,
        1.0 / 120.0,
        1.0 / 24.0,
        1.0 / 6.0,
        0.5,
        1.0,
        1.0,
    ]
);

#[cfg(test)]
mod tests {
    use super::*;

    fn worst_relative_error<F: Real>(step: f64) -> f64 {
        let mut worst = 0.0f64;
        let mut x = F::EXP_LIMIT;
        while x > -F::EXP_LIMIT {
            let xf = F::of(x);
            let (ours, libm) = (xf.exp_clamped().widen(), xf.widen().exp());
            worst = worst.max((ours - libm).abs() / libm);
            x -= step;
        }
        worst
    }

    #[test]
    fn exp_clamped_is_within_two_ulp_of_libm() {
        assert!(worst_relative_error::<f64>(0.012_345_678_9) <= 2.0 * f64::EPSILON);
        assert!(worst_relative_error::<f32>(0.000_987_654_3) <= 2.0 * f32::EPSILON as f64);
        for (below, nan) in [
            ((-709.0f64).exp_clamped(), f64::NAN.exp_clamped()),
            (
                (-88.0f32).exp_clamped() as f64,
                f32::NAN.exp_clamped() as f64,
            ),
        ] {
            assert_eq!(below, 0.0);
            assert!(nan.is_nan());
        }
        assert_eq!(f64::NEG_INFINITY.exp_clamped(), 0.0);
        assert_eq!(f32::NEG_INFINITY.exp_clamped(), 0.0);
        assert_eq!(0.0f64.exp_clamped(), 1.0);
        assert_eq!(0.0f32.exp_clamped(), 1.0);
    }
}
