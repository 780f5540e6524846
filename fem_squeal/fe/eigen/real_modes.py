"""Real modes K φ = ω² M φ: block Lanczos on CHOLMOD (one rank) or on PETSc's factorisation (MUMPS on N
ranks), SLEPc's Krylov-Schur where it does not answer; the modes on a shared band-centre
factorisation."""
from __future__ import annotations

import time
from collections.abc import Callable

import numpy as np
import scipy.sparse as sp
from mpi4py import MPI
from petsc4py import PETSc
from slepc4py import SLEPc

from fem_squeal.fe import cholmod, kernels
from fem_squeal.fe.csr import block_product, csr_view, local_rows
from fem_squeal.fe.dense import apply, block_solve, product_of
from fem_squeal.fe.eigen.block_krylov import _block_lanczos, block_size
from fem_squeal.fe.eigen.options import (
    REAL_MODE_EPS,
    REAL_MODE_FACTOR,
    REAL_MODE_TOL,
    REAL_MODE_TOL_FALLBACK,
    _progress,
    _shift_invert_eps,
    block_columns,
    block_progress,
    drop_zeros,
    eps_defaults,
)
from fem_squeal.fe.eigen.results import TWO_PI, RealModes, _check, _norm_inf
from fem_squeal.fe.factorisation import scoped_options, symmetric_packages, user_option
from fem_squeal.fe.ordering import ORDERINGS, fill_reducing_order, node_block_size, permuted
from fem_squeal.fe.substructured import SubstructuredCholesky, Unavailable
from fem_squeal.util.blas import serial_openmp
from fem_squeal.util.errors import ModelError


def solve_real_modes(K: PETSc.Mat, M: PETSc.Mat, nev: int, target_hz: float, *, tol: float = REAL_MODE_TOL,
                     max_residual: float = 1e-8, options: dict | None = None,
                     prefix: str = "real_", progress: bool = False, f_max_hz: float | None = None,
                     positive_definite: bool | None = None) -> RealModes:
    """Real modes nearest ``target_hz``: K φ = ω² M φ, shift-and-invert at σ = ω_t², by block Lanczos
    on the factor's block solves (:func:`_block_lanczos`; ``<prefix>block_size``, 0: off), else, or
    where it does not converge within its vector budget or misses ``max_residual``, by SLEPc's
    Krylov–Schur on the same factorisation.  On one rank, unless a factorisation is named
    (``<prefix>st_pc_factor_mat_solver_type``), CHOLMOD is called directly
    (:func:`_cholmod_block_lanczos`) with the fill-reducing order of the node graph handed in
    (:mod:`fem_squeal.fe.ordering`; ``<prefix>ordering solver`` leaves the ordering to CHOLMOD);
    PETSc's CHOLMOD works on K and M permuted to that order; the vectors come back in the caller's
    order.  On more than one rank the same block Lanczos runs on the substructured CHOLMOD
    factorisation (:mod:`fem_squeal.fe.substructured`; ``<prefix>substructure 0``: MUMPS instead).
    ``progress``: draw converged/requested pairs on rank 0's stderr (block Lanczos and Krylov–Schur).
    ``f_max_hz``: every mode up to it and :data:`BEYOND` more instead of ``nev`` (then a
    guess: the block size follows it) where block Lanczos answers; Krylov–Schur, where it takes
    over, returns ``nev``.  ``positive_definite``: False where K − σM is known not to be (an earlier
    solve of these K, M at this or a lower σ came back from MUMPS: ``RealModes.solver``), so that
    CHOLMOD's LLᵀ is not tried again; None: not known.  The user's PETSc options (``options``, the
    command line) apply for this solve only (:func:`fem_squeal.fe.factorisation.scoped_options`).
    A negative ``target_hz`` shifts to σ = −(2π target)²: K − σM = K + |σ|M is positive definite
    wherever K is semi-definite (free bodies), so CHOLMOD factorises it and every 1/(λ − σ) of the
    modes from 0 up is positive (a small positive σ makes it indefinite there)."""
    if nev < 1:
        raise ModelError(f"n_modes: must be >= 1 (got {nev})")
    for A in (K, M):
        A.setOption(PETSc.Mat.Option.SYMMETRIC, True)
    with scoped_options(eps_defaults(prefix, REAL_MODE_FACTOR, REAL_MODE_EPS), options):
        lam_max = None if f_max_hz is None else (TWO_PI * f_max_hz) ** 2
        sigma = np.sign(target_hz) * (TWO_PI * target_hz) ** 2
        return _solve_real_modes(K, M, nev, sigma, tol, max_residual, prefix, progress, lam_max,
                                 positive_definite is not False)


def _solve_real_modes(K: PETSc.Mat, M: PETSc.Mat, nev: int, sigma: float, tol: float, max_residual: float,
                      prefix: str, progress: bool, lam_max: float | None, definite: bool) -> RealModes:
    """:func:`solve_real_modes` with the user's options in PETSc's database; ``definite``: CHOLMOD's
    LLᵀ may be tried (K − σM not known to be indefinite)."""
    Ms = drop_zeros(M)
    b = block_columns(nev, prefix)
    lanczos = _cholmod_block_lanczos if K.getComm().getSize() == 1 else _substructured_block_lanczos
    comm = K.getComm().tompi4py()
    try:
        with block_progress("real modes", progress and b > 0, comm, nev) as step:
            direct = lanczos(K, Ms, nev, sigma, tol, b, prefix, definite, lam_max, step) if b > 0 else None
    except cholmod.NotPositiveDefinite:
        # σ above the lowest mode, or a free body: neither is K − σ'M definite for σ' ≥ σ: MUMPS below
        direct, definite = None, False
    if direct is not None:
        rm = _checked_modes(K, Ms, *direct[:2], max_residual, direct[2].pop("solver"), direct[2]["factor"],
                            time.perf_counter(), direct[2]["solve"], b) if direct[0] is not None else None
        if rm is not None:
            if Ms is not M:
                Ms.destroy()
            return rm
        b = 0          # not converged, or a residual missed: Krylov–Schur (PETSc's factorisation) below
    t_order = time.perf_counter()       # the ordering and the permuted copies count as factorisation
    perm = _fill_reducing_order(K, prefix, definite)
    Kw, Mw = (K, Ms) if perm is None else (permuted(K, perm), permuted(Ms, perm))
    t_order = time.perf_counter() - t_order
    eps, solver, t_factor = _factorised_eps(Kw, Mw, nev, sigma, tol, prefix, definite, ordered=perm is not None)
    t_factor += t_order
    try:
        t0 = time.perf_counter()
        with block_progress("real modes", progress and b > 0, comm, nev, t_factor) as step:
            got = _block_lanczos(block_solve(eps.getST().getKSP().getPC().getFactorMatrix()),
                                 product_of(Mw), comm, Kw.getOwnershipRange(), Kw.getSize()[0], nev,
                                 sigma, tol, b, lam_max, progress=step) if b > 0 else None
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
        got = _block_lanczos(solve, product_of(Ms), K.getComm().tompi4py(), K.getOwnershipRange(),
                             K.getSize()[0], nev_guess, sigma, tol, b, lam_max)
        if got is None:
            return None
        return _checked_modes(K, Ms, *got, max_residual, "shared", 0.0, t0, 0.0, b)
    finally:
        if Ms is not M:
            Ms.destroy()


def _cholmod_block_lanczos(K: PETSc.Mat, Ms: PETSc.Mat, nev: int, sigma: float, tol: float, b: int, prefix: str,
                           definite: bool, lam_max: float | None = None, step=None
                           ) -> tuple[np.ndarray | None, np.ndarray | None, dict] | None:
    """Block Lanczos (:func:`_block_lanczos`) on CHOLMOD's supernodal factorisation of K − σM,
    called directly (:mod:`fem_squeal.fe.cholmod`) with the fill-reducing order of K's node
    graph handed in (:func:`_fill_reducing_order`): no permuted copies of K and M, no PETSc dense
    matrices per block solve (:meth:`fem_squeal.fe.cholmod.Cholesky.solve`), and M applied by the
    compiled CSR block product (:func:`fem_squeal.fe.csr.block_product`; SciPy's where it cannot be
    had).  The path of one rank where no factorisation is chosen
    (``<prefix>st_pc_factor_mat_solver_type``; choosing ``cholmod`` there takes PETSc's interface to
    it, with all its options).  Returns None where it does not apply (``definite`` False: K − σM is
    known not to be positive definite); else (λ, rows of the vectors, seconds), λ and rows None where
    the Lanczos did not converge within its budget.  Raises :class:`fem_squeal.fe.cholmod.NotPositiveDefinite`
    where the factorisation finds K − σM not positive definite."""
    if K.getComm().getSize() > 1 or not _cholmod_applies(K, Ms, prefix, definite):
        return None
    t0 = time.perf_counter()
    n = K.getSize()[0]
    with csr_view(K) as k_csr, csr_view(Ms) as m_csr:      # PETSc's arrays, not copies
        A = sp.csr_matrix(k_csr[::-1], shape=(n, n))
        Msp = sp.csr_matrix(m_csr[::-1], shape=(n, n))
        if sigma != 0.0:
            A = (A - sigma * Msp).tocsr()
        perm = _fill_reducing_order(K, prefix, definite, (A.indptr, A.indices))
        factor = cholmod.Cholesky(A.indptr, A.indices, A.data, perm)      # NotPositiveDefinite: to the caller
        kernels.note("factorisation", "cholmod")
        del A
        t1 = time.perf_counter()
        try:
            mass = block_product(m_csr) or Msp.__matmul__
            got = _block_lanczos(factor.solve, mass, K.getComm().tompi4py(), (0, n), n, nev, sigma, tol, b,
                                 lam_max, progress=step)
        finally:
            factor.close()
    seconds = {"factor": t1 - t0, "solve": time.perf_counter() - t1, "solver": "cholmod"}
    return (None, None, seconds) if got is None else (*got, seconds)


def _substructured_block_lanczos(K: PETSc.Mat, Ms: PETSc.Mat, nev: int, sigma: float, tol: float, b: int,
                                 prefix: str, definite: bool, lam_max: float | None = None, step=None
                                 ) -> tuple[np.ndarray | None, np.ndarray | None, dict] | None:
    """:func:`_cholmod_block_lanczos` on N ranks: block Lanczos on the substructured CHOLMOD
    factorisation of K − σM (:class:`fem_squeal.fe.substructured.SubstructuredCholesky`: every rank's
    interior at once, the interface by its dense Schur complement), on each rank's own rows.  None
    where it does not apply (as there; also ``<prefix>substructure 0``, or the path declines:
    :class:`fem_squeal.fe.substructured.Unavailable`), and MUMPS runs.  Collective."""
    if not _cholmod_applies(K, Ms, prefix, definite) or not _substructure(prefix):
        return None
    comm = K.getComm().tompi4py()
    t0 = time.perf_counter()
    n, (r0, r1) = K.getSize()[0], K.getOwnershipRange()
    A = local_rows(K)
    if sigma != 0.0:
        A = (A - sigma * local_rows(Ms)).tocsr()
    try:
        # NotPositiveDefinite goes to the caller (MUMPS then)
        factor = SubstructuredCholesky(A, K.getOwnershipRanges(), node_block_size(K), comm)
    except Unavailable:
        return None
    kernels.note("factorisation", "cholmod-substructured")
    del A
    t1 = time.perf_counter()
    try:
        got = _block_lanczos(factor.solve, product_of(Ms), comm, (r0, r1), n, nev, sigma, tol, b, lam_max,
                             progress=step)
    finally:
        factor.close()
    seconds = {"factor": t1 - t0, "solve": time.perf_counter() - t1,
               "solver": "cholmod-substructured"}
    return (None, None, seconds) if got is None else (*got, seconds)


def _substructure(prefix: str) -> bool:
    """``<prefix>substructure``: 1/true/yes/on (the default) or 0/false/no/off; else a ModelError naming it."""
    value = user_option(f"{prefix}substructure")
    if value is None or value.lower() in ("1", "true", "yes", "on"):
        return True
    if value.lower() in ("0", "false", "no", "off"):
        return False
    raise ModelError(f"{prefix}substructure: must be 1/true/yes/on or 0/false/no/off (got {value!r})")


def _cholmod_applies(K: PETSc.Mat, Ms: PETSc.Mat, prefix: str, definite: bool) -> bool:
    """CHOLMOD may factorise K − σM here (either path): not known to be indefinite, AIJ matrices, the
    package's CHOLMOD shim built, and no factorisation chosen by the user
    (``<prefix>st_pc_factor_mat_solver_type``)."""
    return (definite and "aij" in K.getType() and "aij" in Ms.getType() and cholmod.available()
            and user_option(f"{prefix}st_pc_factor_mat_solver_type") is None)


def _fill_reducing_order(K: PETSc.Mat, prefix: str, definite: bool,
                         pattern: tuple[np.ndarray, np.ndarray] | None = None) -> np.ndarray | None:
    """The fill-reducing row order of K's node graph (:func:`fem_squeal.fe.ordering.fill_reducing_order`;
    ``pattern``: the CSR pattern of K − σM where the caller has it) where CHOLMOD will factorise
    K − σM first: ``<prefix>ordering`` ``auto`` (the default: AMD, or METIS where it pays for
    itself), ``metis`` or ``amd``; None for ``solver`` and where MUMPS factorises (it orders in its
    own analysis, and in parallel)."""
    how = user_option(f"{prefix}ordering") or "auto"
    if how not in (*ORDERINGS, "solver"):
        raise ModelError(f"{prefix}ordering: must be one of {', '.join((*ORDERINGS, 'solver'))} (got {how!r})")
    if how == "solver" or _real_solvers(K, prefix, definite)[0] != "cholmod":
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


def _real_solvers(K: PETSc.Mat, prefix: str, definite: bool) -> list[str]:
    """The factorisations to try for K − σM, in order: the user's choice
    (``<prefix>st_pc_factor_mat_solver_type``), else CHOLMOD on one rank (MUMPS LDLᵀ after it, for
    K − σM not positive definite; MUMPS alone where ``definite`` is False) and MUMPS on more ranks."""
    return symmetric_packages(K.getComm().getSize(), f"{prefix}st_", definite)


def _factorised_eps(K: PETSc.Mat, M: PETSc.Mat, nev: int, shift: float, tol: float, prefix: str,
                    definite: bool, ordered: bool = False) -> tuple[SLEPc.EPS, str, float]:
    """The real-mode EPS with K − σM factorised (``eps.setUp``) by the first of
    :func:`_real_solvers` that succeeds.  ``ordered``: K and M are already in a fill-reducing order
    (:func:`fem_squeal.fe.ordering.fill_reducing_order`), which CHOLMOD then keeps (natural ordering,
    one method) instead of running its own analysis.  Returns the EPS, the solver's name and the
    factorisation's wall time."""
    solvers = _real_solvers(K, prefix, definite)
    t0 = time.perf_counter()       # a failed CHOLMOD attempt counts in the factorisation time
    for k, solver in enumerate(solvers):
        eps = _shift_invert_eps(K, M, SLEPc.EPS.ProblemType.GHEP, nev, shift, tol, prefix)
        factor = REAL_MODE_FACTOR.with_(package=solver)
        if ordered and solver == "cholmod":
            factor = factor.with_(extra={"pc_factor_mat_ordering_type": "natural", "mat_cholmod_nmethods": "1"})
        try:
            with scoped_options(factor.options(f"{prefix}st_")):     # the user's options win
                eps.setFromOptions()
                with serial_openmp():      # CHOLMOD's OpenMP loops: see fem_squeal.util.blas
                    eps.setUp()    # the factorisation of K − σM (it reads the factor's options)
        except PETSc.Error:
            eps.destroy()
            if k + 1 == len(solvers):
                raise
            # CHOLMOD: K − σM not positive definite (σ above the lowest mode, free bodies): MUMPS
            continue
        return eps, solver, time.perf_counter() - t0
    raise AssertionError("unreachable")
