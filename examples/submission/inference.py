"""Inference of the example submission (see ``train.py``): the weights ``train()`` saved, and
the greedy placement of each macro on its best-scoring legal cell.

``a2perf submit`` calls ``load_policy(env, **participant_args)`` once, then for every step
``preprocess_observation(observation)`` (not timed) and ``infer_once(policy=...,
preprocessed_observation=...)`` (timed).
"""

from __future__ import annotations

import numpy as np

from a2perf_rs import submission


def features(observation: dict[str, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """Per cell: density, congestion, wirelength hint and distance from the canvas centre;
    and which cells are legal for the current macro (the grid's legality channel, which is
    the action mask)."""
    grid = observation["grid"]
    _, rows, cols = grid.shape
    r, c = np.mgrid[0:rows, 0:cols]
    centre = np.hypot((r - (rows - 1) / 2) / rows, (c - (cols - 1) / 2) / cols)
    f = np.stack([grid[0], grid[1], grid[3], centre]).reshape(4, -1)
    return f, grid[2].reshape(-1) > 0.5


def best_cell(weights: np.ndarray, f: np.ndarray, legal: np.ndarray) -> int:
    """The legal cell with the highest score ``weights . f``."""
    return int(np.argmax(np.where(legal, weights @ f, -np.inf)))


def greedy_action(weights: np.ndarray, observation: dict[str, np.ndarray]) -> int:
    return best_cell(weights, *features(observation))


def load_policy(env, **participant_args) -> np.ndarray:
    return np.load(submission.task().files_dir / "weights.npy")


def preprocess_observation(observation):
    return features(observation)


def infer_once(policy, preprocessed_observation) -> int:
    return best_cell(policy, *preprocessed_observation)
