//! Invariants of the reliability metrics and CVaR.

use a2perf_metrics::chan2019::{Dispersion, Metric};
use a2perf_metrics::numeric::{Tail, cvar, mean};
use a2perf_metrics::{Curve, a2perf};
use proptest::prelude::*;

fn runs_strategy() -> impl Strategy<Value = Vec<Vec<f64>>> {
    (3usize..7, 12usize..40).prop_flat_map(|(runs, points)| {
        prop::collection::vec(prop::collection::vec(-10.0f64..10.0, points), runs)
    })
}

fn curves(ys: &[Vec<f64>]) -> Vec<Curve> {
    ys.iter()
        .map(|y| Curve::from_values(y.clone()).unwrap())
        .collect()
}

fn close(a: f64, b: f64, tol: f64) -> bool {
    (a.is_nan() && b.is_nan()) || (a - b).abs() <= tol * (1.0 + a.abs().max(b.abs()))
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(48))]

    #[test]
    fn dispersions_are_nonnegative_and_shift_invariant(ys in runs_strategy(), shift in -100.0f64..100.0) {
        let c = curves(&ys);
        let shifted: Vec<Vec<f64>> = ys.iter().map(|y| y.iter().map(|v| v + shift).collect()).collect();
        let s = curves(&shifted);
        let w = a2perf::dispersion_within_runs(&c).unwrap();
        let w2 = a2perf::dispersion_within_runs(&s).unwrap();
        prop_assert!(w.mean >= 0.0);
        prop_assert!(close(w.mean, w2.mean, 1e-9));
        let m = Metric::DispersionAcrossRuns { dispersion: Dispersion::Iqr, across: Default::default(), baseline: Default::default() };
        let a = m.evaluate(&c).unwrap().flatten();
        let b = m.evaluate(&s).unwrap().flatten();
        for (x, y) in a.iter().zip(&b) {
            prop_assert!(*x >= 0.0);
            prop_assert!(close(*x, *y, 1e-9));
        }
        let r = a2perf::dispersion_across_rollouts(&ys[0]).unwrap();
        let r2 = a2perf::dispersion_across_rollouts(&shifted[0]).unwrap();
        prop_assert!(r >= 0.0 && close(r, r2, 1e-9));
    }

    #[test]
    fn across_run_metrics_ignore_run_order(ys in runs_strategy(), rot in 1usize..5) {
        let c = curves(&ys);
        let mut rotated = c.clone();
        let k = rot % rotated.len();
        rotated.rotate_left(k);
        prop_assert_eq!(a2perf::risk_across_runs(&c).unwrap(), a2perf::risk_across_runs(&rotated).unwrap());
        let a = a2perf::dispersion_across_runs(&c).unwrap();
        let b = a2perf::dispersion_across_runs(&rotated).unwrap();
        prop_assert!(close(a.mean, b.mean, 1e-12));
        let m = Metric::lower_cvar_on_across(None);
        prop_assert_eq!(m.evaluate(&c).unwrap(), m.evaluate(&rotated).unwrap());
    }

    #[test]
    fn metrics_are_scale_equivariant(ys in runs_strategy(), scale in 0.1f64..10.0) {
        let c = curves(&ys);
        let scaled: Vec<Vec<f64>> = ys.iter().map(|y| y.iter().map(|v| v * scale).collect()).collect();
        let s = curves(&scaled);
        let (a, b) = (a2perf::training_reliability(&c).unwrap(), a2perf::training_reliability(&s).unwrap());
        prop_assert!(close(a.dispersion_within_runs.mean * scale, b.dispersion_within_runs.mean, 1e-9));
        prop_assert!(close(a.short_term_risk * scale, b.short_term_risk, 1e-9));
        prop_assert!(close(a.long_term_risk * scale, b.long_term_risk, 1e-9));
        prop_assert!(close(a.risk_across_runs * scale, b.risk_across_runs, 1e-9));
        // Across runs: the low-pass is linear, so equivariance holds up to rounding; checked with
        // the well-conditioned cutoff 0.1 (at 0.01 rounding noise dominates near-constant
        // curves, and A2Perf's "drop IQRs of exactly 0" rule is discontinuous there).
        let m = Metric::DispersionAcrossRuns {
            dispersion: Dispersion::Iqr,
            across: a2perf_metrics::chan2019::AcrossRuns { lowpass_thresh: Some(0.1), ..Default::default() },
            baseline: Default::default(),
        };
        let (x, y) = (m.evaluate(&c).unwrap().flatten(), m.evaluate(&s).unwrap().flatten());
        for (u, v) in x.iter().zip(&y) {
            prop_assert!((u * scale - v).abs() <= 1e-7 * (1.0 + v.abs()), "{} vs {}", u * scale, v);
        }
    }

    #[test]
    fn lower_cvar_le_mean_le_upper_cvar(x in prop::collection::vec(-1e3f64..1e3, 1..200), alpha in 0.01f64..0.5) {
        let lo = cvar(&x, Tail::Lower, alpha);
        let hi = cvar(&x, Tail::Upper, alpha);
        let m = mean(&x);
        prop_assert!(lo <= m + 1e-9 * (1.0 + m.abs()), "{lo} > {m}");
        prop_assert!(m <= hi + 1e-9 * (1.0 + m.abs()), "{m} > {hi}");
    }

    #[test]
    fn risk_across_runs_is_min_final_value_below_21_runs(finals in prop::collection::vec(-50.0f64..50.0, 1..21)) {
        let c: Vec<Curve> = finals.iter().map(|f| Curve::from_values(vec![0.0, *f]).unwrap()).collect();
        let min = finals.iter().copied().fold(f64::INFINITY, f64::min);
        prop_assert_eq!(a2perf::risk_across_runs(&c).unwrap(), min);
        let lib = Metric::lower_cvar_on_across(Some(vec![1.0])).evaluate(&c).unwrap().flatten();
        prop_assert_eq!(lib, vec![min]);
    }
}
