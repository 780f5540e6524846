"""Mode coupling of the full CEA: each complex mode on the real modes of the symmetric system.

With Φ the M-orthonormal real modes of (K_s, M) — the CEA stage's: K_s the frictionless symmetric K
(elasticity, springs, closed contacts), whose modes the reduced basis and the projected CEA hold too, so
that a real mode has one number in every table; or K_s = ½(K + Kᵀ) of a given operating stiffness —
every real mode up to ``f_max_hz``, a complex mode x (x^H M x = 1) has the coefficients

    c = Φᵀ M x,    x = Φ c + r,    ‖x‖²_M = Σ |c_i|² + ‖r‖²_M        (M-orthogonality of Φ),

so |c_i|² / ‖x‖²_M is the share of real mode i in the mode's M-norm (kinetic energy) and
‖r‖²_M / ‖x‖²_M = 1 − Σ |c_i|² / ‖x‖²_M the share outside the real modes kept (the basis-norm
residual: 0 to round-off when they span x).  The real modes come from
:func:`fem_squeal.fe.projection.modes_below` (the reduced stage's solver of its basis modes).
The summaries (participation in percent, the coupling pair) are pure NumPy:
:mod:`fem_squeal.reduced.mode_coupling`.
"""
from __future__ import annotations

import numpy as np
from mpi4py import MPI
from petsc4py import PETSc

from fem_squeal.fe.dense import apply, gram
from fem_squeal.fe.eigen import TWO_PI
from fem_squeal.fe.projection.shifted import modes_below
from fem_squeal.reduced.mode_coupling import FRICTIONLESS_MODES, RealModeCoefficients  # the latter: as before

#: what the real modes of :func:`real_mode_coefficients` are without ``frictionless`` (cea_coupling.basis)
SYMMETRIC_PART = ("real modes of ½(K + Kᵀ) (the CEA's operating stiffness, symmetric part) and M, numbered "
                  "from 0 by frequency")


def symmetric_part(K: PETSc.Mat) -> PETSc.Mat:
    """K_s = ½(K + Kᵀ) as a new matrix (K's pattern is structurally symmetric: FE assembly)."""
    Ks = K.copy()
    Kt = K.transpose(PETSc.Mat())
    Ks.axpy(1.0, Kt, structure=PETSc.Mat.Structure.DIFFERENT_NONZERO_PATTERN)
    Ks.scale(0.5)
    Kt.destroy()
    return Ks


def coefficients_on(M: PETSc.Mat, Phi: np.ndarray, modes: list[tuple[PETSc.Vec, PETSc.Vec | None]]
                    ) -> tuple[np.ndarray, np.ndarray]:
    """c = Φᵀ M x for each x = xr + i xi of ``modes`` (Φ: rank-local rows) and x^H M x, summed over the
    ranks: (n_real × n_modes complex, n_modes)."""
    comm = M.getComm().tompi4py()
    n_local = M.getLocalSize()[0]
    X = np.zeros((n_local, 2 * len(modes)), order="F")
    for j, (xr, xi) in enumerate(modes):
        X[:, 2 * j] = xr.array_r
        if xi is not None:
            X[:, 2 * j + 1] = xi.array_r
    MX = apply(M, X) if X.shape[1] else X
    C = gram(comm, MX, Phi).T if Phi.shape[1] else np.zeros((0, X.shape[1]))   # ΦᵀMX
    norms = comm.allreduce(np.einsum("ij,ij->j", X, MX), op=MPI.SUM)
    return C[:, 0::2] + 1j * C[:, 1::2], norms[0::2] + norms[1::2]


def real_mode_coefficients(K: PETSc.Mat, M: PETSc.Mat, modes: list[tuple[PETSc.Vec, PETSc.Vec | None]],
                           f_max_hz: float, *, frictionless: bool = False, options=None, prefix: str = "coupling_",
                           n_start: int = 20) -> RealModeCoefficients:
    """The real modes of (½(K + Kᵀ), M) up to ``f_max_hz`` and the coefficients of ``modes`` on them
    (module docstring); ``frictionless``: K is the frictionless symmetric K itself (not symmetrised: its
    modes are :data:`~fem_squeal.reduced.mode_coupling.FRICTIONLESS_MODES`).  ``options``/``prefix``: the
    PETSc options of the real-mode solve."""
    Ks = K if frictionless else symmetric_part(K)
    try:
        w2, Phi = modes_below(Ks, M, f_max_hz, n_start=n_start, options=options, prefix=prefix)
    finally:
        if Ks is not K:
            Ks.destroy()
    C, norms = coefficients_on(M, Phi, modes)
    return RealModeCoefficients(np.sqrt(np.abs(w2)) * np.sign(w2) / TWO_PI, C, norms, float(f_max_hz), Phi,
                                basis=FRICTIONLESS_MODES if frictionless else SYMMETRIC_PART)
