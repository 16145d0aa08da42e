"""Shared fixtures: the reference data in ../shared/data, the Chromium check, child processes.

Tests that need ../shared/data skip with a reason when it is absent, unless
A2PERF_REQUIRE_SHARED=1; Chromium tests skip when no browser is installed, unless
A2PERF_REQUIRE_CHROME=1 (as the Rust tests do).
"""

from __future__ import annotations

import os
from pathlib import Path

import pytest

import a2perf_rs

REPO = Path(__file__).resolve().parents[2]
SHARED = Path(os.environ.get("A2PERF_SHARED_DATA", REPO.parent / "shared" / "data"))


def shared(*parts: str) -> Path:
    """A file of the reference data, or skip (fail under A2PERF_REQUIRE_SHARED=1)."""
    path = SHARED.joinpath(*parts)
    if not path.exists():
        if os.environ.get("A2PERF_REQUIRE_SHARED") == "1":
            pytest.fail(f"A2PERF_REQUIRE_SHARED=1 but {path} is missing")
        pytest.skip(f"{path} not present")
    return path


def require_chromium() -> None:
    """Skip unless Chromium and chromedriver are installed (fail under A2PERF_REQUIRE_CHROME=1)."""
    reason = a2perf_rs.chromium_unavailable_reason()
    if reason is not None:
        if os.environ.get("A2PERF_REQUIRE_CHROME") == "1":
            pytest.fail(f"A2PERF_REQUIRE_CHROME=1 but {reason}")
        pytest.skip(f"Chromium unavailable: {reason}")


def child_pids() -> set[int]:
    """The ids of this process's child processes (a Chromium backend's chromedriver)."""
    me = str(os.getpid())
    out = set()
    for pid in os.listdir("/proc"):
        if not pid.isdigit():
            continue
        try:
            with open(f"/proc/{pid}/stat") as f:
                fields = f.read().rsplit(")", 1)[1].split()
        except OSError:
            continue
        if fields[1] == me:
            out.add(int(pid))
    return out


def file_kwargs(env_id: str) -> dict[str, str]:
    """The files an id needs (CircuitTraining-ToyMacro/Ariane take a netlist), from the shared data."""
    bare = env_id.split("/", 1)[-1]
    if bare == "CircuitTraining-ToyMacro-v0":
        return {"netlist_file": str(shared("circuit", "toy_macro_stdcell", "netlist.pb.txt"))}
    if bare == "CircuitTraining-Ariane-v0":
        netlist = shared("circuit", "ariane133_ng45", "netlist.pb.txt.gz")
        return {
            "netlist_file": str(netlist),
            "init_placement": str(shared("circuit", "ariane133_ng45", "initial.plc")),
        }
    return {}
