"""`a2perf_rs.verify`: a bundle made by the `a2perf` CLI from a tiny built-in run verifies from
Python with the same checks as `a2perf verify`. A truncated bundle raises ValueError. Tiny
budgets: this checks the plumbing. The replay and tampering cases are tested in Rust
(a2perf-pipeline/tests/bundle_verify.rs)."""

from __future__ import annotations

import subprocess
from pathlib import Path

import pytest

import a2perf_rs
from conftest import REPO, a2perf_cli


@pytest.fixture(scope="module")
def bundle(tmp_path_factory) -> Path:
    tmp = tmp_path_factory.mktemp("bundle")
    cli = a2perf_cli()
    sets = [
        "output.dir=results",
        "training.total_env_steps=480",
        "training.eval_interval=240",
        "algorithm.learning_starts=96",
        "inference.rollouts=3",
        "generalization.episodes=1",
        "metrics.bootstrap_reps=100",
    ]
    args = [cli, "run", str(REPO / "configs/circuit_training/ddqn.ron"), "--seeds", "0", "--quiet"]
    for s in sets:
        args += ["--set", s]
    subprocess.run(args + ["-o", "report"], cwd=tmp, check=True, capture_output=True)
    subprocess.run(
        [cli, "bundle", "results/circuit_ddqn", "-o", "run.a2perf"],
        cwd=tmp,
        check=True,
        capture_output=True,
    )
    return tmp / "run.a2perf"


def test_a_cli_bundle_verifies_from_python(bundle: Path) -> None:
    v = a2perf_rs.verify(bundle)
    assert v["holds"] is True, v
    outcomes = {c["what"]: c["outcome"] for c in v["checks"]}
    assert outcomes["manifest"] == "holds"
    assert outcomes["inference returns (replayed)"] == "holds"
    assert outcomes["generalization returns (replayed)"] == "holds"
    assert outcomes["checkpoint re-run (greedy actions)"] == "holds"
    assert all(set(c) == {"run", "what", "outcome", "detail"} for c in v["checks"])


def test_a_truncated_bundle_raises(bundle: Path, tmp_path: Path) -> None:
    cut = tmp_path / "cut.a2perf"
    data = bundle.read_bytes()
    cut.write_bytes(data[: len(data) // 2])
    with pytest.raises(ValueError, match="cut.a2perf"):
        a2perf_rs.verify(cut)
