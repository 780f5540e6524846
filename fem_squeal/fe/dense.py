"""Blocks of vectors as rank-local NumPy rows against PETSc matrices: A Φ, Aᵀ Φ, and PETSc dense
matrices sharing the rows' memory (for a factor's multiple-right-hand-side solve).  The blocks' own
algebra (XᵀY over the ranks, M-orthonormalisation) is :mod:`fem_squeal.fe.row_blocks`."""
from __future__ import annotations

from collections.abc import Callable

import numpy as np
from petsc4py import PETSc

from fem_squeal.fe import kernels
from fem_squeal.fe.csr import block_product, csr_view
from fem_squeal.fe.row_blocks import (  # noqa: F401  (their former home: fem_squeal.fe.dense)
    gram,
    m_cholesky_qr,
    matmul_f,
    project_out,
    subtract_combination,
)


def dense_matrix(comm, local: np.ndarray, n_global: int) -> PETSc.Mat:
    """A PETSc dense matrix of the rank-local rows ``local``; it shares their memory when they are
    column-major (PETSc's layout; a row-major array is copied and transposed, ~10× slower), so
    ``local`` must outlive it."""
    D = PETSc.Mat().createDense(((local.shape[0], n_global), (PETSc.DECIDE, local.shape[1])),
                                array=np.asfortranarray(local), comm=comm)
    D.assemble()
    return D


def distributed_product(A: PETSc.Mat) -> Callable[[np.ndarray], np.ndarray] | None:
    """X ↦ A X for a distributed AIJ matrix on more than one rank, on rank-local column-major rows,
    by the compiled CSR block product (:func:`fem_squeal.fe.csr.block_product`) on this rank's rows
    only: A_d X + A_o X_g, the diagonal block (owned columns) and the off-diagonal one (the ghost
    columns in ascending global order, as PETSc compresses them), X_g the ghost rows of X fetched
    from their owners (one ``Alltoallv`` of k columns per product; the plan is made here, once).
    The rows are read once (``getValuesCSR``), so the function serves a matrix that does not change
    while it is used (a Krylov solve's M).  None on one rank, for another matrix type, or where the
    kernel is missing (the caller keeps PETSc's MatMatMult)."""
    comm = A.getComm().tompi4py()
    if comm.size == 1 or A.getType() != "mpiaij":
        return None
    lo, hi = A.getOwnershipRange()
    ai, aj, av = A.getValuesCSR()
    own = (aj >= lo) & (aj < hi)
    counts = np.diff(ai)
    rows = np.repeat(np.arange(len(counts)), counts)
    ghosts = np.unique(aj[~own])

    def indptr(keep: np.ndarray) -> np.ndarray:
        return np.concatenate([[0], np.cumsum(np.bincount(rows[keep], minlength=len(counts)))]).astype(np.int32)
    diag = block_product((indptr(own), (aj[own] - lo).astype(np.int32), av[own]), hi - lo)
    off = block_product((indptr(~own), np.searchsorted(ghosts, aj[~own]).astype(np.int32), av[~own]), len(ghosts))
    if diag is None or off is None:
        return None
    ranges = A.getOwnershipRanges()
    owner = np.searchsorted(ranges, ghosts, side="right") - 1
    want = np.bincount(owner, minlength=comm.size).astype(np.int64)       # ghosts asked of each rank
    give = np.empty(comm.size, np.int64)
    comm.Alltoall(want, give)
    asked = np.empty(int(give.sum()), np.int64)
    comm.Alltoallv([ghosts.astype(np.int64), want], [asked, give])
    send_rows = asked - lo                                                 # the rows others need of ours

    def product(X: np.ndarray) -> np.ndarray:
        X = np.asfortranarray(X, dtype=np.float64)
        k = X.shape[1]
        send = np.ascontiguousarray(X[send_rows])                          # row-major: whole rows
        recv = np.empty((len(ghosts), k))
        comm.Alltoallv([send, give * k], [recv, want * k])
        Y = diag(X) if hi > lo else np.zeros((0, k), order="F")
        if len(ghosts):         # a rank whose rows meet no other rank's columns has no ghost block
            Y += off(np.asfortranarray(recv))
        kernels.note("block_product", "compiled, rank-local rows")
        return Y
    return product


def product_of(A: PETSc.Mat) -> Callable[[np.ndarray], np.ndarray]:
    """X ↦ A X on rank-local rows for repeated products with one matrix (a Krylov solve's M): on
    more than one rank :func:`distributed_product` (its plan made once), else :func:`apply`."""
    return distributed_product(A) or (lambda X: apply(A, X))


def apply(A: PETSc.Mat, Phi: np.ndarray) -> np.ndarray:
    """A Φ, rank-local rows (n_local, m), column-major (as PETSc's dense matrices: no transposing
    copies on the way in or out).  On one rank an AIJ matrix is applied by the compiled block product
    (:func:`fem_squeal.fe.csr.block_product`, on PETSc's own arrays: 1.9× PETSc's MatMatMult for the
    50k-DOF brake's stiffness times 233 columns), elsewhere by MatMatMult."""
    comm = A.getComm().tompi4py()
    Phi = np.asfortranarray(Phi)
    if comm.size == 1 and A.getType() == "seqaij" and Phi.ndim == 2:
        with csr_view(A) as csr:
            product = block_product(csr, A.getSize()[1])
            if product is not None:
                kernels.note("block_product", "compiled")
                return product(Phi)
    kernels.note("block_product", "petsc")
    D = dense_matrix(comm, Phi, A.getSize()[1])
    P = A.matMult(D)
    out = np.array(P.getDenseArray(), order="F")
    D.destroy()
    P.destroy()
    return out


def apply_transpose(A: PETSc.Mat, Phi: np.ndarray) -> np.ndarray:
    """Aᵀ Φ, rank-local rows (n_local, m), column-major, by MatTransposeMatMult (no transposed copy of A)."""
    D = dense_matrix(A.getComm().tompi4py(), Phi, A.getSize()[0])
    P = A.transposeMatMult(D)
    out = np.array(P.getDenseArray(), order="F")
    D.destroy()
    P.destroy()
    return out


def block_solve(factor: PETSc.Mat) -> Callable[[np.ndarray], np.ndarray]:
    """B ↦ A⁻¹B for rank-local column-major blocks, by the PETSc factor matrix of A (MatMatSolve:
    one multiple-right-hand-side solve per block)."""
    comm, n = factor.getComm().tompi4py(), factor.getSize()[0]

    def solve(B: np.ndarray) -> np.ndarray:
        Bm = dense_matrix(comm, B, n)
        Xm = Bm.duplicate()
        factor.matSolve(Bm, Xm)
        X = np.array(Xm.getDenseArray(), order="F")
        Bm.destroy()
        Xm.destroy()
        return X
    return solve
