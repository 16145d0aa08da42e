"""A2Perf in Rust from Python.

- :mod:`a2perf_rs.envs`: every benchmark environment as a Gymnasium environment, registered in
  the ``a2perf`` namespace on import (``gymnasium.make("a2perf/QuadrupedLocomotion-DogPace-v0")``);
- :mod:`a2perf_rs.vector`: native vector environments stepped in Rust threads
  (``gymnasium.make_vec("a2perf/<id>", num_envs=N, vectorization_mode="vector_entry_point")``);
- :mod:`a2perf_rs.metrics`: the seven reliability metrics (A2Perf's and the rl-reliability-metrics
  definitions), IQM with bootstrap intervals, probability of improvement, performance profiles;
- :mod:`a2perf_rs.circuit`: ``PlacementCost``, the exact circuit placement cost with the method
  names of circuit_training's ``plc_client``;
- :mod:`a2perf_rs.harness`: your own agent benchmarked like the built-in ones —
  :class:`TrainingRun` (run directory, system meters, seeded environments, curve, checkpoints),
  :func:`infer`, :func:`generalize`, :func:`collect` with Python policies, and :func:`report`;
- :mod:`a2perf_rs.submission`: an A2Perf participant folder run by ``a2perf submit`` (the child
  side, and ``task()`` / ``training_run()`` / ``make_env()`` for the folder's code).

The import name is ``a2perf_rs`` so that the original ``a2perf`` package can be installed beside it.
"""

import json
from typing import Any

from . import _native, circuit, metrics, submission
from ._native import BackendError, RunLockedError
from .envs import A2PerfEnv, env_ids, env_params, register_all
from .harness import TrainingRun, collect, generalize, infer, report
from .vector import A2PerfVectorEnv

__version__: str = _native.__version__

__all__ = [
    "A2PerfEnv",
    "A2PerfVectorEnv",
    "BackendError",
    "RunLockedError",
    "TrainingRun",
    "circuit",
    "collect",
    "generalize",
    "infer",
    "report",
    "metrics",
    "submission",
    "bench",
    "chromium_unavailable_reason",
    "env_ids",
    "env_params",
    "register_all",
    "verify",
]


def verify(path: str, retrain: bool = False) -> dict[str, Any]:
    """``a2perf verify`` in this process: checks the bundle at ``path`` (its manifest, a replay
    of every logged episode, the stated means, and for built-in algorithms a re-run of the
    checkpoint; with ``retrain=True`` also retraining, see docs/bundles.md). Returns
    ``{"holds": bool, "checks": [{"run", "what", "outcome", "detail"}, ...]}`` with ``outcome``
    one of ``"holds"``, ``"fails"``, ``"skipped"``. No code from the bundle runs. A bundle that
    cannot be read at all (truncated, edited, unsafe members) raises ``ValueError``."""
    return json.loads(_native.verify(str(path), retrain))


def bench(
    env_id: str, steps: int = 10_000, seed: int = 0, *, timeline: bool = False, **params: Any
) -> dict[str, Any]:
    """``a2perf bench`` in this process: steps ``env_id`` (with or without the ``a2perf/``
    namespace) ``steps`` times with uniformly random legal actions, timing every native
    ``step``; returns the report ``a2perf bench --json`` prints (``steps_per_second``,
    ``step_latency_us`` p50/p90/p99, ``mean_step_us``, ``reset_time_us``, ``params``). The GIL is
    released meanwhile. Timing the native step in the same process as a Python loop makes the
    two comparable on a machine whose speed drifts. ``timeline=True`` adds ``timeline_us``: the
    loop unit by unit in µs, each step (its action's sampling included) and each reset after an
    episode's end its own unit, the way a vector env with next-step autoreset spends them."""
    bare = env_id.split("/", 1)[1] if env_id.startswith("a2perf/") else env_id
    return json.loads(_native.bench(bare, steps, seed, params, timeline))


def chromium_unavailable_reason() -> str | None:
    """``None`` when Chromium and chromedriver are installed (the web ids' ``backend="chromium"``
    can run), else why not."""
    return _native.chromium_unavailable_reason()


register_all()
