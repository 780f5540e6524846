"""Stability maps: the number of unstable modes per frequency band over a parameter grid
(seed 001 Figs. 17–19: sign(v)μ × disc Young's modulus, one panel per band plus the total)."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from fem_squeal.reduced.eigensolve import TWO_PI, unstable
from fem_squeal.reduced.sweep import SweepResult
from fem_squeal.util.errors import ModelError


@dataclass
class StabilityMap:
    """``counts[b]`` has the grid's shape: unstable modes with frequency in ``bands_hz[b]``."""

    axes: dict[str, np.ndarray]
    bands_hz: list[tuple[float, float]]
    counts: np.ndarray              # (n_bands,) + grid shape
    total: np.ndarray               # grid shape: unstable modes in the whole band range

    def as_dict(self) -> dict:
        return {"axes": self.axes, "bands_hz": self.bands_hz, "counts": self.counts, "total": self.total}


def equal_bands(band_hz: tuple[float, float], n: int) -> list[tuple[float, float]]:
    """``n`` equal frequency ranges covering ``band_hz`` (the seed's ranges A–F for n = 6)."""
    if n < 1:
        raise ModelError(f"n_bands: must be >= 1 (got {n})")
    lo, hi = band_hz
    if not 0 <= lo < hi:
        raise ModelError(f"band_hz: must be increasing and >= 0 (got {band_hz})")
    edges = np.linspace(lo, hi, n + 1)
    return [(float(a), float(b)) for a, b in zip(edges[:-1], edges[1:])]


def stability_map(sweep: SweepResult, bands_hz: list[tuple[float, float]], growth_tol: float = 1e-6
                  ) -> StabilityMap:
    """Count Re λ > growth_tol·|λ| per band (half-open [lo, hi), the last band closed)."""
    lam = sweep.eigenvalues
    f = lam.imag / TWO_PI
    bad = unstable(lam, growth_tol)
    counts = []
    for i, (lo, hi) in enumerate(bands_hz):
        inside = (f >= lo) & ((f < hi) if i < len(bands_hz) - 1 else (f <= hi))
        counts.append(np.sum(bad & inside, axis=-1))
    counts = np.array(counts, dtype=int)
    lo, hi = bands_hz[0][0], bands_hz[-1][1]
    total = np.sum(bad & (f >= lo) & (f <= hi), axis=-1)
    return StabilityMap(dict(sweep.grid.axes), list(bands_hz), counts, total)
