"""Stability maps: the number of unstable modes per frequency band over a parameter grid
(seed 001 Figs. 17–19: sign(v)μ × disc Young's modulus, one panel per band plus the total), and the
map's instabilities: each connected region where one mode is unstable, with the real modes that couple
in it (issue 38)."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse
import scipy.sparse.csgraph

from fem_squeal.reduced.eigensolve import TWO_PI, unstable
from fem_squeal.reduced.mode_coupling import basis_modes, coupling_of
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


#: two unstable eigenvalues at neighbouring grid points are one instability when each is the other's
#: nearest and their frequencies differ by at most this (relative): a grid step moves a mode by ~1 %
#: (E ± 20 % in 21 steps: 1 % of f), while distinct instabilities are further apart or not mutually nearest
LINK_RTOL = 0.03


@dataclass
class Instability:
    """One instability of a map: a connected set of grid points where one mode is unstable (its
    eigenvalues linked point to point, :func:`instabilities`), where it grows fastest, its frequency
    range and each axis's range over which it occurs; ``coupling`` (:func:`instability_couplings`):
    the real modes that make it up where it grows fastest."""

    growth: np.ndarray                      # grid shape: its Re λ [1/s] where unstable, NaN elsewhere
    freq_hz: tuple[float, float]
    max_growth_rate: float                  # the largest Re λ [1/s] ...
    at: dict[str, float]                    # ... at this point,
    eigenvalue: complex                     # ... this eigenvalue
    ranges: dict[str, tuple[float, float]]  # each axis's [min, max] over the points
    coupling: dict | None = None

    @property
    def mask(self) -> np.ndarray:
        """The grid points where it is unstable."""
        return ~np.isnan(self.growth)

    @property
    def points(self) -> int:
        return int(self.mask.sum())

    def as_dict(self) -> dict:
        return {"freq_hz": list(self.freq_hz), "points": self.points, "share": self.points / self.mask.size,
                "max_growth_rate": self.max_growth_rate, "at": dict(self.at),
                "eigenvalue": [self.eigenvalue.real, self.eigenvalue.imag],
                "ranges": {k: list(v) for k, v in self.ranges.items()},
                **({"coupling": self.coupling} if self.coupling else {})}


def instabilities(sweep: SweepResult, band_hz: tuple[float, float], growth_tol: float = 1e-6,
                  rtol: float = LINK_RTOL) -> list[Instability]:
    """The map's instabilities, fastest-growing first: the unstable eigenvalues (Re λ > growth_tol|λ|,
    Im λ/2π in ``band_hz``) of neighbouring grid points (one step along one axis) linked where each is
    the other's nearest in λ and their frequencies differ by at most ``rtol``; each connected set of
    linked eigenvalues is one instability.  Deterministic: the same on every rank."""
    grid, lam = sweep.grid, sweep.eigenvalues
    shape, m = grid.shape, lam.shape[-1]
    L = lam.reshape(-1, m)
    f = L.imag / TWO_PI
    bad = unstable(L, growth_tol) & (f >= band_hz[0]) & (f <= band_hz[1])
    idx = np.arange(L.shape[0]).reshape(shape)
    links: list[tuple[int, int]] = []        # pairs of linked eigenvalues, as point·m + index
    for axis in range(len(shape)):
        a_idx = np.take(idx, np.arange(shape[axis] - 1), axis=axis).ravel()
        b_idx = np.take(idx, np.arange(1, shape[axis]), axis=axis).ravel()
        for p, q in zip(a_idx, b_idx):
            ea, eb = np.flatnonzero(bad[p]), np.flatnonzero(bad[q])
            if not ea.size or not eb.size:
                continue
            d = np.abs(L[p, ea][:, None] - L[q, eb][None, :])
            near_b, near_a = d.argmin(axis=1), d.argmin(axis=0)
            links += [(p * m + ea[i], q * m + eb[j]) for i, j in enumerate(near_b)
                      if near_a[j] == i and abs(f[p, ea[i]] - f[q, eb[j]]) <= rtol * abs(f[p, ea[i]])]
    nodes = np.flatnonzero(bad.ravel())                 # sorted: the links' ends are found by bisection
    e = np.searchsorted(nodes, np.array(links, int).reshape(-1, 2))
    graph = scipy.sparse.coo_matrix((np.ones(len(e)), (e[:, 0], e[:, 1])), (nodes.size, nodes.size))
    _, label = scipy.sparse.csgraph.connected_components(graph, directed=False)
    groups: dict[int, list[int]] = {}
    for n, g in zip(nodes, label):
        groups.setdefault(int(g), []).append(int(n))
    pts = grid.points()
    out = []
    for members in groups.values():
        pts_idx, eig = np.divmod(np.array(members), m)
        vals = L[pts_idx, eig]
        k = int(np.argmax(vals.real))
        growth = np.full(L.shape[0], np.nan)
        np.fmax.at(growth, pts_idx, vals.real)      # two of its eigenvalues at one point: the faster
        fr = vals.imag / TWO_PI
        ranges = {name: (float(v[pts_idx].min()), float(v[pts_idx].max())) for name, v in pts.items()}
        out.append(Instability(growth.reshape(shape), (float(fr.min()), float(fr.max())), float(vals[k].real),
                               {name: float(v[pts_idx[k]]) for name, v in pts.items()}, complex(vals[k]), ranges))
    out.sort(key=lambda x: (-x.max_growth_rate, x.freq_hz[0]))
    return out


def instability_couplings(model, found: list[Instability]) -> None:
    """Each instability's ``coupling`` where it grows fastest: the
    participation of the basis's real modes (the nominal frictionless modes, as the μ sweep's,
    :func:`~fem_squeal.reduced.mode_coupling.basis_modes`) in its eigenvector there, by inverse
    iteration at its eigenvalue (:func:`~fem_squeal.reduced.mode_coupling.coupling_of`: one m × m LU
    each).  Nothing where the model carries no real modes (``model.info['modes']``)."""
    n_modes = int(model.info.get("modes", 0))
    if not n_modes:
        return
    real = basis_modes(model.K0, n_modes)
    for x in found:
        K, C = model.matrices({k: np.array([v]) for k, v in x.at.items()}, 1)
        x.coupling = coupling_of(K[0], None if C is None else C[0], x.eigenvalue, real)
