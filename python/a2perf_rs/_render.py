"""Render modes and frame rates of the benchmark's ids, shared by the single and the vector
environments (:mod:`a2perf_rs.envs`, :mod:`a2perf_rs.vector`)."""

from __future__ import annotations

from typing import Any

import gymnasium as gym

from . import _native

NAMESPACE = "a2perf"

# Render modes and frame rates of each domain's ids: what `gymnasium.make` checks `render_mode`
# against before building anything. The Rust environments' own `render_modes()` are the
# authority (test_render.py checks every id agrees).
RENDER_METADATA: dict[str, dict[str, Any]] = {
    "circuit_training": {"render_modes": ["rgb_array", "svg"], "render_fps": 4},
    # One frame per control step of 33 ms.
    "quadruped_locomotion": {"render_modes": ["rgb_array"], "render_fps": 1000 / 33},
    "web_navigation": {"render_modes": ["html"], "render_fps": 4},
}


def _domain(env_id: str) -> str | None:
    """The domain of ``env_id`` (without namespace), ``None`` for an unknown id."""
    for entry_id, domain, _summary, _params in _native.env_entries():
        if entry_id == env_id:
            return str(domain)
    return None


def metadata_of_domain(domain: str | None) -> dict[str, Any]:
    meta = RENDER_METADATA.get(domain or "", {"render_modes": [], "render_fps": None})
    return {"render_modes": list(meta["render_modes"]), "render_fps": meta["render_fps"]}


def render_metadata(env_id: str) -> dict[str, Any]:
    """``{"render_modes": [...], "render_fps": ...}`` of ``env_id`` (with or without the
    ``a2perf/`` namespace): Gymnasium's ``metadata`` of its environments."""
    bare = env_id.split("/", 1)[1] if env_id.startswith(NAMESPACE + "/") else env_id
    domain = _domain(bare)
    if domain is None:
        raise gym.error.UnregisteredEnv(f"no a2perf environment {env_id!r}")
    return metadata_of_domain(domain)


def checked_metadata(env_id: str, render_mode: str | None) -> dict[str, Any]:
    """What an environment's constructor needs before it builds anything: the metadata of
    ``env_id`` (without namespace), ``render_mode`` checked against it (a bad one must not start
    a browser first). An unknown id gets no render modes here and no check: building it then
    raises the registry's error, which names the id with a did-you-mean."""
    domain = _domain(env_id)
    meta = metadata_of_domain(domain)
    if render_mode is not None and domain is not None:
        check_render_mode(env_id, render_mode, meta["render_modes"])
    return meta


def check_render_mode(env_id: str, render_mode: str, modes: list[str]) -> None:
    """Raises ``ValueError`` naming ``modes`` unless ``render_mode`` is one of them."""
    if render_mode not in modes:
        supported = ", ".join(repr(m) for m in modes) if modes else "none"
        raise ValueError(
            f"render_mode={render_mode!r} is not supported by {env_id}: its render modes are "
            f"{supported} (or None for no rendering)"
        )
