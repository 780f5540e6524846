"""Block Krylov methods on a factorisation's block solves, on rank-local rows (NumPy, SciPy's BLAS and
mpi4py only; the ``<prefix>block_size`` option is read by :func:`fem_squeal.fe.eigen.options.block_columns`):
block Lanczos for K φ = ω² M φ with a threshold, block Arnoldi for the undamped CEA, and their memory
budgets."""
from __future__ import annotations

import os
from collections.abc import Callable

import numpy as np
from mpi4py import MPI
from scipy.linalg import blas

from fem_squeal.fe.row_blocks import gram, m_cholesky_qr, project_out, subtract_combination

# Block Lanczos (issue 23): the factor's multiple-right-hand-side solve (MatMatSolve) costs a
# fraction of single solves per column (clamped disc, 85k DOFs: CHOLMOD 35 → 7 ms, MUMPS on 2 ranks
# 43 → 11 ms with 16 columns), which more than pays for the larger Krylov space a block method
# needs.  ``<prefix>block_size`` 0 turns it off (SLEPc's Krylov–Schur on the same factorisation).
#: Bytes per rank the block methods' vectors may take at most (:func:`_vector_memory`: within it, half the
#: memory available once the factor is held).  4e9 until 2026-11-29: at 711k DOFs on one rank the coupling's
#: block Lanczos (125 modes ≤ 20 kHz) needs 400 vectors, 4.55 GB, and fell back to Krylov–Schur (two
#: solves, 410 s against 110 s; docs/validation.md, "The brake at 711k DOFs on one rank").
BLOCK_MEMORY = 16.0e9
BEYOND = 2             # converged pairs beyond a threshold λ_max that show none below it is missing


#: Columns per block solve where the factor is read back from files (MUMPS out of core, ICNTL(22) = 1): such
#: a solve reads the whole factor whatever its width (the LU of K − σM at 1.32M DOFs, one rank: 1, 12, 24, 32
#: and 48 columns in 9.4, 12.2, 12.9, 15.6 and 15.9 s), so fewer, wider blocks win where their larger space
#: fits.  The brake's 91 pairs ≤ 16 kHz (94 asked) at 348k DOFs: 24 solves of 12 columns (288 vectors), 17 of
#: 24 (408), 15 of 32 (480), 13 of 48 (624); the 1.32M brake's CEA 602.5 s against 698.4 (docs/validation.md,
#: "The 1.32M brake by default").
OUT_OF_CORE_BLOCK = 24
#: The vectors per pair asked the :data:`OUT_OF_CORE_BLOCK` columns need (408 for 91 pairs, 4.5), with a margin:
#: the room the memory rule must leave for them, else the default width (a space that runs out sends the solve
#: to Krylov–Schur's single-column solves, each a read of the whole factor).
OUT_OF_CORE_VECTORS_PER_PAIR = 5.0


def block_size(nev: int) -> int:
    """Columns per block solve: ~nev/8, between 8 and 16.  Measured (seconds of the eigensolve after
    the factorisation): clamped disc, 85k DOFs, 20 modes, CHOLMOD: Krylov–Schur 2.8, blocks of 5, 8,
    12, 16: 2.8, 2.5, 3.0, 3.2; brake, 163k DOFs, 2 ranks, MUMPS, 90 modes ≤ 16 kHz (modes_below,
    with its factorisation and the inertia count): Krylov–Schur 29.4, blocks of 8, 12, 23, 32: 16.7,
    16.5, 19.4, 20.5.  Larger blocks cost less per column but need more columns."""
    return int(min(max(8, -(-nev // 8)), 16))


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
        step = m_cholesky_qr(comm, W, MW, check=True)
        if step is None:
            return None
        W, MW, L = step
        R = L.T @ R
    return W, MW, R


def _grown(A: np.ndarray, shape: tuple[int, int], order: str) -> np.ndarray:
    """A copied into the leading block of zeros of ``shape``."""
    out = np.zeros(shape, order=order)
    out[:A.shape[0], :A.shape[1]] = A
    return out


def _block_lanczos(solve: Callable[[np.ndarray], np.ndarray], mass: Callable[[np.ndarray], np.ndarray],
                   comm, rows: tuple[int, int], n: int, nev: int, sigma: float, tol: float, b: int,
                   lam_max: float | None = None, radius: float | None = None,
                   progress: Callable[[int, int, int], None] | None = None
                   ) -> tuple[np.ndarray, np.ndarray] | None:
    """The ``nev`` eigenpairs of K x = λ M x nearest σ by block Lanczos on (K − σM)⁻¹M in the M-inner
    product, with full reorthogonalisation.  ``solve``: B ↦ (K − σM)⁻¹B and ``mass``: W ↦ MW, both
    on the rank-local rows ``rows`` (r0, r1) of column-major blocks; ``n``: the global size.
    Returns (λ, local rows of the M-orthonormal vectors) or None (not converged within the vector
    budget: max(6 nev, nev + 16 b, 256) vectors, at most :func:`_vector_memory` bytes per rank; a
    cluster of nearly equal eigenvalues, such as the clamped ring's 12 lowest within 0.1 %, needs ~150).
    MV is kept beside V while that room holds both, then dropped (one more mass product per block).

    With V = [Q₀ … Q_j] M-orthonormal and W = (K − σM)⁻¹ M Q_j, T = Vᵀ M (K − σM)⁻¹ M V is
    symmetric; its eigenpairs (θ, y) give λ = σ + 1/θ, x = V y, and the residual of the shift-inverted
    operator ‖(K − σM)⁻¹Mx − θx‖_M = ‖R_{j+1} y_j‖ (the last block of y and the next block's
    triangular factor).  A pair counts as converged where that is ≤ tol·|θ|, SLEPc's criterion.
    Orthogonalisation: W against the last two blocks (the three-term recurrence, where W's large
    components lie), then once against all of V (what round-off leaves along the older blocks), then
    the Cholesky QR of :func:`_m_orthonormal`.

    ``lam_max``: every pair with λ ≤ ``lam_max`` and the next :data:`BEYOND` in |θ| order instead of
    ``nev`` (σ below the middle of [0, ``lam_max``]: those are the leading |θ|); ``nev`` is then a
    guess that sizes the block and the first budget (at most what :func:`_vector_memory` holds), which
    grows (×1.5, the vectors copied: old and new held for the copy) up to that.  This is how
    :func:`fem_squeal.fe.projection.modes_below` asks for the modes below a cut without counting them
    first (an inertia count cost one more factorisation).  ``radius``: likewise every pair with
    |λ − σ| ≤ ``radius`` (|θ| ≥ 1/radius: they lead in |θ| whatever σ) and the next :data:`BEYOND`:
    one slice of spectrum slicing
    (:mod:`fem_squeal.fe.eigen.slicing`).  ``progress``: called with (converged wanted pairs, vectors,
    wanted pairs, block columns) after each block."""
    r0, r1 = rows
    dim = _krylov_dim(nev, b, n)
    open_count = lam_max is not None or radius is not None
    room = vector_room(comm, r1 - r0)
    if open_count:
        # with a threshold the budget starts at what the guess needs (allocating the whole room at once
        # cost 1.4 s of zeroed pages for the 50k-DOF brake's 89 modes) and grows up to the room; the
        # guess beyond the room no longer sends the solve to Krylov–Schur (711k DOFs on one rank:
        # 6·91 vectors were 6.2 GB against 4 GB, and 400 sufficed)
        limit = min(n - b, room) // b * b
        dim = min(dim, limit)
        if dim < 2 * b:
            return None
    elif dim < nev or dim > room:
        return None
    else:
        limit = dim
    V = np.zeros((r1 - r0, dim), order="F")
    # M V, kept while the room holds its filled columns too: the full reorthogonalisation's (MV)ᵀW then
    # needs no mass product; without it, Vᵀ(MW), one more product per block (711k DOFs on one rank, the
    # coupling's 400 vectors: 4.55 GB with MV, more than the room the run's products left, and
    # Krylov–Schur took 270 s)
    MV = np.zeros(V.shape, order="F")    # calloc: pages are touched only as columns are filled
    MR = np.zeros((r1 - r0, 2 * b), order="F")     # M times the last two blocks (the recurrence)
    start = _m_orthonormal(comm, mass, _start_block(np.arange(r0, r1), b))
    if start is None:
        return None
    V[:, :b], MV[:, :b], MR[:, b:] = start[0], start[1], start[1]
    T = np.zeros((dim, dim))
    k = b
    while True:
        W = np.asfortranarray(solve(MR[:, b:]))
        lo = max(0, k - 2 * b)
        C = np.zeros((k, b))
        C[lo:], W = project_out(comm, V[:, lo:k], MR[:, 2 * b - (k - lo):], W)   # the last two blocks
        if MV is not None:                                             # full reorthogonalisation
            C2, W = project_out(comm, V[:, :k], MV[:, :k], W)
        else:
            C2 = gram(comm, V[:, :k], np.asfortranarray(mass(W)))
            W = subtract_combination(V[:, :k], C2, W)
        C += C2
        T[:k, k - b:k] = C
        T[k - b:k, :k] = C.T
        Tk = 0.5 * (T[:k, :k] + T[:k, :k].T)
        theta, Y = np.linalg.eigh(Tk)
        want = np.argsort(-np.abs(theta), kind="stable")
        count = nev if not open_count else BEYOND + int(
            np.sum(sigma + 1.0 / theta <= lam_max) if radius is None else np.sum(np.abs(theta) * radius >= 1.0))
        want = want[:count]
        nxt = _m_orthonormal(comm, mass, W)
        # an invariant subspace (nothing new in W): the Ritz pairs are exact
        res = np.zeros(want.size) if nxt is None else np.linalg.norm(nxt[2] @ Y[k - b:k, want], axis=0)
        done = res <= tol * np.abs(theta[want])
        if progress is not None:
            progress(int(np.count_nonzero(done)), k, count, b)
        if k >= count and np.all(done):
            return sigma + 1.0 / theta[want], blas.dgemm(1.0, V[:, :k], Y[:, want])
        if MV is not None and 2 * (k + b) > room:
            MV = None                                      # the room holds V only from here on
        if nxt is not None and k + b > dim and dim < limit:
            dim = min(limit, (3 * dim // 2) // b * b)
            V, MV = (None if A is None else _grown(A, (A.shape[0], dim), "F") for A in (V, MV))
            T = _grown(T, (dim, dim), "C")
        if nxt is None or k + b > dim:
            return None                       # fewer than nev pairs exist, or the budget is spent
        V[:, k:k + b] = nxt[0]
        MR[:, :b] = MR[:, b:]
        MR[:, b:] = nxt[1]
        if MV is not None:
            MV[:, k:k + b] = nxt[1]
        T[k:k + b, k - b:k] = nxt[2]
        T[k - b:k, k:k + b] = nxt[2].T
        k += b


#: Share of the memory still available when the factorisation is done (MemAvailable, over the ranks on
#: the machine) the block Lanczos and Arnoldi vectors may take; beyond it, Krylov–Schur (2·nev vectors).
VECTOR_MEMORY_SHARE = 0.5
#: The fewest vectors per wanted pair block Arnoldi starts with where the memory rule leaves less than its
#: budget (max(6 nev, nev + 16 b, 256)); below, Krylov–Schur (2·nev vectors).  The brake corner's 120 pairs
#: converged with 3.25·nev (390 vectors at 348k DOFs).
ARNOLDI_MIN_SPACE = 3


def available_memory() -> float:
    """Bytes of this machine's memory available now (Linux ``MemAvailable``: free pages plus the page
    cache that can be dropped); 5 % of the physical memory where /proc/meminfo does not say."""
    try:
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return float(line.split()[1]) * 1024.0
    except OSError:
        pass
    return 0.05 * os.sysconf("SC_PHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")


def _vector_memory(comm) -> float:
    """Bytes per rank the block Lanczos and Arnoldi vectors may take: :data:`BLOCK_MEMORY`, and at most
    :data:`VECTOR_MEMORY_SHARE` of the memory available now (after the factorisation, which is
    held) over the ranks on this machine, which allocate at once.  The CEA's memory model
    (``app/resources.py``) is a prediction made before the run; this is what is free when the
    vectors are allocated, so the block path never takes memory the factor needs.  Brake corner,
    0–16 kHz, 120 modes: 348k DOFs on 2 ranks need 2 × 1.0 GB for the 720-vector budget with about
    10 GB free (block Arnoldi runs); 1.32M on one 24 GiB machine would need 7.6 GB (Krylov–Schur).
    Real modes ≤ 20 kHz (the coupling's), 711k DOFs on one rank: block Lanczos's 400 vectors take 4.55 GB
    with about 15 GB free."""
    node = comm.Split_type(MPI.COMM_TYPE_SHARED)
    try:
        ranks = node.Get_size()
    finally:
        node.Free()
    return min(BLOCK_MEMORY, VECTOR_MEMORY_SHARE * available_memory() / ranks)


def vector_room(comm, rows: int) -> int:
    """The vectors of ``rows`` local rows (8 bytes each) the memory rule allows (:func:`_vector_memory`), the
    smallest over the ranks: all must agree."""
    return comm.allreduce(int(_vector_memory(comm) // (8 * max(rows, 1))), op=MPI.MIN)


def _converged(theta: np.ndarray, Y: np.ndarray, order: np.ndarray, count: int, nxt, tol: float, b: int
               ) -> tuple[np.ndarray, np.ndarray]:
    """Block Arnoldi's wanted Ritz pairs, the first ``count`` of ``order`` (|θ| descending) with a
    complex-conjugate pair kept whole (``count`` + 1), and which of them have converged: ‖R y_j‖ ≤
    tol·|θ| (R: the next block's triangular factor in ``nxt``, y_j the last ``b`` rows of y; None:
    an invariant subspace, every pair exact)."""
    k = len(theta)
    want = list(order[:count])
    last = theta[want[-1]]
    if last.imag != 0.0:               # keep a conjugate pair whole
        mate = int(np.argmin(np.abs(theta[order[count:]] - np.conj(last)))) + count
        if abs(theta[order[mate]] - np.conj(last)) <= 1e-12 * abs(last) and \
                not any(abs(theta[i] - np.conj(last)) <= 1e-12 * abs(last) for i in want[:-1]):
            want.append(order[mate])
    want = np.array(want)
    res = np.zeros(k) if nxt is None else np.linalg.norm(nxt[2] @ Y[k - b:k], axis=0)
    return want, (res <= tol * np.abs(theta))[want]


def _block_arnoldi(solve: Callable[[np.ndarray], np.ndarray], mass: Callable[[np.ndarray], np.ndarray],
                   comm, rows: tuple[int, int], n: int, nev: int, sigma: float, tol: float, b: int,
                   progress: Callable[[int, int, int], None] | None = None, radius: float | None = None
                   ) -> tuple[np.ndarray, np.ndarray] | None:
    """The ``nev`` eigenpairs of the non-symmetric pencil K x = ν M x nearest σ by block Arnoldi on
    (K − σM)⁻¹M, with full reorthogonalisation (classical Gram–Schmidt twice) and no restart: the
    same factor's block solves as :func:`_block_lanczos`, for the linear CEA.  ``solve``: B ↦
    (K − σM)⁻¹B, ``mass``: W ↦ MW on rank-local rows ``rows`` of column-major blocks.  Returns
    (ν, local rows of the unit Ritz vectors, complex) or None (not converged within max(6 nev,
    nev + 16 b, 256) vectors, or within the room :func:`_vector_memory` leaves where that is smaller but
    at least :data:`ARNOLDI_MIN_SPACE`·nev).

    With V = [Q₀ … Q_j] orthonormal, (K − σM)⁻¹M V_j = V_{j+1} H (block upper Hessenberg); the
    eigenpairs (θ, y) of H_j give ν = σ + 1/θ, x = V y and ‖(K − σM)⁻¹Mx − θx‖ = ‖R_{j+1} y_j‖ (R the
    next block's triangular factor, y_j the last block of y), converged where ≤ tol·|θ| (SLEPc's
    relative criterion).  The start block is M times a fixed pseudo-random block, so that it has no
    component in null(M) (the Dirichlet rows), where no eigenvector lies.  It returns the ``nev``
    pairs of largest |θ| (nearest σ), once all of them have converged, largest first; where the cut
    would split a complex-conjugate pair, the pair is kept whole (nev + 1).  Not the other pairs that
    happen to have converged too (SLEPc returns those): which they are depends on round-off, and the
    set returned must not (a scene run on two meshes numbered differently, or on 1 and 2 ranks, must
    give the same modes).  The vectors are at most :func:`_vector_memory` bytes per rank.
    ``radius``: fewer than ``nev`` where every Ritz value with |ν − σ| ≤ ``radius`` (|θ| ≥ 1/radius, so
    they lead in |θ|) and the next :data:`BEYOND` have converged first: the pairs of a band around σ
    without the rest of ``nev`` (the brake's 0–16 kHz at 348k DOFs: 91 pairs of the 120 asked).
    ``progress``: called with (converged wanted pairs, vectors, wanted pairs, block columns) after each step."""
    r0, r1 = rows
    # the space: its budget, or the room the memory rule leaves where that is smaller and still holds
    # ARNOLDI_MIN_SPACE·nev (the pages are touched only as vectors are added: the brake at 348k used 390
    # of the 720 for 120 pairs, and at 711k on one rank the 720 (4.1 GB) were refused, 342 s of Krylov–Schur)
    room = vector_room(comm, r1 - r0) // b * b
    budget = _krylov_dim(nev, b, n)
    dim = min(budget, room)
    if dim < nev + 1 or dim < min(budget, ARNOLDI_MIN_SPACE * nev):
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
        if k >= (nev if radius is None else min(nev, BEYOND)) + 1:
            theta, Y = np.linalg.eig(H[:k, :k])
            order = np.argsort(-np.abs(theta), kind="stable")
            # the nev of largest |θ| or, with a radius, those in its disc and BEYOND more where that is fewer
            # (and fewer than the space holds: else the pairs beyond the disc cannot show yet)
            count = nev if radius is None else min(nev, BEYOND + int(np.sum(np.abs(theta) * radius >= 1.0)))
            got = _converged(theta, Y, order, count, nxt, tol, b) if count < k else None
            if got is not None:
                want, done = got
                if progress is not None:
                    progress(int(done.sum()), k, want.size, b)
                if np.all(done):                  # x = V y in real products (V @ y would copy V to complex)
                    X = np.empty((r1 - r0, want.size), dtype=complex)
                    X.real = blas.dgemm(1.0, V[:, :k], np.asfortranarray(Y[:, want].real))
                    X.imag = blas.dgemm(1.0, V[:, :k], np.asfortranarray(Y[:, want].imag))
                    return sigma + 1.0 / theta[want], X
        if nxt is None or k + b > dim:
            return None
        V[:, k:k + b] = nxt[0]
        H[k:k + b, k - b:k] = nxt[2]
        k += b
