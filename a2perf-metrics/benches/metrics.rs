//! The seven A2Perf reliability metrics on 10 runs × 10,000 points, and an IQM 95% interval with
//! 50,000 bootstrap replicates on 10 runs × 3 tasks.

use a2perf_metrics::rliable::{Aggregate, Aggregates, BootstrapConfig, Scores, bootstrap_ci};
use a2perf_metrics::{Curve, a2perf};
use criterion::{Criterion, criterion_group, criterion_main};
use std::hint::black_box;

fn curves(runs: usize, points: usize) -> Vec<Curve> {
    (0..runs)
        .map(|j| {
            let y = (0..points)
                .map(|t| {
                    let t = t as f64;
                    0.002 * t
                        + 0.3 * (0.07 * t + j as f64).sin()
                        + 0.05 * ((t * 37.0 + j as f64 * 11.0) % 7.0 - 3.0)
                })
                .collect();
            Curve::new((0..points).map(|t| (t * 100) as f64).collect(), y).unwrap()
        })
        .collect()
}

fn reliability(c: &mut Criterion) {
    let runs = curves(10, 10_000);
    let rollouts: Vec<f64> = (0..100).map(|i| (1.3 * i as f64).sin() * 2.0).collect();
    c.bench_function("a2perf_seven_metrics_10x10000", |b| {
        b.iter(|| {
            let t = a2perf::training_reliability(black_box(&runs)).unwrap();
            let r = a2perf::rollout_reliability(black_box(&rollouts)).unwrap();
            black_box((t, r))
        })
    });
}

fn iqm_ci(c: &mut Criterion) {
    let rows: Vec<Vec<f64>> = (0..10)
        .map(|n| {
            (0..3)
                .map(|m| {
                    0.1 * (m + 1) as f64 + 0.5 * (0.9 * n as f64 + 1.3 * m as f64).sin().powi(2)
                })
                .collect()
        })
        .collect();
    let scores = Scores::from_rows(&rows).unwrap();
    let cfg = BootstrapConfig::default();
    let stat = Aggregates(vec![Aggregate::Iqm]);
    c.bench_function("iqm_ci_50000_reps_10x3", |b| {
        b.iter(|| black_box(bootstrap_ci(black_box(&scores), &stat, &cfg).unwrap()))
    });
}

criterion_group!(benches, reliability, iqm_ci);
criterion_main!(benches);
