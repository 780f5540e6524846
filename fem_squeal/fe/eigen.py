"""SLEPc eigen-solvers: real modes (EPS, GHEP) and complex modes of λ²M + λC + K (PEP or linear EPS).

PETSc here is a real build: targets are real shifts, and complex eigenpairs come back as a complex
eigenvalue plus real and imaginary vector parts.  Every solver takes a PETSc options dict and a
prefix, so ``-cea_st_pc_factor_mat_solver_type superlu_dist`` and the like work from the command line.

Complex modes, undamped (C = 0): with θ = −λ², (λ²M + K)x = 0 is the non-symmetric linear
problem K x = θ M x; each θ gives λ = i√θ (principal root, Im λ > 0).  A real shift θ_t = ω_t²
targets a band centre.  With damping the quadratic is solved by PEP (TOAR); a real target σ orders
eigenvalues by |λ − σ|² ≈ σ² + ω², so PEP returns the lowest modes and must be asked for enough of
them to cover the band.
"""
from __future__ import annotations

import os
import time
from collections.abc import Callable
from contextlib import contextmanager
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
from mpi4py import MPI
from petsc4py import PETSc
from scipy.linalg import blas
from slepc4py import SLEPc

from fem_squeal.fe import cholmod, kernels
from fem_squeal.fe.csr import block_product, csr_view
from fem_squeal.fe.dense import apply, block_solve, project_out
from fem_squeal.fe.ordering import ORDERINGS, fill_reducing_order, permuted
from fem_squeal.util.blas import serial_openmp
from fem_squeal.util.errors import EigenSolveError, ModelError
from fem_squeal.util.progress import ProgressBar

TWO_PI = 2.0 * np.pi

# Scalar scaling of λ balances |λ|²‖M‖ against ‖K‖ (stiff bonded/contact penalties make ‖K‖
# large); residual extraction picks the best eigenvector from the TOAR basis.  Measured on the
# damped coarse brake: max relative residual 1.2e-7 without, 4e-13 with, at the same cost.
PEP_OPTIONS = {"pep_scale": "scalar", "pep_extract": "residual"}
DIRECT_SOLVER_OPTIONS = {
    "st_ksp_type": "preonly",
    "st_pc_type": "lu",
    "st_pc_factor_mat_solver_type": "mumps",
}
# Real modes (K, M symmetric; benchmarks/modal_peers.py --speed, clamped P2 disc, 20 modes, 1 rank).
# - CHOLMOD (SuiteSparse, in Debian's PETSc; serial) factorises K − σM faster than MUMPS' LDLᵀ and
#   its triangular solves take 0.4–0.6 of MUMPS' time (METIS ordering: MUMPS here falls back to PORD);
#   it needs K − σM positive definite (σ below the lowest mode), else MUMPS LDLᵀ takes over.
# - No purification: it costs one more solve per returned pair and only removes components in
#   null(M), which K⁻¹M never creates here (M's clamped rows are zero, K's are identity).
# - The tolerance: the Ritz value of a symmetric pencil is accurate to the square of its relative
#   residual (over the relative gap), so 1e-7 leaves the frequencies within 1e-12 of tol 1e-10's
#   (measured: 8e-14, 4e-14, 4e-13 at 26k, 87k, 260k DOFs) and saves the restart that 1e-8 needs on
#   some meshes (54 shift-invert solves instead of 66; 1e-10 with purification: 91).  1e-5 fails the
#   1e-8 residual check at 26k DOFs.
REAL_MODE_TOL = 1e-7
REAL_MODE_TOL_FALLBACK = 1e-10   # the continuation when a pair misses the residual bound
REAL_MODE_OPTIONS = {"st_ksp_type": "preonly", "st_pc_type": "cholesky", "eps_purify": False,
                     "st_mat_cholmod_print": 0}   # CHOLMOD's own "not positive definite" line: we fall back
_NOT_DEFINITE: dict[tuple[int, int], float] = {}  # (K, M) handles -> lowest shift CHOLMOD failed at



@dataclass
class RealModes:
    """Real modes of K φ = ω² M φ, M-normalised (φᵀMφ = 1)."""

    omega2: np.ndarray            # ω² [rad²/s²], ascending
    vectors: list[PETSc.Vec]
    residuals: np.ndarray         # ‖Kφ − ω²Mφ‖ / (‖K‖ ‖φ‖)
    solver: str = ""              # the factorisation used: "cholmod" or "mumps"
    seconds: dict[str, float] = field(default_factory=dict)   # "factor", "solve" (wall, rank 0)
    method: str = ""              # "block Lanczos, <b> columns" or "Krylov-Schur"

    @property
    def freqs_hz(self) -> np.ndarray:
        return np.sqrt(np.abs(self.omega2)) * np.sign(self.omega2) / TWO_PI


@dataclass
class ComplexModes:
    """Complex modes λ = σ + iω (Im λ ≥ 0 only), with vectors x = xr + i xi, x^H M x = 1."""

    eigenvalues: np.ndarray       # complex λ [1/s]
    vectors_re: list[PETSc.Vec]
    vectors_im: list[PETSc.Vec]
    residuals: np.ndarray         # ‖(λ²M+λC+K)x‖ / (‖K‖ ‖x‖)
    method: str
    seconds: dict[str, float] = field(default_factory=dict)   # "factor" (setUp), "solve" (wall, rank 0)
    algorithm: str = ""           # "block Arnoldi, <b> columns", "Krylov-Schur" or "TOAR"

    @property
    def freqs_hz(self) -> np.ndarray:
        return self.eigenvalues.imag / TWO_PI

    @property
    def real_parts(self) -> np.ndarray:
        return self.eigenvalues.real

    @property
    def damping_ratios(self) -> np.ndarray:
        """ζ = −Re λ / |λ| (negative for unstable modes)."""
        return 0.0 - self.eigenvalues.real / np.abs(self.eigenvalues)  # 0.0 - x: no "-0.0"


def set_options(prefix: str, options: dict[str, object] | None, defaults: dict[str, object]) -> None:
    """Write ``defaults`` (keys without prefix) under ``prefix`` into the PETSc options database,
    keeping any value already given on the command line (``-<prefix><key>``), then ``options``
    (full names with their solver prefix, e.g. ``cea_st_pc_factor_mat_solver_type``: the
    scene's ``solver.petsc_options``), which win."""
    db = PETSc.Options()

    def text(value):
        return value if not isinstance(value, bool) else ("true" if value else "false")
    for key, value in defaults.items():
        if not db.hasName(f"{prefix}{key}"):
            db[f"{prefix}{key}"] = text(value)
    for name, value in (options or {}).items():
        db[name.lstrip("-")] = text(value)


def _norm_inf(A: PETSc.Mat | None) -> float:
    return 0.0 if A is None else A.norm(PETSc.NormType.INFINITY)


def _sort_key(lam: np.ndarray, rel: float = 1e-7) -> np.ndarray:
    """Order by frequency; eigenvalues whose frequencies agree to ``rel`` are ordered by real part,
    so that the order does not depend on round-off (PEP resolves the two halves of a quadruple
    ±σ + iω to ~1e-9 relative in ω)."""
    order = np.argsort(lam.imag, kind="stable")
    groups, g = np.zeros(len(lam)), 0
    for j in range(1, len(order)):
        a, b = lam[order[j - 1]].imag, lam[order[j]].imag
        if abs(b - a) > rel * max(abs(a), abs(b), 1.0):
            g += 1
        groups[order[j]] = g
    return np.lexsort((lam.real, groups))


def quadratic_residual(K, C, M, lam: complex, xr: PETSc.Vec, xi: PETSc.Vec) -> float:
    """‖(λ²M + λC + K)x‖₂ / (‖K‖_∞ ‖x‖₂) for x = xr + i xi, in real arithmetic."""
    a, b = lam.real, lam.imag
    l2r, l2i = a * a - b * b, 2 * a * b
    rr, ri, t = xr.duplicate(), xr.duplicate(), xr.duplicate()
    K.mult(xr, rr)
    K.mult(xi, ri)
    M.mult(xr, t)
    rr.axpy(l2r, t)
    ri.axpy(l2i, t)
    M.mult(xi, t)
    rr.axpy(-l2i, t)
    ri.axpy(l2r, t)
    if C is not None:
        C.mult(xr, t)
        rr.axpy(a, t)
        ri.axpy(b, t)
        C.mult(xi, t)
        rr.axpy(-b, t)
        ri.axpy(a, t)
    num = np.hypot(rr.norm(), ri.norm())
    den = _norm_inf(K) * np.hypot(xr.norm(), xi.norm())
    for w in (rr, ri, t):
        w.destroy()
    return float(num / den)


def _m_normalise(M: PETSc.Mat, xr: PETSc.Vec, xi: PETSc.Vec) -> None:
    """Scale x = xr + i xi to x^H M x = 1 with the phase making Σ x_j² real (a fixed, mesh-
    independent phase convention: for a standing mode the vector becomes real)."""
    Mxr, Mxi = xr.duplicate(), xi.duplicate()
    M.mult(xr, Mxr)
    M.mult(xi, Mxi)
    mass = xr.dot(Mxr) + xi.dot(Mxi)
    # x^T M x (no conjugate) = (xr·Mxr − xi·Mxi) + 2i xr·Mxi ; rotate so that it is real and ≥ 0
    q = complex(xr.dot(Mxr) - xi.dot(Mxi), 2 * xr.dot(Mxi))
    phase = np.exp(-0.5j * np.angle(q)) if abs(q) > 1e-14 * mass else 1.0
    scale = phase / np.sqrt(mass)
    r, i = xr.copy(), xi.copy()
    xr.scale(scale.real)
    xr.axpy(-scale.imag, i)
    xi.scale(scale.real)
    xi.axpy(scale.imag, r)
    for w in (Mxr, Mxi, r, i):
        w.destroy()


def _shift_invert_eps(A: PETSc.Mat, B: PETSc.Mat, problem_type, nev: int, target: float, tol: float,
                      prefix: str) -> SLEPc.EPS:
    """Krylov–Schur EPS for A x = θ B x, shift-and-invert at the real ``target``, nearest first."""
    eps = SLEPc.EPS().create(A.getComm())
    eps.setOptionsPrefix(prefix)
    eps.setOperators(A, B)
    eps.setProblemType(problem_type)
    eps.setType(SLEPc.EPS.Type.KRYLOVSCHUR)
    eps.setDimensions(nev, max(2 * nev, nev + 16))
    eps.setTolerances(tol, 200)
    eps.getST().setType(SLEPc.ST.Type.SINVERT)
    eps.setTarget(target)
    eps.setWhichEigenpairs(SLEPc.EPS.Which.TARGET_MAGNITUDE)
    return eps


# Block Lanczos (issue 23): the factor's multiple-right-hand-side solve (MatMatSolve) costs a
# fraction of single solves per column (clamped disc, 85k DOFs: CHOLMOD 35 → 7 ms, MUMPS on 2 ranks
# 43 → 11 ms with 16 columns), which more than pays for the larger Krylov space a block method
# needs.  ``<prefix>block_size`` 0 turns it off (SLEPc's Krylov–Schur on the same factorisation).
BLOCK_MEMORY = 4.0e9   # bytes per rank for the Lanczos vectors (V and MV); beyond it, Krylov–Schur
BEYOND = 2             # converged pairs beyond a threshold λ_max that show none below it is missing


def block_size(nev: int) -> int:
    """Columns per block solve: ~nev/8, between 8 and 16.  Measured (seconds of the eigensolve after
    the factorisation): clamped disc, 85k DOFs, 20 modes, CHOLMOD: Krylov–Schur 2.8, blocks of 5, 8,
    12, 16: 2.8, 2.5, 3.0, 3.2; brake, 163k DOFs, 2 ranks, MUMPS, 90 modes ≤ 16 kHz (modes_below,
    with its factorisation and the inertia count): Krylov–Schur 29.4, blocks of 8, 12, 23, 32: 16.7,
    16.5, 19.4, 20.5.  Larger blocks cost less per column but need more columns."""
    return int(min(max(8, -(-nev // 8)), 16))


def _block_columns(nev: int, prefix: str) -> int:
    """``<prefix>block_size`` if given (0: SLEPc's own iteration), else :func:`block_size`."""
    return PETSc.Options().getInt(f"{prefix}block_size", block_size(nev))


def _krylov_dim(nev: int, b: int, n: int) -> int:
    """The vector budget of a block Krylov space without restart: max(6 nev, nev + 16 b, 256)
    columns, at most n − b, in whole blocks."""
    return min(max(6 * nev, nev + 16 * b, 256), n - b) // b * b


def _start_block(rows: np.ndarray, b: int) -> np.ndarray:
    """A start block that depends on the global row numbers only (the same on any rank count)."""
    x = np.sin(np.outer(rows.astype(float) + 1.0, 12.9898 + 78.233 * np.arange(1, b + 1))) * 43758.5453
    return np.asfortranarray(x - np.floor(x) - 0.5)


def _m_orthonormal(comm, mass: Callable[[np.ndarray], np.ndarray], W: np.ndarray
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """Q, MQ, R with W = Q R and QᵀMQ = I (Cholesky QR, twice); None if W is numerically rank
    deficient (an invariant subspace: nothing new to add).  ``mass``: W ↦ MW on rank-local rows.
    M is applied once: MQ follows W through the same triangular transformations (MW L⁻ᵀ =
    M(W L⁻ᵀ)), which keeps QᵀMQ = I to round-off times the condition of W, as the second pass
    itself does.  The transformations are in-place triangular solves on column-major blocks
    (BLAS dtrsm): ``W @ inv(Lᵀ)`` took 9 ms for 255k × 8 (NumPy's row-major result), dtrsm 0.4 ms."""
    W = np.array(W, order="F")
    MW = np.asfortranarray(mass(W))
    R = np.eye(W.shape[1])
    for _ in range(2):
        G = comm.allreduce(W.T @ MW, op=MPI.SUM)
        G = 0.5 * (G + G.T)
        d = np.linalg.eigvalsh(G)
        if not d[0] > 1e-12 * d[-1]:
            return None
        L = np.linalg.cholesky(G)
        W = blas.dtrsm(1.0, L, W, side=1, lower=1, trans_a=1, overwrite_b=1)      # W L⁻ᵀ
        MW = blas.dtrsm(1.0, L, MW, side=1, lower=1, trans_a=1, overwrite_b=1)
        R = L.T @ R
    return W, MW, R


def _grown(A: np.ndarray, shape: tuple[int, int], order: str) -> np.ndarray:
    """A copied into the leading block of zeros of ``shape``."""
    out = np.zeros(shape, order=order)
    out[:A.shape[0], :A.shape[1]] = A
    return out


def _block_lanczos(solve: Callable[[np.ndarray], np.ndarray], mass: Callable[[np.ndarray], np.ndarray],
                   comm, rows: tuple[int, int], n: int, nev: int, sigma: float, tol: float, b: int,
                   lam_max: float | None = None) -> tuple[np.ndarray, np.ndarray] | None:
    """The ``nev`` eigenpairs of K x = λ M x nearest σ by block Lanczos on (K − σM)⁻¹M in the M-inner
    product, with full reorthogonalisation.  ``solve``: B ↦ (K − σM)⁻¹B and ``mass``: W ↦ MW, both
    on the rank-local rows ``rows`` (r0, r1) of column-major blocks; ``n``: the global size.
    Returns (λ, local rows of the M-orthonormal vectors) or None (not converged within the vector
    budget: max(6 nev, nev + 16 b, 256) vectors, at most :data:`BLOCK_MEMORY` bytes per rank; a
    cluster of nearly equal eigenvalues, such as the clamped ring's 12 lowest within 0.1 %, needs ~150).

    With V = [Q₀ … Q_j] M-orthonormal and W = (K − σM)⁻¹ M Q_j, T = Vᵀ M (K − σM)⁻¹ M V is
    symmetric; its eigenpairs (θ, y) give λ = σ + 1/θ, x = V y, and the residual of the shift-inverted
    operator ‖(K − σM)⁻¹Mx − θx‖_M = ‖R_{j+1} y_j‖ (the last block of y and the next block's
    triangular factor).  A pair counts as converged where that is ≤ tol·|θ|, SLEPc's criterion.
    Orthogonalisation: W against the last two blocks (the three-term recurrence, where W's large
    components lie), then once against all of V (what round-off leaves along the older blocks), then
    the Cholesky QR of :func:`_m_orthonormal`.

    ``lam_max``: every pair with λ ≤ ``lam_max`` and the next :data:`BEYOND` in |θ| order instead of
    ``nev`` (σ below the middle of [0, ``lam_max``]: those are the leading |θ|); ``nev`` is then a
    guess that sizes the block and the first budget, which grows (×1.5, the vectors copied) up to
    what :data:`BLOCK_MEMORY` holds.  This is how :func:`fem_squeal.fe.projection.modes_below` asks
    for the modes below a cut without counting them first (an inertia count cost one more
    factorisation)."""
    r0, r1 = rows
    dim = _krylov_dim(nev, b, n)
    # with a threshold the budget grows (×1.5, the vectors copied) up to what BLOCK_MEMORY holds:
    # allocating that at once cost 1.4 s of zeroed pages for the 50k-DOF brake's 89 modes
    limit = dim if lam_max is None else \
        min(n - b, int(BLOCK_MEMORY // (2 * 8 * max(comm.allreduce(r1 - r0, op=MPI.MAX), 1)))) // b * b
    if (dim < nev and lam_max is None) or comm.allreduce(2 * 8 * (r1 - r0) * dim, op=MPI.MAX) > BLOCK_MEMORY:
        return None
    V = np.zeros((r1 - r0, dim), order="F")
    MV = np.zeros(V.shape, order="F")    # calloc: pages are touched only as columns are filled
    start = _m_orthonormal(comm, mass, _start_block(np.arange(r0, r1), b))
    if start is None:
        return None
    V[:, :b], MV[:, :b] = start[0], start[1]
    T = np.zeros((dim, dim))
    k = b
    while True:
        W = np.asfortranarray(solve(MV[:, k - b:k]))
        lo = max(0, k - 2 * b)
        C = np.zeros((k, b))
        C[lo:], W = project_out(comm, V[:, lo:k], MV[:, lo:k], W)   # the recurrence: the last two blocks
        C2, W = project_out(comm, V[:, :k], MV[:, :k], W)            # full reorthogonalisation
        C += C2
        T[:k, k - b:k] = C
        T[k - b:k, :k] = C.T
        Tk = 0.5 * (T[:k, :k] + T[:k, :k].T)
        theta, Y = np.linalg.eigh(Tk)
        want = np.argsort(-np.abs(theta), kind="stable")
        count = nev if lam_max is None else int(np.sum(sigma + 1.0 / theta <= lam_max)) + BEYOND
        want = want[:count]
        nxt = _m_orthonormal(comm, mass, W)
        # an invariant subspace (nothing new in W): the Ritz pairs are exact
        res = np.zeros(want.size) if nxt is None else np.linalg.norm(nxt[2] @ Y[k - b:k, want], axis=0)
        if k >= count and np.all(res <= tol * np.abs(theta[want])):
            return sigma + 1.0 / theta[want], blas.dgemm(1.0, V[:, :k], Y[:, want])
        if nxt is not None and k + b > dim and dim < limit:
            dim = min(limit, (3 * dim // 2) // b * b)
            V, MV = (_grown(A, (A.shape[0], dim), "F") for A in (V, MV))
            T = _grown(T, (dim, dim), "C")
        if nxt is None or k + b > dim:
            return None                       # fewer than nev pairs exist, or the budget is spent
        V[:, k:k + b], MV[:, k:k + b] = nxt[0], nxt[1]
        T[k:k + b, k - b:k] = nxt[2]
        T[k - b:k, k:k + b] = nxt[2].T
        k += b


ARNOLDI_MEMORY_SHARE = 0.05   # of a machine's memory per rank for the block Arnoldi vectors


def _arnoldi_memory(comm) -> float:
    """Bytes per rank the block Arnoldi vectors may take: :data:`BLOCK_MEMORY`, and at most
    :data:`ARNOLDI_MEMORY_SHARE` of this machine's memory over its ranks.  The CEA's memory model
    (``app/resources.py``) was measured with Krylov–Schur's 2·nev vectors; beyond this share the
    block path gives way to it (brake, 60 modes: 1.32M DOFs on one 24 GiB machine, or 711k on two
    ranks, would need 3.8 and 2 × 1.0 GB for the 360-vector budget)."""
    node = comm.Split_type(MPI.COMM_TYPE_SHARED)
    try:
        ranks = node.Get_size()
    finally:
        node.Free()
    memory = os.sysconf("SC_PHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    return min(BLOCK_MEMORY, ARNOLDI_MEMORY_SHARE * memory / ranks)


def _block_arnoldi(solve: Callable[[np.ndarray], np.ndarray], mass: Callable[[np.ndarray], np.ndarray],
                   comm, rows: tuple[int, int], n: int, nev: int, sigma: float, tol: float, b: int,
                   progress: Callable[[int, int], None] | None = None) -> tuple[np.ndarray, np.ndarray] | None:
    """The ``nev`` eigenpairs of the non-symmetric pencil K x = ν M x nearest σ by block Arnoldi on
    (K − σM)⁻¹M, with full reorthogonalisation (classical Gram–Schmidt twice) and no restart: the
    same factor's block solves as :func:`_block_lanczos`, for the linear CEA.  ``solve``: B ↦
    (K − σM)⁻¹B, ``mass``: W ↦ MW on rank-local rows ``rows`` of column-major blocks.  Returns
    (ν, local rows of the unit Ritz vectors, complex) or None (not converged within max(6 nev,
    nev + 16 b, 256) vectors).

    With V = [Q₀ … Q_j] orthonormal, (K − σM)⁻¹M V_j = V_{j+1} H (block upper Hessenberg); the
    eigenpairs (θ, y) of H_j give ν = σ + 1/θ, x = V y and ‖(K − σM)⁻¹Mx − θx‖ = ‖R_{j+1} y_j‖ (R the
    next block's triangular factor, y_j the last block of y), converged where ≤ tol·|θ| (SLEPc's
    relative criterion).  The start block is M times a fixed pseudo-random block, so that it has no
    component in null(M) (the Dirichlet rows), where no eigenvector lies.  It returns the ``nev``
    pairs of largest |θ| (nearest σ), once all of them have converged, largest first; where the cut
    would split a complex-conjugate pair, the pair is kept whole (nev + 1).  Not the other pairs that
    happen to have converged too (SLEPc returns those): which they are depends on round-off, and the
    set returned must not (a scene run on two meshes numbered differently, or on 1 and 2 ranks, must
    give the same modes).  The vectors are at most :func:`_arnoldi_memory` bytes per rank.
    ``progress``: called with (converged wanted pairs, vectors) after each step."""
    r0, r1 = rows
    dim = _krylov_dim(nev, b, n)
    if dim < nev + 1 or comm.allreduce(8 * (r1 - r0) * dim > _arnoldi_memory(comm), op=MPI.LOR):
        return None

    def unit(x):        # the Euclidean inner product (a copy: _m_orthonormal transforms both in place)
        return np.array(x, order="F")

    V = np.zeros((r1 - r0, dim), order="F")
    start = _m_orthonormal(comm, unit, mass(_start_block(np.arange(r0, r1), b)))
    if start is None:
        return None
    V[:, :b] = start[0]
    H = np.zeros((dim, dim))
    k = b
    while True:
        W = np.asfortranarray(solve(np.asfortranarray(mass(V[:, k - b:k]))))
        C, W = project_out(comm, V[:, :k], V[:, :k], W)
        C2, W = project_out(comm, V[:, :k], V[:, :k], W)     # the second pass: orthogonal to round-off
        H[:k, k - b:k] = C + C2
        nxt = _m_orthonormal(comm, unit, W)
        if k >= nev + 1:
            theta, Y = np.linalg.eig(H[:k, :k])
            order = np.argsort(-np.abs(theta), kind="stable")
            want = list(order[:nev])
            last = theta[want[-1]]
            if last.imag != 0.0:               # keep a conjugate pair whole
                mate = int(np.argmin(np.abs(theta[order[nev:]] - np.conj(last)))) + nev
                if abs(theta[order[mate]] - np.conj(last)) <= 1e-12 * abs(last) and \
                        not any(abs(theta[i] - np.conj(last)) <= 1e-12 * abs(last) for i in want[:-1]):
                    want.append(order[mate])
            want = np.array(want)
            res = np.zeros(k) if nxt is None else np.linalg.norm(nxt[2] @ Y[k - b:k], axis=0)
            done = res <= tol * np.abs(theta)
            if progress is not None:
                progress(int(done[want].sum()), k)
            if np.all(done[want]):            # x = V y in real products (V @ y would copy V to complex)
                X = np.empty((r1 - r0, want.size), dtype=complex)
                X.real = blas.dgemm(1.0, V[:, :k], np.asfortranarray(Y[:, want].real))
                X.imag = blas.dgemm(1.0, V[:, :k], np.asfortranarray(Y[:, want].imag))
                return sigma + 1.0 / theta[want], X
        if nxt is None or k + b > dim:
            return None
        V[:, k:k + b] = nxt[0]
        H[k:k + b, k - b:k] = nxt[2]
        k += b


def solve_real_modes(K: PETSc.Mat, M: PETSc.Mat, nev: int, target_hz: float, *, tol: float = REAL_MODE_TOL,
                     max_residual: float = 1e-8, options: dict | None = None,
                     prefix: str = "real_", progress: bool = False, f_max_hz: float | None = None) -> RealModes:
    """Real modes nearest ``target_hz``: K φ = ω² M φ, shift-and-invert at ω_t², by block Lanczos
    on the factor's block solves (:func:`_block_lanczos`; ``<prefix>block_size``, 0: off), else, or
    where it does not converge within its vector budget or misses ``max_residual``, by SLEPc's
    Krylov–Schur on the same factorisation.  On one rank, unless a factorisation is named
    (``<prefix>st_pc_factor_mat_solver_type``), CHOLMOD is called directly
    (:func:`_cholmod_block_lanczos`) with the fill-reducing order of the node graph handed in
    (:mod:`fem_squeal.fe.ordering`; ``<prefix>ordering solver`` leaves the ordering to CHOLMOD);
    PETSc's CHOLMOD works on K and M permuted to that order; the vectors come back in the caller's
    order.  ``progress``: draw converged/requested pairs on rank 0's stderr (Krylov–Schur
    only).  ``f_max_hz``: every mode up to it and :data:`BEYOND` more instead of ``nev`` (then a
    guess: the block size follows it) where block Lanczos answers; Krylov–Schur, where it takes
    over, returns ``nev``."""
    if nev < 1:
        raise ModelError(f"n_modes: must be >= 1 (got {nev})")
    for A in (K, M):
        A.setOption(PETSc.Mat.Option.SYMMETRIC, True)
    set_options(prefix, options, REAL_MODE_OPTIONS)
    sigma, key = (TWO_PI * target_hz) ** 2, (K.handle, M.handle)
    Ms = drop_zeros(M)
    b = _block_columns(nev, prefix)
    lam_max = None if f_max_hz is None else (TWO_PI * f_max_hz) ** 2
    direct = _cholmod_block_lanczos(K, Ms, nev, sigma, tol, b, prefix, key, lam_max) if b > 0 else None
    if direct is not None:
        rm = _checked_modes(K, Ms, *direct[:2], max_residual, "cholmod", direct[2]["factor"], time.perf_counter(),
                            direct[2]["solve"], b) if direct[0] is not None else None
        if rm is not None:
            if Ms is not M:
                Ms.destroy()
            return rm
        b = 0          # not converged, or a residual missed: Krylov–Schur (PETSc's factorisation) below
    t_order = time.perf_counter()       # the ordering and the permuted copies count as factorisation
    perm = _fill_reducing_order(K, sigma, prefix, key)
    Kw, Mw = (K, Ms) if perm is None else (permuted(K, perm), permuted(Ms, perm))
    t_order = time.perf_counter() - t_order
    eps, solver, t_factor = _factorised_eps(Kw, Mw, nev, sigma, tol, prefix, key, ordered=perm is not None)
    t_factor += t_order
    try:
        t0 = time.perf_counter()
        comm = K.getComm().tompi4py()
        got = _block_lanczos(block_solve(eps.getST().getKSP().getPC().getFactorMatrix()),
                             lambda W: apply(Mw, W), comm, Kw.getOwnershipRange(), Kw.getSize()[0], nev,
                             sigma, tol, b, lam_max) if b > 0 else None
        rm = _checked_modes(K, Ms, got[0], _caller_rows(got[1], perm), max_residual, solver, t_factor, t0,
                            0.0, b) if got is not None else None
        if rm is not None:
            return rm
        with _progress(eps, nev, "real modes", progress):
            eps.solve()
        nconv, vals, vecs, res = _real_pairs(eps, K, Ms, nev, perm)
        if nconv >= nev and not np.all(res <= max_residual) and tol > REAL_MODE_TOL_FALLBACK:
            # SLEPc's criterion is relative to the shift-inverted value 1/(λ − σ): pairs far from
            # the target can pass it and still miss our ‖Kx − λMx‖/(‖K‖‖x‖) bound.  Continue from
            # the pairs at hand with a tighter tolerance on the same factorisation (no new one).
            eps.setTolerances(REAL_MODE_TOL_FALLBACK, 200)
            start = [_eps_vector(Kw, v, perm) for v in vecs]
            eps.setInitialSpace(start)
            for v in (*vecs, *start):
                v.destroy()
            eps.solve()
            nconv, vals, vecs, res = _real_pairs(eps, K, Ms, nev, perm)
        t_solve = time.perf_counter() - t0
    finally:
        eps.destroy()
        for A in {id(A): A for A in (Kw, Mw, Ms) if A is not K and A is not M}.values():
            A.destroy()
    _check(nconv, nev, res, max_residual, "real-mode EPS", np.sqrt(np.abs(vals)) / TWO_PI)
    order = np.argsort(vals)
    kernels.note("real_modes", f"{solver}, Krylov-Schur")
    return RealModes(np.array(vals)[order], [vecs[i] for i in order], res[order], solver,
                     {"factor": t_factor, "solve": t_solve}, "Krylov-Schur")


def _checked_modes(K: PETSc.Mat, Ms: PETSc.Mat, lam: np.ndarray, X: np.ndarray, max_residual: float,
                   solver: str, factor_s: float, t0: float, solve_s: float, b: int) -> RealModes | None:
    """Block Lanczos's pairs (λ, rank-local rows X) as :class:`RealModes` in ascending λ, where every
    relative residual (:func:`_pairs_from_rows`) is ≤ ``max_residual``; else None, the vectors
    destroyed.  The solve's seconds: ``solve_s`` and the time since ``t0``, these pairs included."""
    vals, vecs, res = _pairs_from_rows(K, Ms, lam, X)
    if len(vecs) and np.all(res <= max_residual):
        order = np.argsort(vals)
        kernels.note("real_modes", f"{solver}, block Lanczos")
        return RealModes(vals[order], [vecs[i] for i in order], res[order], solver,
                         {"factor": factor_s, "solve": solve_s + time.perf_counter() - t0},
                         f"block Lanczos, {b} columns")
    for v in vecs:
        v.destroy()
    return None


def modes_on_factor(solve: Callable[[np.ndarray], np.ndarray], K: PETSc.Mat, M: PETSc.Mat, sigma: float,
                    f_max_hz: float, nev_guess: int, *, tol: float = REAL_MODE_TOL,
                    max_residual: float = 1e-8) -> RealModes | None:
    """Every real mode up to ``f_max_hz`` and :data:`BEYOND` more, by block Lanczos on a
    factorisation at hand: ``solve``: B ↦ (K − σM)⁻¹B on rank-local column-major rows, K − σM
    indefinite or not, σ ≤ (2π f_max)²/2 (the modes below the cut then lead in |1/(λ − σ)|).  One
    factorisation then serves the modes and the static solves that share its shift (issue 23:
    the reduced basis of the 163k-DOF brake on 2 ranks factorised K twice with MUMPS, at the band
    centre and near 0).  None where the Lanczos does not converge within its budget or a pair
    misses ``max_residual`` (the caller factorises then)."""
    lam_max = (TWO_PI * f_max_hz) ** 2
    if not sigma <= 0.5 * lam_max:
        return None
    Ms = drop_zeros(M)
    try:
        t0 = time.perf_counter()
        b = block_size(nev_guess)
        got = _block_lanczos(solve, lambda W: apply(Ms, W), K.getComm().tompi4py(), K.getOwnershipRange(),
                             K.getSize()[0], nev_guess, sigma, tol, b, lam_max)
        if got is None:
            return None
        return _checked_modes(K, Ms, *got, max_residual, "shared", 0.0, t0, 0.0, b)
    finally:
        if Ms is not M:
            Ms.destroy()


def _cholmod_block_lanczos(K: PETSc.Mat, Ms: PETSc.Mat, nev: int, sigma: float, tol: float, b: int, prefix: str,
                           key: tuple[int, int], lam_max: float | None = None
                           ) -> tuple[np.ndarray | None, np.ndarray | None, dict] | None:
    """Block Lanczos (:func:`_block_lanczos`) on CHOLMOD's supernodal factorisation of K − σM,
    called directly (:mod:`fem_squeal.fe.cholmod`) with the fill-reducing order of K's node
    graph handed in (:func:`_fill_reducing_order`): no permuted copies of K and M, no PETSc dense
    matrices per block solve (:meth:`fem_squeal.fe.cholmod.Cholesky.solve`), and M applied by the
    compiled CSR block product (:func:`fem_squeal.fe.csr.block_product`; SciPy's where it cannot be
    had).  The path of one rank where no factorisation is chosen
    (``<prefix>st_pc_factor_mat_solver_type``; choosing ``cholmod`` there takes PETSc's interface to
    it, with all its options).  Returns None where it does not apply or K − σM is not positive
    definite (then recorded for these K, M: MUMPS takes over); else (λ, rows of the vectors,
    seconds), λ and rows None where the Lanczos did not converge within its budget."""
    if (K.getComm().getSize() > 1 or "aij" not in K.getType() or "aij" not in Ms.getType()
            or not cholmod.available() or PETSc.Options().hasName(f"{prefix}st_pc_factor_mat_solver_type")
            or sigma >= _NOT_DEFINITE.get(key, np.inf)):
        return None
    t0 = time.perf_counter()
    n = K.getSize()[0]
    with csr_view(K) as k_csr, csr_view(Ms) as m_csr:      # PETSc's arrays, not copies
        A = sp.csr_matrix(k_csr[::-1], shape=(n, n))
        Msp = sp.csr_matrix(m_csr[::-1], shape=(n, n))
        if sigma != 0.0:
            A = (A - sigma * Msp).tocsr()
        perm = _fill_reducing_order(K, sigma, prefix, key, (A.indptr, A.indices))
        try:
            factor = cholmod.Cholesky(A.indptr, A.indices, A.data, perm)
            kernels.note("factorisation", "cholmod")
        except cholmod.NotPositiveDefinite:
            # σ above the lowest mode, or a free body: neither is K − σ'M definite for σ' ≥ σ
            _NOT_DEFINITE[key] = min(sigma, _NOT_DEFINITE.get(key, np.inf))
            return None
        del A
        t1 = time.perf_counter()
        try:
            mass = block_product(m_csr) or Msp.__matmul__
            got = _block_lanczos(factor.solve, mass, K.getComm().tompi4py(), (0, n), n, nev, sigma, tol, b,
                                 lam_max)
        finally:
            factor.close()
    seconds = {"factor": t1 - t0, "solve": time.perf_counter() - t1}
    return (None, None, seconds) if got is None else (*got, seconds)


def _fill_reducing_order(K: PETSc.Mat, sigma: float, prefix: str, key: tuple[int, int],
                         pattern: tuple[np.ndarray, np.ndarray] | None = None) -> np.ndarray | None:
    """The fill-reducing row order of K's node graph (:func:`fem_squeal.fe.ordering.fill_reducing_order`;
    ``pattern``: the CSR pattern of K − σM where the caller has it) where CHOLMOD will factorise
    K − σM first: ``<prefix>ordering`` ``auto`` (the default: AMD, or METIS where it pays for
    itself), ``metis`` or ``amd``; None for ``solver`` and where MUMPS factorises (it orders in its
    own analysis, and in parallel)."""
    how = PETSc.Options().getString(f"{prefix}ordering", "auto")
    if how not in (*ORDERINGS, "solver"):
        raise ModelError(f"{prefix}ordering: must be one of {', '.join((*ORDERINGS, 'solver'))} (got {how!r})")
    if how == "solver" or _real_solvers(K, sigma, prefix, key)[0][0] != "cholmod":
        return None
    return fill_reducing_order(K, pattern, how)


def _caller_rows(X: np.ndarray, perm: np.ndarray | None) -> np.ndarray:
    """Rows of the permuted problem (row i = the caller's row perm[i]) in the caller's order."""
    if perm is None:
        return X
    out = np.empty_like(X)
    out[perm] = X
    return out


def _eps_vector(A: PETSc.Mat, v: PETSc.Vec, perm: np.ndarray | None) -> PETSc.Vec:
    """The caller's vector ``v`` as a vector of the (permuted) problem of matrix ``A``."""
    x = A.createVecRight()
    x.array[:] = v.array_r if perm is None else v.array_r[perm]
    return x


def _pairs_from_rows(K: PETSc.Mat, M: PETSc.Mat, lam: np.ndarray, X: np.ndarray
                     ) -> tuple[np.ndarray, list[PETSc.Vec], np.ndarray]:
    """(λ, M-normalised vectors, relative residuals ‖Kx − λMx‖ / (‖K‖∞ ‖x‖)) of the pairs given as
    rank-local rows X (columns), as :func:`_real_pairs`."""
    comm = K.getComm().tompi4py()
    MX = apply(M, X)
    scale = 1.0 / np.sqrt(comm.allreduce(np.einsum("ij,ij->j", X, MX), op=MPI.SUM))
    X, MX = X * scale, MX * scale
    R = apply(K, X) - MX * lam
    res = np.sqrt(comm.allreduce(np.einsum("ij,ij->j", R, R), op=MPI.SUM)) / \
        (_norm_inf(K) * np.sqrt(comm.allreduce(np.einsum("ij,ij->j", X, X), op=MPI.SUM)))
    vecs = []
    for j in range(X.shape[1]):
        x = K.createVecRight()
        x.array[:] = X[:, j]
        vecs.append(x)
    return np.asarray(lam, float), vecs, res


def _real_pairs(eps: SLEPc.EPS, K: PETSc.Mat, M: PETSc.Mat, nev: int, perm: np.ndarray | None = None
                ) -> tuple[int, np.ndarray, list[PETSc.Vec], np.ndarray]:
    """The first ``nev`` converged pairs of ``eps``, M-normalised, with their relative residuals
    ‖Kx − λMx‖ / (‖K‖∞ ‖x‖) (:func:`_pairs_from_rows`); ``perm``: the EPS works on K and M in that
    row order, the pairs come back in K's."""
    nconv = eps.getConverged()
    if min(nconv, nev) == 0:
        return nconv, np.zeros(0), [], np.zeros(0)
    x = eps.getOperators()[0].createVecRight()
    lam, rows = [], []
    for i in range(min(nconv, nev)):
        lam.append(eps.getEigenpair(i, x).real)
        rows.append(x.array_r.copy())
    x.destroy()
    return (nconv, *_pairs_from_rows(K, M, np.array(lam), _caller_rows(np.column_stack(rows), perm)))


def drop_zeros(A: PETSc.Mat) -> PETSc.Mat:
    """A copy of the AIJ matrix ``A`` without its stored zeros (``A`` itself if it has none or is
    not AIJ).  A vector mass matrix is assembled on the stiffness pattern, whole 3×3 blocks of which
    two thirds are zero: without them each product with M in the Krylov iteration (two per step:
    the operator and the M-inner product) reads a third of the memory."""
    if "aij" not in A.getType():
        return A
    with csr_view(A) as (ai, aj, av):       # serial: PETSc's arrays (the check alone copies nothing)
        keep = av != 0.0
        if A.getComm().tompi4py().allreduce(bool(keep.all()), op=MPI.LAND):
            return A
        counts = np.concatenate([[0], np.cumsum(keep)])
        B = PETSc.Mat().createAIJ(A.getSizes(), csr=(counts[ai].astype(PETSc.IntType), aj[keep], av[keep]),
                                  comm=A.getComm())
    known, symmetric = A.isSymmetricKnown()
    if known:
        B.setOption(PETSc.Mat.Option.SYMMETRIC, symmetric)
    return B


def _real_solvers(K: PETSc.Mat, shift: float, prefix: str, key: tuple[int, int]) -> tuple[list[str], bool]:
    """The factorisations to try for K − σM, in order, and whether the user chose one
    (``<prefix>st_pc_factor_mat_solver_type``): else CHOLMOD on one rank (MUMPS LDLᵀ after it, for
    K − σM not positive definite) and MUMPS on more ranks."""
    chosen = PETSc.Options().getString(f"{prefix}st_pc_factor_mat_solver_type", "")
    if chosen:
        return [chosen], True
    if (K.getComm().getSize() == 1 and PETSc.Sys.hasExternalPackage("suitesparse")
            and shift < _NOT_DEFINITE.get(key, np.inf)):
        return ["cholmod", "mumps"], False
    return ["mumps"], False


def _factorised_eps(K: PETSc.Mat, M: PETSc.Mat, nev: int, shift: float, tol: float, prefix: str,
                    key: tuple[int, int], ordered: bool = False) -> tuple[SLEPc.EPS, str, float]:
    """The real-mode EPS with K − σM factorised (``eps.setUp``) by the first of
    :func:`_real_solvers` that succeeds.  ``ordered``: K and M are already in a fill-reducing order
    (:func:`fem_squeal.fe.ordering.fill_reducing_order`), which CHOLMOD then keeps (natural ordering,
    one method) instead of running its own analysis.  Returns the EPS, the solver's name and the
    factorisation's wall time.  ``key``: the handles of the caller's K and M."""
    db = PETSc.Options()
    name = f"{prefix}st_pc_factor_mat_solver_type"
    solvers, chosen = _real_solvers(K, shift, prefix, key)
    t0 = time.perf_counter()       # a failed CHOLMOD attempt counts in the factorisation time
    for k, solver in enumerate(solvers):
        eps = _shift_invert_eps(K, M, SLEPc.EPS.ProblemType.GHEP, nev, shift, tol, prefix)
        # defaults for this solve only, not left in the options database
        temporary = {} if chosen else {name: solver}
        if ordered and solver == "cholmod":
            temporary.update({f"{prefix}st_pc_factor_mat_ordering_type": "natural",
                              f"{prefix}st_mat_cholmod_nmethods": "1"})
        temporary = {o: v for o, v in temporary.items() if not db.hasName(o)}
        for o, v in temporary.items():
            db[o] = v
        try:
            eps.setFromOptions()
            with serial_openmp():      # CHOLMOD's OpenMP loops: see fem_squeal.util.blas
                eps.setUp()    # the factorisation of K − σM (it reads the factor's options)
        except PETSc.Error:
            eps.destroy()
            if k + 1 == len(solvers):
                raise
            # CHOLMOD: K − σM not positive definite (σ above the lowest mode, free bodies); then
            # neither is it for any larger σ: later solves on the same K, M go to MUMPS directly
            _NOT_DEFINITE[key] = min(shift, _NOT_DEFINITE.get(key, np.inf))
            continue
        finally:
            for o in temporary:
                db.delValue(o)
        return eps, solver, time.perf_counter() - t0
    raise AssertionError("unreachable")


@contextmanager
def _progress(solver, total: int, label: str, enabled: bool):
    """A progress bar of converged eigenpairs on rank 0, fed by the SLEPc monitor of ``solver``
    (set on every rank: monitors are logically collective)."""
    if not enabled:
        yield
        return

    with ProgressBar(total, label, unit=" pairs", enabled=solver.getComm().getRank() == 0) as bar:
        solver.setMonitor(lambda _s, its, nconv, *_: bar.update(min(nconv, total), extra=f"it {its}"))
        try:
            yield
        finally:
            solver.cancelMonitor()


def _check(nconv: int, nev: int, res: np.ndarray, max_residual: float, what: str, freqs) -> None:
    if nconv < nev:
        raise EigenSolveError(
            f"{what}: {nconv} of {nev} requested eigenpairs converged; residuals of the converged: "
            + ", ".join(f"{f:.1f} Hz: {r:.1e}" for f, r in zip(freqs, res)))
    bad = np.flatnonzero(~(res <= max_residual))
    if bad.size:
        raise EigenSolveError(
            f"{what}: residual above {max_residual:.0e} for " +
            ", ".join(f"{freqs[i]:.1f} Hz: {res[i]:.1e}" for i in bad))


def solve_complex_modes(K: PETSc.Mat, M: PETSc.Mat, C: PETSc.Mat | None, nev: int, target_hz: float,
                        *, method: str = "auto", tol: float = 1e-10, max_residual: float = 1e-8,
                        band_hz: tuple[float, float] | None = None, options: dict | None = None,
                        prefix: str = "cea_", progress: bool = False) -> ComplexModes:
    """Complex modes of (λ²M + λC + K)x = 0 with Im λ > 0, ``nev`` of them near ``target_hz``.

    At least ``nev`` pairs must converge; those with Im λ/2π inside ``band_hz`` (all when None)
    are residual-checked and returned.  Rigid-body modes (λ ≈ 0) are kept out by a band with
    a positive lower end: their residual relative to ‖K‖ is not meaningful.

    ``method``: ``"linear"`` (C must be None: non-symmetric EPS on K x = θ M x, θ = −λ²),
    ``"pep"`` (TOAR on the quadratic), or ``"auto"`` (linear when C is None, else PEP).
    Raises :class:`EigenSolveError` if fewer than ``nev`` pairs converge or a residual exceeds
    ``max_residual``.
    """
    if nev < 1:
        raise ModelError(f"n_modes: must be >= 1 (got {nev})")
    if method == "auto":
        method = "linear" if C is None else "pep"
    if method == "linear" and C is not None:
        raise ModelError("method: 'linear' needs an undamped model (C = 0); use 'pep'")
    if method not in ("linear", "pep"):
        raise ModelError(f"method: must be 'auto', 'linear' or 'pep' (got {method!r})")
    set_options(prefix, options, DIRECT_SOLVER_OPTIONS if method == "linear" else
                {**DIRECT_SOLVER_OPTIONS, **PEP_OPTIONS})
    comm = K.getComm()
    lams, xrs, xis = [], [], []
    if method == "linear":
        solver = _shift_invert_eps(K, M, SLEPc.EPS.ProblemType.GNHEP, nev, (TWO_PI * target_hz) ** 2,
                                   tol, prefix)
    else:
        solver = SLEPc.PEP().create(comm)
        solver.setOptionsPrefix(prefix)
        solver.setOperators([K, C if C is not None else _zero_like(M), M])
        solver.setType(SLEPc.PEP.Type.TOAR)
        n_wanted = 2 * nev  # conjugate pairs are both counted
        solver.setDimensions(n_wanted, max(2 * n_wanted, n_wanted + 16))
        solver.setTolerances(tol, 200)
        solver.getST().setType(SLEPc.ST.Type.SINVERT)
        solver.setTarget(TWO_PI * max(target_hz, 1.0))
        solver.setWhichEigenpairs(SLEPc.PEP.Which.TARGET_MAGNITUDE)
        solver.setConvergenceTest(SLEPc.PEP.Conv.REL)
    try:
        solver.setFromOptions()
        t0 = time.perf_counter()
        solver.setUp()          # the factorisation of the shifted operator
        t1 = time.perf_counter()
        got = _cea_block(solver, K, M, nev, (TWO_PI * target_hz) ** 2, tol, prefix, progress) \
            if method == "linear" else None
        if got is not None:
            for val, x in zip(got[0], got[1].T):
                xr, xi = K.createVecRight(), K.createVecRight()
                xr.array[:], xi.array[:] = x.real, x.imag
                lams.append(1j * np.sqrt(val))
                xrs.append(xr)
                xis.append(xi)
            nconv = 0
            algorithm = f"block Arnoldi, {_block_columns(nev, prefix)} columns"
        else:
            algorithm = "Krylov-Schur" if method == "linear" else "TOAR"
            with _progress(solver, nev if method == "linear" else 2 * nev, "CEA", progress):
                solver.solve()
            nconv = solver.getConverged()
        seconds = {"factor": t1 - t0, "solve": time.perf_counter() - t1}
        for i in range(nconv):
            xr, xi = K.createVecRight(), K.createVecRight()
            val = complex(solver.getEigenpair(i, xr, xi))
            lam = 1j * np.sqrt(val) if method == "linear" else val
            if method == "pep" and lam.imag < 0:
                xr.destroy()
                xi.destroy()
                continue
            if method == "pep" and lam.imag == 0:
                xi.set(0.0)
            lams.append(lam)
            xrs.append(xr)
            xis.append(xi)
    finally:
        solver.destroy()
    lams = np.array(lams, dtype=complex)
    n_found = len(lams)
    if band_hz is not None:
        f = lams.imag / TWO_PI
        keep = np.flatnonzero((f >= band_hz[0]) & (f <= band_hz[1]))
        for j in sorted(set(range(n_found)) - set(keep.tolist())):
            xrs[j].destroy()
            xis[j].destroy()
        lams, xrs, xis = lams[keep], [xrs[i] for i in keep], [xis[i] for i in keep]
    res = np.empty(len(lams))
    for j, (lam, xr, xi) in enumerate(zip(lams, xrs, xis)):
        _m_normalise(M, xr, xi)
        res[j] = quadratic_residual(K, C, M, lam, xr, xi)
    order = _sort_key(lams)
    lams, res = lams[order], res[order]
    xrs, xis = [xrs[i] for i in order], [xis[i] for i in order]
    what = f"complex-mode {'EPS' if method == 'linear' else 'PEP'} (prefix {prefix!r})"
    _check(n_found, nev, res, max_residual, what, lams.imag / TWO_PI)
    kernels.note("complex_modes", f"{method}, {algorithm.split(',')[0]}")
    return ComplexModes(lams, xrs, xis, res, method, seconds, algorithm)


# options that configure SLEPc's own iteration: given, the CEA runs it (they would not apply to the block path)
SLEPC_SOLVER_OPTIONS = ("type", "ncv", "mpd", "max_it", "krylovschur_restart", "krylovschur_locking")


def _cea_block(eps: SLEPc.EPS, K: PETSc.Mat, M: PETSc.Mat, nev: int, sigma: float, tol: float, prefix: str,
               progress: bool) -> tuple[np.ndarray, np.ndarray] | None:
    """The linear CEA's pairs by block Arnoldi (:func:`_block_arnoldi`) on the factorisation the
    set-up EPS holds, where it is a direct one (``preonly`` + LU/Cholesky), ``<prefix>block_size``
    is not 0 and no option of SLEPc's own iteration is given (:data:`SLEPC_SOLVER_OPTIONS`); None
    otherwise or where it does not converge (then the EPS solves as before).
    Measured on the brake corner (163k DOFs, 1 rank, 60 modes, tol 1e-10): see docs/validation.md."""
    b = _block_columns(nev, prefix)
    ksp = eps.getST().getKSP()
    db = PETSc.Options()
    if (b <= 0 or ksp.getType() != "preonly" or ksp.getPC().getType() not in ("lu", "cholesky")
            or any(db.hasName(f"{prefix}eps_{o}") for o in SLEPC_SOLVER_OPTIONS)):
        return None
    comm = K.getComm().tompi4py()
    with ProgressBar(nev, "CEA", unit=" pairs", enabled=progress and comm.rank == 0) as bar:
        return _block_arnoldi(block_solve(ksp.getPC().getFactorMatrix()), lambda W: apply(M, W), comm,
                              K.getOwnershipRange(), K.getSize()[0], nev, sigma, tol, b,
                              lambda done, k: bar.update(min(done, nev), extra=f"{k} vectors"))


def _zero_like(M: PETSc.Mat) -> PETSc.Mat:
    Z = M.duplicate()
    Z.zeroEntries()
    return Z


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
