"""Left eigenvectors of the complex modes (the transposed problem), for the sensitivities."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from petsc4py import PETSc

from fem_squeal.fe.eigen.complex_modes import solve_complex_modes
from fem_squeal.util.errors import EigenSolveError


@dataclass
class LeftVectors:
    """Left eigenvectors y (yᴴQ(λ) = 0) of given eigenvalues, as z = ȳ = zr + i zi (Q(λ)ᵀz = 0)."""

    eigenvalues: np.ndarray       # the eigenvalues of the transposed problem matched to the given ones
    vectors_re: list[PETSc.Vec]
    vectors_im: list[PETSc.Vec]
    mismatch: np.ndarray          # |λ_transposed − λ| / |λ| of each match


def solve_left_vectors(K: PETSc.Mat, M: PETSc.Mat, C: PETSc.Mat | None, eigenvalues: np.ndarray,
                       target_hz: float, *, band_hz: tuple[float, float] | None = None, extra: int = 2,
                       options: dict | None = None, prefix: str = "left_", progress: bool = False) -> LeftVectors:
    """Left eigenvectors of (λ²M + λC + K) at ``eigenvalues`` (Im λ > 0, e.g. a CEA's own).

    For real matrices yᴴQ(λ) = 0 ⇔ Q(λ)ᵀ ȳ = 0: z = ȳ is a right eigenvector of the transposed
    problem λ²Mᵀ + λCᵀ + Kᵀ at the same λ, which :func:`solve_complex_modes` finds with the same
    shift (len(eigenvalues) + ``extra`` pairs near ``target_hz``; the linear EPS when C is None,
    PEP otherwise).  Each given λ is matched to the nearest eigenvalue of the transposed problem;
    the match is reported (``mismatch``: round-off of the two solves, ~1e-10, for a simple
    eigenvalue).  With x the CEA's right vector, dλ/dp = −zᵀ(λ²∂M + λ∂C + ∂K)x / zᵀ(2λM + C)x
    (no conjugation: zᵀ = yᴴ)."""
    lam = np.asarray(eigenvalues, complex)
    # petsc4py's A.transpose() with no argument transposes A in place: ask for a new matrix
    mats = [None if A is None else A.transpose(PETSc.Mat()) for A in (K, M, C)]
    nev = len(lam) + extra
    try:
        for attempt in range(4):   # more pairs until each λ has its own match (a band with modes between)
            cm = solve_complex_modes(mats[0], mats[1], mats[2], nev, target_hz, band_hz=band_hz,
                                     options=options, prefix=prefix, progress=progress)
            pick = [int(np.argmin(np.abs(cm.eigenvalues - x))) for x in lam] if cm.eigenvalues.size else []
            mism = np.array([abs(cm.eigenvalues[j] - x) / abs(x) for j, x in zip(pick, lam)])
            if (len(pick) == len(lam) and len(set(pick)) == len(pick) and np.all(mism < 1e-6)) or attempt == 3:
                break
            for v in (*cm.vectors_re, *cm.vectors_im):
                v.destroy()
            nev *= 2
    finally:
        for A in mats:
            if A is not None:
                A.destroy()
    if len(pick) < len(lam) or len(set(pick)) < len(pick):
        raise EigenSolveError(f"left eigenvectors (prefix {prefix!r}): no distinct eigenvalue of the transposed "
                              f"problem for each of {len(lam)} eigenvalues with {nev} pairs near "
                              f"{target_hz:.0f} Hz (a multiple eigenvalue?)")
    out = LeftVectors(cm.eigenvalues[pick], [cm.vectors_re[j] for j in pick], [cm.vectors_im[j] for j in pick],
                      mism)
    for j in set(range(len(cm.eigenvalues))) - set(pick):
        cm.vectors_re[j].destroy()
        cm.vectors_im[j].destroy()
    return out
