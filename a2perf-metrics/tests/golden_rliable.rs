//! Golden tests against `shared/data/metrics/golden_rliable.json` (rliable v1.2.0).

mod common;

use a2perf_metrics::rliable::{
    self, Aggregate, Aggregates, BootstrapConfig, Profile, Scores, bootstrap_ci,
    probability_of_improvement, probability_of_improvement_ci,
};
use common::{assert_close, f, load, vec1, vec2};

const POINT: f64 = 1e-12;
/// rliable's intervals come from NumPy's global RNG; ours from `RngStream`. The recorded
/// intervals for three seeds spread by about ±0.001.
const CI: f64 = 0.005;

fn scores(v: &serde_json::Value) -> Scores {
    Scores::from_rows(&vec2(v)).unwrap()
}

#[test]
fn point_estimates_match() {
    let Some(g) = load("golden_rliable.json") else {
        return;
    };
    let (x, y, z) = (
        scores(&g["inputs"]["X"]),
        scores(&g["inputs"]["Y"]),
        scores(&g["inputs"]["Z"]),
    );
    let p = &g["point_estimates"];
    let check = |name: &str, got: f64| assert_close(name, &[got], &[f(&p[name])], POINT, 0.0);
    check("aggregate_median_X", rliable::median(&x));
    check("aggregate_iqm_X", rliable::iqm(&x));
    check("aggregate_mean_X", rliable::mean(&x));
    check(
        "aggregate_optimality_gap_X_gamma1",
        rliable::optimality_gap(&x, 1.0),
    );
    check(
        "aggregate_optimality_gap_X_gamma0.8",
        rliable::optimality_gap(&x, 0.8),
    );
    check("aggregate_iqm_Y", rliable::iqm(&y));
    check("aggregate_mean_Y", rliable::mean(&y));
    check("aggregate_median_Y", rliable::median(&y));
    check(
        "aggregate_optimality_gap_Y_gamma1",
        rliable::optimality_gap(&y, 1.0),
    );
    check(
        "probability_of_improvement_X_over_Y",
        probability_of_improvement(&x, &y).unwrap(),
    );
    check(
        "probability_of_improvement_Y_over_X",
        probability_of_improvement(&y, &x).unwrap(),
    );
    check(
        "probability_of_improvement_X_over_Z(ties+identical task)",
        probability_of_improvement(&x, &z).unwrap(),
    );
    let y7 = Scores::from_rows(&vec2(&g["inputs"]["Y"])[..7]).unwrap();
    check(
        "probability_of_improvement_X_over_Y_first7runs_of_Y",
        probability_of_improvement(&x, &y7).unwrap(),
    );
    for (key, other) in [("per_task_P(X>Z)", &z), ("per_task_P(X>Y)", &y)] {
        let got: Vec<f64> = (0..3)
            .map(|t| rliable::prob_greater(&x.task_column(t), &other.task_column(t)))
            .collect();
        assert_close(key, &got, &vec1(&p[key]), POINT, 0.0);
    }
    let taus = vec1(&g["inputs"]["taus"]);
    assert_close(
        "score_distribution",
        &rliable::score_distribution(&x, &taus),
        &vec1(&p["score_distribution_X(run_score_deviation, frac of all scores > tau)"]),
        POINT,
        0.0,
    );
    assert_close(
        "average_score_distribution",
        &rliable::average_score_distribution(&x, &taus),
        &vec1(&p["average_score_distribution_X(frac of task means > tau)"]),
        POINT,
        0.0,
    );
    for (n, case) in p["iqm_small_n_cases(values v_i=((7i) mod n)+0.1i)"]
        .as_object()
        .unwrap()
    {
        let got = rliable::iqm_of(&vec1(&case["values"]));
        assert_close(
            &format!("iqm n={n}"),
            &[got],
            &[f(&case["iqm"])],
            POINT,
            0.0,
        );
    }
}

#[test]
fn aggregate_cis_agree_with_recorded_intervals() {
    let Some(g) = load("golden_rliable.json") else {
        return;
    };
    let b =
        &g["bootstrap_cis"]["aggregate_[median,iqm,mean,optimality_gap]_percentile_95_reps50000"];
    let stat = Aggregates(vec![
        Aggregate::Median,
        Aggregate::Iqm,
        Aggregate::Mean,
        Aggregate::OptimalityGap(1.0),
    ]);
    let cfg = BootstrapConfig::default();
    assert_eq!(cfg.reps, 50_000);
    for key in ["X", "Y"] {
        let s = scores(&g["inputs"][key]);
        let ci = bootstrap_ci(&s, &stat, &cfg).unwrap();
        for seed in ["0", "1", "2"] {
            let want = vec2(&b["by_numpy_global_seed"][seed][key]);
            assert_close(
                &format!("{key} lower (seed {seed})"),
                &ci.lower,
                &want[0],
                0.0,
                CI,
            );
            assert_close(
                &format!("{key} upper (seed {seed})"),
                &ci.upper,
                &want[1],
                0.0,
                CI,
            );
        }
    }
    let x = scores(&g["inputs"]["X"]);
    let want = vec2(&g["bootstrap_cis"]["iqm_X_percentile_95_reps200000_seed2024"]);
    let ci = bootstrap_ci(&x, &Aggregates(vec![Aggregate::Iqm]), &cfg).unwrap();
    assert_close(
        "iqm vs 200k reference",
        &[ci.lower[0], ci.upper[0]],
        &[want[0][0], want[1][0]],
        0.0,
        CI,
    );
}

#[test]
fn poi_and_profile_cis_agree() {
    let Some(g) = load("golden_rliable.json") else {
        return;
    };
    let (x, y) = (scores(&g["inputs"]["X"]), scores(&g["inputs"]["Y"]));
    let b = &g["bootstrap_cis"];
    let cfg = BootstrapConfig {
        reps: 2000,
        ..BootstrapConfig::default()
    };
    let poi = probability_of_improvement_ci(&x, &y, &cfg).unwrap();
    let want = vec2(&b["probability_of_improvement_X_over_Y_reps2000_seed0"]["ci"]);
    assert_close(
        "poi point",
        &poi.point,
        &[f(
            &b["probability_of_improvement_X_over_Y_reps2000_seed0"]["point"]
        )],
        POINT,
        0.0,
    );
    // 2,000 replicates of a statistic on a 1/300 grid: percentile noise is about ±0.01.
    assert_close(
        "poi ci",
        &[poi.lower[0], poi.upper[0]],
        &[want[0][0], want[1][0]],
        0.0,
        0.02,
    );
    let taus = vec1(&g["inputs"]["taus"]);
    let prof = bootstrap_ci(
        &x,
        &Profile {
            taus,
            over_runs: true,
        },
        &cfg,
    )
    .unwrap();
    let p = &b["performance_profile_X_reps2000_seed0"];
    assert_close("profile", &prof.point, &vec1(&p["profile"]), POINT, 0.0);
    // Profile bounds live on a 1/30 grid; allow one grid step.
    assert_close(
        "profile lower",
        &prof.lower,
        &vec1(&p["ci_lower"]),
        0.0,
        1.0 / 30.0 + 1e-9,
    );
    assert_close(
        "profile upper",
        &prof.upper,
        &vec1(&p["ci_upper"]),
        0.0,
        1.0 / 30.0 + 1e-9,
    );
}

#[test]
fn bootstrap_is_deterministic_per_seed() {
    let Some(g) = load("golden_rliable.json") else {
        return;
    };
    let x = scores(&g["inputs"]["X"]);
    let cfg = BootstrapConfig {
        reps: 3000,
        ..BootstrapConfig::default()
    };
    let stat = Aggregates(vec![Aggregate::Iqm]);
    let a = bootstrap_ci(&x, &stat, &cfg).unwrap();
    let b = bootstrap_ci(&x, &stat, &cfg).unwrap();
    assert_eq!(a, b);
    let c = bootstrap_ci(&x, &stat, &BootstrapConfig { seed: 1, ..cfg }).unwrap();
    assert_ne!(a.lower, c.lower);
}
