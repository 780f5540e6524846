"""The modal basis of a model given as matrices built on the ranks of a communicator (the rows of each
named matrix dealt to the ranks by :func:`fem_squeal.fe.matrix_operators.row_range`), so that a model
too large for one process reduces under MPI: the same basis as the serial
:func:`fem_squeal.reduced.matrix_reduction.modal_basis` (the same subspace), by PETSc/SLEPc:

- the real modes of the symmetric parts at the nominal point, K_s φ = ω² M_s φ, as the modes of the
  shifted pencil (K_s − σM_s) φ = (ω² − σ) M_s φ (σ = ``shift`` < 0: a singular K_s is allowed; the
  eigenvectors are the same) by :func:`fem_squeal.fe.eigen.solve_real_modes` (CHOLMOD on one rank,
  MUMPS on several) to :data:`MODE_TOL`;
- the static corrections (K_s − σM_s)⁻¹ A_k Φ of every term A_k of K and C that is non-symmetric
  (‖A − Aᵀ‖₁ > 1e-14 ‖A‖₁, entrywise, as the serial path) or whose coefficient reads a parameter, by
  one factorisation of K_s − σM_s (:func:`fem_squeal.fe.assembly.direct_solver`) and block solves;
- the whole M_s-orthonormalised column by column
  (:func:`fem_squeal.reduced.matrix_reduction.orthonormal_columns`, the inner products summed over the
  ranks) and every affine term projected, Vᵀ A_k V = Σ_ranks V_rᵀ (A_k,r V)
  (:func:`fem_squeal.reduced.matrix_reduction.project`).

Every rank ends with the same :class:`~fem_squeal.reduced.matrix_reduction.ReducedMatrixModel` (the
sums over the ranks are reduced on rank 0 and broadcast).  The basis itself is gathered whole on every
rank for the products A_k,r V (n × m numbers: 130 MB for 163k DOFs and 100 columns)."""
from __future__ import annotations

from collections.abc import Mapping

import numpy as np
import scipy.sparse as sp
from mpi4py import MPI
from petsc4py import PETSc

from fem_squeal.fe.assembly import direct_solver
from fem_squeal.fe.dense import apply, block_solve
from fem_squeal.fe.eigen import solve_real_modes
from fem_squeal.fe.matrix_operators import operators, petsc_matrix, symmetric_part
from fem_squeal.reduced.matrix_model import MatrixModel
from fem_squeal.reduced.matrix_reduction import ReducedMatrixModel, orthonormal_columns, project
from fem_squeal.util.errors import ModelError

#: the tolerance of the real modes: ARPACK's of the serial basis (the default of the real-modes analysis,
#: 1e-7, leaves the two bases' reduced eigenvalues 4e-6 apart on the 50k-DOF brake)
MODE_TOL = 1e-12


def _total(comm: MPI.Comm):
    """X ↦ Σ_ranks X, the same numbers on every rank (reduced on rank 0, broadcast)."""
    return lambda X: comm.bcast(comm.reduce(X, op=MPI.SUM, root=0), root=0)


def _whole(comm: MPI.Comm, local: np.ndarray) -> np.ndarray:
    """The rows of every rank stacked in rank order (the rows of :func:`row_range`)."""
    return np.vstack(comm.allgather(local)) if comm.size > 1 else local


def _skew(A: sp.csr_matrix, comm: MPI.Comm, bs: int) -> bool:
    """‖A − Aᵀ‖₁ > 1e-14 ‖A‖₁ (sums of |entries|) of the matrix whose rows on this rank are ``A``."""
    P = petsc_matrix(A, comm, bs)
    Pt = P.transpose(PETSc.Mat())
    P.axpy(-1.0, Pt, structure=PETSc.Mat.Structure.DIFFERENT_NONZERO_PATTERN)
    _, _, d = P.getValuesCSR()
    diff, total = _total(comm)(np.array([np.abs(d).sum(), np.abs(A.data).sum()]))
    P.destroy()
    Pt.destroy()
    return bool(diff > 1e-14 * total)


def modal_basis_rows(model: MatrixModel, rows: Mapping[str, sp.csr_matrix], comm: MPI.Comm, n_modes: int,
                     corrections: bool = True, shift: float = -1.0, bs: int = 1, options: dict | None = None
                     ) -> tuple[np.ndarray, np.ndarray, int]:
    """(V whole on every rank, f [Hz] of the real modes, the number of static corrections kept): the
    basis of :func:`fem_squeal.reduced.matrix_reduction.modal_basis` from this rank's ``rows`` of the
    named matrices (module docstring).  Raises a ModelError where the real modes fail or M_s is not
    positive definite (then: the snapshot basis)."""
    ops = operators(model, rows, comm, bs=bs)
    (Ms, _), (Ks, _) = symmetric_part(ops["M"]), symmetric_part(ops["K"])
    n = Ks.getSize()[0]
    if n_modes < 1 or n_modes >= n - 1:
        raise ModelError(f"modes: must be in [1, {n - 2}] for {n} DOFs (got {n_modes})")
    Kshift = Ks.copy()
    Kshift.axpy(-shift, Ms, structure=PETSc.Mat.Structure.DIFFERENT_NONZERO_PATTERN)
    ksp = None
    try:
        try:
            rm = solve_real_modes(Kshift, Ms, n_modes, 0.0, tol=MODE_TOL, options=options, prefix="matrix_basis_")
        except PETSc.Error as e:
            raise ModelError(f"modes: the real modes of the symmetric part failed ({e})") from None
        vecs = rm.vectors[:n_modes]
        if len(vecs) < n_modes:
            raise ModelError(f"modes: {len(vecs)} real modes of the symmetric part converged of {n_modes}")
        w2 = np.asarray(rm.omega2[:n_modes], float) + shift
        Phi = np.asfortranarray(np.column_stack([v.getArray() for v in vecs]))
        MPhi = apply(Ms, Phi)
        if np.min(_total(comm)(np.einsum("ij,ij->j", Phi, MPhi))) <= 0:
            raise ModelError("modes: the symmetric part of M is not positive definite")
        for v in rm.vectors:
            v.destroy()
        extra = []
        if corrections:
            whole = _whole(comm, Phi)
            ksp = direct_solver(Kshift, options, "matrix_basis_corr_")
            solve = block_solve(ksp.getPC().getFactorMatrix())
            for name in ("K", "C"):
                op = model.operators.get(name)
                for t in (op.terms if op is not None else ()):
                    A = sp.csr_matrix(rows[t.matrix])
                    if t.parameters or _skew(A, comm, bs):
                        extra.append(solve(np.asfortranarray(A @ whole)))
        total = _total(comm)
        V = orthonormal_columns(np.hstack([Phi, *extra]), lambda X: apply(Ms, np.asfortranarray(X)), total)
    finally:
        if ksp is not None:
            ksp.destroy()
        for A in {id(x): x for x in (Ms, Ks, Kshift, *ops.values())}.values():
            A.destroy()
    f = np.sign(w2) * np.sqrt(np.abs(w2)) / (2 * np.pi)
    return _whole(comm, V), f, V.shape[1] - n_modes


def reduce_rows(model: MatrixModel, rows: Mapping[str, sp.csr_matrix], comm: MPI.Comm, n_modes: int,
                corrections: bool = True, bs: int = 1, options: dict | None = None) -> ReducedMatrixModel:
    """The reduced model of the modal basis (:func:`modal_basis_rows`) of the matrices whose rows on
    this rank are ``rows``: the same on every rank."""
    V, f, n_corr = modal_basis_rows(model, rows, comm, n_modes, corrections, bs=bs, options=options)
    lo = sum(comm.allgather(next(iter(rows.values())).shape[0])[:comm.rank])
    mine = V[lo:lo + next(iter(rows.values())).shape[0]]
    info = {"basis": "modes", "modes": n_modes, "corrections": n_corr, "modes_hz": [float(x) for x in f],
            "size": int(V.shape[1]), "built_on": f"{comm.size} rank(s) (PETSc/SLEPc)"}
    return ReducedMatrixModel(model, project(model, rows, V, mine, _total(comm)), info)
