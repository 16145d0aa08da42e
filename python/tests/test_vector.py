"""Native vector environments: Gymnasium 1.x semantics and equality with N single environments."""

from __future__ import annotations

import os
import select
import signal
import time

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.vector import AutoresetMode

from a2perf_rs import A2PerfEnv, A2PerfVectorEnv
from conftest import child_pids, require_chromium

CASES = [
    ("CircuitTraining-Synthetic-Small-v0", {"std_cell_placer": "none"}, 40),
    ("WebNavigation-Difficulty-01-v0", {"num_websites": 3}, 60),
    ("QuadrupedLocomotion-DogPace-v0", {"episode_steps": 15}, 40),
]


def _row(obs, i):
    return {k: v[i] for k, v in obs.items()} if isinstance(obs, dict) else obs[i]


def _equal(a, b) -> bool:
    """Same keys, element types and values (int32 ids must stay int32 in a batch)."""
    if isinstance(a, dict):
        return a.keys() == b.keys() and all(_equal(a[k], b[k]) for k in a)
    a, b = np.asarray(a), np.asarray(b)
    return a.dtype == b.dtype and np.array_equal(a, b)


def _actions(venv: A2PerfVectorEnv, infos, rng: np.random.Generator) -> np.ndarray:
    if isinstance(venv.single_action_space, gym.spaces.Discrete):
        # A finished episode may have no legal action left; next-step autoreset ignores it.
        legal = [np.flatnonzero(m) for m in infos["action_mask"]]
        return np.array([rng.choice(ix) if ix.size else 0 for ix in legal])
    return rng.uniform(-0.4, 0.4, (venv.num_envs, 12)).astype(np.float32)


def _replay_against_singles(venv, singles: list[A2PerfEnv], seed: int, steps: int) -> int:
    """Resets `venv` with `seed` and environment i of `singles` with `seed + i`, steps them all
    with the same random actions (next-step autoreset replayed by hand on the singles) and asserts
    every observation, reward, flag and action mask equal; returns the episodes that ended."""
    obs, infos = venv.reset(seed=seed)
    for i, env in enumerate(singles):
        o, _ = env.reset(seed=seed + i)
        assert _equal(_row(obs, i), o)
    assert obs in venv.observation_space
    rng = np.random.default_rng(0)
    ended = [False] * len(singles)
    episodes = 0
    for _ in range(steps):
        actions = _actions(venv, infos, rng)
        obs, rewards, terms, truncs, infos = venv.step(actions)
        for i, env in enumerate(singles):
            if ended[i]:  # next-step autoreset: this step resets environment i
                o, info = env.reset()
                r, te, tr = 0.0, False, False
            else:
                o, r, te, tr, info = env.step(actions[i])
            ended[i] = te or tr
            episodes += int(ended[i])
            assert _equal(_row(obs, i), o)
            assert (rewards[i], terms[i], truncs[i]) == (r, te, tr)
            if "action_mask" in info:
                np.testing.assert_array_equal(infos["action_mask"][i], info["action_mask"])
    return episodes


@pytest.mark.parametrize(("env_id", "params", "steps"), CASES)
def test_vector_equals_n_single_environments(env_id: str, params: dict, steps: int) -> None:
    n = 3
    venv = gym.make_vec(
        f"a2perf/{env_id}", num_envs=n, vectorization_mode="vector_entry_point", **params
    )
    assert isinstance(venv, gym.vector.VectorEnv)
    assert venv.metadata["autoreset_mode"] == AutoresetMode.NEXT_STEP
    singles = [A2PerfEnv(env_id, **params) for _ in range(n)]
    episodes = _replay_against_singles(venv, singles, seed=7, steps=steps)
    assert episodes >= n, "the run should cover autoresets"
    venv.close()


def _same_infos(a: dict, b: dict, path: str = "infos") -> None:
    """Asserts two vector info dicts equal: the same keys, arrays of the same dtype and values,
    object arrays (``final_obs``) element by element, nested dicts (``final_info``) recursively."""
    assert sorted(a) == sorted(b), f"{path}: keys {sorted(a)} vs {sorted(b)}"
    for k in a:
        x, y = a[k], b[k]
        if isinstance(x, dict):
            assert isinstance(y, dict), f"{path}[{k!r}]: a dict vs {type(y).__name__}"
            _same_infos(x, y, f"{path}[{k!r}]")
        elif x.dtype == object:
            assert y.dtype == object and len(x) == len(y), f"{path}[{k!r}]"
            for u, v in zip(x, y):
                assert (u is None and v is None) or _equal(u, v), f"{path}[{k!r}]"
        else:
            assert x.dtype == y.dtype, f"{path}[{k!r}]: dtype {x.dtype} vs {y.dtype}"
            np.testing.assert_array_equal(x, y, err_msg=f"{path}[{k!r}]")


@pytest.mark.parametrize("mode", [AutoresetMode.NEXT_STEP, AutoresetMode.SAME_STEP])
@pytest.mark.parametrize(("env_id", "params", "steps"), CASES)
def test_everything_returned_equals_gymnasium_sync_vector_env_over_single_envs(
    env_id: str, params: dict, steps: int, mode: AutoresetMode
) -> None:
    # Gymnasium's own SyncVectorEnv over single A2PerfEnvs is the reference for the whole
    # return value, infos included (same-step mode's final_obs/final_info among them). A quarter
    # of the discrete actions are drawn from the whole space, so illegal actions occur.
    n = 3
    venv = A2PerfVectorEnv(env_id, num_envs=n, autoreset_mode=mode, **params)
    sync = gym.vector.SyncVectorEnv(
        [lambda: A2PerfEnv(env_id, **params) for _ in range(n)], autoreset_mode=mode
    )
    (obs, infos), (s_obs, s_infos) = venv.reset(seed=5), sync.reset(seed=5)
    assert _equal(obs, s_obs)
    _same_infos(infos, s_infos)
    rng = np.random.default_rng(1)
    seen = set()
    for _ in range(steps):
        actions = _actions(venv, infos, rng)
        if isinstance(venv.single_action_space, gym.spaces.Discrete):
            wild = rng.random(n) < 0.25
            actions[wild] = rng.integers(0, venv.single_action_space.n, int(wild.sum()))
        out, s_out = venv.step(actions), sync.step(actions)
        assert _equal(out[0], s_out[0])
        for x, y in zip(out[1:4], s_out[1:4]):
            assert x.dtype == y.dtype
            np.testing.assert_array_equal(x, y)
        _same_infos(out[4], s_out[4])
        infos = out[4]
        seen |= set(infos) | {f"final_info.{k}" for k in infos.get("final_info", {})}
    if mode == AutoresetMode.SAME_STEP:
        assert "final_obs" in seen, "the run should cover same-step autoresets"
    if env_id.startswith("Web"):
        assert "illegal_action" in seen or "final_info.illegal_action" in seen
    venv.close()
    sync.close()


def test_a_refused_action_steps_no_environment() -> None:
    # illegal_action="raise": one environment's masked-out action refuses the whole batch, so
    # the environments stay in step with each other and with single environments.
    env_id, params = "WebNavigation-Difficulty-01-v0", {"num_websites": 3}
    venv = A2PerfVectorEnv(env_id, num_envs=2, illegal_action="raise", **params)
    singles = [A2PerfEnv(env_id, illegal_action="raise", **params) for _ in range(2)]
    with pytest.raises(RuntimeError, match="environment 0: step.. called before reset"):
        venv.step(np.zeros(2, np.int64))
    _, infos = venv.reset(seed=2)
    for i, env in enumerate(singles):
        env.reset(seed=2 + i)
    illegal = np.flatnonzero(infos["action_mask"][1] == 0)
    legal = np.flatnonzero(infos["action_mask"][0])
    assert illegal.size and legal.size
    with pytest.raises(ValueError, match=rf"environment 1: action {illegal[0]} is masked out"):
        venv.step(np.array([legal[0], illegal[0]]))
    # Nothing moved: the next legal batch matches single environments stepped once.
    legal1 = np.flatnonzero(infos["action_mask"][1])
    obs, rewards, *_ = venv.step(np.array([legal[0], legal1[0]]))
    for i, (env, a) in enumerate(zip(singles, (legal[0], legal1[0]))):
        o, r, *_ = env.step(a)
        assert _equal(_row(obs, i), o) and rewards[i] == r
    with pytest.raises(ValueError, match=r"environment 1: action 18446744073709551615 is outside"):
        venv.step(np.array([0, 2**64 - 1], np.uint64))
    venv.close()


@pytest.mark.parametrize(
    ("env_id", "params", "mode"),
    [
        ("QuadrupedLocomotion-DogPace-v0", {}, "rgb_array"),
        ("CircuitTraining-Synthetic-Small-v0", {"std_cell_placer": "none"}, "svg"),
        ("WebNavigation-Difficulty-01-v0", {"num_websites": 3}, "html"),
    ],
)
def test_render_gives_every_environments_frame_as_single_ones_draw_it(
    env_id: str, params: dict, mode: str
) -> None:
    venv = gym.make_vec(
        f"a2perf/{env_id}", num_envs=2, vectorization_mode="vector_entry_point",
        render_mode=mode, **params,
    )
    assert venv.metadata["render_modes"] == A2PerfEnv(env_id, **params).metadata["render_modes"]
    singles = [A2PerfEnv(env_id, render_mode=mode, **params) for _ in range(2)]
    _, infos = venv.reset(seed=4)
    for i, env in enumerate(singles):
        env.reset(seed=4 + i)
    rng = np.random.default_rng(2)
    for _ in range(3):
        actions = _actions(venv, infos, rng)
        *_, infos = venv.step(actions)
        for env, a in zip(singles, actions):
            env.step(a)
    frames = venv.render()
    assert isinstance(frames, tuple) and len(frames) == 2
    for frame, env in zip(frames, singles):
        assert _equal(frame, env.render())
    with pytest.raises(ValueError, match="render modes are"):
        A2PerfVectorEnv(env_id, num_envs=2, render_mode="human", **params)
    assert A2PerfVectorEnv(env_id, num_envs=1, **params).render() is None
    venv.close()


def test_same_step_autoreset_reports_the_final_observation() -> None:
    venv = A2PerfVectorEnv(
        "QuadrupedLocomotion-DogPace-v0",
        num_envs=2,
        episode_steps=3,
        autoreset_mode=AutoresetMode.SAME_STEP,
    )
    single = A2PerfEnv("QuadrupedLocomotion-DogPace-v0", episode_steps=3)
    obs, _ = venv.reset(seed=3)
    single.reset(seed=3)
    zero = np.zeros((2, 12), np.float32)
    for t in range(3):
        obs, rewards, terms, truncs, infos = venv.step(zero)
        o, r, te, tr, _ = single.step(zero[0])
        assert rewards[0] == r
    assert truncs[0] or terms[0]
    assert infos["_final_obs"][0]
    np.testing.assert_array_equal(infos["final_obs"][0], o)
    np.testing.assert_array_equal(obs[0], single.reset()[0])


def test_copy_false_returns_the_preallocated_buffers() -> None:
    venv = A2PerfVectorEnv("QuadrupedLocomotion-DogPace-v0", num_envs=2, copy=False)
    a, _ = venv.reset(seed=0)
    b, *_ = venv.step(np.zeros((2, 12), np.float32))
    assert a is b or np.shares_memory(a, b)
    copying = A2PerfVectorEnv("QuadrupedLocomotion-DogPace-v0", num_envs=2)
    c, _ = copying.reset(seed=0)
    d, r, te, tr, _ = copying.step(np.zeros((2, 12), np.float32))
    assert not np.shares_memory(c, d)
    # What a step returned is the caller's: later steps do not touch it.
    kept = [x.copy() for x in (d, r, te, tr)]
    e, *_ = copying.step(np.ones((2, 12), np.float32))
    assert not np.array_equal(e, d)
    for x, y in zip(kept, (d, r, te, tr)):
        np.testing.assert_array_equal(x, y)
    web = A2PerfVectorEnv("WebNavigation-Difficulty-01-v0", num_envs=2)
    web.reset(seed=0)
    w1, *_, i1 = web.step(np.zeros(2, np.int64))
    kept_web = ({k: v.copy() for k, v in w1.items()}, i1["action_mask"].copy())
    web.step(np.ones(2, np.int64))
    for k, v in kept_web[0].items():
        np.testing.assert_array_equal(w1[k], v)
    np.testing.assert_array_equal(i1["action_mask"], kept_web[1])


@pytest.mark.parametrize("copy", [False, True])
@pytest.mark.parametrize(("env_id", "params", "steps"), CASES)
def test_batches_have_the_single_spaces_dtypes(env_id, params, steps, copy) -> None:
    venv = A2PerfVectorEnv(env_id, num_envs=2, copy=copy, **params)
    single = venv.single_observation_space
    want = ({k: s.dtype for k, s in single.spaces.items()}
            if isinstance(single, gym.spaces.Dict) else {"obs": single.dtype})
    if env_id.startswith("Web"):
        assert want["dom_tokens"] == np.int32 and want["dom_features"] == np.float32
    if env_id.startswith("Circuit"):
        assert want["current_node"] == np.int32 and want["grid"] == np.float32
    obs, infos = venv.reset(seed=2)
    rng = np.random.default_rng(3)
    for _ in range(5):
        arrays = obs if isinstance(obs, dict) else {"obs": obs}
        assert {k: a.dtype for k, a in arrays.items()} == want
        assert obs in venv.observation_space
        obs, *_, infos = venv.step(_actions(venv, infos, rng))
    venv.close()


def test_seeds_per_environment_and_bad_vector_input() -> None:
    venv = A2PerfVectorEnv("QuadrupedLocomotion-DogTrot-v0", num_envs=2)
    a, _ = venv.reset(seed=[5, 9])
    b, _ = venv.reset(seed=5)
    np.testing.assert_array_equal(a[0], b[0])
    assert not np.array_equal(a[1], b[1])
    with pytest.raises(ValueError, match="shape"):
        venv.step(np.zeros((3, 12), np.float32))
    with pytest.raises(TypeError, match="real numbers"):
        venv.step(np.array([["a"] * 12] * 2))
    with pytest.raises(ValueError, match="outside the action space"):
        venv.step(np.full((2, 12), 100.0, np.float32))
    with pytest.raises(ValueError, match="2 seeds for 3|3 seeds for 2"):
        venv.reset(seed=[1, 2, 3])
    with pytest.raises(ValueError, match="at least 1"):
        A2PerfVectorEnv("QuadrupedLocomotion-DogTrot-v0", num_envs=0)
    with pytest.raises(ValueError, match="did you mean `QuadrupedLocomotion-DogPace-v0`"):
        A2PerfVectorEnv("QuadrupedLocomotion-DogPac-v0", num_envs=2, render_mode="rgb_array")
    web = A2PerfVectorEnv("WebNavigation-Difficulty-01-v0", num_envs=2)
    web.reset(seed=0)
    with pytest.raises(TypeError, match="integers"):
        web.step(np.array([0.5, 1.0]))
    with pytest.raises(ValueError, match="outside Discrete"):
        web.step(np.array([0, 10**9]))
    venv.close()
    venv.close()
    with pytest.raises(RuntimeError, match="closed"):
        venv.reset(seed=0)


def test_building_on_several_threads_reports_bad_parameters_and_files(tmp_path) -> None:
    # Each environment is built on the thread that steps it; errors still name the problem.
    dog = "QuadrupedLocomotion-DogPace-v0"
    with pytest.raises(TypeError, match=r"unknown parameter `episode_stepz`.*did you mean"):
        A2PerfVectorEnv(dog, num_envs=3, episode_stepz=3)
    with pytest.raises(FileNotFoundError, match="missing.txt"):
        A2PerfVectorEnv(dog, num_envs=3, motion_file=str(tmp_path / "missing.txt"))
    # Built on different threads, the environments still start from the same state.
    venv = A2PerfVectorEnv(dog, num_envs=3)
    obs, _ = venv.reset(seed=[4, 4, 4])
    assert np.array_equal(obs[0], obs[1]) and np.array_equal(obs[0], obs[2])
    venv.close()


def test_a_chromium_vector_env_equals_single_ones_and_close_stops_the_browsers() -> None:
    require_chromium()
    env_id, params = "WebNavigation-Difficulty-01-v0", {"backend": "chromium", "num_websites": 1}
    before = child_pids()
    venv = A2PerfVectorEnv(env_id, num_envs=2, **params)
    assert len(child_pids() - before) >= 2, "each environment starts its own browser"
    singles = [A2PerfEnv(env_id, **params) for _ in range(2)]
    _replay_against_singles(venv, singles, seed=11, steps=6)
    for env in singles:
        env.close()
    venv.close()
    assert not (child_pids() - before), "close() must stop every environment's browser"


@pytest.mark.skipif(not hasattr(os, "fork"), reason="os.fork is POSIX-only")
@pytest.mark.filterwarnings("ignore::DeprecationWarning")  # fork() of a multi-threaded process
def test_a_forked_child_steps_the_inherited_vector_env_like_the_parent() -> None:
    # The worker threads stay in the parent; the child's steps must neither hang waiting for
    # them nor differ from the parent's.
    venv = gym.make_vec(
        "a2perf/QuadrupedLocomotion-DogPace-v0", num_envs=2,
        vectorization_mode="vector_entry_point", episode_steps=15,
    )
    venv.reset(seed=3)
    actions = np.random.default_rng(5).uniform(-0.4, 0.4, (30, 2, 12)).astype(np.float32)
    venv.step(actions[0])  # the workers have run before the fork

    def run() -> bytes:
        out = [venv.step(a) for a in actions[1:]]
        return b"".join(np.concatenate([o.ravel(), r, te, tr]).tobytes() for o, r, te, tr, _ in out)

    read, write = os.pipe()
    pid = os.fork()
    if pid == 0:  # the child: report its trajectory, then leave without pytest's teardown
        try:
            data = run()
            os.write(write, len(data).to_bytes(8, "little"))
            view = memoryview(data)
            while view:
                view = view[os.write(write, view):]
        finally:
            os._exit(0)
    os.close(write)
    expected = run()
    received = b""
    deadline = time.monotonic() + 60
    while True:
        ready, _, _ = select.select([read], [], [], max(0.0, deadline - time.monotonic()))
        if not ready:
            os.kill(pid, signal.SIGKILL)
            os.waitpid(pid, 0)
            pytest.fail("the forked child hung stepping the inherited vector env")
        chunk = os.read(read, 1 << 16)
        if not chunk:
            break
        received += chunk
    os.close(read)
    os.waitpid(pid, 0)
    assert int.from_bytes(received[:8], "little") == len(expected)
    assert received[8:] == expected
    venv.close()
