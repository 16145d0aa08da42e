"""a2perf_rs.metrics against the golden values the Rust tests use, at the same tolerances
(a2perf-metrics/tests/golden_reliability.rs and golden_rliable.rs)."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest

from a2perf_rs import metrics
from conftest import shared

# Tolerances of golden_reliability.rs.
REL, ABS = 1e-9, 1e-12
ABS_LOWPASS_001 = 1e-12
ABS_LOWPASS_01 = 1e-9
# golden_rliable.rs.
POINT = 1e-12
CI = 0.005


def close(name: str, got, want, rel: float, abs_: float) -> None:
    got = np.asarray(got, dtype=np.float64).ravel()
    want = np.asarray(want, dtype=np.float64).ravel()
    assert got.shape == want.shape, f"{name}: shape {got.shape} vs {want.shape}"
    both_nan = np.isnan(got) & np.isnan(want)
    ok = both_nan | (np.abs(got - want) <= abs_ + rel * np.maximum(np.abs(got), np.abs(want)))
    assert ok.all(), f"{name}: {got[~ok][:5]} vs {want[~ok][:5]}"


@pytest.fixture(scope="module")
def golden() -> dict:
    return json.loads(shared("metrics", "golden_reliability.json").read_text())


@pytest.fixture(scope="module")
def curves(golden: dict) -> pd.DataFrame:
    t = golden["inputs"]["timepoints"]
    rows = [
        (f"seed{j}", step, y)
        for j, ys in enumerate(golden["inputs"]["curves_y"])
        for step, y in zip(t, ys)
    ]
    return pd.DataFrame(rows, columns=["run", "step", "value"])


def test_a2perf_reliability_py_outputs(golden: dict, curves: pd.DataFrame) -> None:
    rollouts = pd.DataFrame({"return": golden["inputs"]["rollouts"]})
    r = metrics.reliability(curves, rollouts)
    tr = golden["a2perf_reliability_py"]["training"]
    across = tr["dispersion_across_runs(mean,std over steps of IQR of lowpassed)"]
    close("across", [r["dispersion_across_runs"]["mean"], r["dispersion_across_runs"]["std"]],
          [across["mean"], across["std"]], 0.0, ABS_LOWPASS_001)
    within = tr["dispersion_within_runs(mean,std of windowed IQR of diffs)"]
    close("within", [r["dispersion_within_runs"]["mean"], r["dispersion_within_runs"]["std"]],
          [within["mean"], within["std"]], REL, 0.0)
    close("short", r["short_term_risk"], tr["short_term_risk(-CVaR_0.05 of pooled raw diffs)"], REL, 0.0)
    close("long", r["long_term_risk"],
          tr["long_term_risk(upper CVaR of pooled drawdowns >= p95)"], REL, 0.0)
    close("risk", r["risk_across_runs"], tr["risk_across_runs(CVaR_0.05 of final values)"], REL, 0.0)
    inf = golden["a2perf_reliability_py"]["inference"]
    close("ro disp", r["dispersion_across_rollouts"], inf["dispersion_across_rollouts(IQR)"], REL, 0.0)
    close("ro risk", r["risk_across_rollouts"], inf["risk_across_rollouts(CVaR_0.05)"], REL, 0.0)
    assert set(r) == set(metrics.A2PERF_METRICS)
    # The same numbers from a runs × points array and from a shuffled table.
    arr = np.array(golden["inputs"]["curves_y"])
    assert metrics.reliability(arr, steps=golden["inputs"]["timepoints"])["long_term_risk"] == r["long_term_risk"]
    # Rows in any order: runs then come in another order, which moves sums by an ulp at most.
    shuffled = curves.sample(frac=1.0, random_state=0)
    close("shuffled", metrics.reliability(shuffled)["short_term_risk"], r["short_term_risk"], 1e-14, 0.0)


def _check(name: str, class_name: str, entry: dict, curves: pd.DataFrame, rollouts) -> int:
    params = dict(entry["params"])
    for unused in ("target", "tail"):
        params.pop(unused, None)
    out = metrics.evaluate(class_name, curves, rollouts=rollouts, **params)
    if "bigger_is_better" in entry:
        assert out["bigger_is_better"] == entry["bigger_is_better"], name
    got = out["values"]
    if "shape" in entry:
        assert got.size == int(np.prod(entry["shape"])), name
    lowpass = entry["params"].get("lowpass_thresh")
    if lowpass == 0.01:
        close(name, got, entry["value"], 0.0, ABS_LOWPASS_001)
    elif lowpass is not None:
        close(name, got, entry["value"], REL, ABS_LOWPASS_01)
    else:
        close(name, got, entry["value"], REL, ABS)
    return got.size


def test_library_defaults(golden: dict, curves: pd.DataFrame) -> None:
    ro = np.array(golden["inputs"]["rollouts"])
    n = sum(_check(c, c, e, curves, ro) for c, e in golden["library_defaults"].items())
    assert n > 200


def test_library_variants(golden: dict, curves: pd.DataFrame) -> None:
    ro = np.array(golden["inputs"]["rollouts"])
    variants = golden["library_variants"]
    assert len(variants) == 21
    for name, entry in variants.items():
        _check(name, entry["class"], entry, curves, ro)


def test_chan2019_definition_has_the_clis_keys(golden: dict, curves: pd.DataFrame) -> None:
    r = metrics.reliability(curves, golden["inputs"]["rollouts"], definition="chan2019")
    assert list(r) == [
        "IqrWithinRuns", "IqrAcrossRuns", "LowerCVaROnDiffs", "UpperCVaROnDrawdown",
        "LowerCVaROnAcross", "MedianPerfDuringTraining", "IqrAcrossRollouts",
        "LowerCVaRAcrossRollouts",
    ]
    close("IqrAcrossRuns", r["IqrAcrossRuns"]["values"],
          golden["library_defaults"]["IqrAcrossRuns"]["value"], REL, ABS)
    assert r["LowerCVaRAcrossRollouts"]["bigger_is_better"] is True


@pytest.fixture(scope="module")
def rl() -> dict:
    return json.loads(shared("metrics", "golden_rliable.json").read_text())


def test_rliable_point_estimates(rl: dict) -> None:
    x, y, z = (np.array(rl["inputs"][k]) for k in "XYZ")
    p = rl["point_estimates"]
    a = metrics.aggregates(x, ("median", "iqm", "mean"))
    close("median", a["median"], p["aggregate_median_X"], POINT, 0.0)
    close("iqm", metrics.iqm(x), p["aggregate_iqm_X"], POINT, 0.0)
    close("mean", a["mean"], p["aggregate_mean_X"], POINT, 0.0)
    close("og", metrics.aggregates(x, ("optimality_gap",), gamma=0.8)["optimality_gap"],
          p["aggregate_optimality_gap_X_gamma0.8"], POINT, 0.0)
    close("iqm Y", metrics.iqm(y), p["aggregate_iqm_Y"], POINT, 0.0)
    close("poi", metrics.probability_of_improvement(x, y, reps=0)[0],
          p["probability_of_improvement_X_over_Y"], POINT, 0.0)
    close("poi xz", metrics.probability_of_improvement(x, z, reps=0)[0],
          p["probability_of_improvement_X_over_Z(ties+identical task)"], POINT, 0.0)
    taus = rl["inputs"]["taus"]
    close("profile", metrics.performance_profile(x, taus, reps=0)[0],
          p["score_distribution_X(run_score_deviation, frac of all scores > tau)"], POINT, 0.0)
    close("avg profile", metrics.performance_profile(x, taus, over_runs=False, reps=0)[0],
          p["average_score_distribution_X(frac of task means > tau)"], POINT, 0.0)


def test_rliable_intervals(rl: dict) -> None:
    b = rl["bootstrap_cis"]["aggregate_[median,iqm,mean,optimality_gap]_percentile_95_reps50000"]
    for key in ("X", "Y"):
        s = np.array(rl["inputs"][key])
        ci = metrics.aggregate_ci(s, ("median", "iqm", "mean", "optimality_gap"))
        lower = [ci[n][1] for n in ci]
        upper = [ci[n][2] for n in ci]
        for seed in ("0", "1", "2"):
            want = b["by_numpy_global_seed"][seed][key]
            close(f"{key} lower", lower, want[0], 0.0, CI)
            close(f"{key} upper", upper, want[1], 0.0, CI)
    x, y = np.array(rl["inputs"]["X"]), np.array(rl["inputs"]["Y"])
    poi = rl["bootstrap_cis"]["probability_of_improvement_X_over_Y_reps2000_seed0"]
    point, lo, hi = metrics.probability_of_improvement(x, y, reps=2000)
    close("poi point", point, poi["point"], POINT, 0.0)
    close("poi ci", [lo, hi], [poi["ci"][0][0], poi["ci"][1][0]], 0.0, 0.02)
    prof = rl["bootstrap_cis"]["performance_profile_X_reps2000_seed0"]
    p, lo, hi = metrics.performance_profile(x, rl["inputs"]["taus"], reps=2000)
    close("profile", p, prof["profile"], POINT, 0.0)
    close("profile lower", lo, prof["ci_lower"], 0.0, 1.0 / 30.0 + 1e-9)
    close("profile upper", hi, prof["ci_upper"], 0.0, 1.0 / 30.0 + 1e-9)
    # Deterministic per seed.
    assert metrics.iqm_ci(x, reps=3000) == metrics.iqm_ci(x, reps=3000)
    assert metrics.iqm_ci(x, reps=3000) != metrics.iqm_ci(x, reps=3000, seed=1)


def test_iqm_table_matches_the_clis_columns(rl: dict) -> None:
    rows = [
        (algo, f"task{t}", f"run{r}", v)
        for algo in ("X", "Y")
        for r, row in enumerate(rl["inputs"][algo])
        for t, v in enumerate(row)
    ]
    table = metrics.iqm_ci(pd.DataFrame(rows, columns=["algorithm", "task", "run", "score"]), reps=2000)
    assert list(table.columns) == ["algorithm", "iqm", "ci_lower", "ci_upper", "runs", "tasks"]
    assert list(table["algorithm"]) == ["X", "Y"]
    x = table.set_index("algorithm").loc["X"]
    close("iqm", x["iqm"], rl["point_estimates"]["aggregate_iqm_X"], POINT, 0.0)
    assert x["ci_lower"] < x["iqm"] < x["ci_upper"]
