"""Pressure continuation of the nonlinear preload: the static contact state at several brake pressures.

The load of a scene is linear in its ``loads.pressure`` entries, so a pressure scale s gives the load s·f
(:func:`fem_squeal.fe.preload.solve_preload` with ``scale``).  The scales are solved in increasing order
(from a given state at s₀: those above s₀ increasing, then those below decreasing), each from the
previous converged state u(s_{i−1}) moved along its tangent (the equilibrium's rate du/ds = J⁻¹ f, one
solve with the kept Jacobian of that state's last Newton step),

    u⁰(s_i) = u(s_{i−1}) + (s_i − s_{i−1}) J⁻¹ f

(exact for the linear penalty while the contact set does not change, whatever the initial gaps: then a
state is accepted without a Newton step; where points open or close, it predicts their gaps to first
order, so the first step starts near the new set: on the tapered brake corner at 163k DOFs the scaled
state u⁰ = (s_i/s_{i−1}) u(s_{i−1}), exact only where the closed points touched initially, began 500
points off it and overshot), and
with the previous pressure's Jacobian factorisation kept (:class:`fem_squeal.fe.preload.NewtonFactor`):
the Newton steps of the next pressure differ from it only at the points that opened or closed, so they
are low-rank updates of it (:mod:`fem_squeal.fe.kept_factorisation`, Woodbury), refactorised only when
the measured cost says that is cheaper.  Every pressure is still solved to the preload's own tolerance
(same closed set twice and ‖R‖ ≤ tol‖s f‖): the states are those of separate runs, to the tolerance.

The converged states are cached by content: the key hashes the model's own key (what the operators were
built from), the scale, the solver settings that change the answer and the rank layout; a cached state is
accepted only after its residual is checked at the start of the solve (no Newton step when it holds).
"""
from __future__ import annotations

import hashlib
import json
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from mpi4py import MPI
from petsc4py import PETSc

from fem_squeal.fe.assembly import Operators
from fem_squeal.fe.preload import NewtonFactor, PreloadResult, solve_preload
from fem_squeal.util.atomic import write_npz_atomic
from fem_squeal.util.errors import ModelError


@dataclass
class PressureState:
    """The preload at one pressure scale: the solve's result, its wall time [s] (slowest rank) and
    whether it started from a cached state."""

    scale: float
    result: PreloadResult
    seconds: float
    cached: bool


def check_scales(scales: Sequence[float]) -> np.ndarray:
    """The pressure scales as an array; a ModelError naming the first one that is not a finite number > 0."""
    s = np.asarray(scales, float).reshape(-1)
    if s.size == 0:
        raise ModelError("pressure: at least one pressure scale is needed")
    bad = ~np.isfinite(s) | (s <= 0)
    if np.any(bad):
        raise ModelError(f"pressure: must be > 0 (a scale of loads.pressure; got {s[bad][0]:g})")
    return s


class StateCache:
    """Converged preload states on disk, one file per rank and state: ``<folder>/preload-<key>.r<rank>.npz``
    with the rank's part of u and its SHA-256 (a file whose digest does not match is a miss)."""

    def __init__(self, folder: Path | str, model_key: str, settings: dict, comm):
        self.folder, self.comm = Path(folder), comm
        self.base = {"model": model_key, "settings": settings, "ranks": comm.size}
        self.folder.mkdir(parents=True, exist_ok=True)

    def key(self, scale: float) -> str:
        """Content key of the state at ``scale`` (the model, the settings, the ranks, the scale)."""
        body = json.dumps({**self.base, "scale": float(scale).hex()}, sort_keys=True, separators=(",", ":"))
        return hashlib.sha256(body.encode()).hexdigest()[:20]

    def _path(self, scale: float) -> Path:
        return self.folder / f"preload-{self.key(scale)}.r{self.comm.rank}.npz"

    def load(self, scale: float, like: PETSc.Vec) -> PETSc.Vec | None:
        """The cached state at ``scale`` (a new Vec laid out as ``like``) or None (on every rank alike)."""
        p = self._path(scale)
        a = None
        try:
            with np.load(p) as z:
                u = np.asarray(z["u"], float)
                if hashlib.sha256(u.tobytes()).hexdigest() == str(z["sha256"]) and u.size == like.getLocalSize():
                    a = u
        except (OSError, KeyError, ValueError):
            a = None
        if not self.comm.allreduce(int(a is not None), op=MPI.MIN):
            return None
        v = like.duplicate()
        v.array[:] = a
        return v

    def store(self, scale: float, u: PETSc.Vec) -> None:
        a = np.array(u.array_r, float)
        write_npz_atomic(self._path(scale), {"u": a, "sha256": np.array(hashlib.sha256(a.tobytes()).hexdigest())})


def continuation_order(scales: np.ndarray, start: float | None) -> list[int]:
    """The order in which the scales are solved: increasing from the smallest without a ``start``; with a
    state at scale ``start``, the scales above it increasing and those below it decreasing, each branch
    continued from the start (indices into ``scales``)."""
    if start is None:
        return [int(i) for i in np.argsort(scales, kind="stable")]
    up = [int(i) for i in np.argsort(scales, kind="stable") if scales[i] >= start]
    down = [int(i) for i in np.argsort(-scales, kind="stable") if scales[i] < start]
    return up + down


def continue_preload(ops: Operators, scales: Sequence[float], *, start: tuple[float, PETSc.Vec] | None = None,
                     factor: NewtonFactor | None = None, cache: StateCache | None = None,
                     progress: Callable[[str], None] | None = None, **settings) -> list[PressureState]:
    """The preload at every pressure scale of ``scales`` (returned in their order) by continuation (module
    doc), from ``start`` = (scale, converged state) when given (e.g. the scene's own preload, solved with
    ``factor`` so that its factorisation is kept), else from the smallest scale solved cold.  ``settings``:
    those of :func:`~fem_squeal.fe.preload.solve_preload` (friction, k3, tol, max_iterations, options,
    jacobian, max_factorisations).  ``factor`` (None: a new one unless jacobian = "refactorise") is destroyed at
    the end; the caller destroys the states' ``u``."""
    s = check_scales(scales)
    comm = ops.K.getComm().tompi4py()
    if factor is None and settings.get("jacobian", "update") != "refactorise":
        factor = NewtonFactor()
    out: dict[int, PressureState] = {}
    rates: list[PETSc.Vec] = []               # du/ds of the states continued from (destroyed at the end)

    def rate() -> PETSc.Vec | None:
        """du/ds with the Jacobian the factor holds (None without a factor)."""
        r = factor.load_rate(ops) if factor is not None else None
        if r is not None:
            rates.append(r)
        return r

    # the state the next scale continues from: (scale, u, du/ds).  The start's rate is taken now, while the
    # factor holds its Jacobian (the branch below the start comes back to it); a solved state's when the
    # next scale continues from it, the factor holding its Jacobian still (none after the last scale)
    first = None if start is None else (*start, rate())
    prev = first
    try:
        for i in continuation_order(s, None if start is None else start[0]):
            scale = float(s[i])
            if start is not None and scale < start[0] and (prev is None or prev[0] >= start[0]):
                prev = first                  # the branch below the start begins at the start again
            t = time.perf_counter()
            u0 = None
            if cache is not None:
                like = ops.K.createVecRight()
                u0 = cache.load(scale, like)
                like.destroy()
            cached = u0 is not None
            if u0 is None and prev is not None:
                u0 = prev[1].copy()
                du = prev[2] if prev is first else rate()
                if du is not None:            # the tangent predictor u + (s − s') du/ds
                    u0.axpy(scale - prev[0], du)
                else:                         # no Jacobian kept: the scaled state
                    u0.scale(scale / prev[0])
            res = solve_preload(ops, scale=scale, start=u0, factor=factor,
                                progress=(None if progress is None else
                                          lambda line, sc=scale: progress(f"[p × {sc:g}] {line}")), **settings)
            if u0 is not None:
                u0.destroy()
            if cache is not None and not cached:
                cache.store(scale, res.u)
            seconds = comm.allreduce(time.perf_counter() - t, op=MPI.MAX)
            out[i] = PressureState(scale, res, seconds, cached)
            prev = (scale, res.u)
    finally:
        for r in rates:
            r.destroy()
        if factor is not None:
            factor.destroy()
    return [out[i] for i in range(s.size)]
