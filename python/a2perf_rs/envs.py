"""The benchmark's environments as Gymnasium environments.

Importing :mod:`a2perf_rs` registers every id in the ``a2perf`` namespace::

    import gymnasium as gym
    import a2perf_rs  # noqa: F401  (registers the ids)

    env = gym.make("a2perf/QuadrupedLocomotion-DogPace-v0")
    obs, info = env.reset(seed=0)
    obs, reward, terminated, truncated, info = env.step(env.action_space.sample())

Keyword arguments of ``gym.make`` are the environment's typed parameters (``a2perf list`` or
:func:`a2perf_rs.env_params` shows them); an unknown or mistyped name raises ``TypeError`` naming
it, with a did-you-mean.

**Action masks.** Discrete environments with illegal actions (circuit placement, web navigation)
put the mask of the current state in ``info["action_mask"]`` (``np.int8``, 1 = legal, ready for
``env.action_space.sample(mask=info["action_mask"])``) and return it from
:meth:`A2PerfEnv.action_masks` (the method sb3-contrib's ``MaskablePPO`` calls). Observations stay
exactly the Rust observation space; they carry no mask key.

**Observations are not copied.** The arrays ``reset`` and ``step`` return are the buffers the
Rust environment wrote; their numpy ``base`` owns the memory. They are never written again while
anything references them (a view or memoryview included); released ones are reused for later
steps, which every environment overwrites completely (tested for every id).

**Illegal actions.** Gymnasium lets every element of the action space be stepped. An action the
mask forbids is not applied: by default (``illegal_action="terminate"``) the episode terminates
with ``illegal_action_reward`` (default: the circuit's ``infeasible_reward``, else -1) and
``info["illegal_action"] = True``; with ``illegal_action="raise"`` it raises ``ValueError``.

**Rendering.** ``gym.make(id, render_mode=...)`` takes one of the id's render modes
(``env.metadata["render_modes"]``), and :meth:`A2PerfEnv.render` then returns the current state
drawn by the Rust environment, computed only when called:

- circuit placement: ``"rgb_array"``, the placement rasterized to a ``uint8`` array
  ``(H, W, 3)``, 400 pixels on the canvas's longer side (white canvas, congestion heatmap, soft
  macros, placed hard macros, ports), and ``"svg"``, a ``str``: the picture
  ``a2perf circuit render`` draws (800 pixels) with the macros placed so far, for a finished
  placement exactly the CLI's output;
- locomotion: ``"rgb_array"``, a ``(240, 320, 3)`` side view (x–z plane, camera following the
  robot's base) of the robot's stick figure (red) over the reference pose (green) and the ground;
- web navigation: ``"html"``, a ``str``: the current page as a standalone HTML document (which
  page is shown, values typed, boxes checked, ``visited`` classes), with either backend.

``render_mode=None`` (the default) renders nothing and ``render()`` returns ``None``; a mode the
id does not have raises ``ValueError`` naming the ones it has. ``metadata["render_fps"]`` is
1000/33 for locomotion (a frame per 33 ms control step) and 4 for the others (a watchable pace).
"""

from __future__ import annotations

import dataclasses
import os
from typing import Any, SupportsFloat

import gymnasium as gym
import numpy as np
from gymnasium.envs.registration import EnvSpec

from . import _native
from ._render import (
    NAMESPACE,
    check_render_mode,
    checked_metadata,
    metadata_of_domain,
    render_metadata,
)
from .spaces import to_gymnasium
from .vector import A2PerfVectorEnv

# Keyword arguments handled by the Python bindings rather than by the environment itself.
BINDING_KWARGS = ("illegal_action", "illegal_action_reward")

class A2PerfEnv(gym.Env[Any, Any]):
    """One environment of the benchmark, stepped in Rust.

    Args:
        env_id: The benchmark id, e.g. ``"QuadrupedLocomotion-DogPace-v0"`` (without namespace).
        render_mode: ``None`` (default: nothing is rendered) or one of the id's render modes
            (``metadata["render_modes"]``; see the module documentation), which
            :meth:`render` then draws. Any other value raises ``ValueError`` naming the modes.
        illegal_action: ``"terminate"`` (default) or ``"raise"``, see the module documentation.
        illegal_action_reward: Reward of an illegal action under ``"terminate"``.
        episode_seeds: ``(run_seed, index)``: every ``reset()`` without a seed takes the next
            seed of environment ``index``'s stream in a run with ``run_seed``, as the built-in
            algorithms' training environments do (what :meth:`a2perf_rs.TrainingRun.make_env`
            gives). ``None`` (default): the environment continues its own random stream.
        **params: The environment's parameters.

    ``metadata`` is the id's (an instance attribute): ``{"render_modes": [...], "render_fps":
    ...}``.
    """

    metadata: dict[str, Any] = {"render_modes": []}

    def __init__(
        self,
        env_id: str,
        render_mode: str | None = None,
        illegal_action: str = "terminate",
        illegal_action_reward: float | None = None,
        episode_seeds: tuple[int, int] | None = None,
        **params: Any,
    ) -> None:
        meta = checked_metadata(env_id, render_mode)
        self._native = _native.Env(
            env_id,
            params,
            illegal_action=illegal_action,
            illegal_action_reward=illegal_action_reward,
            # A spec read back from JSON holds the pair as a list.
            episode_seeds=None if episode_seeds is None else tuple(episode_seeds),
        )
        modes = list(self._native.render_modes())
        if render_mode is not None:
            try:
                check_render_mode(env_id, render_mode, modes)
            except ValueError:
                self._native.close()
                raise
        self.metadata = {"render_modes": modes, "render_fps": meta["render_fps"]}
        self.render_mode = render_mode
        spec = self._native.spec()
        self.env_id = env_id
        self.observation_space = to_gymnasium(spec["observation_space"])
        self.action_space = to_gymnasium(spec["action_space"])
        self.max_episode_steps: int | None = spec["max_episode_steps"]
        self.params: dict[str, Any] = spec["params"]
        self.provenance: dict[str, str] = spec["metadata"]

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[Any, dict[str, Any]]:
        """Starts an episode. ``seed`` re-seeds the episode's randomness (same seed ⇒ same
        episode); without it the environment continues its own random stream."""
        super().reset(seed=seed)
        return self._native.reset(seed)

    def step(self, action: Any) -> tuple[Any, SupportsFloat, bool, bool, dict[str, Any]]:
        """Applies ``action``; returns ``(observation, reward, terminated, truncated, info)``."""
        return self._native.step(action)

    def render(self) -> np.ndarray | str | None:
        """The current state drawn in ``render_mode``: a ``uint8`` array ``(H, W, 3)`` for
        ``"rgb_array"``, a ``str`` for ``"svg"`` and ``"html"``; ``None`` when ``render_mode`` is
        ``None``. Each call draws anew (a fresh array); same seed and actions, same frames."""
        if self.render_mode is None:
            return None
        return self._native.render(self.render_mode)

    def action_masks(self) -> np.ndarray | None:
        """The legal actions of the current state as a boolean array (``None`` when the action
        space is continuous)."""
        mask = self._native.action_mask()
        return None if mask is None else mask.astype(bool)

    def close(self) -> None:
        """Releases the environment's resources (its Chromium browser for the web ids with
        ``backend="chromium"``). Calling it twice is fine."""
        native = getattr(self, "_native", None)
        if native is not None:
            native.close()

    @property  # type: ignore[override]
    def spec(self) -> EnvSpec | None:
        """The Gymnasium spec ``gymnasium.make`` gave this environment, its kwargs plain JSON
        data (paths as ``str``, numpy values as Python numbers and lists) so that
        ``spec.to_json()``, pickling and ``gymnasium.make(spec)`` work."""
        return self.__dict__.get("_spec")

    @spec.setter
    def spec(self, value: EnvSpec | None) -> None:
        if value is not None:
            kwargs = {k: _json_value(v) for k, v in value.kwargs.items()}
            value = dataclasses.replace(value, kwargs=kwargs)
        self.__dict__["_spec"] = value

    def __repr__(self) -> str:
        return f"A2PerfEnv({self.env_id!r})"


def _json_value(value: Any) -> Any:
    """``value`` as plain JSON data where it is a path or a numpy scalar/array (what a user
    naturally passes as a parameter), so that the spec's ``to_json`` works; else unchanged."""
    if isinstance(value, os.PathLike):
        return os.fspath(value)
    if isinstance(value, (np.generic, np.ndarray)):
        return value.tolist()
    if isinstance(value, (list, tuple)):
        return [_json_value(v) for v in value]
    return value


class CircuitTrainingEnv(A2PerfEnv):
    """The entry point of the ``CircuitTraining-*`` ids (an :class:`A2PerfEnv`)."""

    domain = "circuit_training"
    metadata = metadata_of_domain(domain)


class QuadrupedLocomotionEnv(A2PerfEnv):
    """The entry point of the ``QuadrupedLocomotion-*`` ids (an :class:`A2PerfEnv`)."""

    domain = "quadruped_locomotion"
    metadata = metadata_of_domain(domain)


class WebNavigationEnv(A2PerfEnv):
    """The entry point of the ``WebNavigation-*`` ids (an :class:`A2PerfEnv`)."""

    domain = "web_navigation"
    metadata = metadata_of_domain(domain)


# Entry points are "module:attr" strings, as for every Gymnasium environment, so that specs
# serialize (`EnvSpec.to_json`, pickle, Minari datasets) and `gymnasium.make(spec)` rebuilds them.
# The class of a domain carries its render metadata, which `gymnasium.make` reads from the
# entry point to check `render_mode` (and to offer the "<mode>_list" and "human" wrappers)
# before building anything; a domain without a class of its own gets `A2PerfEnv`.
_DOMAIN_ENTRY_POINTS = {
    cls.domain: f"{__name__}:{cls.__name__}"
    for cls in (CircuitTrainingEnv, QuadrupedLocomotionEnv, WebNavigationEnv)
}
_GENERIC_ENTRY_POINT = f"{__name__}:A2PerfEnv"
_VECTOR_ENTRY_POINT = f"{A2PerfVectorEnv.__module__}:{A2PerfVectorEnv.__name__}"


def env_params(env_id: str) -> list[tuple[str, str, list[str], Any, str]]:
    """The typed parameters of ``env_id`` (with or without the ``a2perf/`` namespace) as
    ``(name, kind, choices, default, doc)``."""
    bare = env_id.split("/", 1)[1] if env_id.startswith(NAMESPACE + "/") else env_id
    for entry_id, _kind, _summary, params in _native.env_entries():
        if entry_id == bare:
            return list(params)
    raise gym.error.UnregisteredEnv(f"no a2perf environment {env_id!r}")


def env_ids() -> list[str]:
    """Every environment id, with its ``a2perf/`` namespace."""
    return [f"{NAMESPACE}/{entry[0]}" for entry in _native.env_entries()]


def register_all() -> None:
    """Registers every benchmark environment in Gymnasium's ``a2perf`` namespace (idempotent)."""
    for entry_id, domain, _summary, _params in _native.env_entries():
        full = f"{NAMESPACE}/{entry_id}"
        if full in gym.registry:
            continue
        gym.register(
            id=full,
            entry_point=_DOMAIN_ENTRY_POINTS.get(domain, _GENERIC_ENTRY_POINT),
            vector_entry_point=_VECTOR_ENTRY_POINT,
            kwargs={"env_id": entry_id},
            # Episode limits depend on parameters (web `step_limit`, circuit macros, locomotion
            # `episode_steps`); the environments truncate themselves at their spec's limit.
            max_episode_steps=None,
            disable_env_checker=False,
        )
