"""The values of a condition variable in a scene section: a list of numbers or a range {start, stop, n}
(the operating matrix's pressures, temperatures and speeds; the preload's pressure continuation reads the
pressures too)."""
from __future__ import annotations

import numpy as np

from fem_squeal.util.errors import SceneError

VALUES = "a list of numbers or a range {start, stop, n}"


def values(v, key: str) -> list[float]:
    """A list of numbers, or the range {start, stop, n} (n ≥ 1 values, linspace); SceneError naming ``key``."""
    if isinstance(v, dict):
        unknown = sorted(set(v) - {"start", "stop", "n"})
        if unknown or not {"start", "stop", "n"} <= set(v):
            raise SceneError(f"{key}: a range is {{start, stop, n}} (got {v!r})")
        n = v["n"]
        if isinstance(n, bool) or not isinstance(n, int) or n < 1:
            raise SceneError(f"{key}.n: must be an integer >= 1 (got {n!r})")
        return np.linspace(float(v["start"]), float(v["stop"]), n).tolist()
    if not v or not all(isinstance(x, (int, float)) and not isinstance(x, bool) and np.isfinite(x) for x in v):
        raise SceneError(f"{key}: must be {VALUES} (got {v!r})")
    return [float(x) for x in v]
