"""M-orthonormal bases: the basis type, A ↦ ΦᵀAΦ, M-orthonormalisation with deflation (block
Gram–Schmidt and Cholesky QR), rows in a rank-independent order."""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from mpi4py import MPI
from petsc4py import PETSc

from fem_squeal.fe.csr import csr_view
from fem_squeal.fe.dense import apply, gram, m_cholesky_qr, matmul_f, project_out, subtract_combination


@dataclass
class Basis:
    """Mass-orthonormal basis Φ (rank-local owned rows) and where its vectors come from."""

    Phi: np.ndarray               # (n_local, m)
    n_global: int
    modal_hz: np.ndarray          # frequencies of the nominal frictionless modes included
    counts: dict = field(default_factory=dict)  # modes, sampled modes, static corrections, dropped
    orthonormality: float | None = None   # max |ΦᵀMΦ − I| as measured when built (None: not measured)

    @property
    def size(self) -> int:
        return self.Phi.shape[1]


def project(A: PETSc.Mat, Phi: np.ndarray) -> np.ndarray:
    """Φᵀ A Φ (m × m, the same on every rank), summed over the rows where A has entries only when
    they are fewer than half (a contact operator's, a small part's stiffness: the m × m sum over
    all rows cost 80 ms at 50k DOFs × 232 vectors, whatever the rows held)."""
    comm = A.getComm().tompi4py()
    AP = apply(A, Phi)
    if comm.size == 1 and A.getType() == "seqaij":
        with csr_view(A) as (indptr, _, _):
            rows = np.flatnonzero(np.diff(indptr))
    else:     # the local rows of A Φ that are not zero (a scan costs a quarter of the sum)
        rows = np.flatnonzero(np.any(AP != 0.0, axis=1))
    if len(rows) >= 0.5 * Phi.shape[0]:
        return gram(comm, Phi, AP)
    return gram(comm, Phi[rows], AP[rows])


def m_orthonormalise(M: PETSc.Mat, V: np.ndarray, rtol: float = 1e-8, Phi: np.ndarray | None = None
                     ) -> tuple[np.ndarray, int]:
    """Extend the M-orthonormal ``Phi`` (or start afresh) by span(V), with deflation; returns
    (basis, number of dropped directions).  See :func:`m_extend`."""
    Phi, _, dropped = m_extend(M, V, rtol, Phi)
    return Phi, dropped


def m_extend(M: PETSc.Mat, V: np.ndarray, rtol: float = 1e-8, Phi: np.ndarray | None = None,
             MPhi: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, int]:
    """Extend the M-orthonormal ``Phi`` (``MPhi`` = M Φ if at hand) by span(V), with deflation;
    returns (basis Φ', M Φ', number of dropped directions).  See :func:`_new_block`."""
    blocks = []
    if Phi is not None and Phi.shape[1] > 0:
        blocks = [(Phi, apply(M, Phi) if MPhi is None else MPhi)]
    W, MW, dropped = _new_block(M, V, rtol, blocks)
    blocks.append((W, MW))
    return _stack([b[0] for b in blocks], V.shape[0]), _stack([b[1] for b in blocks], V.shape[0]), dropped


def _orthonormality(comm, blocks: list[tuple[np.ndarray, np.ndarray]]) -> float:
    """max |ΦᵀMΦ − I| of the basis held as blocks [(Φ_b, MΦ_b)], block by block (the M Φ of the
    whole basis is never stacked: it served this check alone)."""
    err = 0.0
    for i, (Pi, _) in enumerate(blocks):
        for j, (_, MPj) in enumerate(blocks[i:], start=i):
            G = gram(comm, Pi, MPj)
            err = max(err, float(np.max(np.abs(G - np.eye(G.shape[0]) if i == j else G), initial=0.0)))
    return err


def _stack(blocks: list[np.ndarray], n_local: int) -> np.ndarray:
    """The blocks side by side, column-major (as :func:`fem_squeal.fe.dense.apply` takes them)."""
    out = np.empty((n_local, sum(b.shape[1] for b in blocks)), order="F")
    j = 0
    for b in blocks:
        out[:, j:j + b.shape[1]] = b
        j += b.shape[1]
    return out


def _new_block(M: PETSc.Mat, V: np.ndarray, rtol: float, blocks: list[tuple[np.ndarray, np.ndarray]],
               owned: bool = False) -> tuple[np.ndarray, np.ndarray, int]:
    """The block (W, M W, number of dropped directions) that extends the M-orthonormal basis held as
    ``blocks`` [(Φ_b, M Φ_b), …] by span(V): [Φ_1 … W] is M-orthonormal to round-off.

    Each column of V is scaled by its M-norm and M-orthogonalised against the basis (block
    Gram–Schmidt, ΦᵀMW = (MΦ)ᵀW); then G = WᵀMW = Q diag(s) Qᵀ and directions with s < rtol² (new
    content below ``rtol`` of the vector) are dropped, W Q s^(-1/2) is kept.  A second pass against
    the basis on the kept directions only (one pass leaves a part ~ε/√s along the basis, which the
    scaling brings to ~ε/√s ≤ ε/rtol and the second pass back to ε: "twice is enough"; the dropped
    directions do not need it, and the brake's enrichment drops 5 of every 6) and the Cholesky
    factor of the new block's Gram matrix make it M-orthonormal.  The basis is kept as blocks and
    never re-multiplied nor re-stacked (the whole basis was once re-multiplied by the Cholesky
    factor of its whole Gram matrix: 2·2·n·m² flops per call, 1.3 s of the 50k-DOF brake's 11 s
    basis, to move Φ by round-off; then stacked at each call, 0.6 s).
    M is applied to V and to the kept directions before their Cholesky factor (afresh: s^(-1/2)
    amplifies the round-off of a tracked product by up to 1/rtol); M W after the first pass and
    through the Cholesky factor (close to I) is carried, never applied to the basis (issue 23: the
    basis of the 50k-DOF brake spent 5.5 s re-applying M to it)."""
    comm = M.getComm().tompi4py()

    def against_basis(W: np.ndarray, MW: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray | None]:
        """W − Σ Φ_b C_b, C_b = (MΦ_b)ᵀW, in place; and M W − Σ (MΦ_b) C_b where ``MW`` is given."""
        # collective calls depend on column counts only: a rank may own no rows of V
        for Phi, MPhi in blocks:
            C, W = project_out(comm, Phi, MPhi, W)
            if MW is not None:
                MW = subtract_combination(MPhi, C, MW)
        return W, MW

    MV = apply(M, V)
    norms = np.sqrt(np.maximum(comm.allreduce(np.einsum("ij,ij->j", V, MV), op=MPI.SUM), 0.0))
    ok = norms > 0
    # scaled in place: in V itself where the caller made it for this (``owned``), else in one copy
    W = V if owned and ok.all() and V.flags.f_contiguous and V.flags.writeable else \
        np.array(V if ok.all() else V[:, ok], order="F")
    W /= norms[ok]
    dropped = int(np.sum(~ok))
    if blocks:
        # W = V/‖V‖ − Σ Φ_b C_b and M W = M V/‖V‖ − Σ (MΦ_b) C_b, the latter carried in place of a
        # sparse product (the same cost in flops, and no new array): an absolute round-off ε either
        # way, as the subtraction that makes W itself
        MW = MV if ok.all() else np.asfortranarray(MV[:, ok])
        MW /= norms[ok]
        W, MW = against_basis(W, MW)
        G = gram(comm, W, MW)
    else:                 # W scaled (V itself where owned), MV not: its columns divided here
        G = gram(comm, W, MV if ok.all() else MV[:, ok]) / norms[ok]
    s, Q = np.linalg.eigh(0.5 * (G + G.T))
    keep = s > rtol ** 2
    dropped += int(np.sum(~keep))
    W = against_basis(matmul_f(W, Q[:, keep] / np.sqrt(s[keep])))[0]
    MW = apply(M, W)
    if W.shape[1]:
        # the new block's Cholesky QR, in place (L well conditioned, G ≈ I), M W following W
        # through it (M W L⁻ᵀ = M(W L⁻ᵀ) to round-off times κ(L) ≈ 1)
        W, MW, _ = m_cholesky_qr(comm, W, MW)
    return W, MW, dropped


def _local_array(vecs: list[PETSc.Vec]) -> np.ndarray:
    """The vectors' rank-local rows as the columns of a column-major array."""
    return np.array([v.array_r for v in vecs]).T if vecs else np.zeros((0, 0), order="F")


def _gather_rows(comm, a: np.ndarray) -> np.ndarray:
    return np.concatenate(comm.allgather(a), axis=0)


def canonical_order(x: np.ndarray) -> np.ndarray:
    """Permutation sorting points by their coordinates (rounded to 1e-9 of the extent), so that
    gathered point data does not depend on how the mesh was partitioned."""
    if len(x) == 0:
        return np.zeros(0, int)
    scale = max(float(np.max(np.abs(x))), 1e-300)
    r = np.round(x / (1e-9 * scale))
    return np.lexsort((r[:, 2], r[:, 1], r[:, 0]))
