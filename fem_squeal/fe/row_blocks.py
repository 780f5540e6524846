"""Blocks of vectors as rank-local rows: the dense algebra of the block Krylov methods and the reduced
bases (XᵀY summed over the ranks, W − V C, one M-orthonormalisation pass), in NumPy, SciPy's BLAS and
mpi4py only; :mod:`fem_squeal.fe.dense` applies PETSc matrices and factors to such blocks."""
from __future__ import annotations

import numpy as np
from mpi4py import MPI
from scipy.linalg import blas


def matmul_f(A: np.ndarray, B: np.ndarray) -> np.ndarray:
    """A B, column-major (NumPy returns a product row-major: (Bᵀ Aᵀ)ᵀ is the same BLAS call on
    transposed views), so that the rows of a basis stay in the layout :func:`apply` takes, without
    a transposing copy (0.5 s of the 50k-DOF brake's basis went into such copies)."""
    return (B.T @ A.T).T


def gram(comm, X: np.ndarray, Y: np.ndarray) -> np.ndarray:
    """Xᵀ Y summed over the ranks."""
    return comm.allreduce(X.T @ Y, op=MPI.SUM)


def subtract_combination(V: np.ndarray, C: np.ndarray, W: np.ndarray) -> np.ndarray:
    """W − V C, in place on column-major W (BLAS dgemm: no temporary V C); W as it is where it has no
    columns or this rank no rows."""
    if W.size == 0:
        return W
    return blas.dgemm(-1.0, V, C, beta=1.0, c=W, overwrite_c=1)


def project_out(comm, V: np.ndarray, MV: np.ndarray, W: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """C = (MV)ᵀW summed over the ranks (collective, also where this rank has no rows) and W − V C in
    place (:func:`subtract_combination`)."""
    C = gram(comm, MV, W)
    return C, subtract_combination(V, C, W)


def m_cholesky_qr(comm, W: np.ndarray, MW: np.ndarray, check: bool = False
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """One Cholesky QR pass in the M inner product, on rank-local column-major rows: G = WᵀMW
    (summed over the ranks, symmetrised), G = L Lᵀ, then W L⁻ᵀ and M W L⁻ᵀ in place (BLAS dtrsm;
    M W follows W through the triangular solve instead of a new product).  Returns (W, MW, L);
    ``check``: None where G is numerically singular (λ_min(G) ≤ 1e-12 λ_max(G)).  The one
    M-orthonormalisation step of the block Krylov methods and of the reduced bases."""
    G = gram(comm, W, MW)
    G = 0.5 * (G + G.T)
    if check:
        d = np.linalg.eigvalsh(G)
        if not d[0] > 1e-12 * d[-1]:
            return None
    L = np.linalg.cholesky(G)
    if W.shape[0]:     # a rank may own no rows
        W = blas.dtrsm(1.0, L, W, side=1, lower=1, trans_a=1, overwrite_b=1)      # W L⁻ᵀ
        MW = blas.dtrsm(1.0, L, MW, side=1, lower=1, trans_a=1, overwrite_b=1)
    return W, MW, L
