"""a2perf_rs.metrics against the golden values the Rust tests use, at the same tolerances
(a2perf-metrics/tests/golden_reliability.rs and golden_rliable.rs); scores DataFrames against
the arrays they hold; and against `a2perf metrics` for the same CSV files."""

from __future__ import annotations

import json
import subprocess
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from a2perf_rs import metrics
from conftest import a2perf_cli, shared

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


# Scores DataFrames (the columns of scores.csv) give, per algorithm, the numbers of the arrays.

SCORE_COLUMNS = ["algorithm", "task", "run", "score"]


def scores_frame(rl: dict, algos: str = "XYZ") -> pd.DataFrame:
    rows = [
        (algo, f"task{t}", f"run{r}", v)
        for algo in algos
        for r, row in enumerate(rl["inputs"][algo])
        for t, v in enumerate(row)
    ]
    return pd.DataFrame(rows, columns=SCORE_COLUMNS)


def test_one_algorithm_frame_equals_its_array(rl: dict) -> None:
    x = np.array(rl["inputs"]["X"])
    # Task-major instead of run-major rows (tasks and runs first appear in the same order, which
    # fixes the matrix's columns and rows), scores as text (a column read_csv left as strings):
    # the same matrix.
    frames = [
        scores_frame(rl, "X"),
        scores_frame(rl, "X").sort_values(["task", "run"]),
        scores_frame(rl, "X").astype({"score": str}),
    ]
    taus = rl["inputs"]["taus"]
    for f in frames:
        assert list(metrics.iqm(f)["iqm"]) == [metrics.iqm(x)]
        agg = metrics.aggregates(f, ("median", "iqm", "mean", "optimality_gap"), gamma=0.8)
        want = metrics.aggregates(x, ("median", "iqm", "mean", "optimality_gap"), gamma=0.8)
        assert list(agg.columns) == [
            "algorithm", "median", "iqm", "mean", "optimality_gap", "runs", "tasks"
        ]
        assert agg.iloc[0][list(want)].tolist() == list(want.values())
        assert (agg.iloc[0]["runs"], agg.iloc[0]["tasks"]) == x.shape
        ci = metrics.aggregate_ci(f, ("iqm", "mean"), reps=500, seed=3)
        want_ci = metrics.aggregate_ci(x, ("iqm", "mean"), reps=500, seed=3)
        assert list(ci.columns) == [
            "algorithm", "iqm", "iqm_ci_lower", "iqm_ci_upper",
            "mean", "mean_ci_lower", "mean_ci_upper", "runs", "tasks",
        ]
        for n in ("iqm", "mean"):
            got = ci.iloc[0][[n, f"{n}_ci_lower", f"{n}_ci_upper"]].tolist()
            assert tuple(got) == want_ci[n]
        row = metrics.iqm_ci(f, reps=500).iloc[0]
        assert (row["iqm"], row["ci_lower"], row["ci_upper"]) == metrics.iqm_ci(x, reps=500)
        for over_runs in (True, False):
            prof = metrics.performance_profile(f, taus, over_runs=over_runs, reps=300)
            want_p = metrics.performance_profile(x, taus, over_runs=over_runs, reps=300)
            assert list(prof.columns) == ["algorithm", "tau", "profile", "ci_lower", "ci_upper"]
            assert prof["tau"].tolist() == [float(t) for t in taus]
            for col, w in zip(("profile", "ci_lower", "ci_upper"), want_p):
                np.testing.assert_array_equal(prof[col].to_numpy(), w)


def test_probability_of_improvement_of_two_frames_equals_the_arrays(rl: dict) -> None:
    x, y = np.array(rl["inputs"]["X"]), np.array(rl["inputs"]["Y"])
    fx = scores_frame(rl, "X")
    # y's tasks in another order: aligned by name.
    fy = scores_frame(rl, "Y").sort_values("task", ascending=False, kind="stable")
    assert metrics.probability_of_improvement(fx, fy, reps=500) == \
        metrics.probability_of_improvement(x, y, reps=500)
    point = metrics.probability_of_improvement(fx, fy, reps=0)[0]
    close("poi", point, rl["point_estimates"]["probability_of_improvement_X_over_Y"], POINT, 0.0)


def test_multi_algorithm_frame_gives_per_algorithm_results(rl: dict) -> None:
    frame = scores_frame(rl, "XYZ")
    arrays = {a: np.array(rl["inputs"][a]) for a in "XYZ"}
    iqms = metrics.iqm(frame)
    assert list(iqms.columns) == ["algorithm", "iqm", "runs", "tasks"]
    assert iqms["algorithm"].tolist() == ["X", "Y", "Z"]
    assert iqms["iqm"].tolist() == [metrics.iqm(arrays[a]) for a in "XYZ"]
    agg = metrics.aggregates(frame).set_index("algorithm")
    ci = metrics.aggregate_ci(frame, ("median",), reps=400).set_index("algorithm")
    for a, s in arrays.items():
        assert agg.loc[a, ["median", "iqm", "mean"]].tolist() == list(metrics.aggregates(s).values())
        p, lo, hi = metrics.aggregate_ci(s, ("median",), reps=400)["median"]
        assert ci.loc[a, ["median", "median_ci_lower", "median_ci_upper"]].tolist() == [p, lo, hi]
    prof = metrics.performance_profile(frame, [0.0, 0.5], reps=200)
    assert len(prof) == 6
    for a, s in arrays.items():
        mine = prof[prof["algorithm"] == a]
        want = metrics.performance_profile(s, [0.0, 0.5], reps=200)
        np.testing.assert_array_equal(mine[["profile", "ci_lower", "ci_upper"]].to_numpy().T, want)
    poi = metrics.probability_of_improvement(frame, reps=300)
    assert list(poi.columns) == ["x", "y", "probability", "ci_lower", "ci_upper", "tasks"]
    assert list(zip(poi["x"], poi["y"])) == [
        ("X", "Y"), ("X", "Z"), ("Y", "X"), ("Y", "Z"), ("Z", "X"), ("Z", "Y")
    ]
    for _, r in poi.iterrows():
        want = metrics.probability_of_improvement(arrays[r["x"]], arrays[r["y"]], reps=300)
        assert (r["probability"], r["ci_lower"], r["ci_upper"]) == want
        assert r["tasks"] == 3


SCORE_FUNCTIONS = {
    "iqm": lambda f: metrics.iqm(f),
    "aggregates": lambda f: metrics.aggregates(f),
    "aggregate_ci": lambda f: metrics.aggregate_ci(f, reps=100),
    "iqm_ci": lambda f: metrics.iqm_ci(f, reps=100),
    "performance_profile": lambda f: metrics.performance_profile(f, [0.5], reps=100),
    "probability_of_improvement": lambda f: metrics.probability_of_improvement(f, reps=100),
    "probability_of_improvement(x, y)": lambda f: metrics.probability_of_improvement(
        f[f["algorithm"] == "X"], f[f["algorithm"] == "Y"], reps=100
    ),
}


@pytest.mark.parametrize("fn", list(SCORE_FUNCTIONS))
def test_bad_scores_frames_name_the_column_and_row(rl: dict, fn: str) -> None:
    call = SCORE_FUNCTIONS[fn]
    good = scores_frame(rl, "XY")
    with pytest.raises(ValueError, match=r"scores: missing column 'score'"):
        call(good.rename(columns={"score": "return"}))
    bad = good.astype({"score": object})
    bad.loc[bad.index[3], "score"] = "abc"
    with pytest.raises(ValueError, match=r"scores:3: column 'score': 'abc' is not a number"):
        call(bad)
    missing_run = good.astype({"run": object})
    missing_run.loc[missing_run.index[4], "run"] = None
    with pytest.raises(ValueError, match=r"scores:4: column 'run' has no value"):
        call(missing_run)
    nan = good.copy()
    nan.loc[nan.index[5], "score"] = np.nan
    with pytest.raises(ValueError, match=r"scores:5: score `NaN` is not finite"):
        call(nan)
    dup = pd.concat([good.iloc[:10], good.iloc[[7]], good.iloc[10:]], ignore_index=True)
    with pytest.raises(
        ValueError,
        match=r"scores:10: duplicate score for algorithm `X`, task `task1`, run `run2` "
        r"\(first on line 7\)",
    ):
        call(dup)
    with pytest.raises(ValueError, match=r"algorithm `X` has no score for task `task2`, run `run9`"):
        call(good.drop(index=29))


def test_probability_of_improvement_frame_arguments(rl: dict) -> None:
    frame = scores_frame(rl, "XY")
    with pytest.raises(ValueError, match=r"needs two algorithms, found 1 \(X\)"):
        metrics.probability_of_improvement(scores_frame(rl, "X"))
    with pytest.raises(ValueError, match=r"x: expected the scores of one algorithm, found 2 \(X, Y\)"):
        metrics.probability_of_improvement(frame, scores_frame(rl, "Z"))
    other_tasks = scores_frame(rl, "Y").replace({"task": {"task2": "task9"}})
    with pytest.raises(ValueError, match=r"only in x: \['task2'\], only in y: \['task9'\]"):
        metrics.probability_of_improvement(scores_frame(rl, "X"), other_tasks)
    with pytest.raises(TypeError, match="both be arrays or both DataFrames"):
        metrics.probability_of_improvement(scores_frame(rl, "X"), np.array(rl["inputs"]["Y"]))
    with pytest.raises(TypeError, match="y is required"):
        metrics.probability_of_improvement(np.array(rl["inputs"]["X"]))


# The same numbers as the a2perf binary.


def _cli_json(*args: str) -> dict:
    out = subprocess.run([a2perf_cli(), "metrics", *args, "--json"], check=True, capture_output=True,
                         text=True)
    return json.loads(out.stdout)


def _nan_as_null(x):
    if isinstance(x, dict):
        return {k: _nan_as_null(v) for k, v in x.items()}
    if isinstance(x, list):
        return [_nan_as_null(v) for v in x]
    return None if isinstance(x, float) and np.isnan(x) else x


@pytest.mark.parametrize("definition", ["chan2019", "a2perf"])
def test_reliability_equals_a2perf_metrics_reliability(
    golden: dict, curves: pd.DataFrame, tmp_path: Path, definition: str
) -> None:
    curves.to_csv(tmp_path / "curves.csv", index=False)
    rollouts = pd.DataFrame({"return": golden["inputs"]["rollouts"]})
    rollouts.to_csv(tmp_path / "rollouts.csv", index=False)
    want = _cli_json("reliability", "--curves", str(tmp_path / "curves.csv"), "--rollouts",
                     str(tmp_path / "rollouts.csv"), "--definition", definition)
    got = metrics.reliability(curves, rollouts, definition=definition)
    # Same keys and values (the CLI's JSON has its keys sorted and NaN as null).
    assert sorted(got) == sorted(want)
    assert _nan_as_null(got) == want
    if definition == "chan2019":
        assert len(want) == 8 and want["LowerCVaROnAcross"]["values"]


def test_iqm_ci_of_a_frame_equals_a2perf_metrics_iqm(rl: dict, tmp_path: Path) -> None:
    frame = scores_frame(rl, "XYZ")
    frame.to_csv(tmp_path / "scores.csv", index=False)
    want = _cli_json("iqm", "--scores", str(tmp_path / "scores.csv"), "--reps", "3000",
                     "--seed", "7")
    table = metrics.iqm_ci(frame, reps=3000, seed=7)
    assert list(table["algorithm"]) == list(want["algorithms"])
    for _, row in table.iterrows():
        w = want["algorithms"][row["algorithm"]]
        assert {k: row[k] for k in w} == w
