"""The benchmark's spaces as ``gymnasium.spaces``.

Box spaces are float32 with the exact per-element bounds of the Rust space (infinite bounds stay
infinite); discrete spaces are ``Discrete(n)`` (int64); dict observations keep the Rust key order.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from gymnasium import spaces


def to_gymnasium(desc: tuple[Any, ...]) -> spaces.Space[Any]:
    """Converts the native description ``("box", low, high)``, ``("discrete", n)`` or
    ``("dict", [(name, desc), ...])`` into a Gymnasium space."""
    kind = desc[0]
    if kind == "box":
        low = np.asarray(desc[1], dtype=np.float32)
        high = np.asarray(desc[2], dtype=np.float32)
        return spaces.Box(low=low, high=high, shape=low.shape, dtype=np.float32)
    if kind == "discrete":
        return spaces.Discrete(int(desc[1]))
    if kind == "dict":
        # A sequence keeps the Rust key order (a plain dict would be sorted by Gymnasium).
        return spaces.Dict([(name, to_gymnasium(sub)) for name, sub in desc[1]])
    raise ValueError(f"unknown space kind {kind!r}")
