"""A model given as matrices on the ranks of a communicator: the rows of each named matrix dealt to
the ranks as PETSc does (rank r owns rows [lo_r, hi_r): ⌊n/N⌋ each, one more on the first n mod N),
the operators M(p), C(p), K(p) of a :class:`fem_squeal.reduced.matrix_model.MatrixModel` formed on
each rank's rows and made PETSc matrices, and the way back: a distributed PETSc matrix gathered to
rank 0 as SciPy CSR (what ``fem-squeal export`` writes)."""
from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
import scipy.sparse as sp
from mpi4py import MPI
from petsc4py import PETSc

from fem_squeal.fe.csr import local_rows
from fem_squeal.reduced.matrix_model import MatrixModel


def row_range(n: int, rank: int, size: int, bs: int = 1) -> tuple[int, int]:
    """The rows [lo, hi) of rank ``rank`` of ``size`` (PETSc's default split of the n/bs blocks of
    ``bs`` rows)."""
    base, extra = divmod(n // bs, size)
    lo = rank * base + min(rank, extra)
    return bs * lo, bs * (lo + base + (1 if rank < extra else 0))


def scatter_rows(A: sp.spmatrix | None, n: int, comm: MPI.Comm, bs: int = 1) -> sp.csr_matrix:
    """This rank's rows of the n×n matrix ``A`` held by rank 0 (None elsewhere), as CSR (rows × n)."""
    if comm.size == 1:
        return sp.csr_matrix(A)
    pieces = None
    if comm.rank == 0:
        A = sp.csr_matrix(A)
        pieces = [A[slice(*row_range(n, r, comm.size, bs))] for r in range(comm.size)]
    return comm.scatter(pieces, root=0)


def petsc_matrix(rows: sp.csr_matrix, comm: MPI.Comm, bs: int = 1) -> PETSc.Mat:
    """The AIJ matrix whose rows on this rank are ``rows`` (global column indices; the rows of
    :func:`row_range`), of block size ``bs`` (the degrees of freedom of a node: the fill-reducing
    ordering keeps a node's rows together, :mod:`fem_squeal.fe.ordering`), assembled."""
    n = rows.shape[1]
    rows = sp.csr_matrix(rows, dtype=np.float64)
    rows.sum_duplicates()
    rows.sort_indices()
    lo, hi = row_range(n, comm.rank, comm.size, bs)
    if rows.shape[0] != hi - lo:
        raise ValueError(f"petsc_matrix: {rows.shape[0]} rows on rank {comm.rank}, expected {hi - lo}")
    A = PETSc.Mat().createAIJ(((hi - lo, n), (hi - lo, n)), bsize=bs,
                              csr=(rows.indptr.astype(PETSc.IntType), rows.indices.astype(PETSc.IntType),
                                   rows.data), comm=comm)
    A.assemble()
    return A


def operators(model: MatrixModel, rows: Mapping[str, sp.csr_matrix], comm: MPI.Comm,
              given: Mapping[str, Any] | None = None, bs: int = 1) -> dict[str, PETSc.Mat]:
    """{"M", "C" (damped models), "K"}: the operators at the point ``given`` (nominal where not given)
    as distributed PETSc matrices of block size ``bs``, from each rank's ``rows`` of the named matrices."""
    return {name: petsc_matrix(A, comm, bs) for name, A in model.assemble(rows, given).items()}


def gather_csr(A: PETSc.Mat) -> sp.csr_matrix | None:
    """The distributed AIJ matrix ``A`` as SciPy CSR on rank 0 (None on the other ranks)."""
    comm = A.getComm().tompi4py()
    n_rows, n_cols = A.getSize()
    parts = comm.gather(local_rows(A), root=0)
    if comm.rank != 0:
        return None
    out = sp.vstack(parts, format="csr")
    out.sort_indices()
    return out


def symmetric_part(A: PETSc.Mat) -> tuple[PETSc.Mat, float]:
    """(A + Aᵀ)/2 and ‖A − Aᵀ‖_F/‖A‖_F; ``A`` itself where it is symmetric (the ratio 0)."""
    At = A.transpose(PETSc.Mat())
    D = A.copy()
    D.axpy(-1.0, At, structure=PETSc.Mat.Structure.DIFFERENT_NONZERO_PATTERN)
    norm = A.norm(PETSc.NormType.FROBENIUS)
    skew = D.norm(PETSc.NormType.FROBENIUS) / norm if norm > 0 else 0.0
    D.destroy()
    if skew == 0.0:
        At.destroy()
        return A, 0.0
    S = A.copy()
    S.axpy(1.0, At, structure=PETSc.Mat.Structure.DIFFERENT_NONZERO_PATTERN)
    S.scale(0.5)
    At.destroy()
    return S, float(skew)
