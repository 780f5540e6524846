"""Real modes K φ = ω² M φ up to a cut by spectrum slicing: [0, ω_cut²] cut into slices, each solved
by block Lanczos on its own factorisation K − c M (MUMPS LDLᵀ, on one rank or N), every slice's count
proved by the factorisation's inertia (Sylvester's law of inertia).

The slices (bounds 0 = s₀ < s₁ < … < s_m = ω_cut²): slice j < m is solved at its centre
c_j = (s_{j−1} + s_j)/2 for every pair with |λ − c_j| ≤ (s_j − s_{j−1})/2 (they lead in
|θ| = 1/|λ − c_j|: :func:`~fem_squeal.fe.eigen.block_krylov._block_lanczos`'s ``radius``), the last at
the cut itself, c_m = ω_cut², for |λ − c_m| ≤ ω_cut² − s_{m−1}.  The bounds are planned equal in the
number of modes (N ∝ λ^0.75 between plates and beams), the last slice half as wide in count (its
Lanczos also converges the modes as far above the cut).  Each bound s_j actually used lies in the
middle of a gap of slice j's converged eigenvalues (at most the planned bound), so that the same
mode cannot fall on both sides of it (or neither) in the slices on either side.

Proof of completeness: LDLᵀ of K − c_j M has as many negative pivots ν_j as there are eigenvalues
λ < c_j; the pairs kept (slice j those in (s_{j−1}, s_j]) must number exactly ν_j below c_j for every
j, and c_m is the cut: no mode below the cut is missed, and none counted twice.  Where a count
differs (a Lanczos run that stopped short, a mode within round-off of a shift) the solve returns None
and the caller falls back to a single shift.
"""
from __future__ import annotations

import time
from dataclasses import asdict, dataclass

import numpy as np
from mpi4py import MPI
from petsc4py import PETSc

from fem_squeal.fe import kernels
from fem_squeal.fe.dense import block_solve, product_of
from fem_squeal.fe.eigen.block_krylov import _block_lanczos, block_size
from fem_squeal.fe.eigen.options import drop_zeros
from fem_squeal.fe.eigen.real_modes import _checked_modes
from fem_squeal.fe.eigen.results import TWO_PI, RealModes
from fem_squeal.fe.factorisation import CHOLESKY, factor_solver
from fem_squeal.util.progress import ProgressBar

#: MUMPS LDLᵀ of K − cM with its inertia: ICNTL(13) = 1 (no ScaLAPACK root, whose pivots the count
#: would miss) and ICNTL(24) = 1 (null pivot detection), as :func:`fem_squeal.fe.projection.count_below`.
SLICE_FACTOR = CHOLESKY.with_(icntl={13: 1, 24: 1})
#: the first slice's window reaches this share of its half-width below 0 (rigid-body modes: λ ≈ 0 to round-off)
BELOW_ZERO = 0.05


@dataclass
class Slice:
    """One slice: its shift c and the interval (lo, hi] of the modes kept from it [Hz], the negative
    inertia of K − cM (the modes below c), the modes kept, the block columns and the seconds."""

    shift_hz: float
    lo_hz: float
    hi_hz: float
    inertia: int
    modes: int
    columns: int
    factor_s: float
    solve_s: float

    def as_dict(self) -> dict:
        return asdict(self)


def _hz(lam: float) -> float:
    return float(np.sign(lam) * np.sqrt(abs(lam)) / TWO_PI)


def planned_bounds(lam_cut: float, slices: int) -> np.ndarray:
    """The planned upper bounds s₁ … s_m of ``slices`` slices of [0, λ_cut]: equal counts for
    N ∝ λ^0.75, the last slice half a share (module docstring): s_j = λ_cut (q_j)^(4/3)."""
    q = np.concatenate([np.arange(1.0, slices), [slices - 0.5]]) / (slices - 0.5)
    return lam_cut * q ** (4.0 / 3.0)


def _upper_bound(lam: np.ndarray, planned: float) -> float:
    """The bound actually used near ``planned``: the middle of the gap of the converged eigenvalues
    ``lam`` around it, at most ``planned`` (the window ends there)."""
    below, above = lam[lam <= planned], lam[lam > planned]
    if not below.size or not above.size:
        return planned
    return float(min(planned, 0.5 * (below.max() + above.min())))


def sliced_modes(K: PETSc.Mat, M: PETSc.Mat, f_cut_hz: float, slices: int, *, tol: float, max_residual: float,
                 options=None, prefix: str = "slice_", progress: bool = False
                 ) -> tuple[RealModes | None, list[Slice]]:
    """Every real mode with f ≤ ``f_cut_hz`` by ``slices`` slices (module docstring), M-normalised, in
    ascending ω², and one :class:`Slice` per slice solved.  ``tol``: the Lanczos convergence (SLEPc's
    criterion, as :func:`fem_squeal.fe.eigen.solve_real_modes`); ``max_residual``: the pairs'
    ‖Kφ − λMφ‖/(‖K‖∞‖φ‖) bound.  The factorisation: :data:`SLICE_FACTOR` under ``prefix``, the user's
    options (``options``, the command line) over it.  ``progress``: one line per slice on rank 0's
    stderr with the modes so far and the remaining time (as much per slice as so far: the last
    slice, half the modes of the others, converges as many above the cut; measured at 78k DOFs, 3
    slices: 22 s estimated after the first, 27 s taken).  None (with the slices done) where a
    Lanczos run stops short, an inertia count differs or a residual misses: the caller solves
    otherwise."""
    if slices < 1:
        raise ValueError(f"slices: must be >= 1 (got {slices})")
    lam_cut = (TWO_PI * f_cut_hz) ** 2
    comm = K.getComm().tompi4py()
    rows, n = K.getOwnershipRange(), K.getSize()[0]
    Ms = drop_zeros(M)
    mass = product_of(Ms)
    planned = planned_bounds(lam_cut, slices)
    lower, kept_lam, kept_X, done, counts = -np.inf, [], [], [], []
    n_kept, t_factor, t_solve, b = 0, 0.0, 0.0, 0
    bar = ProgressBar(slices, f"real modes to {f_cut_hz:.0f} Hz", unit=" slices",
                      enabled=progress and comm.rank == 0)
    try:
        for j, upper in enumerate(planned):
            last = j == slices - 1
            lo = max(lower, 0.0)
            c = lam_cut if last else 0.5 * (lo + upper)
            r = (lam_cut - lo) if last else 0.5 * (upper - lo)
            if j == 0:
                r *= 1.0 + BELOW_ZERO
            t0 = MPI.Wtime()
            A = K.copy()
            A.axpy(-c, M, structure=PETSc.Mat.Structure.SUBSET_NONZERO_PATTERN)
            A.setOption(PETSc.Mat.Option.SYMMETRIC, True)
            try:
                ksp = factor_solver(A, SLICE_FACTOR, prefix, options)
                try:
                    F = ksp.getPC().getFactorMatrix()
                    nu = int(F.getInertia()[0])
                    t1 = MPI.Wtime()
                    # the window holds about twice the modes between its lower end and c (the count)
                    guess = max(2 * (nu - n_kept) + 8, 16)
                    b = block_size(guess)
                    got = _block_lanczos(block_solve(F), mass, comm, rows, n, guess, c, tol, b, radius=r)
                finally:
                    ksp.destroy()
            finally:
                A.destroy()
            t2 = MPI.Wtime()
            t_factor += t1 - t0
            t_solve += t2 - t1
            if got is None:
                return None, done
            lam, X = got
            order = np.argsort(lam)
            lam, X = lam[order], X[:, order]
            hi = lam_cut if last else _upper_bound(lam, upper)
            keep = (lam > lower) & (lam <= hi)
            # Sylvester: ν = the modes below c, those kept before and this slice's below c
            counts.append((c, nu))
            proved = n_kept + int(np.sum((lam > lower) & (lam < c))) == nu
            kept_lam.append(lam[keep])
            kept_X.append(X[:, keep])
            n_kept += int(keep.sum())
            done.append(Slice(_hz(c), _hz(max(lower, 0.0)), _hz(hi), nu, int(keep.sum()), b, t1 - t0, t2 - t1))
            bar.update(j + 1, extra=f"slice {j + 1}/{slices} to {_hz(hi):.0f} Hz: {n_kept} modes, inertia {nu} "
                             f"below {_hz(c):.0f} Hz {'proves the count' if proved else 'DIFFERS'}")
            if not proved:
                return None, done
            lower = hi
        lam = np.concatenate(kept_lam)
        X = np.asfortranarray(np.concatenate(kept_X, axis=1))
        del kept_X
        if any(int(np.sum(lam < c)) != nu for c, nu in counts):
            return None, done
        t0 = time.perf_counter()
        rm = _checked_modes(K, Ms, lam, X, max_residual, "mumps", t_factor, t0, t_solve, b)
        if rm is not None:
            rm.method = f"block Lanczos, spectrum slicing ({slices} slices)"
            kernels.note("real_modes", "mumps, block Lanczos, spectrum slicing")
        return rm, done
    finally:
        if bar.enabled and bar.tty:
            bar.stream.write("\n")
        if Ms is not M:
            Ms.destroy()
