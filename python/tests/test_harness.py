"""The harness for Python agents: TrainingRun records a run as `a2perf train` does, infer and
generalize roll Python callables out in the Rust environments, and every bad input is refused
with an exception that names it, writing nothing half."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

import a2perf_rs
from a2perf_rs import _native

WEB = "WebNavigation-Difficulty-01-v0"
WEB_PARAMS = {"num_websites": 1}
PACE = "QuadrupedLocomotion-DogPace-v0"


def first_legal(obs, info):
    """A deterministic legal policy for masked environments."""
    return int(np.argmax(info["action_mask"]))


def training_run(out: Path, seed: int = 0, **kwargs) -> a2perf_rs.TrainingRun:
    kwargs.setdefault("env_id", WEB)
    kwargs.setdefault("env_params", WEB_PARAMS)
    kwargs.setdefault("algorithm", "py-agent")
    kwargs.setdefault("set", ["training.eval_episodes=2", "inference.rollouts=3",
                              "generalization.episodes=1"])
    return a2perf_rs.TrainingRun(out, seed=seed, **kwargs)


def complete_run(out: Path, seed: int = 0, **kwargs) -> Path:
    with training_run(out, seed, **kwargs) as run:
        run.evaluate(10, first_legal)
    return run.run_dir


def read(path: Path):
    return json.loads(path.read_text())


def test_training_run_writes_what_a2perf_train_writes(tmp_path: Path) -> None:
    run = training_run(tmp_path, hyperparameters={"lr": 0.1, "hidden": [8, 8], "tag": "x"})
    # The directory a2perf train would use: <out>/<experiment>/<task>__<algorithm>__seed<k>.
    assert run.task == "WebNavigation-Difficulty-01-v0[num_websites=1]"
    assert run.run_dir == tmp_path / "py-agent" / (
        "WebNavigation-Difficulty-01-v0_num_websites_1___py-agent__seed0"
    )
    assert not run.run_dir.exists(), "nothing is written before the block"
    ckpt = tmp_path / "weights.npz"
    np.savez(ckpt, w=np.arange(3.0))
    with run:
        assert read(run.run_dir / "status.json")["state"] == "running"
        env = run.make_env()
        obs, info = env.reset()
        for _ in range(3):
            obs, *_ = env.step(first_legal(obs, info))
        run.log_evaluation(100, -1.0, 0.5)
        mean, std = run.evaluate(200, first_legal)
        stored = run.save_checkpoint(200, ckpt)
    assert read(run.run_dir / "status.json")["state"] == "complete"
    names = sorted(p.name for p in run.run_dir.iterdir())
    assert names == sorted([
        "checkpoints", "curve.csv", "curve.json", "operative_config.ron", "run.json",
        "status.json", "system_info.json", "train_emissions.csv", "train_segments.json",
        "train_system.json", "train.lock",
    ])
    # The training lock was released and its record emptied when the block was left.
    assert (run.run_dir / "train.lock").read_text() == ""
    record = read(run.run_dir / "run.json")
    assert record["algorithm"] == {"name": "py-agent",
                                   "params": {"hidden": [8, 8], "lr": 0.1, "tag": "x"}}
    assert record["task"]["env_params"]["num_websites"] == 1
    assert record["external"]["runtime"].startswith(("CPython", "PyPy"))
    assert "numpy" in record["external"]["runtime"]
    curve = read(run.run_dir / "curve.json")["points"]
    assert [(p["env_steps"], p["mean_return"]) for p in curve] == [(100, -1.0), (200, mean)]
    assert curve[1]["std_return"] == pytest.approx(std)
    lines = (run.run_dir / "curve.csv").read_text().splitlines()
    assert lines[0] == "env_steps,mean_return,std_return,wall_seconds" and len(lines) == 3
    assert stored == run.run_dir / "checkpoints" / "step_000000000200.ckpt"
    assert np.load(stored)["w"].tolist() == [0.0, 1.0, 2.0]
    # The same Rust meters as a built-in run: RAM, energy (measured or labelled estimated).
    system = read(run.run_dir / "train_system.json")
    meters = {m["name"]: m for m in system["meters"]["measurements"]}
    assert meters["peak_ram_gb"]["value"] > 0.01
    energy = meters["energy_kwh"]
    assert energy["value"] > 0 and energy["provenance"]["kind"] in ("measured", "estimated")
    if energy["provenance"]["kind"] == "estimated":
        assert energy["provenance"]["method"], "an estimate says how it was made"
    emissions = (run.run_dir / "train_emissions.csv").read_text().splitlines()
    assert len(emissions) == 2 and "energy_consumed" in emissions[0]


def test_environments_are_seeded_from_the_run_like_the_builtin_ones(tmp_path: Path) -> None:
    run = training_run(tmp_path, seed=5)
    env = run.make_env(index=1)
    ref = a2perf_rs.A2PerfEnv(WEB, **WEB_PARAMS)
    for episode in range(2):
        obs, _ = env.reset()
        want, _ = ref.reset(seed=_native.episode_seed(5, 1, episode))
        for key in obs:
            np.testing.assert_array_equal(obs[key], want[key])
    vec = run.make_vec(2)
    obs, infos = vec.reset()
    for i in range(2):
        want, _ = ref.reset(seed=_native.episode_seed(5, i, 0))
        np.testing.assert_array_equal(obs["dom_tokens"][i], want["dom_tokens"])
    # Autoresets take each environment's next seed too.
    for _ in range(60):
        obs, _, term, trunc, infos = vec.step(np.zeros(2, dtype=np.int64))
        if term[0] or trunc[0]:
            break
    else:
        pytest.fail("the first episode did not end")
    obs, *_ = vec.step(np.zeros(2, dtype=np.int64))  # next-step autoreset
    want, _ = ref.reset(seed=_native.episode_seed(5, 0, 1))
    np.testing.assert_array_equal(obs["dom_tokens"][0], want["dom_tokens"])
    vec.close()


def test_same_seed_same_results(tmp_path: Path) -> None:
    def run_once(out: Path) -> tuple[list, list]:
        rng = np.random.default_rng(3)
        with training_run(out, seed=3) as run:
            env = run.make_env()
            obs, info = env.reset()
            returns = []
            for _ in range(40):
                obs, r, term, trunc, info = env.step(
                    int(rng.choice(np.flatnonzero(info["action_mask"]))))
                returns.append(r)
                if term or trunc:
                    obs, info = env.reset()
            run.evaluate(40, first_legal)
        inf = a2perf_rs.infer(run.run_dir, first_legal)
        curve = [p["mean_return"] for p in read(run.run_dir / "curve.json")["points"]]
        return returns + curve, inf["rollout_returns"]

    assert run_once(tmp_path / "a") == run_once(tmp_path / "b")


def test_infer_and_generalize_write_what_the_cli_writes(tmp_path: Path) -> None:
    run_dir = complete_run(tmp_path)
    calls = []

    def policy(obs, info):
        calls.append(obs)
        assert set(obs) == {"profile_keys", "profile_values", "profile_mask", "dom_tokens",
                            "dom_features", "dom_mask", "time_step"}
        assert obs["dom_tokens"].dtype == np.int32 and obs["dom_tokens"].shape == (250, 5, 10)
        assert info["action_mask"].dtype == np.int8 and info["action_mask"].shape == (12500,)
        return first_legal(obs, info)

    inf = a2perf_rs.infer(run_dir, policy)
    assert inf == read(run_dir / "inference.json")
    assert inf["episodes"] == 3 and len(inf["rollout_returns"]) == 3
    assert inf["rollout_call_time_ms"]["count"] == len(calls) == sum(inf["episode_lengths"])
    assert inf["observation_source"] == "rollouts"
    assert calls[0] is not calls[1], "a fresh observation at every call"
    assert (run_dir / "inference_emissions.csv").is_file()
    gen = a2perf_rs.generalize(run_dir, first_legal, episodes=1)
    assert gen == read(run_dir / "generalization.json")
    assert len(gen["tasks"]) == 5 and gen["sum_of_mean_returns"] is not None
    # The callable may take the observation only; random observations are timed on request.
    inf = a2perf_rs.infer(run_dir, lambda obs: 0, episodes=1, observation_source="random",
                          timing_samples=20)
    assert inf["random_observation_time_ms"]["count"] == 20


def test_continuous_actions_are_checked_like_env_step(tmp_path: Path) -> None:
    with training_run(tmp_path, env_id=PACE, env_params={"episode_steps": 20}) as run:
        run.log_evaluation(1, 0.0)
    zero = np.zeros(12, dtype=np.float32)
    inf = a2perf_rs.infer(run.run_dir, lambda obs: zero, episodes=2)
    assert inf["episode_lengths"] == [20, 20]
    with pytest.raises(ValueError, match=r"episode 0, step 0 .*shape \[3\], expected \[12\]"):
        a2perf_rs.infer(run.run_dir, lambda obs: np.zeros(3, np.float32), episodes=2)
    with pytest.raises(ValueError, match=r"episode 0, step 0 .*outside the action space"):
        a2perf_rs.infer(run.run_dir, lambda obs: np.full(12, 7.0), episodes=2)  # bounds ±2π


# -- bad input --------------------------------------------------------------------------------


def test_a_policy_that_raises_names_episode_and_step_and_writes_nothing(tmp_path: Path) -> None:
    run_dir = complete_run(tmp_path)
    calls = {"n": 0}

    def flaky(obs, info):
        calls["n"] += 1
        if calls["n"] == 30:
            raise ZeroDivisionError("boom")
        return first_legal(obs, info)

    with pytest.raises(ZeroDivisionError) as err:
        a2perf_rs.infer(run_dir, flaky)
    # The first legal action loops until the 25-step limit: call 30 is episode 1, step 4.
    assert "episode 1, step 4 (counted from 0)" in str(err.value)
    assert "the policy raised ZeroDivisionError: boom" in str(err.value)
    assert isinstance(err.value.__cause__, ZeroDivisionError)
    assert not (run_dir / "inference.json").exists()
    assert not (run_dir / "inference_emissions.csv").exists()

    calls["n"] = 0
    with pytest.raises(ZeroDivisionError, match="on difficulty_level_1_num_websites_1"):
        a2perf_rs.generalize(run_dir, flaky, episodes=2)
    assert not (run_dir / "generalization.json").exists()

    # A completed inference is not touched by a failed one afterwards.
    a2perf_rs.infer(run_dir, first_legal)
    before = (run_dir / "inference.json").read_bytes()
    emissions = (run_dir / "inference_emissions.csv").read_bytes()
    calls["n"] = 0
    with pytest.raises(ZeroDivisionError):
        a2perf_rs.infer(run_dir, flaky)
    assert (run_dir / "inference.json").read_bytes() == before
    assert (run_dir / "inference_emissions.csv").read_bytes() == emissions


def test_actions_outside_the_space_or_the_mask_are_refused(tmp_path: Path) -> None:
    run_dir = complete_run(tmp_path)
    with pytest.raises(ValueError, match=r"episode 0, step 0 .*action 12500 is outside Discrete"):
        a2perf_rs.infer(run_dir, lambda obs: 12500)
    with pytest.raises(ValueError, match=r"episode 0, step 0 .*masked out"):
        a2perf_rs.infer(run_dir, lambda obs: 1)
    with pytest.raises(TypeError, match=r"episode 0, step 0 .*must be one integer"):
        a2perf_rs.infer(run_dir, lambda obs: "click")
    with pytest.raises(TypeError, match="not float"):
        a2perf_rs.infer(run_dir, lambda obs: 0.0)
    assert not (run_dir / "inference.json").exists()


def test_non_callable_policies_are_refused(tmp_path: Path) -> None:
    run_dir = complete_run(tmp_path)
    with pytest.raises(TypeError, match="policy must be callable .*got int"):
        a2perf_rs.infer(run_dir, 3)
    with pytest.raises(TypeError, match="takes no positional argument"):
        a2perf_rs.generalize(run_dir, lambda: 0)
    with pytest.raises(TypeError, match="requires 3 arguments"):
        a2perf_rs.infer(run_dir, lambda obs, info, extra: 0)
    with pytest.raises(TypeError, match="policy must be callable"):
        with training_run(tmp_path / "x") as run:
            run.evaluate(1, "greedy")
    assert not (run_dir / "inference.json").exists()


def test_run_directories_that_are_not_runs_are_refused(tmp_path: Path) -> None:
    with pytest.raises(FileNotFoundError, match="no such run directory"):
        a2perf_rs.infer(tmp_path / "missing", first_legal)
    with pytest.raises(ValueError, match="not a run directory"):
        a2perf_rs.generalize(tmp_path, first_legal)
    # A run that did not complete, and a built-in run, are not inferred from Python.
    with pytest.raises(ZeroDivisionError):
        with training_run(tmp_path / "f") as run:
            raise ZeroDivisionError("x")
    with pytest.raises(ValueError, match="training did not complete"):
        a2perf_rs.infer(run.run_dir, first_legal)
    record = read(run.run_dir / "run.json")
    del record["external"]
    (run.run_dir / "run.json").write_text(json.dumps(record))
    with pytest.raises(ValueError, match="built-in algorithm `py-agent`"):
        a2perf_rs.infer(run.run_dir, first_legal)


def test_a_block_left_by_an_exception_is_failed_kept_and_listed(tmp_path: Path) -> None:
    good = complete_run(tmp_path, seed=0)
    ckpt = tmp_path / "w.bin"
    ckpt.write_bytes(b"weights")
    with pytest.raises(RuntimeError, match="diverged"):
        with training_run(tmp_path, seed=1) as run:
            run.log_evaluation(50, -2.0)
            run.save_checkpoint(50, ckpt)
            raise RuntimeError("diverged")
    status = read(run.run_dir / "status.json")
    assert status == {"state": "failed", "note": "failed: RuntimeError: diverged"}
    assert (run.run_dir / "checkpoints" / "step_000000000050.ckpt").read_bytes() == b"weights"
    assert len(read(run.run_dir / "curve.json")["points"]) == 1
    segments = read(run.run_dir / "train_segments.json")["segments"]
    assert segments[0]["outcome"] == "failed" and segments[0]["system"] is not None
    with pytest.raises(RuntimeError, match="the training run is over"):
        run.log_evaluation(60, 0.0)

    with pytest.raises(KeyboardInterrupt):
        with training_run(tmp_path, seed=2) as stopped:
            raise KeyboardInterrupt
    assert read(stopped.run_dir / "status.json")["state"] == "interrupted"

    with pytest.raises(ValueError, match="logged no evaluation"):
        with training_run(tmp_path, seed=3) as silent:
            pass
    assert read(silent.run_dir / "status.json")["state"] == "failed"

    a2perf_rs.infer(good, first_legal)
    report = a2perf_rs.report(tmp_path / "py-agent", tmp_path / "report", bootstrap_reps=100)
    assert [g["seeds"] for g in report["groups"]] == [[0]]
    skipped = dict(report["skipped_runs"])
    assert skipped[str(run.run_dir)] == "training failed: RuntimeError: diverged"
    assert skipped[str(stopped.run_dir)].startswith("training interrupted: KeyboardInterrupt")
    assert skipped[str(silent.run_dir)].startswith("training failed: the agent logged no")
    md = (tmp_path / "report" / "report.md").read_text()
    assert "training failed: RuntimeError: diverged" in md

    # Rerunning a failed run starts it again; a complete one is refused.
    with training_run(tmp_path, seed=1) as rerun:
        assert not (rerun.run_dir / "checkpoints").exists()
        rerun.log_evaluation(10, 0.0)
    with pytest.raises(ValueError, match="already complete"):
        with training_run(tmp_path, seed=1):
            pass


def test_bad_training_run_arguments_name_the_problem(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="built-in algorithm"):
        training_run(tmp_path, algorithm="ppo")
    with pytest.raises(TypeError, match="did you mean `num_websites`"):
        training_run(tmp_path, env_params={"num_website": 1})
    with pytest.raises(ValueError, match="hyperparameter `net`: a map"):
        training_run(tmp_path, hyperparameters={"net": {"hidden": 8}})
    with pytest.raises(ValueError, match="unknown environment|no environment|Unknown"):
        training_run(tmp_path, env_id="Nope-v0")
    with pytest.raises(ValueError, match="did you mean `training`"):
        training_run(tmp_path, set=["trainig.eval_episodes=2"])
    with pytest.raises(ValueError, match="seed must be a non-negative integer"):
        training_run(tmp_path, seed=-1)
    run = training_run(tmp_path)
    with pytest.raises(RuntimeError, match="use it as a context manager"):
        run.log_evaluation(1, 0.0)
    with run:
        with pytest.raises(ValueError, match="does not increase"):
            run.log_evaluation(5, 0.0)
            run.log_evaluation(5, 0.0)
        with pytest.raises(ValueError, match="must be finite"):
            run.log_evaluation(6, float("nan"))
        with pytest.raises(ValueError, match="is not a file"):
            run.save_checkpoint(6, tmp_path / "missing.npz")


def test_a_config_gives_exactly_a_builtin_runs_task(tmp_path: Path) -> None:
    from conftest import REPO

    config = REPO / "configs" / "web_navigation" / "ppo.ron"
    run = a2perf_rs.TrainingRun(tmp_path, algorithm="py-agent", config=config,
                                set=["inference.rollouts=7"])
    assert run.task == "WebNavigation-Difficulty-01-v0[num_websites=1]"
    assert run.training["num_envs"] == 4 and run.training["total_env_steps"] == 20_000
    assert run.run_dir.parent == tmp_path / "py-agent"
    with run:
        run.log_evaluation(1, 0.0)
    record = read(run.run_dir / "run.json")
    assert record["inference"]["episodes"] == 7
    assert "algorithm" in (run.run_dir / "operative_config.ron").read_text()


def test_collect_loads_python_checkpoints(tmp_path: Path) -> None:
    for seed in (0, 1):
        with training_run(tmp_path, seed=seed) as run:
            for step in (10, 20):
                path = tmp_path / "policy.json"
                path.write_text(json.dumps({"kind": "first_legal", "step": step}))
                run.save_checkpoint(step, path)
                run.evaluate(step, first_legal)
    loaded = []

    def load_policy(path: str):
        loaded.append(json.loads(Path(path).read_text())["step"])
        return first_legal

    summary = a2perf_rs.collect(tmp_path / "py-agent", load_policy, tmp_path / "datasets",
                                eval_episodes=2, dataset_episodes=2, one_sigma=True)
    assert set(loaded) == {10, 20} and len(loaded) >= 4
    assert len(summary["evaluations"]) == 4
    assert summary["datasets"], summary
    for d in summary["datasets"]:
        assert (Path(d["path"]) / "samples.json").is_file()
    with pytest.raises(TypeError, match="load_policy must be callable"):
        a2perf_rs.collect(tmp_path / "py-agent", "load", tmp_path / "d2")
    with pytest.raises(TypeError, match=r"returned a policy that must be callable"):
        a2perf_rs.collect(tmp_path / "py-agent", lambda path: None, tmp_path / "d3",
                          eval_episodes=1, dataset_episodes=1)
    with pytest.raises(FileNotFoundError, match=r"load_policy failed: FileNotFoundError"):
        a2perf_rs.collect(tmp_path / "py-agent", lambda path: open("/nonexistent/x"),
                          tmp_path / "d4", eval_episodes=1, dataset_episodes=1)


def test_a_run_being_trained_is_refused_naming_its_trainer(tmp_path: Path) -> None:
    import os
    import socket
    import subprocess
    import sys
    import textwrap

    # Another process trains the run (its block is open); this one may not.
    holder = subprocess.Popen(
        [sys.executable, "-c", textwrap.dedent(f"""
            import sys, a2perf_rs
            with a2perf_rs.TrainingRun({str(tmp_path)!r}, algorithm="py-agent", env_id={WEB!r},
                                       env_params={WEB_PARAMS!r}) as run:
                print("holding", flush=True)
                sys.stdin.readline()
                run.log_evaluation(10, 0.0, 0.0)
        """)],
        stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True,
    )
    try:
        assert holder.stdout.readline().strip() == "holding"
        rival = training_run(tmp_path)
        with pytest.raises(a2perf_rs.RunLockedError) as caught:
            rival.__enter__()
        text = str(caught.value)
        assert f"pid {holder.pid} on " in text and str(rival.run_dir) in text, text
        assert socket.gethostname() in text or "unknown host" in text, text
        # Left alone: the holder's run is still running, and finishes normally.
        assert read(rival.run_dir / "status.json")["state"] == "running"
        holder.stdin.write("\n")
        holder.stdin.flush()
        assert holder.wait(timeout=60) == 0
    finally:
        if holder.poll() is None:
            holder.kill()
            holder.wait()
    assert read(rival.run_dir / "status.json")["state"] == "complete"
    # Released with its process: a second block of this process takes the lock, and a block of
    # the same run in this process refuses a third one.
    first = training_run(tmp_path, seed=1)
    with first:
        with pytest.raises(a2perf_rs.RunLockedError, match=f"pid {os.getpid()} on "):
            training_run(tmp_path, seed=1).__enter__()
        first.log_evaluation(10, 0.0, 0.0)


def test_report_with_the_papers_tables_adds_verdicts_and_comparison_json(tmp_path: Path) -> None:
    # As `a2perf report --paper`: the paper's figures (here a one-task test paper) beside ours,
    # a verdict per return, and comparison.json; a bad tables file is refused before anything
    # is written.
    run_dir = complete_run(tmp_path, seed=0)
    a2perf_rs.infer(run_dir, first_legal)
    ours = read(run_dir / "inference.json")
    tables = {
        "schema": "a2perf-paper-tables/2",
        "paper": {"title": "Test paper", "version": "test v1"},
        "tasks": [{
            "id": "web_one", "title": "Web, one website", "domain": "web_navigation",
            "table": "Table 1", "env_id": WEB, "params": WEB_PARAMS,
            "algorithms": {"py-agent": {"returns": {
                "mean": 1e6, "std": 1.0, "unit": "100 eps.", "paper_metric": "Returns",
                "phase": "training", "source": "Table 1, row 'Returns'"}}},
        }],
    }
    path = tmp_path / "tables.json"
    path.write_text(json.dumps(tables))
    report = a2perf_rs.report(tmp_path / "py-agent", tmp_path / "report", bootstrap_reps=100,
                              paper=path)
    [comparison] = report["paper"]
    [cell] = comparison["columns"][0]["cells"]
    assert cell["key"] == "returns" and cell["verdict"] == "trails"
    assert ours["returns"]["mean"] < 1e6
    cmp = read(tmp_path / "report" / "comparison.json")
    assert [(c["task"], c["verdict"]) for c in cmp["cells"]] == [("web_one", "trails")]
    assert "(paper)" in (tmp_path / "report" / "report.md").read_text()

    tables["tasks"][0]["algorithms"]["py-agent"]["returns"]["std"] = -1.0
    path.write_text(json.dumps(tables))
    with pytest.raises(ValueError, match="tables.json"):
        a2perf_rs.report(tmp_path / "py-agent", tmp_path / "report2", paper=path)
    assert not (tmp_path / "report2").exists()
