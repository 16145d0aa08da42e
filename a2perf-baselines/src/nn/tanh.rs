//! `tanh` in `f32`, written out so that it vectorizes and is the same on every platform.
//!
//! The networks used to call `f32::tanh`, which is the C library's `tanhf`: an out-of-line
//! call per element (about a sixth of a locomotion PPO run's CPU went to glibc's `tanhf` and
//! the `expm1f` under it), and a result that depends on the host's C library. This is
//! fdlibm's algorithm, the one glibc's `tanhf` used up to 2.40 (`tanh` through `expm1`:
//! argument reduction by ln 2, a degree-5 rational correction, reconstruction by exponent
//! arithmetic), with every operation in the same order. So on those glibc versions it gives
//! the same bits for every one of the 2³² inputs (checked exhaustively once, 2026-11-29, on
//! glibc 2.36; the tests compare a dense sample), and trained policies did not move.
//!
//! The branches of the original become selects: every lane computes every case and keeps the
//! one its input takes, which lets the loop run 8 or 16 lanes at a time. Only the cases `tanh`
//! reaches are kept: `expm1` is called with `-2|x|` for `|x| < 1` (its reduction then gives
//! `k ∈ {0, -1, -2, -3}`) and with `2|x| ∈ [2, 44)` otherwise (`k ∈ [3, 63]`).
//!
//! ```
//! use a2perf_baselines::nn::tanh::{tanh, tanh_in_place};
//! assert_eq!(tanh(0.0), 0.0);
//! assert_eq!(tanh(30.0), 1.0);
//! assert!((tanh(0.5) - 0.5f64.tanh() as f32).abs() <= f32::EPSILON);
//! let mut v = [-1.0, 0.25, 3.0];
//! tanh_in_place(&mut v);
//! assert_eq!(v, [tanh(-1.0), tanh(0.25), tanh(3.0)]);
//! ```

const LN2_HI: f32 = f32::from_bits(0x3f31_7180);
const LN2_LO: f32 = f32::from_bits(0x3717_f7d1);
const INV_LN2: f32 = f32::from_bits(0x3fb8_aa3b);
const Q1: f32 = f32::from_bits(0xbd08_8889);
const Q2: f32 = f32::from_bits(0x3ad0_0d01);
const Q3: f32 = f32::from_bits(0xb8a6_70cd);
const Q4: f32 = f32::from_bits(0x3686_7e54);
const Q5: f32 = f32::from_bits(0xb457_edbb);

/// `tanh(x)`: the same bits as glibc ≤ 2.40's `tanhf`, so within two ulps of the exact value
/// (exhaustively: 729,782 of the 2³² inputs are two ulps off, none more).
#[inline(always)]
pub fn tanh(x: f32) -> f32 {
    let ax = x.abs();
    let ix = ax.to_bits();
    // tanh(|x|) = 1 − 2/(expm1(2|x|) + 2) for |x| ≥ 1, else −t/(t + 2) with t = expm1(−2|x|).
    let big = ix >= 0x3f80_0000;
    let u = if big { 2.0 * ax } else { -2.0 * ax };
    // |u|'s bits: doubling adds one to the exponent (|x| < 22 wherever the result is kept).
    let hu = ix.wrapping_add(0x0080_0000);

    // expm1(u): u = k ln2 + r, |r| ≤ ln2 / 2, with r = hi − lo carried with its error c.
    let reduce_none = hu <= 0x3eb1_7218; // |u| ≤ ln2 / 2
    let reduce_one = hu < 0x3f85_1592; // |u| < 3 ln2 / 2 (u < 0 here, so k = −1)
    let rounded = (INV_LN2 * u + if big { 0.5 } else { -0.5 }) as i32;
    let k = if reduce_none {
        0
    } else if reduce_one {
        -1
    } else {
        rounded
    };
    let kf = k as f32;
    let hi = u - kf * LN2_HI;
    let lo = kf * LN2_LO;
    let r = if reduce_none { u } else { hi - lo };
    let c = (hi - r) - lo;
    let hfx = 0.5 * r;
    let hxs = r * hfx;
    let r1 = 1.0 + hxs * (Q1 + hxs * (Q2 + hxs * (Q3 + hxs * (Q4 + hxs * Q5))));
    let t = 3.0 - r1 * hfx;
    let e = hxs * ((r1 - t) / (6.0 - r * t));
    let e2 = (r * (e - c) - c) - hxs;
    // 2^k · y by adding k to y's exponent.
    let scale = |y: f32| f32::from_bits((y.to_bits() as i32).wrapping_add(k << 23) as u32);
    let pow_minus_k = f32::from_bits(((0x7f - k) << 23) as u32);
    let expm1 = if k == 0 {
        r - (r * e - hxs)
    } else if k == -1 {
        0.5 * (r - e2) - 0.5
    } else if k <= -2 || k > 56 {
        scale(1.0 - (e2 - r)) - 1.0
    } else if k < 23 {
        scale((1.0 - pow_minus_k) - (e2 - r))
    } else {
        scale((r - (e2 + pow_minus_k)) + 1.0)
    };
    // expm1(u) = u for |u| < 2⁻²⁵.
    let t = if hu < 0x3300_0000 { u } else { expm1 };

    let q = (if big { 2.0 } else { -t }) / (t + 2.0);
    let z = if big { 1.0 - q } else { q };
    let z = if ix >= 0x41b0_0000 { 1.0 } else { z }; // |x| ≥ 22 (and ±∞)
    let z = if x.is_sign_negative() { -z } else { z };
    if ix < 0x2400_0000 {
        x * (1.0 + x) // |x| < 2⁻⁵⁵, ±0 included
    } else if ix > 0x7f80_0000 {
        x + x // NaN
    } else {
        z
    }
}

/// `v[i] = tanh(v[i])` for every element, in the widest vectors the CPU has.
pub fn tanh_in_place(v: &mut [f32]) {
    #[cfg(target_arch = "x86_64")]
    {
        use std::arch::is_x86_feature_detected as has;
        if has!("avx512f") {
            // SAFETY: the CPU has the features this build is compiled for.
            return unsafe { tanh_avx512(v) };
        }
        if has!("avx2") {
            // SAFETY: the CPU has the features this build is compiled for.
            return unsafe { tanh_avx2(v) };
        }
    }
    tanh_generic(v);
}

#[inline(always)]
fn tanh_generic(v: &mut [f32]) {
    for x in v {
        *x = tanh(*x);
    }
}

// Only wider vectors: the code has no `mul_add`, so no build fuses an operation and every build
// rounds alike.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn tanh_avx2(v: &mut [f32]) {
    tanh_generic(v);
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f,avx2")]
fn tanh_avx512(v: &mut [f32]) {
    tanh_generic(v);
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every `step`-th bit pattern (both signs, NaNs and infinities included).
    fn sample(step: u32) -> Vec<f32> {
        (0..=u32::MAX / step)
            .map(|i| f32::from_bits(i * step))
            .collect()
    }

    fn ulps(a: f32, b: f32) -> u32 {
        let key = |x: f32| {
            let b = x.to_bits() as i32;
            if b < 0 { i32::MIN - b } else { b }
        };
        key(a).abs_diff(key(b))
    }

    #[test]
    fn within_two_ulps_of_the_exact_value_and_odd() {
        let mut worst = 0;
        for x in sample(997) {
            let got = tanh(x);
            if x.is_nan() {
                assert!(got.is_nan());
                continue;
            }
            let exact = (x as f64).tanh() as f32;
            worst = worst.max(ulps(got, exact));
            assert_eq!(tanh(-x).to_bits(), (-got).to_bits(), "odd at {x:e}");
            assert!((-1.0..=1.0).contains(&got), "{x:e} -> {got:e}");
        }
        assert!(worst <= 2, "worst error {worst} ulp");
    }

    #[test]
    fn the_slice_builds_equal_the_scalar_function() {
        let xs = sample(65_537);
        let mut v = xs.clone();
        tanh_in_place(&mut v);
        for (x, y) in xs.iter().zip(&v) {
            let want = tanh(*x);
            assert!(
                y.to_bits() == want.to_bits() || (y.is_nan() && want.is_nan()),
                "{x:e}: {y:e} != {want:e}"
            );
        }
    }

    /// The glibc version, when the C library is glibc (`getconf GNU_LIBC_VERSION`).
    fn glibc_version() -> Option<(u32, u32)> {
        let out = std::process::Command::new("getconf")
            .arg("GNU_LIBC_VERSION")
            .output()
            .ok()?;
        let text = String::from_utf8(out.stdout).ok()?;
        let (major, minor) = text.trim().strip_prefix("glibc ")?.split_once('.')?;
        Some((major.parse().ok()?, minor.parse().ok()?))
    }

    #[test]
    fn the_same_bits_as_glibc_tanhf_before_its_correctly_rounded_one() {
        // glibc 2.41 replaced tanhf with CORE-MATH's correctly rounded one; before, it was
        // fdlibm's, which this module reproduces.
        match glibc_version() {
            Some(v) if v < (2, 41) => {}
            other => {
                println!(
                    "the C library's tanhf is not fdlibm's here ({other:?}, glibc < 2.41 has it); not compared"
                );
                return;
            }
        }
        let differ: Vec<String> = sample(1_009)
            .into_iter()
            .filter(|x| {
                let (got, want) = (tanh(*x), x.tanh());
                got.to_bits() != want.to_bits() && !(got.is_nan() && want.is_nan())
            })
            .take(5)
            .map(|x| {
                format!(
                    "{x:e} ({:#x}): {:e} != {:e}",
                    x.to_bits(),
                    tanh(x),
                    x.tanh()
                )
            })
            .collect();
        assert!(differ.is_empty(), "{differ:#?}");
    }
}
