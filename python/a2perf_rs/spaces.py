"""The benchmark's spaces as ``gymnasium.spaces``.

Box spaces have the element type of the Rust space (``int32`` for token ids, node indices and
flags, as in the original environments; ``float32`` for real-valued features) and its exact
per-element bounds (infinite float bounds stay infinite); discrete spaces are ``Discrete(n)``
(int64); dict observations keep the Rust key order.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from gymnasium import spaces


def to_gymnasium(desc: tuple[Any, ...]) -> spaces.Space[Any]:
    """Converts the native description ``("box", low, high, dtype)``, ``("discrete", n)`` or
    ``("dict", [(name, desc), ...])`` into a Gymnasium space."""
    kind = desc[0]
    if kind == "box":
        dtype = np.dtype(desc[3]) if len(desc) > 3 else np.dtype(np.float32)
        # The bounds arrive as float64, which holds every int32 and float32 value exactly.
        low = np.asarray(desc[1], dtype=np.float64).astype(dtype)
        high = np.asarray(desc[2], dtype=np.float64).astype(dtype)
        return spaces.Box(low=low, high=high, shape=low.shape, dtype=dtype)
    if kind == "discrete":
        return spaces.Discrete(int(desc[1]))
    if kind == "dict":
        # A sequence keeps the Rust key order (a plain dict would be sorted by Gymnasium).
        return spaces.Dict([(name, to_gymnasium(sub)) for name, sub in desc[1]])
    raise ValueError(f"unknown space kind {kind!r}")
