"""Training of the example submission: a linear cell-scoring placer for chip macro placement,
found by the cross-entropy method.

At each step of a placement episode the observation's ``grid`` holds, per cell of the canvas,
its density, its congestion, whether the current macro may go there, and how little the macro's
nets would grow there. The policy scores every legal cell as ``w . features(cell)`` and places
the macro on the best one (see ``inference.py``). Training searches the four weights ``w``: each
iteration draws a population of weight vectors from a Gaussian, runs one episode with each, and
refits the Gaussian to the best few. The search spends the harness's environment-step budget
(``training.total_env_steps``) and logs the mean weights' return after every iteration.

``a2perf submit`` calls ``train(**participant_args)``: here ``population`` and ``elite``
(strings, as the original harness passes them).
"""

from __future__ import annotations

import numpy as np

from a2perf_rs import submission

from inference import greedy_action


def _episode(env, weights: np.ndarray) -> tuple[float, int]:
    obs, info = env.reset()
    total, steps, done = 0.0, 0, False
    while not done:
        obs, reward, terminated, truncated, info = env.step(greedy_action(weights, obs))
        total += float(reward)
        steps += 1
        done = terminated or truncated
    return total, steps


def train(population: str = "8", elite: str = "2") -> None:
    task = submission.task()
    run = submission.training_run()
    n, k = int(population), int(elite)
    rng = np.random.default_rng(task.seed)
    env = submission.make_env()  # every reset() draws the run's next training episode
    mean, std = np.zeros(4), np.ones(4)
    steps = 0
    budget = task.training["total_env_steps"]
    while steps < budget:
        candidates = mean + std * rng.standard_normal((n, 4))
        returns = []
        for w in candidates:
            ret, used = _episode(env, w)
            returns.append(ret)
            steps += used
        best = candidates[np.argsort(returns)[-k:]]
        mean, std = best.mean(axis=0), best.std(axis=0) + 0.05
        m, s = run.evaluate(steps, lambda obs, info: greedy_action(mean, obs))
        print(f"step {steps:>5}: return {m:.4f} ± {s:.4f}, weights {np.round(mean, 3)}")
    np.save(task.files_dir / "weights.npy", mean)
    env.close()
