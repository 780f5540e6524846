"""The snapshot basis of a model given as matrices built on the ranks of a communicator (each rank on its
rows of the named matrices, :func:`fem_squeal.fe.matrix_operators.row_range`), the basis of the
non-symmetric problems that have no symmetric part to take modes of: the same basis as the serial
:func:`fem_squeal.reduced.matrix_reduction.snapshot_basis`, by PETSc/SLEPc:

- at each snapshot point p the ``k`` eigenpairs of (λ²M(p) + λC(p) + K(p))x = 0 nearest ±i·2π·target_hz
  as the serial basis takes them (the ``k`` of largest ν = |λ/(λ² + ω²)|:
  :func:`fem_squeal.reduced.matrix_reduction.nearness`), by SLEPc's TOAR (shift-and-invert at 0, MUMPS)
  for the pairs of smallest |λ|, as many as make the choice certain: |ν| decreases with |λ| beyond ω,
  so every eigenvalue with |ν| ≥ ν_k (the k-th's) has |λ| ≤ R = (1 + √(1 + 4ν_k²ω²))/(2ν_k), and the
  solve is repeated with twice the pairs until the found ones reach R (real arithmetic: no complex
  shift);
- the real and imaginary parts of their eigenvectors in the phase where Σ x_i² is real
  (:func:`fem_squeal.reduced.matrix_reduction.real_columns`: the same columns whatever phase the
  solver returned), orthonormalised column by column with the inner products summed over the ranks
  (:func:`fem_squeal.reduced.matrix_reduction.orthonormal_columns`), and every affine term projected.

Every rank ends with the same :class:`~fem_squeal.reduced.matrix_reduction.ReducedMatrixModel`."""
from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np
import scipy.sparse as sp
from mpi4py import MPI
from petsc4py import PETSc
from slepc4py import SLEPc

from fem_squeal.fe.eigen.options import PEP_OPTIONS, _zero_like, eps_defaults
from fem_squeal.fe.factorisation import LU, scoped_options
from fem_squeal.fe.matrix_basis import _total, _whole
from fem_squeal.fe.matrix_operators import operators
from fem_squeal.reduced.matrix_model import MatrixModel
from fem_squeal.reduced.matrix_reduction import (
    ReducedMatrixModel,
    nearest,
    nearness,
    orthonormal_columns,
    project,
    real_columns,
)
from fem_squeal.util.errors import ModelError

#: the eigenpairs' tolerance (SciPy's of the serial basis)
SNAPSHOT_TOL = 1e-12


def _smallest_pairs(ops: Mapping[str, PETSc.Mat], nev: int, options: dict | None, prefix: str
                    ) -> tuple[np.ndarray, np.ndarray]:
    """(λ, this rank's rows of x) of at least ``nev`` eigenpairs of smallest |λ| (TOAR, shift-and-invert
    at 0), both of each conjugate pair."""
    K, M = ops["K"], ops["M"]
    C = ops.get("C")
    Z = _zero_like(M) if C is None else None
    lams, vecs = [], []
    with scoped_options(eps_defaults(prefix, LU, PEP_OPTIONS), options):
        pep = SLEPc.PEP().create(K.getComm())
        try:
            pep.setOptionsPrefix(prefix)
            pep.setOperators([K, C if C is not None else Z, M])
            pep.setType(SLEPc.PEP.Type.TOAR)
            pep.setDimensions(nev, min(max(2 * nev, nev + 16), 2 * K.getSize()[0]))
            pep.setTolerances(SNAPSHOT_TOL, 1000)
            pep.getST().setType(SLEPc.ST.Type.SINVERT)
            pep.setTarget(0.0)
            pep.setWhichEigenpairs(SLEPc.PEP.Which.TARGET_MAGNITUDE)
            pep.setConvergenceTest(SLEPc.PEP.Conv.REL)
            pep.setFromOptions()
            pep.solve()
            xr, xi = K.createVecRight(), K.createVecRight()
            for i in range(pep.getConverged()):
                lams.append(complex(pep.getEigenpair(i, xr, xi)))
                vecs.append(xr.getArray() + 1j * (xi.getArray() if lams[-1].imag != 0 else 0.0))
            xr.destroy()
            xi.destroy()
        finally:
            pep.destroy()
            if Z is not None:
                Z.destroy()
    if len(lams) < nev:
        raise ModelError(f"snapshots: {len(lams)} eigenpairs of the non-symmetric problem converged of {nev}")
    n_local = K.getLocalSize()[0]
    return np.array(lams), (np.column_stack(vecs) if vecs else np.zeros((n_local, 0), complex))


def qep_pairs_rows(ops: Mapping[str, PETSc.Mat], k: int, target_hz: float, options: dict | None = None,
                   prefix: str = "matrix_snapshot_") -> tuple[np.ndarray, np.ndarray]:
    """(λ, this rank's rows of x): the ``k`` eigenpairs of λ²M + λC + K nearest ±i·2π·target_hz, nearest
    first (:func:`fem_squeal.reduced.matrix_reduction.nearest`; module docstring)."""
    n = ops["K"].getSize()[0]
    w = 2 * np.pi * target_hz
    nev = min(k, 2 * n)
    while True:
        lam, X = _smallest_pairs(ops, nev, options, prefix)
        idx = nearest(lam, k, target_hz)
        nu = nearness(lam[idx[-1:]], target_hz)[0]
        reach = np.sort(np.abs(lam))[nev - 1]
        if nu <= 0 or reach >= (1 + np.sqrt(1 + 4 * nu ** 2 * w ** 2)) / (2 * nu) or nev >= 2 * n:
            return lam[idx], X[:, idx]
        nev = min(2 * nev, 2 * n)


def snapshot_basis_rows(model: MatrixModel, rows: Mapping[str, sp.csr_matrix], comm: MPI.Comm,
                        points: Sequence[Mapping[str, float]], k: int, target_hz: float, bs: int = 1,
                        options: dict | None = None) -> np.ndarray:
    """This rank's rows of the snapshot basis (module docstring) of the matrices whose rows on this rank
    are ``rows``."""
    if not points:
        raise ModelError("snapshots: no parameter points to sample")
    total = _total(comm)
    cols = []
    for p in points:
        ops = operators(model, rows, comm, dict(p), bs=bs)
        try:
            _, X = qep_pairs_rows(ops, k, target_hz, options)
        finally:
            for A in ops.values():
                A.destroy()
        cols.append(real_columns(X, total))
    return orthonormal_columns(np.hstack(cols), None, total)


def reduce_snapshot_rows(model: MatrixModel, rows: Mapping[str, sp.csr_matrix], comm: MPI.Comm,
                         points: Sequence[Mapping[str, float]], k: int, target_hz: float, bs: int = 1,
                         options: dict | None = None) -> ReducedMatrixModel:
    """The reduced model of the snapshot basis (:func:`snapshot_basis_rows`): the same on every rank."""
    mine = snapshot_basis_rows(model, rows, comm, points, k, target_hz, bs, options)
    info = {"basis": "snapshots", "points": [dict(p) for p in points], "per_point": k, "size": int(mine.shape[1]),
            "built_on": f"{comm.size} rank(s) (PETSc/SLEPc)"}
    return ReducedMatrixModel(model, project(model, rows, _whole(comm, mine), mine, _total(comm)), info)
