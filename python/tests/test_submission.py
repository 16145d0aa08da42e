"""`a2perf submit`: the example participant folder (examples/submission/) trained, inferred,
generalized and reported in a venv made from its requirements.txt, beside a built-in PPO run;
and the folder shapes and failures the harness must handle (with `--python`, this venv).

The venv needs the a2perf_rs wheel: `$A2PERF_WHEEL` (scripts/test sets it to the wheel it
built), else the one in dist/. Without a wheel or `python3 -m venv` the venv test skips with
the reason, unless A2PERF_REQUIRE_INTEROP=1 (CI), where it fails. pip installs numpy from the
index (or pip's cache): CI has the network; offline, point pip at a wheelhouse with
PIP_FIND_LINKS and PIP_NO_INDEX=1, which the harness's pip inherits."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from conftest import REPO, a2perf_cli

EXAMPLE = REPO / "examples" / "submission"
CONFIG = "configs/circuit_training/ppo.ron"
SMALL = [
    "--set", "training.total_env_steps=192", "--set", "training.eval_episodes=2",
    "--set", "inference.rollouts=6", "--set", "generalization.episodes=2",
]


def read(path: Path):
    return json.loads(path.read_text())


def submit(*args: str, check: bool = True) -> subprocess.CompletedProcess:
    out = subprocess.run([a2perf_cli(), "submit", *args], cwd=REPO, capture_output=True,
                         text=True)
    if check:
        assert out.returncode == 0, f"{args} failed:\n{out.stdout}\n{out.stderr}"
    return out


def wheel_or_skip() -> str:
    def unavailable(reason: str) -> None:
        if os.environ.get("A2PERF_REQUIRE_INTEROP") == "1":
            pytest.fail(f"A2PERF_REQUIRE_INTEROP=1 but {reason}")
        pytest.skip(reason)

    wheel = os.environ.get("A2PERF_WHEEL")
    if not wheel:
        found = sorted((REPO / "dist").glob("a2perf_rs-*.whl"))
        if not found:
            unavailable("no a2perf_rs wheel (set A2PERF_WHEEL or run scripts/wheel)")
        wheel = str(found[-1])
    probe = subprocess.run(["python3", "-m", "venv", "--help"], capture_output=True)
    if probe.returncode != 0:
        unavailable("python3 -m venv is unavailable")
    return wheel


@pytest.fixture(scope="module")
def example(tmp_path_factory) -> dict[str, Path]:
    wheel = wheel_or_skip()
    tmp = tmp_path_factory.mktemp("submit")
    # The built-in PPO on the same task, for the shared report.
    ppo = subprocess.run(
        [a2perf_cli(), "run", CONFIG, "--seeds", "0", "--quiet", "--set",
         f"output.dir={tmp / 'builtin'}", "--set", "training.eval_interval=96",
         "--set", "training.checkpoint_interval=192", *SMALL, "-o", str(tmp / "ppo_report")],
        cwd=REPO, capture_output=True, text=True)
    assert ppo.returncode == 0, ppo.stderr
    out = submit(str(EXAMPLE), CONFIG, "--seeds", "0", "--root-dir", str(tmp / "runs"),
                 "--participant-args", "population=6,elite=2", "--wheel", wheel, *SMALL,
                 "--with", str(tmp / "builtin" / "circuit_ppo"), "-o", str(tmp / "report"))
    run_dir = next((tmp / "runs" / "submission").glob("*__submission__seed0"))
    return {"tmp": tmp, "run": run_dir, "stderr": out.stderr, "stdout": out.stdout,
            "wheel": Path(wheel)}


def test_the_example_is_trained_inferred_and_generalized_by_the_harness(example) -> None:
    run = example["run"]
    assert read(run / "status.json")["state"] == "complete"
    record = read(run / "run.json")
    assert record["external"]["harness"].startswith("a2perf submit "), record["external"]
    assert "numpy" in record["external"]["runtime"]
    assert record["algorithm"]["name"] == "submission"
    assert record["algorithm"]["params"] == {"elite": "2", "population": "6"}
    # One point per cross-entropy iteration (6 episodes of at most 12 macros), to the budget.
    curve = read(run / "curve.json")
    points = curve["points"] if isinstance(curve, dict) else curve
    steps = [p["env_steps"] for p in points]
    assert len(steps) >= 3 and steps[-1] >= 192 and steps[-2] < 192, steps
    inference = read(run / "inference.json")
    assert inference["episodes"] == 6
    assert 6 <= inference["inference_time_ms"]["count"] <= 6 * 12
    assert inference["inference_time_ms"]["mean"] > 0
    tasks = read(run / "generalization.json")["tasks"]
    assert len(tasks) == 5 and all(t["mean_return"] is not None for t in tasks), tasks
    # The code that ran and the folder's own files belong to the run; the venv does not.
    assert (run / "submission" / "code" / "train.py").read_text() == (
        EXAMPLE / "train.py").read_text()
    assert not (run / "submission" / "code" / ".venv").exists()
    assert (run / "submission" / "files" / "weights.npy").is_file()
    kinds = {m["name"]: m["provenance"]["kind"]
             for m in read(run / "train_system.json")["meters"]["measurements"]}
    assert kinds["peak_ram_gb"] in ("measured", "estimated")


def test_the_submission_sits_beside_the_builtin_ppo_in_one_report(example) -> None:
    board = read(example["tmp"] / "report" / "leaderboard.json")
    entries = {e["algorithm"]: e for e in board["entries"]}
    assert set(entries) == {"submission", "ppo"}, set(entries)
    assert entries["submission"]["task"] == entries["ppo"]["task"]
    assert entries["submission"]["metrics"]["inference_time"]["mean"] > 0
    assert (example["tmp"] / "report" / "index.html").is_file()
    assert "SUBMISSION" in (example["tmp"] / "report" / "report.md").read_text()


def test_the_venv_is_made_from_requirements_and_reused(example) -> None:
    venv = example["tmp"] / "runs" / "submission" / ".venv"
    marker = read(venv / "a2perf-submit.json")
    assert marker["requirements"] == (EXAMPLE / "requirements.txt").read_text()
    assert "python3 -m venv" in example["stderr"]
    python = venv / "bin" / "python"
    probe = subprocess.run([str(python), "-c", "import numpy, a2perf_rs; print(a2perf_rs.__file__)"],
                           capture_output=True, text=True)
    assert probe.returncode == 0 and str(venv) in probe.stdout, probe
    # Again: the venv is reused and the complete run is not trained again.
    again = submit(str(EXAMPLE), CONFIG, "--seeds", "0", "--root-dir",
                   str(example["tmp"] / "runs"), "--participant-args", "population=6,elite=2",
                   "--wheel", str(example["wheel"]), *SMALL)
    assert "(reused)" in again.stderr and "already trained" in again.stderr, again.stderr


def folder(tmp: Path, name: str, train: str, inference: str) -> Path:
    d = tmp / name
    d.mkdir()
    (d / "train.py").write_text(textwrap.dedent(train))
    (d / "inference.py").write_text(textwrap.dedent(inference))
    (d / "requirements.txt").write_text("numpy\n")
    return d


TEMPLATE_INFERENCE = """
    import os
    import numpy as np

    def load_model(env):
        return float(open(os.path.join(os.environ["ROOT_DIR"], "bias.txt")).read())

    def preprocess_observation(observation):
        return observation

    def infer_once(model, observation):
        legal = observation["grid"][2].reshape(-1) > 0.5
        return int(np.flatnonzero(legal)[int(model) % legal.sum()])
"""


FIRST_LEGAL_CELL = """
    def load_policy(env):
        return None

    def preprocess_observation(observation):
        return observation["grid"][2].reshape(-1)  # the legality channel: the action mask

    def infer_once(policy, preprocessed_observation):
        return int(preprocessed_observation.argmax())
"""


def test_a_template_folder_that_ignores_the_harness_still_trains(tmp_path) -> None:
    # The template's load_model(env) and infer_once(model, observation), a train() that uses
    # nothing of the harness but the original's ROOT_DIR and logs no evaluation.
    d = folder(tmp_path, "template", """
        import os

        def train():
            with open(os.path.join(os.environ["ROOT_DIR"], "bias.txt"), "w") as f:
                f.write("3")
    """, TEMPLATE_INFERENCE)
    submit(str(d), CONFIG, "--seeds", "1", "--root-dir", str(tmp_path / "runs"),
           "--python", sys.executable, *SMALL)
    run = next((tmp_path / "runs" / "template").glob("*seed1"))
    curve = read(run / "curve.json")
    points = curve["points"] if isinstance(curve, dict) else curve
    assert [p["env_steps"] for p in points] == [192]  # the budget: one point, by the harness
    assert read(run / "inference.json")["episodes"] == 6
    assert (tmp_path / "runs" / "template" / "report" / "report.md").is_file()


def test_preprocess_observation_may_take_the_info_dict_with_the_mask(tmp_path) -> None:
    d = folder(tmp_path, "masked", """
        def train(offset):
            pass
    """, """
        import numpy as np

        def load_policy(env, offset="0"):
            return int(offset)

        def preprocess_observation(observation, info):
            return np.flatnonzero(info["action_mask"])

        def infer_once(policy, preprocessed_observation):
            return int(preprocessed_observation[policy % len(preprocessed_observation)])
    """)
    submit(str(d), CONFIG, "--seeds", "0,1", "--root-dir", str(tmp_path / "runs"),
           "--participant-args", "offset=5", "--python", sys.executable, *SMALL)
    runs = sorted((tmp_path / "runs" / "masked").glob("*seed*"))
    assert [r.name[-5:] for r in runs] == ["seed0", "seed1"]
    for run in runs:
        assert read(run / "inference.json")["episodes"] == 6
        assert read(run / "run.json")["algorithm"]["params"] == {"offset": "5"}
    board = read(tmp_path / "runs" / "masked" / "report" / "leaderboard.json")
    assert [e["seeds"] for e in board["entries"]] == [[0, 1]], board["entries"]


def test_an_exception_in_infer_once_names_the_step_and_writes_no_inference(tmp_path) -> None:
    train = """
        from a2perf_rs import submission

        def train():
            submission.training_run().log_evaluation(1, 0.0)
    """
    d = folder(tmp_path, "bad_infer", train, FIRST_LEGAL_CELL.replace(
        "return int(preprocessed_observation.argmax())", "raise KeyError('no such cell')"))
    out = submit(str(d), CONFIG, "--seeds", "0", "--root-dir", str(tmp_path / "runs"),
                 "--python", sys.executable, *SMALL, check=False)
    assert out.returncode != 0
    assert "KeyError" in out.stderr and "no such cell" in out.stderr, out.stderr
    assert "episode 0, step 0" in out.stderr, out.stderr
    assert "inference code raised" in out.stderr, out.stderr
    run = next((tmp_path / "runs" / "bad_infer").glob("*seed0"))
    assert read(run / "status.json")["state"] == "complete"  # training did not fail
    assert not (run / "inference.json").exists()


def test_the_training_meters_cover_the_processes_train_starts(tmp_path) -> None:
    # train() starts a process that holds 400 MB for a second: the run's peak RAM counts it.
    d = folder(tmp_path, "spawner", """
        import subprocess
        import sys

        def train():
            code = "import time; b = b'x' * 400_000_000; time.sleep(1.0)"
            subprocess.run([sys.executable, "-c", code], check=True)
    """, FIRST_LEGAL_CELL)
    submit(str(d), CONFIG, "--seeds", "0", "--root-dir", str(tmp_path / "runs"),
           "--python", sys.executable, "--set", "metrics.ram_sample_interval_s=0.05", *SMALL)
    run = next((tmp_path / "runs" / "spawner").glob("*seed0"))
    peak = {m["name"]: m["value"]
            for m in read(run / "train_system.json")["meters"]["measurements"]}["peak_ram_gb"]
    assert peak > 0.4, peak


def test_a_participant_exception_fails_the_run_and_shows_its_traceback(tmp_path) -> None:
    d = folder(tmp_path, "broken", """
        def train(**kwargs):
            with open("partial.txt", "w") as f:
                f.write("written before the error")
            return 1 / 0
    """, TEMPLATE_INFERENCE)
    out = submit(str(d), CONFIG, "--seeds", "0", "--root-dir", str(tmp_path / "runs"),
                 "--python", sys.executable, *SMALL, check=False)
    assert out.returncode != 0
    assert "ZeroDivisionError" in out.stderr and "train.py" in out.stderr, out.stderr
    assert "training raised" in out.stderr and "marked failed" in out.stderr, out.stderr
    run = next((tmp_path / "runs" / "broken").glob("*seed0"))
    status = read(run / "status.json")
    assert status["state"] == "failed" and "ZeroDivisionError" in status["note"], status
    assert (run / "run.json").is_file() and (run / "submission" / "code" / "train.py").is_file()
    assert (d / "partial.txt").read_text() == "written before the error"  # cwd: the folder
    assert not (run / "inference.json").exists()


@pytest.mark.parametrize("remove, message", [
    ("inference.py", "no inference.py"),
    ("infer_once", "defines no infer_once"),
    ("load", "defines no load_policy or load_model"),
])
def test_an_incomplete_folder_is_refused_before_anything_is_written(
        tmp_path, remove: str, message: str) -> None:
    inference = TEMPLATE_INFERENCE
    if remove == "infer_once":
        inference = inference.replace("def infer_once", "def infer_twice")
    if remove == "load":
        inference = inference.replace("def load_model", "def load_it")
    d = folder(tmp_path, "incomplete", "def train():\n    pass\n", inference)
    if remove == "inference.py":
        (d / "inference.py").unlink()
    out = submit(str(d), CONFIG, "--root-dir", str(tmp_path / "runs"), "--python",
                 sys.executable, *SMALL, check=False)
    assert out.returncode != 0 and message in out.stderr, out.stderr
    assert not list((tmp_path / "runs").glob("incomplete/*seed*"))


def test_bad_participant_args_are_refused(tmp_path) -> None:
    out = submit(str(EXAMPLE), CONFIG, "--participant-args", "population=6,elite",
                 "--root-dir", str(tmp_path), "--python", sys.executable, check=False)
    assert out.returncode != 0
    assert "`elite` is not `key=value`" in out.stderr, out.stderr
    assert not any(tmp_path.iterdir())


def test_the_submission_and_the_builtin_bundle_and_verify(example) -> None:
    """Bundle → verify passes for the submission (replay; no participant code runs) and for the
    built-in PPO beside it (replay and the checkpoint re-run). The tampering cases are tested on
    bundles in a2perf-pipeline/tests and a2perf-cli/tests."""
    tmp = example["tmp"]
    cli = a2perf_cli()
    for name, runs in [("submission", example["run"]),
                       ("builtin", tmp / "builtin" / "circuit_ppo")]:
        bundle = tmp / f"{name}.a2perf"
        packed = subprocess.run([cli, "bundle", str(runs), "-o", str(bundle)], cwd=REPO,
                                capture_output=True, text=True)
        assert packed.returncode == 0, packed.stderr
        verified = subprocess.run([cli, "verify", str(bundle)], cwd=REPO, capture_output=True,
                                  text=True)
        assert verified.returncode == 0, f"{name}:\n{verified.stdout}\n{verified.stderr}"
        assert "FAILS" not in verified.stdout, verified.stdout
    # The submission's folder travels in its bundle.
    import tarfile
    with tarfile.open(tmp / "submission.a2perf", "r:gz") as tar:
        names = tar.getnames()
    assert any(n.endswith("submission/code/train.py") for n in names), names


def test_seeds_run_side_by_side_with_jobs_give_the_same_results(example) -> None:
    # Seeds 0 and 1 two at a time, in the venv the fixture made: both complete, and seed 0 is
    # what the fixture's one-at-a-time submission of seed 0 gave (curve and rollouts).
    python = example["tmp"] / "runs" / "submission" / ".venv" / "bin" / "python"
    root = example["tmp"] / "jobs"
    out = submit(str(EXAMPLE), CONFIG, "--seeds", "0,1", "--jobs", "2", "--root-dir",
                 str(root), "--participant-args", "population=6,elite=2", "--python",
                 str(python), *SMALL)
    runs = sorted((root / "submission").glob("*__submission__seed*"))
    assert [r.name[-5:] for r in runs] == ["seed0", "seed1"], out.stderr
    for run in runs:
        assert read(run / "status.json")["state"] == "complete"
        assert len(read(run / "generalization.json")["tasks"]) == 5
    def curve(run: Path) -> list:
        points = read(run / "curve.json")["points"]
        return [(p["env_steps"], p["mean_return"], p["std_return"]) for p in points]

    assert curve(runs[0]) == curve(example["run"])
    ours, before = read(runs[0] / "inference.json"), read(example["run"] / "inference.json")
    assert ours["rollout_returns"] == before["rollout_returns"]
    assert out.stderr.count("== train") == 2, out.stderr
    board = read(root / "submission" / "report" / "leaderboard.json")
    assert [e["seeds"] for e in board["entries"]] == [[0, 1]], board["entries"]
