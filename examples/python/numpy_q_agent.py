"""A complete agent in plain numpy, benchmarked exactly like the built-in baselines.

Tabular Q-learning on web navigation, difficulty level 1 with one website (the task of
``configs/web_navigation/ppo.ron``, so that the agent lands in the same report table as the
built-in PPO). A state is the set of legal actions plus which page elements were already acted
on and which profile field each holds; the agent learns one Q-value per (state, legal action)
with epsilon-greedy exploration. It needs no GPU and no PyTorch: it solves the task within a few
hundred environment steps, and the whole script (3,000 steps per seed, inference and the
generalization suite) takes seconds.

The benchmark does the rest, with the same Rust meters and files as ``a2perf train``:

1. ``a2perf_rs.TrainingRun``: the run directory, system meters over the training block
   (RAM of the process tree, energy, wall clock, emissions), environments seeded from the run's
   seed, the training curve (``run.evaluate``: the built-in evaluation protocol) and checkpoints;
2. ``a2perf_rs.infer`` / ``a2perf_rs.generalize``: rollouts of the greedy policy in the Rust
   environments, every call timed;
3. ``a2perf_rs.report``: one report with any other runs (e.g. the built-in PPO's).

Run from the repository root (after ``pip install ./python``)::

    python examples/python/numpy_q_agent.py --out results/python_agent
    python examples/python/numpy_q_agent.py --out results/python_agent \\
        --report-with results/web_ppo --report results/python_vs_ppo
"""

from __future__ import annotations

import argparse
import hashlib
import json
import sys
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

import a2perf_rs

ENV_ID = "WebNavigation-Difficulty-01-v0"
ENV_PARAMS = {"num_websites": 1}
ALGORITHM = "numpy-q"


def state_key(obs: dict[str, np.ndarray], mask: np.ndarray) -> str:
    """The legal actions, and for every element already acted on (``dom_features`` column 1)
    which profile field's value it holds: on a fixed website these tell the page and the
    progress on it (right or wrong), whatever the profile's values are in this episode."""
    acted = np.flatnonzero(obs["dom_features"][:, 1])
    values = obs["dom_tokens"][acted, 1]  # the value attribute's tokens of those elements
    fields = obs["profile_values"][1:]  # field 0 is the `_dummy` field
    holds = [
        int(np.flatnonzero((fields == v).all(axis=1))[0]) if (fields == v).all(axis=1).any() else -1
        for v in values
    ]
    h = hashlib.blake2b(digest_size=12)
    h.update(np.flatnonzero(mask).astype(np.int32).tobytes())
    h.update(np.asarray([acted, holds], dtype=np.int32).tobytes())
    return h.hexdigest()


class QTable:
    """Q-values per state: ``key -> (legal actions, values)``."""

    def __init__(self) -> None:
        self.rows: dict[str, tuple[np.ndarray, np.ndarray]] = {}

    def row(self, key: str, mask: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        row = self.rows.get(key)
        if row is None:
            legal = np.flatnonzero(mask)
            row = self.rows[key] = (legal, np.zeros(len(legal)))
        return row

    def save(self, path: Path) -> None:
        rows = {k: [legal.tolist(), q.tolist()] for k, (legal, q) in self.rows.items()}
        path.write_text(json.dumps({"format": "numpy-q/1", "rows": rows}))

    @classmethod
    def load(cls, path: str | Path) -> QTable:
        data = json.loads(Path(path).read_text())
        if data.get("format") != "numpy-q/1":
            raise ValueError(f"{path}: not a numpy-q checkpoint")
        table = cls()
        for k, (legal, q) in data["rows"].items():
            table.rows[k] = (np.asarray(legal, dtype=np.int64), np.asarray(q, dtype=np.float64))
        return table


class GreedyPolicy:
    """``policy(obs, info) -> action``: the best legal action known for the state; in a state
    never met in training, the first legal action."""

    def __init__(self, table: QTable) -> None:
        self.table = table

    def __call__(self, obs: dict[str, np.ndarray], info: dict[str, Any]) -> int:
        mask = info["action_mask"]
        row = self.table.rows.get(state_key(obs, mask))
        if row is None:
            return int(np.argmax(mask))
        legal, q = row
        return int(legal[int(np.argmax(q))])


def load_policy(path: str) -> GreedyPolicy:
    """The policy of a checkpoint file (for ``a2perf_rs.collect``)."""
    return GreedyPolicy(QTable.load(path))


def train(run: a2perf_rs.TrainingRun, hp: dict[str, float]) -> QTable:
    """Q-learning for ``run.training["total_env_steps"]`` steps, evaluating and checkpointing at
    the run's intervals (and at the end)."""
    settings = run.training
    total = settings["total_env_steps"]
    eval_every = settings["eval_interval"] or total
    ckpt_every = settings["checkpoint_interval"] or total
    rng = np.random.default_rng(run.seed)
    env = run.make_env()  # every reset() takes the run's next episode seed
    table = QTable()
    steps, next_eval, next_ckpt = 0, eval_every, ckpt_every
    with tempfile.TemporaryDirectory() as tmp:
        ckpt = Path(tmp) / "q.json"
        while steps < total:
            obs, info = env.reset()
            legal, q = table.row(state_key(obs, info["action_mask"]), info["action_mask"])
            done = False
            while not done and steps < total:
                eps = max(hp["epsilon_end"], 1.0 - steps / hp["epsilon_decay_steps"])
                i = int(rng.integers(len(legal))) if rng.random() < eps else int(np.argmax(q))
                obs, reward, terminated, truncated, info = env.step(int(legal[i]))
                steps += 1
                done = terminated or truncated
                target = float(reward)
                if not done:
                    mask = info["action_mask"]
                    next_legal, next_q = table.row(state_key(obs, mask), mask)
                    target += hp["gamma"] * float(next_q.max())
                q[i] += hp["alpha"] * (target - q[i])
                if not done:
                    legal, q = next_legal, next_q
                if steps >= next_eval or steps == total:
                    mean, std = run.evaluate(steps, GreedyPolicy(table))
                    print(f"  step {steps:>6}: return {mean:.2f} ± {std:.2f}, {len(table.rows)} states")
                    next_eval += eval_every
                if steps >= next_ckpt or steps == total:
                    table.save(ckpt)
                    run.save_checkpoint(steps, ckpt)
                    next_ckpt += ckpt_every
    env.close()
    return table


def random_reference(episodes: int) -> float:
    """Mean return of uniformly random legal actions (the README's reference point)."""
    env = a2perf_rs.A2PerfEnv(ENV_ID, **ENV_PARAMS)
    rng = np.random.default_rng(0)
    returns = []
    for episode in range(episodes):
        obs, info = env.reset(seed=episode)
        total, done = 0.0, False
        while not done:
            action = int(rng.choice(np.flatnonzero(info["action_mask"])))
            obs, reward, terminated, truncated, info = env.step(action)
            total += reward
            done = terminated or truncated
        returns.append(total)
    return float(np.mean(returns))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", default="results/python_agent", help="output root")
    parser.add_argument("--seeds", type=int, nargs="+", default=[0])
    parser.add_argument("--steps", type=int, default=3_000, help="environment steps per seed")
    parser.add_argument("--episodes", type=int, default=100, help="inference rollouts")
    parser.add_argument(
        "--generalization-episodes", type=int, default=100, help="rollouts per suite task"
    )
    parser.add_argument(
        "--report-with", nargs="*", default=[], help="other result directories to report beside"
    )
    parser.add_argument("--report", default=None, help="report directory (with --report-with)")
    args = parser.parse_args(argv)

    hp = {"alpha": 0.5, "gamma": 0.95, "epsilon_end": 0.05, "epsilon_decay_steps": 2_000}
    settings = [
        f"training.total_env_steps={args.steps}",
        "training.eval_interval=100",
        "training.eval_episodes=10",
        "training.checkpoint_interval=1000",
        f"inference.rollouts={args.episodes}",
        f"generalization.episodes={args.generalization_episodes}",
    ]
    for seed in args.seeds:
        print(f"== {ALGORITHM}, seed {seed}")
        with a2perf_rs.TrainingRun(
            args.out,
            env_id=ENV_ID,
            env_params=ENV_PARAMS,
            algorithm=ALGORITHM,
            seed=seed,
            hyperparameters=hp,
            set=settings,
        ) as run:
            table = train(run, hp)
        policy = GreedyPolicy(table)
        inference = a2perf_rs.infer(run.run_dir, policy)
        generalization = a2perf_rs.generalize(run.run_dir, policy)
        print(
            f"  {run.run_dir}\n"
            f"  inference: return {inference['returns']['mean']:.2f} over "
            f"{inference['episodes']} episodes, {inference['inference_time_ms']['median'] * 1e3:.1f} "
            f"µs/call (median)\n"
            f"  generalization: {generalization['sum_of_mean_returns']:.2f} "
            f"(sum over {len(generalization['tasks'])} tasks)"
        )
    print(f"random legal actions on the same task: {random_reference(100):.2f}")

    if args.report_with:
        out = args.report or str(Path(args.out) / "report")
        report = a2perf_rs.report([args.out, *args.report_with], out)
        print(f"report of {len(report['groups'])} (task, algorithm) groups: {out}/report.md")
        for group in report["groups"]:
            returns = next(m for m in group["metrics"] if m["key"] == "returns")
            mean = "—" if returns["mean"] is None else f"{returns['mean']:.2f}"
            print(f"  {group['algorithm']:>10} on {group['task']}: returns {mean}")
        for run_dir, why in report["skipped_runs"]:
            print(f"  left out {run_dir}: {why}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
