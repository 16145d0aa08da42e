"""Gymnasium specs: string entry points, so that every id's spec serializes (JSON, pickle) and
rebuilds the same environment with ``gymnasium.make(spec)``."""

from __future__ import annotations

import json
import pickle
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.envs.registration import EnvSpec, load_env_creator

import a2perf_rs
from a2perf_rs.envs import render_metadata
from conftest import file_kwargs

ALL_IDS = a2perf_rs.env_ids()
DOG = "a2perf/QuadrupedLocomotion-DogPace-v0"
TOY = "a2perf/CircuitTraining-ToyMacro-v0"
WEB = "a2perf/WebNavigation-Difficulty-01-v0"

# Parameters that keep each domain's episodes short (every parameter is typed and validated).
SMALL = {
    "QuadrupedLocomotion": {"episode_steps": 8},
    "WebNavigation": {"num_websites": 2, "num_elements": 30},
    "CircuitTraining": {},
}


def small_kwargs(env_id: str) -> dict[str, Any]:
    """Short-episode parameters of ``env_id`` with the files it needs (skip when absent)."""
    domain = env_id.split("/", 1)[1].split("-", 1)[0]
    return {**SMALL[domain], **file_kwargs(env_id)}


def rollout(env: gym.Env, seed: int, steps: int) -> list[Any]:
    """The observations, rewards and flags of ``steps`` seeded random legal steps (resetting
    after an episode ends)."""
    env.action_space.seed(seed)
    obs, info = env.reset(seed=seed)
    out: list[Any] = [obs]
    for _ in range(steps):
        mask = info.get("action_mask")
        action = env.action_space.sample(mask=mask) if mask is not None else env.action_space.sample()
        obs, reward, terminated, truncated, info = env.step(action)
        out.append((obs, reward, terminated, truncated))
        if terminated or truncated:
            obs, info = env.reset()
            out.append(obs)
    return out


def assert_same(a: Any, b: Any) -> None:
    if isinstance(a, dict):
        assert list(a) == list(b)
        for key in a:
            assert_same(a[key], b[key])
    elif isinstance(a, (tuple, list)):
        assert len(a) == len(b)
        for x, y in zip(a, b):
            assert_same(x, y)
    else:
        np.testing.assert_array_equal(a, b)


def test_entry_points_are_strings_that_carry_the_render_metadata() -> None:
    for env_id in ALL_IDS:
        spec = gym.spec(env_id)
        assert isinstance(spec.entry_point, str) and isinstance(spec.vector_entry_point, str)
        assert load_env_creator(spec.entry_point).metadata == render_metadata(env_id)
        assert issubclass(load_env_creator(spec.entry_point), a2perf_rs.A2PerfEnv)
        assert load_env_creator(spec.vector_entry_point) is a2perf_rs.A2PerfVectorEnv
        # The registered spec itself serializes and pickles.
        assert EnvSpec.from_json(spec.to_json()) == spec
        assert pickle.loads(pickle.dumps(spec)) == spec


@pytest.mark.parametrize("env_id", ALL_IDS)
def test_spec_round_trips_through_json_to_the_same_environment(env_id: str) -> None:
    env = gym.make(env_id, **small_kwargs(env_id))
    text = env.spec.to_json()
    restored = EnvSpec.from_json(text)
    assert restored == env.spec
    again = gym.make(restored)
    try:
        assert again.spec == env.spec
        assert again.unwrapped.params == env.unwrapped.params
        assert again.observation_space == env.observation_space
        assert again.action_space == env.action_space
        assert_same(rollout(again, 3, 10), rollout(env, 3, 10))
    finally:
        env.close()
        again.close()


def test_typed_kwargs_survive_json_and_pickle(tmp_path: Path) -> None:
    # A path and numpy numbers, as a user passes them, are stored as plain JSON values.
    kwargs = file_kwargs(TOY)
    env = gym.make(
        TOY,
        netlist_file=Path(kwargs["netlist_file"]),
        density_weight=np.float32(0.5),
        illegal_action="raise",
    )
    assert env.spec.kwargs["netlist_file"] == kwargs["netlist_file"]
    weight = env.spec.kwargs["density_weight"]
    assert type(weight) is float and weight == 0.5
    assert env.unwrapped.params["density_weight"] == 0.5
    decoded = json.loads(env.spec.to_json())
    assert decoded["kwargs"]["illegal_action"] == "raise"
    for restored in (EnvSpec.from_json(env.spec.to_json()), pickle.loads(pickle.dumps(env.spec))):
        again = gym.make(restored)
        assert again.unwrapped.params == env.unwrapped.params
        assert_same(rollout(again, 1, 6), rollout(env, 1, 6))
        again.close()
    # A training run's episode seeds (a tuple) come back from JSON as a list and still work.
    seeded = gym.make(DOG, episode_steps=4, episode_seeds=(5, 1))
    again = gym.make(EnvSpec.from_json(seeded.spec.to_json()))
    assert again.spec.kwargs["episode_seeds"] == [5, 1]
    first, _ = seeded.reset()
    np.testing.assert_array_equal(again.reset()[0], first)
    env.close()


def test_make_from_a_spec_keeps_validation_and_rendering() -> None:
    env = gym.make(DOG, episode_steps=5, render_mode="rgb_array")
    again = gym.make(env.spec)
    again.reset(seed=0)
    frame = again.render()
    assert isinstance(frame, np.ndarray) and frame.dtype == np.uint8 and frame.ndim == 3
    # gymnasium.make reads the render modes from the entry point: the collection wrapper works.
    frames = gym.make(DOG, episode_steps=5, render_mode="rgb_array_list")
    frames.reset(seed=0)
    frames.step(frames.action_space.sample())
    assert len(frames.render()) == 2
    with pytest.raises(ValueError, match="render modes are 'rgb_array'"):
        gym.make(DOG, render_mode="svg")
    # Typed parameters are still checked, with a did-you-mean, through a spec too.
    bad = EnvSpec.from_json(env.spec.to_json())
    bad.kwargs["episode_step"] = 5
    with pytest.raises(TypeError, match=r"unknown parameter `episode_step`.*episode_steps"):
        gym.make(bad)
    env.close()
    again.close()
    frames.close()


def test_vector_entry_point_from_a_restored_spec() -> None:
    spec = EnvSpec.from_json(gym.spec(WEB).to_json())
    envs = gym.make_vec(spec, num_envs=2, vectorization_mode="vector_entry_point", num_websites=1)
    try:
        assert isinstance(envs, a2perf_rs.A2PerfVectorEnv)
        obs, infos = envs.reset(seed=0)
        assert infos["action_mask"].shape[0] == 2
    finally:
        envs.close()
