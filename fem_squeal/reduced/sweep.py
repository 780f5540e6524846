"""Parameter grids on the reduced model: full-factorial designs, evaluated over MPI ranks.

A :class:`Grid` is the Cartesian product of named parameter axes (``"mu"`` is sign(v)μ,
``"E.<part>"`` a part's Young's modulus in Pa).  :func:`evaluate` solves the reduced quadratic
eigenproblem at every point, in chunks (one batched LAPACK call per chunk), the points being
dealt to the ranks of ``comm`` round-robin and gathered on every rank: each point is computed by
exactly the same arithmetic whatever the rank count.
"""
from __future__ import annotations

import time
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from fem_squeal.reduced.eigensolve import quadratic_eigs
from fem_squeal.reduced.model import ReducedModel
from fem_squeal.util.errors import ModelError
from fem_squeal.util.progress import ProgressBar


@dataclass
class Grid:
    """Full-factorial design: ``axes`` name → values; points in C order (last axis fastest)."""

    axes: dict[str, np.ndarray]

    def __post_init__(self):
        if not self.axes:
            raise ModelError("grid: needs at least one parameter axis")
        self.axes = {k: np.atleast_1d(np.asarray(v, float)) for k, v in self.axes.items()}
        for k, v in self.axes.items():
            if v.ndim != 1 or v.size == 0 or not np.all(np.isfinite(v)):
                raise ModelError(f"grid.{k}: must be a non-empty list of finite numbers")

    @property
    def shape(self) -> tuple[int, ...]:
        return tuple(v.size for v in self.axes.values())

    @property
    def size(self) -> int:
        return int(np.prod(self.shape))

    def points(self) -> dict[str, np.ndarray]:
        """Every point as flat arrays, one per axis."""
        mesh = np.meshgrid(*self.axes.values(), indexing="ij")
        return {k: g.ravel() for k, g in zip(self.axes, mesh)}


def signed_mu_axis(mu_max: float, n: int) -> np.ndarray:
    """n values of sign(v)μ in [−μ_max, μ_max] (backward < 0 < forward), as in seed 001 Fig. 8."""
    if not mu_max > 0:
        raise ModelError(f"mu_max: must be > 0 (got {mu_max})")
    if n < 2:
        raise ModelError(f"n_mu: must be >= 2 (got {n})")
    return np.linspace(-mu_max, mu_max, n)


@dataclass
class SweepResult:
    """Eigenvalues at every grid point: ``eigenvalues`` has shape grid.shape + (m,)."""

    grid: Grid
    eigenvalues: np.ndarray
    seconds: float
    ranks: int

    @property
    def seconds_per_point(self) -> float:
        return self.seconds * self.ranks / self.grid.size


def solve_points(model: ReducedModel, points: Mapping[str, np.ndarray], vectors: bool = False,
                 chunk: int = 32, bar=None):
    """Eigenvalues (n, m) [and vectors (n, m, m)] at the points given as flat arrays
    (``bar``: a :class:`~fem_squeal.util.progress.ProgressBar` fed with the points done)."""
    n = len(next(iter(points.values()))) if points else 1
    lams, Ys = [], []
    for s in range(0, n, chunk):
        if bar is not None:
            bar.update(s)
        sub = {k: np.asarray(v)[s:s + chunk] for k, v in points.items()}
        K, C = model.matrices(sub, min(chunk, n - s))
        out = quadratic_eigs(K, C, vectors)
        if vectors:
            lams.append(out[0])
            Ys.append(out[1])
        else:
            lams.append(out)
    lam = np.concatenate(lams) if lams else np.zeros((0, model.size), complex)
    return (lam, np.concatenate(Ys)) if vectors else lam


def evaluate(model: ReducedModel, grid: Grid, comm=None, chunk: int = 32, progress: bool = False
             ) -> SweepResult:
    """Eigenvalues at every point of ``grid``; the points are shared among the ranks of ``comm``
    (an mpi4py communicator, or None for serial) and the result is on every rank.  ``progress``
    draws rank 0's share of the points."""
    t = time.perf_counter()
    pts = grid.points()
    size, rank = (1, 0) if comm is None else (comm.size, comm.rank)
    mine = np.arange(rank, grid.size, size)
    with ProgressBar(mine.size, "stability map", enabled=progress and rank == 0, unit=" points") as bar:
        lam = solve_points(model, {k: v[mine] for k, v in pts.items()}, chunk=chunk, bar=bar)
    if comm is not None and size > 1:
        parts = comm.allgather((mine, lam))
        full = np.empty((grid.size, model.size), complex)
        for idx, val in parts:
            full[idx] = val
        lam = full
    seconds = time.perf_counter() - t
    if comm is not None:
        seconds = comm.allreduce(seconds, op=_max_op())
    return SweepResult(grid, lam.reshape(grid.shape + (model.size,)), seconds, size)


def _max_op():
    from mpi4py import MPI  # heavy: MPI initialisation

    return MPI.MAX


def path_solver(model: ReducedModel, name: str, fixed: Mapping[str, float] | None = None,
                vectors: bool = True):
    """``p -> (λ, Y)`` along parameter ``name`` (the others at ``fixed`` or nominal), for tracking;
    ``vectors`` False: ``p -> λ`` (eigenvalues only, for refining critical values)."""
    fixed = {k: np.array([float(v)]) for k, v in (fixed or {}).items()}

    def solve(p: float):
        lam, Y = solve_points(model, {name: np.array([p]), **fixed}, vectors=True)
        return lam[0], Y[0]

    def values(p: float):
        return solve_points(model, {name: np.array([p]), **fixed})[0]
    return solve if vectors else values
