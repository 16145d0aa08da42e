"""Gymnasium environments: registration, check_env for every id, spaces, seeding, masks, close."""

from __future__ import annotations

from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import a2perf_rs
from a2perf_rs import A2PerfEnv
from conftest import child_pids, file_kwargs, require_chromium, shared

ALL_IDS = a2perf_rs.env_ids()
WEB_IDS = [i for i in ALL_IDS if "WebNavigation" in i]


def test_every_registry_id_is_registered_in_the_a2perf_namespace() -> None:
    assert len(ALL_IDS) == 12
    for env_id in ALL_IDS:
        assert env_id.startswith("a2perf/")
        assert env_id in gym.registry
        assert gym.registry[env_id].vector_entry_point is not None


def test_the_original_a2perf_package_imports_beside_it(tmp_path, monkeypatch) -> None:
    # The installed distribution ships only `a2perf_rs`, so the original's `a2perf` (here a
    # stand-in on sys.path) imports beside it, each from its own files.
    import importlib.metadata
    import sys

    top = {f.parts[0] for f in importlib.metadata.files("a2perf-rs") or []}
    assert "a2perf_rs" in top
    assert not {t for t in top if t == "a2perf" or t.startswith("a2perf.")}, top
    (tmp_path / "a2perf").mkdir()
    (tmp_path / "a2perf" / "__init__.py").write_text("ORIGINAL = True\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.delitem(sys.modules, "a2perf", raising=False)
    import a2perf

    assert a2perf.ORIGINAL and Path(a2perf.__file__).parent == tmp_path / "a2perf"
    assert Path(a2perf_rs.__file__).parent.name == "a2perf_rs"


@pytest.mark.parametrize("env_id", ALL_IDS)
def test_check_env_passes(env_id: str) -> None:
    env = gym.make(env_id, **file_kwargs(env_id))
    try:
        check_env(env.unwrapped)
    finally:
        env.close()


@pytest.mark.parametrize("env_id", WEB_IDS)
def test_check_env_passes_on_chromium(env_id: str) -> None:
    require_chromium()
    env = gym.make(env_id, backend="chromium", num_websites=1)
    try:
        check_env(env.unwrapped)
    finally:
        env.close()


def test_locomotion_with_the_motion_file() -> None:
    clip = shared("locomotion", "motions", "dog_pace.txt")
    env = gym.make("a2perf/QuadrupedLocomotion-DogPace-v0", motion_file=str(clip))
    assert env.unwrapped.provenance["clip_source"] != ""
    check_env(env.unwrapped)
    env.close()


def test_spaces_are_the_rust_spaces_exactly() -> None:
    env = A2PerfEnv("QuadrupedLocomotion-DogPace-v0")
    native = env._native.spec()
    _, low, high, dtype = native["observation_space"]
    assert dtype == "float32"
    obs_space = env.observation_space
    assert isinstance(obs_space, gym.spaces.Box)
    assert obs_space.dtype == np.float32 and obs_space.shape == (160,)
    np.testing.assert_array_equal(obs_space.low, low)
    np.testing.assert_array_equal(obs_space.high, high)
    assert isinstance(env.action_space, gym.spaces.Box) and env.action_space.shape == (12,)

    web = A2PerfEnv("WebNavigation-Difficulty-01-v0", num_fields=5, num_elements=20, num_tokens=4)
    assert isinstance(web.observation_space, gym.spaces.Dict)
    assert list(web.observation_space.keys()) == [
        "profile_keys", "profile_values", "profile_mask", "dom_tokens", "dom_features", "dom_mask",
        "time_step",
    ]
    assert web.observation_space["dom_tokens"].shape[0] == 20
    assert web.action_space == gym.spaces.Discrete(20 * 5 * 2)
    obs, info = web.reset(seed=0)
    assert all(obs[k].dtype == web.observation_space[k].dtype for k in obs)
    assert obs["dom_tokens"].dtype == np.int32
    assert obs in web.observation_space
    mask = info["action_mask"]
    assert mask.dtype == np.int8 and mask.shape == (200,) and mask.sum() > 0
    np.testing.assert_array_equal(web.action_masks(), mask.astype(bool))
    legal = web.action_space.sample(mask=mask)
    assert mask[legal] == 1
    # Circuit: dict observations with infinite bounds where the Rust space has them.
    circ = A2PerfEnv("CircuitTraining-Synthetic-Small-v0")
    assert np.isinf(circ.observation_space["grid"].high).all()
    assert circ.max_episode_steps == 12


# The tensors the original environments declare int32 (A2Perf's web observation wrapper and
# circuit_training's observation config); every other tensor is float32.
INT32_TENSORS = {
    "profile_keys", "profile_values", "dom_tokens",
    "is_node_placed", "current_node", "node_types", "sparse_adj_i", "sparse_adj_j",
}


def _dtypes_by_name(space: gym.spaces.Space) -> dict[str, np.dtype]:
    if isinstance(space, gym.spaces.Dict):
        return {k: sub.dtype for k, sub in space.spaces.items()}
    return {"obs": space.dtype}


@pytest.mark.parametrize("env_id", ALL_IDS)
def test_int32_exactly_where_the_original_has_it(env_id: str) -> None:
    env = gym.make(env_id, **file_kwargs(env_id))
    try:
        want = {
            name: np.dtype(np.int32 if name in INT32_TENSORS else np.float32)
            for name in _dtypes_by_name(env.observation_space)
        }
        assert _dtypes_by_name(env.observation_space) == want
        obs, info = env.reset(seed=0)
        # Several steps: the single environment hands out recycled buffers after the first.
        for _ in range(4):
            arrays = obs if isinstance(obs, dict) else {"obs": obs}
            assert {k: a.dtype for k, a in arrays.items()} == want
            assert obs in env.observation_space
            mask = info.get("action_mask")
            action = env.action_space.sample(mask=mask) if mask is not None else (
                env.action_space.sample())
            obs, _, term, trunc, info = env.step(action)
            if term or trunc:
                obs, info = env.reset()
        if "WebNavigation" in env_id:
            assert {"profile_keys", "profile_values", "dom_tokens"} <= {
                k for k, d in want.items() if d == np.int32}
        if "CircuitTraining" in env_id:
            assert {"current_node", "is_node_placed", "node_types"} <= {
                k for k, d in want.items() if d == np.int32}
    finally:
        env.close()


def test_int32_ids_stay_exact_and_embed_directly() -> None:
    env = A2PerfEnv("WebNavigation-Difficulty-01-v0")
    obs, _ = env.reset(seed=3)
    tokens = obs["dom_tokens"]
    assert tokens.dtype == np.int32 and tokens.max() < env.observation_space["dom_tokens"].high.max()
    # An embedding lookup takes the ids as they come (no float-to-index cast).
    table = np.arange(int(env.observation_space["dom_tokens"].high.max()) + 1)
    assert (table[tokens] == tokens).all()


def test_params_are_typed_and_resolved() -> None:
    env = gym.make("a2perf/WebNavigation-Difficulty-02-v0", num_websites=3, seed=4)
    assert env.unwrapped.params["num_websites"] == 3
    assert env.unwrapped.params["backend"] == "simulated"
    names = [p[0] for p in a2perf_rs.env_params("a2perf/WebNavigation-Difficulty-02-v0")]
    assert "num_websites" in names and "backend" in names
    # numpy scalars and paths are accepted.
    env2 = A2PerfEnv("QuadrupedLocomotion-DogPace-v0", episode_steps=np.int64(50))
    assert env2.max_episode_steps == 50


def test_locomotion_physics_engine_is_a_parameter() -> None:
    """`physics="articulated"` selects the reduced-coordinate engine: it passes Gymnasium's checks,
    is deterministic per seed, and its trajectory differs from the default rapier engine's."""
    env = gym.make("a2perf/QuadrupedLocomotion-DogPace-v0", physics="articulated")
    assert env.unwrapped.params["physics"] == "articulated"
    assert "articulated" in env.unwrapped.provenance["physics"]
    check_env(env.unwrapped)
    actions = np.random.default_rng(1).uniform(-0.3, 0.3, (10, 12)).astype(np.float32)

    def rollout(e) -> np.ndarray:
        obs, _ = e.reset(seed=5)
        out = [obs]
        for a in actions:
            obs, _, term, trunc, _ = e.step(a)
            out.append(obs)
            if term or trunc:
                break
        return np.stack(out)

    art = rollout(env.unwrapped)
    assert np.array_equal(art, rollout(env.unwrapped))
    assert not np.array_equal(art, rollout(A2PerfEnv("QuadrupedLocomotion-DogPace-v0")))
    with pytest.raises(Exception, match="physics"):
        A2PerfEnv("QuadrupedLocomotion-DogPace-v0", physics="bullet")


def test_same_seed_same_episode_and_reset_does_not_leak_state() -> None:
    env = A2PerfEnv("QuadrupedLocomotion-DogTrot-v0")
    actions = np.random.default_rng(0).uniform(-0.3, 0.3, (20, 12)).astype(np.float32)

    def episode() -> list[np.ndarray]:
        obs, _ = env.reset(seed=11)
        out = [obs]
        for a in actions:
            obs, r, term, trunc, _ = env.step(a)
            out.append(np.append(obs, r))
            if term or trunc:
                break
        return out

    first, second = episode(), episode()
    assert all(np.array_equal(a, b) for a, b in zip(first, second))
    other = A2PerfEnv("QuadrupedLocomotion-DogTrot-v0")
    assert not np.array_equal(other.reset(seed=12)[0], first[0])


def test_episode_limit_truncates_and_step_after_end_raises() -> None:
    env = A2PerfEnv("QuadrupedLocomotion-DogPace-v0", episode_steps=3)
    env.reset(seed=0)
    flags = [env.step(np.zeros(12, np.float32))[2:4] for _ in range(3)]
    assert flags[-1] in ((False, True), (True, False))
    with pytest.raises(RuntimeError, match="reset"):
        env.step(np.zeros(12, np.float32))


def test_illegal_actions_terminate_by_default_or_raise() -> None:
    env = A2PerfEnv("WebNavigation-Difficulty-01-v0", num_websites=1)
    _, info = env.reset(seed=0)
    illegal = int(np.flatnonzero(info["action_mask"] == 0)[0])
    before, _ = env.reset(seed=0)
    obs, reward, terminated, truncated, info = env.step(illegal)
    assert terminated and not truncated and reward == -1.0 and info["illegal_action"] is True
    # The state did not change, so neither did the observation; it is a copy, not the same memory.
    for k in before:
        assert np.array_equal(obs[k], before[k]) and not np.shares_memory(obs[k], before[k])
    circuit = A2PerfEnv("CircuitTraining-Synthetic-Small-v0", infeasible_reward=-7.5)
    _, info = circuit.reset(seed=0)
    bad = int(np.flatnonzero(info["action_mask"] == 0)[0])
    assert circuit.step(bad)[1] == -7.5
    strict = A2PerfEnv("WebNavigation-Difficulty-01-v0", num_websites=1, illegal_action="raise")
    strict.reset(seed=0)
    with pytest.raises(ValueError, match=f"action {illegal} is masked out"):
        strict.step(illegal)
    with pytest.raises(ValueError, match="did you mean `raise`"):
        A2PerfEnv("WebNavigation-Difficulty-01-v0", illegal_action="rase")


def test_observations_are_handed_over_without_copies_and_never_overwritten() -> None:
    """A step's buffers become the numpy arrays (no copy); they are reused for a later step only
    once Python holds no reference to them (not even a view), and reuse changes no value."""

    def run(keep: bool) -> tuple[list, list, set, list]:
        env = A2PerfEnv("WebNavigation-Difficulty-01-v0")
        obs, info = env.reset(seed=3)
        rng = np.random.default_rng(0)
        kept, snapshots, buffers, views = [], [], set(), []
        for step in range(80):
            a = int(rng.choice(np.flatnonzero(info["action_mask"])))
            obs, _, terminated, truncated, info = env.step(a)
            snapshots.append({k: v.copy() for k, v in obs.items()})
            buffers.add(obs["dom_tokens"].ctypes.data)
            if keep:
                kept.append(obs)
            elif step % 20 == 5:
                # Only a view (and a memoryview) of the observation survives.
                views.append((obs["dom_features"][1:], memoryview(obs["dom_mask"]), step))
            if terminated or truncated:
                obs, info = env.reset()
        return kept, snapshots, buffers, views

    kept, snapshots_kept, buffers_kept, _ = run(keep=True)
    _, snapshots_dropped, buffers_dropped, views = run(keep=False)
    assert len(buffers_kept) == 80, "a held observation's memory was reused"
    # Two sets in turn (the caller's current observation, and the one being written), plus one
    # per observation that a surviving view pins.
    assert len(buffers_dropped) <= 2 + len(views), f"buffers not recycled: {len(buffers_dropped)}"
    for obs, snap in zip(kept, snapshots_kept):
        assert all(np.array_equal(obs[k], snap[k]) for k in snap)
    for a, b in zip(snapshots_kept, snapshots_dropped):
        assert all(np.array_equal(a[k], b[k]) for k in a)
    for features, mask, step in views:
        assert np.array_equal(features, snapshots_dropped[step]["dom_features"][1:])
        assert np.array_equal(np.asarray(mask), snapshots_dropped[step]["dom_mask"])


def test_a_circuit_episode_ends_with_the_proxy_cost() -> None:
    env = A2PerfEnv("CircuitTraining-Synthetic-Small-v0", std_cell_placer="none")
    obs, info = env.reset(seed=1)
    total, terminated = 0.0, False
    while not terminated:
        obs, reward, terminated, truncated, info = env.step(
            env.action_space.sample(mask=info["action_mask"])
        )
        total += reward
    assert info["proxy"] > 0 and total == pytest.approx(-info["proxy"])


def test_close_releases_the_chromium_backend() -> None:
    require_chromium()
    before = child_pids()
    env = gym.make("a2perf/WebNavigation-Difficulty-01-v0", backend="chromium", num_websites=1)
    env.reset(seed=0)
    assert child_pids() - before, "the Chromium backend should run as a child process"
    env.close()
    assert not (child_pids() - before), "close() must stop chromedriver and the browser"
    env.close()  # twice is fine
    with pytest.raises(RuntimeError, match="closed"):
        env.unwrapped.reset(seed=0)


def test_bench_runs_the_native_benchmark_in_this_process() -> None:
    report = a2perf_rs.bench("a2perf/WebNavigation-Difficulty-01-v0", steps=300, seed=4)
    assert report["env_id"] == "WebNavigation-Difficulty-01-v0" and report["steps"] == 300
    assert 0 < report["step_latency_us"]["p50"] <= report["step_latency_us"]["p99"]
    assert report["steps_per_second"] > 0 and report["params"]["num_websites"] >= 1
    # Same seed, same trajectory: the same episodes.
    again = a2perf_rs.bench("WebNavigation-Difficulty-01-v0", steps=300, seed=4, timeline=True)
    assert again["episodes"] == report["episodes"] and "timeline_us" not in report
    # One unit per step and per reset after the first, in order.
    assert len(again["timeline_us"]) == 300 + again["episodes"] - 1
    assert min(again["timeline_us"]) > 0
    with pytest.raises(ValueError, match="did you mean"):
        a2perf_rs.bench("WebNavigation-Difficulty-1-v0", steps=10)
    with pytest.raises(TypeError, match="num_website"):
        a2perf_rs.bench("WebNavigation-Difficulty-01-v0", steps=10, num_website=3)
    with pytest.raises(ValueError, match="at least 1"):
        a2perf_rs.bench("WebNavigation-Difficulty-01-v0", steps=0)
