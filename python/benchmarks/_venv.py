"""Own-venv bootstrap and same-run helpers of the by-hand ratio benchmarks (mujoco_ratio.py,
sb3_ratio.py). Not run in CI: they install large third-party packages from PyPI.

A script calls :func:`enter` first: outside its venv it creates the venv (once), installs the
requirements and the a2perf_rs wheel there, and re-executes itself with the venv's interpreter.
"""

from __future__ import annotations

import os
import statistics
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
CACHE = Path(os.environ.get("A2PERF_BENCH_CACHE", Path.home() / ".cache" / "a2perf-rs"))


def _newest_wheel() -> Path:
    """The wheel in dist/, built by scripts/wheel when there is none."""
    wheels = sorted((REPO / "dist").glob("a2perf_rs-*.whl"), key=lambda p: p.stat().st_mtime)
    if wheels:
        return wheels[-1]
    out = subprocess.run([str(REPO / "scripts" / "wheel")], check=True, capture_output=True, text=True)
    return Path(out.stdout.strip().splitlines()[-1]).resolve()


def enter(venv_name: str, requirements: list[str], wheel: str | None) -> None:
    """Runs the calling script inside ``CACHE/venv_name`` with ``requirements`` and the a2perf_rs
    wheel (``wheel``, default the newest in dist/) installed; returns at once when already there.

    The wheel is reinstalled on every entry (it is what is being measured, and a rebuilt one
    keeps its file name); the requirements only when the venv is new.
    """
    if not _inside(venv_name):
        _enter(venv_name, requirements, Path(wheel).resolve() if wheel else _newest_wheel())


def _inside(venv_name: str) -> bool:
    return Path(sys.prefix).resolve() == (CACHE / venv_name).resolve()


def _enter(venv_name: str, requirements: list[str], wheel: Path | None) -> None:
    venv = CACHE / venv_name
    if _inside(venv_name):
        return
    python = venv / "bin" / "python"
    pip = [str(python), "-m", "pip", "install", "-q"]
    if not python.exists():
        subprocess.run([sys.executable, "-m", "venv", str(venv)], check=True)
        subprocess.run([*pip, "--upgrade", "pip"], check=True)
        subprocess.run([*pip, *requirements], check=True)
    if wheel is not None:
        subprocess.run([*pip, "--force-reinstall", "--no-deps", str(wheel)], check=True)
    os.execv(str(python), [str(python), *sys.argv])


def enter_without_wheel(venv_name: str, requirements: list[str]) -> None:
    """:func:`enter` for a script that measures no wheel."""
    _enter(venv_name, requirements, None)


def pin_one_core() -> int | None:
    """Pins this process to one CPU (the last allowed one) so that both sides of a ratio run on
    the same core, one thread each; returns it (None where affinity is unsupported)."""
    if not hasattr(os, "sched_setaffinity"):
        return None
    cpu = max(os.sched_getaffinity(0))
    os.sched_setaffinity(0, {cpu})
    return cpu


def load_average() -> list[float] | None:
    return list(os.getloadavg()) if hasattr(os, "getloadavg") else None


def summary(values: list[float]) -> dict:
    """Median, min and max of a measurement's rounds, and every round."""
    return {
        "median": statistics.median(values),
        "min": min(values),
        "max": max(values),
        "rounds": values,
    }
