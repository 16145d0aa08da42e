"""Reliability metrics and rliable statistics, computed in Rust (``a2perf-metrics``).

Inputs use the column names of the CLI's CSV files, so a report's ``curves.csv`` and
``scores.csv`` load straight into these functions with ``pandas.read_csv``:

- **curves**: a DataFrame with columns ``run, step, value`` (one row per evaluation point), or a
  2-D array ``runs × points`` (with ``steps``, default ``0, 1, …``), or a mapping
  ``{run: values}`` / ``{run: (steps, values)}``, or a list of 1-D arrays;
- **rollouts**: a DataFrame with a ``return`` column, or a 1-D array of episode returns;
- **scores**: a DataFrame with columns ``algorithm, task, run, score``, or a 2-D array
  ``runs × tasks`` for one algorithm.

Run ids are kept in order of first appearance, steps are sorted per run and a step given twice
for one run is an error, exactly as ``a2perf metrics`` reads its CSV files. Errors name the table
and its row (rows count from 0), e.g. ``scores:3: column 'score': 'abc' is not a number``.

A scores array gives the statistics of its one algorithm; a scores DataFrame is grouped per
algorithm (see :func:`group_scores`) and gives a ``pandas.DataFrame`` with one row per algorithm
(per algorithm and threshold for :func:`performance_profile`, per ordered pair of algorithms for
:func:`probability_of_improvement`), each computed exactly as on that algorithm's array.

Example::

    import numpy as np
    from a2perf_rs import metrics

    curves = np.cumsum(np.random.default_rng(0).normal(0.1, 1.0, (5, 100)), axis=1)
    metrics.reliability(curves, rollouts=np.random.default_rng(1).normal(size=100))
    metrics.iqm_ci(np.random.default_rng(2).normal(size=(10, 3)), reps=2000)
"""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from . import _native

_m = _native.metrics

#: The seven A2Perf reliability metrics (the paper's table order) and whether higher is better.
A2PERF_METRICS: dict[str, bool] = {
    "dispersion_across_runs": False,
    "dispersion_within_runs": False,
    "short_term_risk": False,
    "long_term_risk": False,
    "risk_across_runs": True,
    "dispersion_across_rollouts": False,
    "risk_across_rollouts": True,
}


def _is_frame(x: Any) -> bool:
    return hasattr(x, "columns") and hasattr(x, "__getitem__")


def _column(frame: Any, name: str, table: str, columns: tuple[str, ...]) -> Any:
    if name not in frame.columns:
        raise ValueError(
            f"{table}: missing column {name!r}; expected columns {', '.join(columns)}, "
            f"found {', '.join(map(str, frame.columns))}"
        )
    return frame[name]


def _floats(x: Any, what: str) -> np.ndarray:
    arr = np.asarray(x)
    if arr.dtype.kind not in "fiu":
        raise TypeError(f"{what} must be numbers, got dtype {arr.dtype}")
    return np.ascontiguousarray(arr, dtype=np.float64)


def _frame_floats(frame: Any, name: str, table: str, columns: tuple[str, ...]) -> np.ndarray:
    """A numeric column of a frame as float64; text that reads as a number (a column that
    ``read_csv`` left as strings) is accepted, anything else is an error naming its row."""
    arr = np.asarray(_column(frame, name, table, columns))
    if arr.dtype.kind in "fiu":
        return np.ascontiguousarray(arr, dtype=np.float64)
    out = np.empty(arr.shape[0], dtype=np.float64)
    for i, v in enumerate(arr):
        try:
            if isinstance(v, (bool, np.bool_)):
                raise TypeError
            out[i] = float(v)
        except (TypeError, ValueError):
            raise ValueError(f"{table}:{i}: column {name!r}: {v!r} is not a number") from None
    return out


def _frame_labels(frame: Any, name: str, table: str, columns: tuple[str, ...]) -> list[str]:
    """An id column of a frame as strings; a missing value (None, NaN, NA) is an error naming
    its row."""
    out: list[str] = []
    for i, v in enumerate(_column(frame, name, table, columns)):
        if not isinstance(v, str):
            try:
                missing = v is None or bool(v != v)
            except (TypeError, ValueError):  # pandas.NA
                missing = True
            if missing:
                raise ValueError(f"{table}:{i}: column {name!r} has no value ({v!r})")
        out.append(str(v))
    return out


def curve_records(
    curves: Any, steps: Any = None
) -> tuple[list[str], np.ndarray, np.ndarray]:
    """Curves in any accepted form as long-format ``(runs, steps, values)``."""
    if _is_frame(curves):
        cols = ("run", "step", "value")
        runs = _frame_labels(curves, "run", "curves", cols)
        st = _frame_floats(curves, "step", "curves", cols)
        va = _frame_floats(curves, "value", "curves", cols)
        return runs, st, va
    if isinstance(curves, Mapping):
        items = [(str(k), v) for k, v in curves.items()]
    else:
        arr = np.asarray(curves, dtype=object) if not isinstance(curves, np.ndarray) else curves
        if isinstance(arr, np.ndarray) and arr.dtype != object and arr.ndim == 2:
            items = [(str(i), row) for i, row in enumerate(arr)]
        elif isinstance(curves, Sequence) or (isinstance(arr, np.ndarray) and arr.ndim == 1):
            items = [(str(i), c) for i, c in enumerate(curves)]
        else:
            raise TypeError(
                "curves must be a DataFrame (run, step, value), a runs × points array, a mapping "
                f"or a list of arrays; got {type(curves).__name__}"
            )
    runs: list[str] = []
    all_steps: list[np.ndarray] = []
    all_values: list[np.ndarray] = []
    for run, c in items:
        if isinstance(c, tuple) and len(c) == 2:
            s, v = _floats(c[0], f"steps of run {run}"), _floats(c[1], f"values of run {run}")
        else:
            v = _floats(c, f"values of run {run}")
            s = (
                _floats(steps, "steps")
                if steps is not None
                else np.arange(v.shape[0], dtype=np.float64)
            )
        if v.ndim != 1 or s.shape != v.shape:
            raise ValueError(
                f"run {run}: steps of shape {s.shape} and values of shape {v.shape} must be 1-D "
                "and of the same length"
            )
        runs.extend([run] * v.shape[0])
        all_steps.append(s)
        all_values.append(v)
    if not runs:
        raise ValueError("curves: no data")
    return runs, np.concatenate(all_steps), np.concatenate(all_values)


def _rollouts(rollouts: Any) -> np.ndarray:
    if _is_frame(rollouts):
        arr = _frame_floats(rollouts, "return", "rollouts", ("return",))
    else:
        arr = _floats(rollouts, "rollouts")
    if arr.ndim != 1:
        raise ValueError(f"rollouts must be one-dimensional, got shape {arr.shape}")
    return arr


def reliability(
    curves: Any,
    rollouts: Any = None,
    *,
    definition: str = "a2perf",
    steps: Any = None,
) -> dict[str, Any]:
    """The reliability metrics of training curves (and of rollout returns, when given).

    ``definition="a2perf"`` (default): A2Perf's seven metrics as its paper tables computed them,
    the same dict as ``a2perf metrics reliability --json``: ``dispersion_across_runs`` and
    ``dispersion_within_runs`` as ``{"mean", "std"}``, ``short_term_risk``, ``long_term_risk``,
    ``risk_across_runs``, and with rollouts ``dispersion_across_rollouts``,
    ``risk_across_rollouts`` (see :data:`A2PERF_METRICS` for which direction is better).

    ``definition="chan2019"``: the rl-reliability-metrics library's defaults, keyed by class name
    like the CLI: ``{"bigger_is_better", "dimensions", "values"}``.
    """
    runs, st, va = curve_records(curves, steps)
    ro = None if rollouts is None else _rollouts(rollouts)
    if definition == "a2perf":
        return json.loads(_m.a2perf_reliability(runs, st, va, ro))
    if definition == "chan2019":
        return _chan2019_defaults(runs, st, va, ro)
    raise ValueError(f"definition must be 'a2perf' or 'chan2019', got {definition!r}")


def _chan2019_defaults(
    runs: list[str], st: np.ndarray, va: np.ndarray, ro: np.ndarray | None
) -> dict[str, Any]:
    # The CLI's set: the library defaults, risk across runs at the last step common to all runs.
    last_common = None
    common: set[float] | None = None
    for _, s, _ in _m.group_curves(runs, st, va):
        common = set(s.tolist()) if common is None else common & set(s.tolist())
    if common:
        last_common = [max(common)]
    specs: list[tuple[str, dict[str, Any]]] = [
        ("IqrWithinRuns", {}),
        ("IqrAcrossRuns", {}),
        ("LowerCVaROnDiffs", {}),
        ("UpperCVaROnDrawdown", {}),
        ("LowerCVaROnAcross", {"eval_points": last_common}),
        ("MedianPerfDuringTraining", {}),
    ]
    if ro is not None:
        specs += [("IqrAcrossRollouts", {}), ("LowerCVaRAcrossRollouts", {})]
    out: dict[str, Any] = {}
    for name, params in specs:
        spec = library_metric(name, **params)
        if name.endswith("Rollouts"):
            r = _m.chan2019_evaluate(json.dumps(spec), rollout_sets=[ro])
        else:
            r = _m.chan2019_evaluate(json.dumps(spec), runs, st, va)
        values = r[1].reshape(r[2])
        out[r[0]] = {
            "bigger_is_better": r[3],
            "dimensions": r[4],
            "values": values.tolist(),
        }
    return out


def _baseline(b: Any) -> Any:
    if b is None:
        return "none"
    if isinstance(b, str):
        if b not in ("curve_range", "median_perf"):
            raise ValueError(
                f"baseline {b!r}: expected None, 'curve_range', 'median_perf', a number or "
                "(low, high)"
            )
        return b
    if isinstance(b, (int, float, np.number)) and not isinstance(b, bool):
        return {"value": float(b)}
    if isinstance(b, (tuple, list)) and len(b) == 2:
        return {"band": {"low": float(b[0]), "high": float(b[1])}}
    raise TypeError(f"baseline must be None, a string, a number or (low, high); got {b!r}")


def _points(p: Any) -> list[float] | None:
    return None if p is None else [float(x) for x in np.asarray(p, dtype=np.float64).ravel()]


def _opt(x: Any) -> float | None:
    return None if x is None else float(x)


_DISPERSIONS = {"Iqr": "iqr", "Mad": "mad", "Stddev": "std"}


def library_metric(class_name: str, **params: Any) -> dict[str, Any]:
    """The specification of one rl-reliability-metrics metric by its library class name and
    keyword arguments (``IqrWithinRuns(window_size=…, eval_points=…, baseline=…)``,
    ``LowerCVaROnDiffs(alpha=…)``, ``IqrAcrossRuns(lowpass_thresh=…)``, …), as
    :func:`evaluate` takes it."""
    p = dict(params)

    def take(name: str, default: Any = None) -> Any:
        return p.pop(name, default)

    def done(spec: dict[str, Any]) -> dict[str, Any]:
        for ignored in ("target", "tail"):  # implied by the class name
            p.pop(ignored, None)
        if p:
            raise TypeError(f"{class_name}: unexpected parameters {sorted(p)}")
        return spec

    disp = next((v for k, v in _DISPERSIONS.items() if class_name.startswith(k)), None)
    if disp and class_name.endswith("WithinRuns"):
        if not take("detrend", True):
            raise ValueError(f"{class_name}: only detrend=True (the library default) is supported")
        return done(
            {
                "dispersion_within_runs": {
                    "dispersion": disp,
                    "window_size": _opt(take("window_size")),
                    "eval_points": _points(take("eval_points")),
                    "baseline": _baseline(take("baseline")),
                }
            }
        )

    def across() -> dict[str, Any]:
        return {
            "lowpass_thresh": _opt(take("lowpass_thresh")),
            "eval_points": _points(take("eval_points")),
            "window_size": _opt(take("window_size")),
        }

    if disp and class_name.endswith("AcrossRuns"):
        return done(
            {
                "dispersion_across_runs": {
                    "dispersion": disp,
                    "across": across(),
                    "baseline": _baseline(take("baseline")),
                }
            }
        )
    if disp and class_name.endswith("AcrossRollouts"):
        return done(
            {
                "dispersion_across_rollouts": {
                    "dispersion": disp,
                    "baseline": _baseline(take("baseline")),
                }
            }
        )
    for tail in ("Lower", "Upper"):
        if class_name == f"{tail}CVaRAcrossRollouts":
            return done(
                {
                    "cvar_across_rollouts": {
                        "tail": tail.lower(),
                        "alpha": float(take("alpha", 0.05)),
                        "baseline": _baseline(take("baseline")),
                    }
                }
            )
        for on in ("Diffs", "Raw", "Drawdown", "Across"):
            if class_name == f"{tail}CVaROn{on}":
                if on == "Across":
                    target: Any = {"across": across()}
                else:
                    target = on.lower()
                    for unused in ("lowpass_thresh", "eval_points", "window_size"):
                        if take(unused) is not None:
                            raise TypeError(f"{class_name}: {unused} applies to CVaROnAcross only")
                return done(
                    {
                        "cvar": {
                            "target": target,
                            "tail": tail.lower(),
                            "alpha": float(take("alpha", 0.05)),
                            "baseline": _baseline(take("baseline")),
                        }
                    }
                )
    if class_name == "MaxDrawdown":
        return done(
            {
                "max_drawdown": {
                    "baseline": _opt(take("baseline")),
                    "mean_normalize": bool(take("mean_normalize", False)),
                }
            }
        )
    if class_name == "HighFreqEnergyWithinRuns":
        return done({"high_freq_energy_within_runs": {"thresh": float(take("thresh", 0.1))}})
    if class_name == "MedianPerfDuringTraining":
        return done(
            {
                "median_perf_during_training": {
                    "window_size": _opt(take("window_size")),
                    "eval_points": _points(take("eval_points")),
                    "baseline": _baseline(take("baseline")),
                }
            }
        )
    if class_name == "MedianPerfAcrossRollouts":
        return done({"median_perf_across_rollouts": {"baseline": _baseline(take("baseline"))}})
    raise ValueError(f"unknown rl-reliability-metrics class {class_name!r}")


def evaluate(
    class_name: str,
    curves: Any = None,
    *,
    rollouts: Any = None,
    steps: Any = None,
    **params: Any,
) -> dict[str, Any]:
    """Evaluates one rl-reliability-metrics metric (see :func:`library_metric`) on curves, or on
    rollouts (one array, or a list of arrays = several rollout sets) for the ``*AcrossRollouts``
    metrics. Returns ``{"values", "bigger_is_better", "dimensions"}`` with ``values`` shaped as
    the library's result (``ATRP`` metrics: runs × eval points)."""
    spec = json.dumps(library_metric(class_name, **params))
    if class_name.endswith("AcrossRollouts"):
        if rollouts is None:
            raise TypeError(f"{class_name} takes rollouts=")
        sets = rollouts if isinstance(rollouts, list) else [rollouts]
        r = _m.chan2019_evaluate(spec, rollout_sets=[_rollouts(s) for s in sets])
    else:
        if curves is None:
            raise TypeError(f"{class_name} takes curves")
        runs, st, va = curve_records(curves, steps)
        r = _m.chan2019_evaluate(spec, runs, st, va)
    return {"values": r[1].reshape(r[2]), "bigger_is_better": r[3], "dimensions": r[4]}


def _score_matrix(scores: Any, what: str = "scores") -> np.ndarray:
    arr = _floats(scores, what)
    if arr.ndim != 2 or arr.shape[0] == 0 or arr.shape[1] == 0:
        raise ValueError(f"{what} must be a non-empty runs × tasks array, got shape {arr.shape}")
    return arr


def group_scores(scores: Any) -> tuple[list[str], dict[str, np.ndarray]]:
    """A scores DataFrame (``algorithm, task, run, score``) as ``(tasks, {algorithm: runs × tasks
    array})``, grouped as ``a2perf metrics iqm`` groups ``scores.csv``: algorithms, tasks and runs
    in order of first appearance. A missing column, an id or score missing or not a number, a
    score that is not finite, an ``(algorithm, task, run)`` given twice and an algorithm without
    a score for some task and run are ``ValueError``s naming the column or row."""
    cols = ("algorithm", "task", "run", "score")
    algos = _frame_labels(scores, "algorithm", "scores", cols)
    tasks = _frame_labels(scores, "task", "scores", cols)
    runs = _frame_labels(scores, "run", "scores", cols)
    values = _frame_floats(scores, "score", "scores", cols)
    task_names, groups = _m.group_scores(algos, tasks, runs, values)
    return list(task_names), dict(groups)


def _per_algorithm(scores: Any) -> dict[str, np.ndarray] | None:
    """The runs × tasks array of each algorithm of a scores DataFrame; ``None`` for an array."""
    return group_scores(scores)[1] if _is_frame(scores) else None


def _table(rows: list[dict[str, Any]], columns: list[str]) -> Any:
    import pandas as pd

    return pd.DataFrame(rows, columns=columns)


def _size(s: np.ndarray) -> dict[str, int]:
    return {"runs": s.shape[0], "tasks": s.shape[1]}


def iqm(scores: Any) -> Any:
    """Interquartile mean (rliable's 25 % trimmed mean) of a runs × tasks array, a float.

    A scores DataFrame gives one row per algorithm: ``algorithm, iqm, runs, tasks``."""
    out = aggregates(scores, ("iqm",))
    return out if _is_frame(scores) else out["iqm"]


def aggregates(
    scores: Any, names: Sequence[str] = ("median", "iqm", "mean"), gamma: float = 1.0
) -> Any:
    """Point aggregates (``iqm``, ``mean``, ``median``, ``optimality_gap`` with ``gamma``) of a
    runs × tasks array: ``{name: value}``.

    A scores DataFrame gives one row per algorithm: ``algorithm``, one column per name,
    ``runs, tasks``."""
    names = list(names)
    groups = _per_algorithm(scores)
    if groups is None:
        return dict(zip(names, _m.aggregates(_score_matrix(scores), names, gamma)))
    rows = [
        {"algorithm": algo, **dict(zip(names, _m.aggregates(s, names, gamma))), **_size(s)}
        for algo, s in groups.items()
    ]
    return _table(rows, ["algorithm", *names, "runs", "tasks"])


def aggregate_ci(
    scores: Any,
    names: Sequence[str] = ("iqm",),
    *,
    reps: int = 50_000,
    seed: int = 0,
    confidence: float = 0.95,
    gamma: float = 1.0,
    task_bootstrap: bool = False,
) -> Any:
    """Stratified-bootstrap percentile intervals (rliable's ``get_interval_estimates``) of a
    runs × tasks array: ``{name: (point, lower, upper)}``. Deterministic for a given ``seed``.

    A scores DataFrame gives one row per algorithm, each bootstrapped with the same ``seed`` as
    ``a2perf metrics iqm`` does: ``algorithm``, then ``<name>, <name>_ci_lower, <name>_ci_upper``
    per name, then ``runs, tasks``."""
    names = list(names)

    def one(s: np.ndarray) -> dict[str, tuple[float, float, float]]:
        point, lower, upper = _m.aggregate_ci(
            s, names, gamma, reps, seed, confidence, task_bootstrap
        )
        return {n: (float(point[i]), float(lower[i]), float(upper[i])) for i, n in enumerate(names)}

    groups = _per_algorithm(scores)
    if groups is None:
        return one(_score_matrix(scores))
    rows = []
    for algo, s in groups.items():
        row: dict[str, Any] = {"algorithm": algo}
        for n, (p, lo, hi) in one(s).items():
            row.update({n: p, f"{n}_ci_lower": lo, f"{n}_ci_upper": hi})
        rows.append({**row, **_size(s)})
    columns = [c for n in names for c in (n, f"{n}_ci_lower", f"{n}_ci_upper")]
    return _table(rows, ["algorithm", *columns, "runs", "tasks"])


def iqm_ci(scores: Any, *, reps: int = 50_000, seed: int = 0, confidence: float = 0.95) -> Any:
    """IQM with its bootstrap interval.

    A runs × tasks array gives ``(iqm, lower, upper)``. A DataFrame with the columns of
    ``scores.csv`` gives one row per algorithm with the columns of ``a2perf metrics iqm --json``
    (and its numbers for the same ``reps`` and ``seed``):
    ``algorithm, iqm, ci_lower, ci_upper, runs, tasks``.
    """
    out = aggregate_ci(scores, ("iqm",), reps=reps, seed=seed, confidence=confidence)
    if _is_frame(scores):
        return out.rename(columns={"iqm_ci_lower": "ci_lower", "iqm_ci_upper": "ci_upper"})
    return out["iqm"]


def _one_algorithm(frame: Any, what: str) -> tuple[list[str], np.ndarray]:
    try:
        tasks, groups = group_scores(frame)
    except ValueError as e:
        raise ValueError(f"{what}: {e}") from None
    if len(groups) != 1:
        raise ValueError(
            f"{what}: expected the scores of one algorithm, found {len(groups)} "
            f"({', '.join(groups)}); pass one DataFrame alone to compare every pair"
        )
    return tasks, next(iter(groups.values()))


def probability_of_improvement(
    x: Any, y: Any = None, *, reps: int = 2000, seed: int = 0, confidence: float = 0.95
) -> Any:
    """P(X > Y) (Mann–Whitney, averaged over tasks) with an independent stratified-bootstrap
    interval (``reps=0``: no interval, NaN bounds).

    - two runs × tasks arrays with the same tasks (columns): ``(point, lower, upper)``;
    - two scores DataFrames of one algorithm each, with the same task names (in any order):
      ``(point, lower, upper)``, equal to the arrays' with the tasks in ``x``'s order;
    - one scores DataFrame (``y`` omitted) of two or more algorithms: every ordered pair, as the
      probability-of-improvement table of ``a2perf report`` lists them, in a DataFrame
      ``x, y, probability, ci_lower, ci_upper, tasks`` (algorithms in order of first appearance,
      each pair bootstrapped with the same ``seed``).
    """

    def poi(a: np.ndarray, b: np.ndarray) -> tuple[float, float, float]:
        return _m.probability_of_improvement(a, b, reps, seed, confidence)

    if y is None:
        groups = _per_algorithm(x)
        if groups is None:
            raise TypeError(
                "probability_of_improvement: y is required unless x is a scores DataFrame"
            )
        if len(groups) < 2:
            raise ValueError(
                f"scores: probability of improvement needs two algorithms, found {len(groups)} "
                f"({', '.join(groups)})"
            )
        rows = [
            {"x": a, "y": b, **dict(zip(("probability", "ci_lower", "ci_upper"), poi(sa, sb))),
             "tasks": sa.shape[1]}
            for a, sa in groups.items()
            for b, sb in groups.items()
            if a != b
        ]
        return _table(rows, ["x", "y", "probability", "ci_lower", "ci_upper", "tasks"])
    if _is_frame(x) != _is_frame(y):
        raise TypeError(
            "probability_of_improvement: x and y must both be arrays or both DataFrames"
        )
    if not _is_frame(x):
        return poi(_score_matrix(x, "x"), _score_matrix(y, "y"))
    (tx, sx), (ty, sy) = _one_algorithm(x, "x"), _one_algorithm(y, "y")
    if set(tx) != set(ty) or len(tx) != len(ty):
        raise ValueError(
            f"x and y must have the same tasks: only in x: {sorted(set(tx) - set(ty))}, "
            f"only in y: {sorted(set(ty) - set(tx))}"
        )
    return poi(sx, np.ascontiguousarray(sy[:, [ty.index(t) for t in tx]]))


def performance_profile(
    scores: Any,
    taus: Any,
    *,
    over_runs: bool = True,
    reps: int = 2000,
    seed: int = 0,
    confidence: float = 0.95,
) -> Any:
    """Score distribution at thresholds ``taus`` (fraction of run scores above τ; with
    ``over_runs=False`` the fraction of task means), with bootstrap intervals (``reps=0``: none,
    NaN bounds).

    A runs × tasks array gives ``(profile, lower, upper)``, three arrays of ``len(taus)``. A scores
    DataFrame gives one row per algorithm and τ, each algorithm bootstrapped with the same
    ``seed``: ``algorithm, tau, profile, ci_lower, ci_upper``."""
    t = _floats(taus, "taus").ravel().tolist()

    def one(s: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        return _m.performance_profile(s, t, over_runs, reps, seed, confidence)

    groups = _per_algorithm(scores)
    if groups is None:
        return one(_score_matrix(scores))
    rows = []
    for algo, s in groups.items():
        p, lo, hi = one(s)
        rows += [
            {"algorithm": algo, "tau": t[i], "profile": float(p[i]),
             "ci_lower": float(lo[i]), "ci_upper": float(hi[i])}
            for i in range(len(t))
        ]
    return _table(rows, ["algorithm", "tau", "profile", "ci_lower", "ci_upper"])
