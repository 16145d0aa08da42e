"""Shared fixtures: the reference data in ../shared/data, the Chromium check, child processes.

Tests that need ../shared/data skip with a reason when it is absent, unless
A2PERF_REQUIRE_SHARED=1; Chromium tests skip when no browser is installed, unless
A2PERF_REQUIRE_CHROME=1 (as the Rust tests do).
"""

from __future__ import annotations

import os
import shutil
import subprocess
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


def a2perf_cli() -> str:
    """The `a2perf` binary to compare the package with: `$A2PERF_BIN` (scripts/test sets it to
    the binary its `cargo test --workspace --release` just built, so it must exist), else
    `$CARGO_TARGET_DIR/release/a2perf` or `target/release/a2perf`, else `a2perf` on PATH, else
    built here with `cargo build --release -p a2perf-cli` (skip when there is no cargo)."""
    if os.environ.get("A2PERF_BIN"):
        if not Path(os.environ["A2PERF_BIN"]).is_file():
            pytest.fail(f"A2PERF_BIN={os.environ['A2PERF_BIN']} does not exist")
        return os.environ["A2PERF_BIN"]
    target = Path(os.environ.get("CARGO_TARGET_DIR", REPO / "target"))
    if not target.is_absolute():
        target = REPO / target
    binary = target / "release" / "a2perf"
    if binary.is_file():
        return str(binary)
    on_path = shutil.which("a2perf")
    if on_path:
        return on_path
    if shutil.which("cargo") is None:
        pytest.skip("no a2perf binary (set A2PERF_BIN) and no cargo to build it")
    subprocess.run(["cargo", "build", "--release", "-p", "a2perf-cli"], cwd=REPO, check=True)
    return str(binary)


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
