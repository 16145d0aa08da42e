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
  :func:`infer`, :func:`generalize`, :func:`collect` with Python policies, and :func:`report`.

The import name is ``a2perf_rs`` so that the original ``a2perf`` package can be installed beside it.
"""

from . import _native, circuit, metrics
from ._native import BackendError
from .envs import A2PerfEnv, env_ids, env_params, register_all
from .harness import TrainingRun, collect, generalize, infer, report
from .vector import A2PerfVectorEnv

__version__: str = _native.__version__

__all__ = [
    "A2PerfEnv",
    "A2PerfVectorEnv",
    "BackendError",
    "TrainingRun",
    "circuit",
    "collect",
    "generalize",
    "infer",
    "report",
    "metrics",
    "chromium_unavailable_reason",
    "env_ids",
    "env_params",
    "register_all",
]


def chromium_unavailable_reason() -> str | None:
    """``None`` when Chromium and chromedriver are installed (the web ids' ``backend="chromium"``
    can run), else why not."""
    return _native.chromium_unavailable_reason()


register_all()
