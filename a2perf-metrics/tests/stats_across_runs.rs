//! Permutation tests and bootstrap intervals for across-run (ATP) metrics behave statistically.

use a2perf_core::RngStream;
use a2perf_metrics::Curve;
use a2perf_metrics::chan2019::{Dispersion, Metric};
use a2perf_metrics::chan2019_stats::{
    bootstrap_mean_rank_ci_across_runs, permutation_test_across_runs,
};

/// `tasks` tasks of `runs` runs; run spread grows with `noise`.
fn algo(runs: usize, tasks: usize, noise: f64, seed: u64) -> Vec<Vec<Curve>> {
    let mut rng = RngStream::new(seed, "test/curves");
    (0..tasks)
        .map(|_| {
            (0..runs)
                .map(|_| {
                    let offset = noise * rng.normal();
                    Curve::from_values((0..20).map(|t| 0.1 * t as f64 + offset).collect()).unwrap()
                })
                .collect()
        })
        .collect()
}

#[test]
fn permutation_p_values_separate_different_from_equal_algorithms() {
    let metric = Metric::DispersionAcrossRuns {
        dispersion: Dispersion::Iqr,
        across: Default::default(),
        baseline: Default::default(),
    };
    let mut rng = RngStream::new(0, "test/perm");
    let different = vec![algo(8, 6, 0.1, 1), algo(8, 6, 3.0, 2)];
    let t = permutation_test_across_runs(&different, &metric, 0, 1, None, 300, &mut rng).unwrap();
    // Algorithm 0 is much less dispersed on every task: rank 1 everywhere.
    assert_eq!(t.observed_diff, 1.0);
    assert!(t.p_value < 0.05, "p = {}", t.p_value);

    let same = vec![algo(8, 6, 1.0, 3), algo(8, 6, 1.0, 4)];
    let t = permutation_test_across_runs(&same, &metric, 0, 1, None, 300, &mut rng).unwrap();
    assert!(t.p_value > 0.05, "p = {}", t.p_value);

    let (lo, hi) =
        bootstrap_mean_rank_ci_across_runs(&different, &metric, 0, None, 200, 0.05, &mut rng)
            .unwrap();
    assert!((1.0..=hi).contains(&lo) && hi <= 2.0, "[{lo}, {hi}]");
}
