"""Minari datasets recorded from a Python loop over the Gymnasium environments: a
``minari.DataCollector`` wraps ``gymnasium.make("a2perf/<id>")``, and the dataset it writes gives
back, through its serialized spec, an environment that replays the recorded episode exactly.

Skips when minari is not installed, unless A2PERF_REQUIRE_INTEROP=1 (CI installs it with the
wheel's ``test`` extra).
"""

from __future__ import annotations

import os
from typing import Any

import gymnasium as gym
import numpy as np
import pytest

import a2perf_rs  # noqa: F401  (registers the ids)

try:
    import minari
except ImportError as e:  # pragma: no cover - depends on the venv
    if os.environ.get("A2PERF_REQUIRE_INTEROP") == "1":
        raise RuntimeError("A2PERF_REQUIRE_INTEROP=1 but minari is not installed") from e
    pytest.skip(f"minari is not installed: {e}", allow_module_level=True)

# One cheap id of each domain, with parameters that keep the episode short.
CASES = {
    "circuit": ("a2perf/CircuitTraining-Synthetic-Small-v0", {}),
    "web": ("a2perf/WebNavigation-Difficulty-01-v0", {"num_websites": 2, "step_limit": 6}),
    "locomotion": ("a2perf/QuadrupedLocomotion-DogPace-v0", {"episode_steps": 12}),
}


def legal_action(env: gym.Env, info: dict[str, Any]) -> Any:
    mask = info.get("action_mask")
    return env.action_space.sample(mask=mask) if mask is not None else env.action_space.sample()


def assert_same(a: Any, b: Any) -> None:
    if isinstance(a, dict):
        assert sorted(a) == sorted(b)
        for key in a:
            assert_same(a[key], b[key])
    else:
        np.testing.assert_array_equal(a, b)


def at(obs: Any, i: int) -> Any:
    """Step ``i`` of an episode's stacked observations (a dict of arrays for dict spaces)."""
    return {k: at(v, i) for k, v in obs.items()} if isinstance(obs, dict) else obs[i]


@pytest.mark.parametrize("domain", sorted(CASES))
def test_data_collector_records_an_episode_that_the_dataset_replays(
    domain: str, tmp_path, monkeypatch
) -> None:
    monkeypatch.setenv("MINARI_DATASETS_PATH", str(tmp_path))
    env_id, params = CASES[domain]
    env = minari.DataCollector(gym.make(env_id, **params), data_format="arrow")
    env.action_space.seed(0)
    obs, info = env.reset(seed=5)
    steps = 0
    while True:
        obs, _, terminated, truncated, info = env.step(legal_action(env, info))
        steps += 1
        if terminated or truncated:
            break
        assert steps < 1000, "the episode did not end"
    dataset_id = f"a2perf/{domain}-random-v0"
    dataset = env.create_dataset(dataset_id=dataset_id, algorithm_name="random")
    env.close()

    loaded = minari.load_dataset(dataset_id)
    assert loaded.total_episodes == 1 and loaded.total_steps == steps
    assert loaded.spec.env_spec.id == env_id
    assert loaded.spec.env_spec.kwargs == {"env_id": env_id.split("/", 1)[1], **params}
    (episode,) = list(loaded.iterate_episodes())

    # The recovered environment is the recording one: same seed, same actions, same episode.
    recovered = dataset.recover_environment()
    try:
        assert recovered.observation_space == loaded.observation_space
        first, _ = recovered.reset(seed=5)
        assert_same(first, at(episode.observations, 0))
        for t in range(steps):
            obs, reward, terminated, truncated, _ = recovered.step(episode.actions[t])
            assert_same(obs, at(episode.observations, t + 1))
            assert reward == episode.rewards[t]
            assert (terminated, truncated) == (episode.terminations[t], episode.truncations[t])
    finally:
        recovered.close()
