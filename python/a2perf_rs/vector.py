"""Native vector environments: N environments stepped in Rust threads with the GIL released.

``gymnasium.make_vec("a2perf/<id>", num_envs=N, vectorization_mode="vector_entry_point")``
returns an :class:`A2PerfVectorEnv`. Observations, rewards and flags are written by the Rust
threads straight into numpy arrays: with ``copy=True`` (the default, as Gymnasium's vector
environments) into fresh arrays each call, which are the caller's to keep; with ``copy=False``
into the vector environment's own buffers, returned as they are and overwritten by the next
call.

Threads: ``min(N, cores)`` in all — the caller's and the vector environment's own workers — each
stepping a fixed, contiguous share of the environments (an environment stays on one thread, its
state in that core's cache), and each environment is built on the thread that steps it, all at
once. Between steps the workers spin for up to 200 µs before sleeping, so an agent that returns
quickly does not pay a thread wake-up per step.

Semantics are Gymnasium 1.x's: ``reset(seed=s)`` seeds environment ``i`` with ``s + i`` (a list
gives one seed per environment); later resets continue each environment's own random stream; the
autoreset mode is next-step by default (``autoreset_mode=AutoresetMode.SAME_STEP`` is supported
too). ``infos`` is a dict of arrays with ``_key`` masks, holding ``action_mask`` (``(N, n)``
int8) for discrete environments with masks; in same-step mode ``final_obs`` (an object array,
``None`` where no episode ended) and ``final_info`` (itself such a dict). All of it is what
Gymnasium's ``SyncVectorEnv`` over N :class:`~a2perf_rs.envs.A2PerfEnv` returns (tested, both
modes, infos included).

A step that any environment refuses (``step`` before ``reset``, or a masked-out action with
``illegal_action="raise"``) raises naming that environment and steps none of them.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from . import _native
from ._render import checked_metadata
from .spaces import to_gymnasium

_MODES = {AutoresetMode.NEXT_STEP: "next_step", AutoresetMode.SAME_STEP: "same_step"}


class A2PerfVectorEnv(VectorEnv):
    """``num_envs`` copies of one benchmark environment, stepped in parallel in Rust.

    Args:
        env_id: The benchmark id (without namespace).
        num_envs: Number of environments.
        autoreset_mode: ``AutoresetMode.NEXT_STEP`` (default) or ``AutoresetMode.SAME_STEP``.
        copy: Return fresh arrays each call (default) or the vector environment's own buffers,
            overwritten by the next call.
        illegal_action, illegal_action_reward: As for :class:`a2perf_rs.envs.A2PerfEnv`.
        render_mode: ``None`` (default) or one of the id's render modes (as for
            :class:`a2perf_rs.envs.A2PerfEnv`): :meth:`render` then returns every environment's
            frame.
        max_episode_steps: Ignored unless it equals the environment's own limit (Gymnasium passes
            the registered value, which is ``None`` here); the environments truncate themselves.
        episode_seeds: A training run's seed: every reset without a seed of environment ``i``
            (autoresets included) takes the next seed of stream ``i`` of that run, as the
            built-in algorithms' training environments do (what
            :meth:`a2perf_rs.TrainingRun.make_vec` gives). ``None`` (default): Gymnasium's
            semantics above.
        **params: The environment's parameters (the same for every copy).
    """

    def __init__(
        self,
        env_id: str,
        num_envs: int = 1,
        autoreset_mode: AutoresetMode | str = AutoresetMode.NEXT_STEP,
        copy: bool = True,
        illegal_action: str = "terminate",
        illegal_action_reward: float | None = None,
        max_episode_steps: int | None = None,
        render_mode: str | None = None,
        episode_seeds: int | None = None,
        **params: Any,
    ) -> None:
        if not isinstance(num_envs, (int, np.integer)) or isinstance(num_envs, bool):
            raise TypeError(f"num_envs must be an integer, got {type(num_envs).__name__}")
        if num_envs < 1:
            raise ValueError(f"num_envs must be at least 1, got {num_envs}")
        meta = checked_metadata(env_id, render_mode)
        mode = AutoresetMode(autoreset_mode)
        if mode not in _MODES:
            raise ValueError(
                f"autoreset_mode {mode} is not supported: use AutoresetMode.NEXT_STEP or SAME_STEP"
            )
        self._native = _native.VecEnv(
            env_id,
            int(num_envs),
            params,
            autoreset_mode=_MODES[mode],
            copy=copy,
            illegal_action=illegal_action,
            illegal_action_reward=illegal_action_reward,
            episode_seeds=episode_seeds,
        )
        spec = self._native.spec()
        if max_episode_steps is not None and max_episode_steps != spec["max_episode_steps"]:
            raise ValueError(
                f"max_episode_steps={max_episode_steps} differs from the environment's own limit "
                f"{spec['max_episode_steps']}; set it through the environment's parameters"
            )
        self.env_id = env_id
        self.num_envs = int(num_envs)
        self.single_observation_space = to_gymnasium(spec["observation_space"])
        self.single_action_space = to_gymnasium(spec["action_space"])
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        self.action_space = batch_space(self.single_action_space, self.num_envs)
        self.metadata = {"autoreset_mode": mode, **meta}
        self.render_mode = render_mode
        self.max_episode_steps: int | None = spec["max_episode_steps"]
        self.params: dict[str, Any] = spec["params"]
        self.provenance: dict[str, str] = spec["metadata"]
        self._discrete = isinstance(self.single_action_space, gym.spaces.Discrete)
        self._action_dtype = np.dtype(np.int64 if self._discrete else np.float32)
        self._action_shape = (self.num_envs, *self.single_action_space.shape)

    def reset(
        self,
        *,
        seed: int | list[int | None] | None = None,
        options: dict[str, Any] | None = None,
    ) -> tuple[Any, dict[str, Any]]:
        """Resets every environment: ``seed`` int ⇒ environment ``i`` gets ``seed + i``; a list
        gives each its own (``None`` = continue its stream)."""
        if seed is None:
            seeds: list[int | None] = [None] * self.num_envs
        elif isinstance(seed, (int, np.integer)) and not isinstance(seed, bool):
            seeds = [int(seed) + i for i in range(self.num_envs)]
        else:
            seeds = list(seed)
            if len(seeds) != self.num_envs:
                raise ValueError(f"{len(seeds)} seeds for {self.num_envs} environments")
        for s in seeds:
            if s is not None and (
                not isinstance(s, (int, np.integer)) or isinstance(s, bool) or s < 0
            ):
                raise ValueError(f"seeds must be non-negative integers or None, got {s!r}")
        if options:
            raise ValueError(f"reset options are not supported, got {sorted(options)}")
        super().reset(seed=seeds[0] if seed is not None else None)
        return self._native.reset([None if s is None else int(s) for s in seeds])

    def step(
        self, actions: Any
    ) -> tuple[Any, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        """Steps environment ``i`` with ``actions[i]``."""
        if (
            actions.__class__ is np.ndarray
            and actions.dtype == self._action_dtype
            and actions.flags.c_contiguous
            and actions.shape == self._action_shape
        ):
            # Already what the native side takes (it checks the values): every microsecond here
            # is one that the threads stepping the environments wait for.
            return self._native.step(actions)
        actions = np.asarray(actions)
        if self._discrete:
            if actions.dtype.kind not in "iu":
                raise TypeError(f"discrete actions must be integers, got dtype {actions.dtype}")
            if actions.dtype.kind == "u" and actions.size and actions.max() > np.iinfo(np.int64).max:
                # Cast to int64 such a value would wrap around to a negative one.
                i = int(np.argmax(actions.reshape(-1) > np.iinfo(np.int64).max))
                raise ValueError(
                    f"environment {i}: action {actions.reshape(-1)[i]} is outside "
                    f"Discrete({self.single_action_space.n})"
                )
            actions = actions.astype(np.int64, copy=False)
        else:
            if actions.dtype.kind not in "fiu":
                raise TypeError(f"box actions must be real numbers, got dtype {actions.dtype}")
            actions = np.ascontiguousarray(actions, dtype=np.float32)
        if actions.shape != self._action_shape:
            raise ValueError(f"actions have shape {actions.shape}, expected {self._action_shape}")
        return self._native.step(actions)

    def render(self) -> tuple[Any, ...] | None:
        """Every environment's frame in ``render_mode``, as a tuple (what Gymnasium's
        ``SyncVectorEnv`` returns): ``uint8`` arrays ``(H, W, 3)`` for ``"rgb_array"``, ``str``
        for ``"svg"`` and ``"html"``; ``None`` when ``render_mode`` is ``None``."""
        if self.render_mode is None:
            return None
        return tuple(self._native.render(self.render_mode))

    def close_extras(self, **kwargs: Any) -> None:
        """Closes every environment (releasing their Chromium browsers)."""
        native = getattr(self, "_native", None)
        if native is not None:
            native.close()

    def __repr__(self) -> str:
        return f"A2PerfVectorEnv({self.env_id!r}, num_envs={self.num_envs})"
