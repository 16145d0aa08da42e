"""A Python agent in the same report as a built-in one: the numpy example (examples/python/)
trained with TrainingRun, inferred and generalized from Python, and a PPO run trained by the
`a2perf` CLI, merged by `a2perf report` (and by `a2perf_rs.report`) into one set of tables,
radar plots and leaderboard entries. Tiny budgets: this checks the plumbing, not the learning.

The CLI is the one `conftest.a2perf_cli` finds (in `scripts/test`: the binary its `cargo test`
just built)."""

from __future__ import annotations

import csv
import importlib.util
import json
import subprocess
import sys
from pathlib import Path

import pytest

import a2perf_rs
from conftest import REPO, a2perf_cli

EXAMPLE = REPO / "examples" / "python"
TASK = "WebNavigation-Difficulty-01-v0[num_websites=1]"


def run(*args: str, cwd: Path = REPO) -> str:
    out = subprocess.run(list(args), cwd=cwd, capture_output=True, text=True)
    assert out.returncode == 0, f"{args} failed:\n{out.stdout}\n{out.stderr}"
    return out.stdout


def read(path: Path):
    return json.loads(path.read_text())


@pytest.fixture(scope="module")
def results(tmp_path_factory) -> dict[str, Path]:
    tmp = tmp_path_factory.mktemp("python_vs_ppo")
    cli = a2perf_cli()
    # The built-in PPO on the same task, trained, inferred and generalized by the CLI.
    run(cli, "run", "configs/web_navigation/ppo.ron", "--seeds", "0", "--quiet",
        "--set", f"output.dir={tmp / 'cli'}",
        "--set", "training.total_env_steps=512", "--set", "training.eval_interval=256",
        "--set", "training.checkpoint_interval=512", "--set", "training.eval_episodes=3",
        "--set", "inference.rollouts=5", "--set", "generalization.episodes=2",
        "-o", str(tmp / "cli_report"))
    # The numpy agent, as the README runs it (its own report beside the PPO run included).
    stdout = run(sys.executable, str(EXAMPLE / "numpy_q_agent.py"), "--out", str(tmp / "py"),
                 "--steps", "300", "--episodes", "5", "--generalization-episodes", "2",
                 "--report-with", str(tmp / "cli" / "web_ppo"), "--report", str(tmp / "py_report"))
    assert "numpy-q on " + TASK in stdout and "ppo on " + TASK in stdout, stdout
    # One report of both from the CLI.
    run(cli, "report", str(tmp / "py"), str(tmp / "cli" / "web_ppo"), "-o", str(tmp / "report"),
        "--bootstrap-reps", "2000")
    runs = {
        "numpy-q": next((tmp / "py" / "numpy-q").iterdir()),
        "ppo": next((tmp / "cli" / "web_ppo").iterdir()),
    }
    return {"tmp": tmp, "report": tmp / "report", **runs}


def test_the_python_run_has_every_file_of_a_cli_run(results) -> None:
    py, ppo = results["numpy-q"], results["ppo"]
    cli_files = {p.name for p in ppo.iterdir()}
    py_files = {p.name for p in py.iterdir()}
    # Everything the CLI writes, except the built-in algorithm's own policy and resume files.
    builtin_only = {"policy.ckpt", "resume", "train_state"}
    assert cli_files - builtin_only <= py_files, sorted(cli_files - py_files)
    for run_dir in (py, ppo):
        assert read(run_dir / "status.json")["state"] == "complete"
        inference = read(run_dir / "inference.json")
        assert inference["episodes"] == 5 and inference["inference_time_ms"]["count"] > 0
        assert len(read(run_dir / "generalization.json")["tasks"]) == 5
    assert read(py / "run.json")["external"]["harness"].startswith("a2perf_rs")
    assert len(list((py / "checkpoints").iterdir())) >= 1


def test_one_report_lists_both_in_tables_radar_and_leaderboard(results) -> None:
    report = results["report"]
    md = (report / "report.md").read_text()
    section = md.split(f"## {TASK}", 1)[1].split("\n## ", 1)[0]
    header = next(line for line in section.splitlines() if line.startswith("| Category"))
    assert "NUMPY-Q (seeds 1)" in header and "PPO (seeds 1)" in header, header
    tex = (report / "report.tex").read_text()
    assert "NUMPY-Q" in tex and "PPO" in tex
    with open(report / "metrics.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    assert {r["algorithm"] for r in rows if r["task"] == TASK} == {"numpy-q", "ppo"}
    keys = {(r["algorithm"], r["metric"]) for r in rows}
    assert {(a, m) for a in ("numpy-q", "ppo") for m in ("returns", "energy", "inference_time",
                                                         "generalization")} <= keys
    radars = list((report / "plots").glob("radar_*.svg"))
    assert len(radars) == 1
    svg = radars[0].read_text()
    assert "NUMPY-Q" in svg and "PPO" in svg
    board = read(report / "leaderboard.json")
    entries = {e["algorithm"]: e for e in board["entries"]}
    assert set(entries) == {"numpy-q", "ppo"}
    assert entries["numpy-q"]["task"] == entries["ppo"]["task"] == TASK
    assert entries["numpy-q"]["run"]["external"] is not None
    assert entries["ppo"]["run"].get("external") is None
    assert entries["numpy-q"]["run"]["algorithm"]["params"]["gamma"] == 0.95
    assert read(report / "report.json")["skipped_runs"] == []


def test_the_python_run_has_system_metrics_measured_or_labelled_estimated(results) -> None:
    board = read(results["report"] / "leaderboard.json")
    metrics = next(e for e in board["entries"] if e["algorithm"] == "numpy-q")["metrics"]
    train_system = read(results["numpy-q"] / "train_system.json")
    kinds = {m["name"]: m["provenance"]["kind"] for m in train_system["meters"]["measurements"]}
    for key, meter in [("energy", "energy_kwh"), ("peak_ram", "peak_ram_gb"),
                       ("mean_ram", "mean_ram_gb"), ("wall_clock", "wall_clock_h")]:
        m = metrics[key]
        assert m["mean"] is not None and m["mean"] > 0, (key, m)
        assert kinds[meter] in ("measured", "estimated"), (meter, kinds)
        if kinds[meter] == "estimated":
            assert "estimated" in (m["note"] or ""), (key, m)
    for key in ("inference_time", "inference_energy", "inference_peak_ram"):
        assert metrics[key]["mean"] is not None and metrics[key]["mean"] > 0, (key, metrics[key])
    emissions = (results["numpy-q"] / "train_emissions.csv").read_text().splitlines()
    assert len(emissions) == 2


def test_python_and_cli_reports_agree(results) -> None:
    tmp = results["tmp"]
    cli = read(results["report"] / "report.json")
    # The example's own report (a2perf_rs.report, the runs' recorded 50,000 resamples) and
    # one from Python with the CLI's settings: the same groups and, at equal settings, values.
    assert [g["algorithm"] for g in read(tmp / "py_report" / "report.json")["groups"]] == [
        "numpy-q", "ppo"]
    again = a2perf_rs.report([tmp / "py", tmp / "cli" / "web_ppo"], tmp / "again",
                             bootstrap_reps=2000)
    assert again["groups"] == cli["groups"]
    assert (tmp / "again" / "report.md").read_text() == (results["report"] / "report.md").read_text()


def test_offline_datasets_from_the_examples_checkpoints(results) -> None:
    spec = importlib.util.spec_from_file_location("numpy_q_agent", EXAMPLE / "numpy_q_agent.py")
    example = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(example)
    summary = a2perf_rs.collect(results["tmp"] / "py", example.load_policy,
                                results["tmp"] / "datasets", eval_episodes=3, dataset_episodes=2)
    checkpoints = sorted((results["numpy-q"] / "checkpoints").iterdir())
    assert len(summary["evaluations"]) == len(checkpoints)
    assert summary["datasets"], summary
    for d in summary["datasets"]:
        assert (Path(d["path"]) / "samples.json").is_file()


def test_the_pytorch_example_compiles() -> None:
    # Documented, not run here (the tests do not install PyTorch).
    path = EXAMPLE / "torch_ppo.py"
    compile(path.read_text(), str(path), "exec")
