"""Rendering: render modes per id, frames from the Rust renderers, Gymnasium's render checks."""

from __future__ import annotations

import warnings

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.envs.registration import load_env_creator
from gymnasium.utils.env_checker import check_env

import a2perf_rs
from a2perf_rs import A2PerfEnv, _native
from a2perf_rs.envs import render_metadata
from conftest import file_kwargs, require_chromium

ALL_IDS = a2perf_rs.env_ids()
RGB_IDS = [i for i in ALL_IDS if "rgb_array" in render_metadata(i)["render_modes"]]
WEB_IDS = [i for i in ALL_IDS if "WebNavigation" in i]
# Cheap ids for the frame tests, one per domain with frames.
CIRCUIT = "a2perf/CircuitTraining-Synthetic-Small-v0"
DOG = "a2perf/QuadrupedLocomotion-DogPace-v0"
WEB = "a2perf/WebNavigation-Difficulty-01-v0"


def test_every_id_declares_the_modes_its_rust_environment_renders() -> None:
    assert len(RGB_IDS) == 9  # 5 circuit + 4 locomotion ids
    for env_id in ALL_IDS:
        meta = render_metadata(env_id)
        spec = gym.registry[env_id]
        assert load_env_creator(spec.entry_point).metadata == meta
        assert meta["render_fps"] > 0
        try:
            kwargs = file_kwargs(env_id)
        except pytest.skip.Exception:
            continue  # its netlist is not in the shared data
        env = A2PerfEnv(env_id.split("/", 1)[1], **kwargs)
        try:
            assert env.metadata == meta
            assert list(env._native.render_modes()) == meta["render_modes"]
        finally:
            env.close()
    assert render_metadata(DOG) == {"render_modes": ["rgb_array"], "render_fps": 1000 / 33}
    assert render_metadata(CIRCUIT)["render_modes"] == ["rgb_array", "svg"]
    assert render_metadata(WEB)["render_modes"] == ["html"]


@pytest.mark.parametrize("env_id", RGB_IDS)
def test_check_env_renders(env_id: str) -> None:
    env = gym.make(env_id, render_mode="rgb_array", **file_kwargs(env_id))
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            check_env(env.unwrapped, skip_render_check=False)
        about_render = [str(w.message) for w in caught if "render" in str(w.message).lower()]
        assert not about_render, about_render
        frame = env.unwrapped.render()
        assert isinstance(frame, np.ndarray) and frame.dtype == np.uint8
        assert frame.ndim == 3 and frame.shape[2] == 3 and frame.flags.c_contiguous
    finally:
        env.close()


@pytest.mark.parametrize("env_id", WEB_IDS)
def test_check_env_renders_html(env_id: str) -> None:
    env = gym.make(env_id, render_mode="html", num_websites=2)
    try:
        check_env(env.unwrapped, skip_render_check=False)
    finally:
        env.close()


def _frames(env_id: str, seed: int, steps: int, **kw: object) -> list[np.ndarray]:
    env = gym.make(env_id, render_mode="rgb_array", **kw)
    obs, info = env.reset(seed=seed)
    frames = [env.render()]
    rng = np.random.default_rng(seed)
    for _ in range(steps):
        if "action_mask" in info:
            action = int(rng.choice(np.flatnonzero(info["action_mask"])))
        else:
            action = rng.uniform(-0.2, 0.2, env.action_space.shape).astype(np.float32)
        obs, _, terminated, truncated, info = env.step(action)
        frames.append(env.render())
        if terminated or truncated:
            break
    env.close()
    return frames


@pytest.mark.parametrize(
    ("env_id", "shape"), [(CIRCUIT, None), (DOG, (240, 320, 3))], ids=["circuit", "locomotion"]
)
def test_rgb_frames_follow_the_episode_and_are_deterministic(
    env_id: str, shape: tuple[int, int, int] | None
) -> None:
    frames = _frames(env_id, seed=5, steps=6)
    assert len(frames) == 7
    for f in frames:
        assert f.dtype == np.uint8 and f.ndim == 3 and f.shape[2] == 3
        assert f.shape == frames[0].shape
    if shape is not None:
        assert frames[0].shape == shape
    else:
        assert max(frames[0].shape[:2]) == 400
    assert not np.array_equal(frames[0], frames[-1]), "the state changed, the frame did not"
    again = _frames(env_id, seed=5, steps=6)
    assert all(np.array_equal(a, b) for a, b in zip(frames, again, strict=True))
    # Each call draws anew into a fresh array.
    env = gym.make(env_id, render_mode="rgb_array")
    env.reset(seed=0)
    a, b = env.render(), env.render()
    assert np.array_equal(a, b) and not np.shares_memory(a, b)
    env.close()


def test_text_modes_return_documents() -> None:
    env = gym.make(CIRCUIT, render_mode="svg")
    obs, info = env.reset(seed=0)
    first = env.render()
    assert isinstance(first, str) and first.startswith("<svg") and first.rstrip().endswith("</svg>")
    env.step(int(np.flatnonzero(info["action_mask"])[0]))
    assert env.render() != first
    env.close()

    web = gym.make(WEB, render_mode="html", num_websites=2)
    obs, info = web.reset(seed=0)
    page = web.render()
    assert isinstance(page, str) and page.startswith("<!DOCTYPE html>")
    changed = False
    for _ in range(10):
        a = web.action_space.sample(mask=info["action_mask"])
        obs, _, terminated, truncated, info = web.step(a)
        changed |= web.render() != page
        if terminated or truncated:
            break
    assert changed
    web.close()


def test_rendering_does_not_change_the_episode() -> None:
    def run(render_mode: str | None) -> list[float]:
        env = A2PerfEnv("QuadrupedLocomotion-DogTrot-v0", render_mode=render_mode)
        obs, _ = env.reset(seed=3)
        out = list(obs)
        for _ in range(10):
            env.render()
            obs, r, *_ = env.step(np.full(12, 0.1, np.float32))
            out += [*obs, r]
        return out

    assert run("rgb_array") == run(None)


def test_unsupported_modes_raise_value_error_naming_the_modes() -> None:
    with pytest.raises(ValueError, match=r"render_mode='human'.*'rgb_array', 'svg'"):
        A2PerfEnv("CircuitTraining-Synthetic-Small-v0", render_mode="human")
    with pytest.raises(ValueError, match=r"render_mode='svg'.*'rgb_array'"):
        A2PerfEnv("QuadrupedLocomotion-DogPace-v0", render_mode="svg")
    # gymnasium.make warns about the mode, then the environment refuses it.
    with pytest.raises(ValueError, match=r"render_mode='rgb_array'.*'html'"):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            gym.make(WEB, render_mode="rgb_array")
    # The native environment names them too.
    native = _native.Env("WebNavigation-Difficulty-01-v0", {"num_websites": 1})
    with pytest.raises(ValueError, match=r"`rgb_array` is not supported.*supported modes: html"):
        native.render("rgb_array")
    native.close()
    with pytest.raises(RuntimeError, match="closed"):
        native.render("html")


def test_without_a_render_mode_render_returns_none() -> None:
    env = gym.make(DOG)
    env.reset(seed=0)
    assert env.unwrapped.render_mode is None
    assert env.render() is None
    assert A2PerfEnv("WebNavigation-Difficulty-01-v0", num_websites=1).render() is None


def test_list_modes_collect_every_frame() -> None:
    env = gym.make(DOG, render_mode="rgb_array_list")
    env.reset(seed=0)
    for _ in range(3):
        env.step(np.zeros(12, np.float32))
    frames = env.render()
    assert isinstance(frames, list) and len(frames) == 4
    assert all(f.shape == (240, 320, 3) for f in frames)
    env.close()


def test_html_is_the_same_with_the_chromium_backend() -> None:
    require_chromium()

    def pages(backend: str) -> list[str]:
        env = gym.make(WEB, render_mode="html", num_websites=3, backend=backend)
        obs, info = env.reset(seed=1)
        out = [env.render()]
        rng = np.random.default_rng(1)
        for _ in range(12):
            a = int(rng.choice(np.flatnonzero(info["action_mask"])))
            obs, _, terminated, truncated, info = env.step(a)
            out.append(env.render())
            if terminated or truncated:
                obs, info = env.reset()
                out.append(env.render())
        env.close()
        return out

    simulated = pages("simulated")
    assert len(set(simulated)) > 2
    assert pages("chromium") == simulated
