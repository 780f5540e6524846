"""Solver settings: the eigensolvers' default options (their factorisations typed by
:mod:`fem_squeal.fe.factorisation`), the shift-and-invert EPS on a factorisation, the progress bar of
a SLEPc solve, matrices without stored zeros."""
from __future__ import annotations

import time
from collections.abc import Mapping
from contextlib import contextmanager

import numpy as np
from petsc4py import PETSc
from slepc4py import SLEPc

from fem_squeal.fe.csr import drop_zeros  # noqa: F401  (its former home: fe.eigen.options.drop_zeros)
from fem_squeal.fe.eigen.block_krylov import OUT_OF_CORE_BLOCK, OUT_OF_CORE_VECTORS_PER_PAIR, block_size
from fem_squeal.fe.factorisation import CHOLESKY, QUIET_CHOLMOD, Factorisation
from fem_squeal.util.progress import ProgressBar

# Scalar scaling of λ balances |λ|²‖M‖ against ‖K‖ (stiff bonded/contact penalties make ‖K‖
# large); residual extraction picks the best eigenvector from the TOAR basis.  Measured on the
# damped coarse brake: max relative residual 1.2e-7 without, 4e-13 with, at the same cost.
PEP_OPTIONS = {"pep_scale": "scalar", "pep_extract": "residual"}
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
REAL_MODE_EPS = {"eps_purify": "false"}
#: The real modes' factorisation of K − σM (the package is chosen per solve: CHOLMOD, then MUMPS);
#: CHOLMOD's own "not positive definite" line is silenced: MUMPS takes over.
REAL_MODE_FACTOR = CHOLESKY.with_(package="", extra=QUIET_CHOLMOD)


def eps_defaults(prefix: str, factorisation: Factorisation, eps: Mapping[str, str] | None = None
                 ) -> dict[str, str]:
    """The default PETSc options of a shift-and-invert eigensolver with options prefix ``prefix``:
    its ``eps`` settings (keys without prefix) and the factorisation of its spectral transformation
    (under ``<prefix>st_``), for :func:`fem_squeal.fe.factorisation.scoped_options`."""
    return {**{f"{prefix}{k}": v for k, v in (eps or {}).items()}, **factorisation.options(f"{prefix}st_")}


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


#: seconds between progress lines of a SLEPc solve in a log (a terminal redraws the bar in place)
PROGRESS_HEARTBEAT = 10.0


def restarts_left(before: np.ndarray | None, now: np.ndarray, tol: float) -> float:
    """Restarts until every error estimate in ``now`` is ≤ ``tol``, each falling geometrically at
    its rate since the last restart: max_j log(e_j/tol) / log(e_j⁻/e_j) over the pending pairs
    whose estimate fell (e⁻: ``before``, the same Ritz pairs one restart earlier); NaN where no
    pending estimate has fallen yet (no rate known)."""
    pending = now > tol
    if not pending.any():
        return 0.0
    if before is None or before.size < now.size:
        return float("nan")
    e, p = now[pending], before[:now.size][pending]
    falling = (p > e) & (e > 0)
    if not falling.any():
        return float("nan")
    return float(np.max(np.log(e[falling] / tol) / np.log(p[falling] / e[falling])))


def block_columns(nev: int, prefix: str) -> int:
    """``<prefix>block_size`` if given (0: SLEPc's own iteration), else
    :func:`~fem_squeal.fe.eigen.block_krylov.block_size`."""
    return PETSc.Options().getInt(f"{prefix}block_size", block_size(nev))


@contextmanager
def _progress(solver, total: int, label: str, enabled: bool):
    """A progress line of converged eigenpairs on rank 0, fed by the SLEPc monitor of ``solver``
    (set on every rank: monitors are logically collective), once per restart: the converged pairs,
    the seconds per restart and the time left, estimated from the convergence rate of the wanted
    pairs' error estimates (:func:`restarts_left` × the mean seconds per restart).  In a log a line
    every :data:`PROGRESS_HEARTBEAT` seconds at least."""
    if not enabled:
        yield
        return

    tol = solver.getTolerances()[0]
    state: dict = {"before": None}
    with ProgressBar(total, label, unit=" pairs", enabled=solver.getComm().getRank() == 0,
                     heartbeat=PROGRESS_HEARTBEAT) as bar:
        def monitor(_s, its, nconv, _eig, errest):
            err = np.abs(np.asarray(errest, float))[:max(total, nconv)]
            left = restarts_left(state["before"], err[nconv:], tol) if nconv < total else 0.0
            state["before"] = err[nconv:]
            per = (time.perf_counter() - bar.t0) / max(its, 1)
            bar.update(min(nconv, total), eta=left * per,
                       extra=f"restart {its}, {per:.1f} s each, {'?' if left != left else f'{left:.0f}'} "
                             "restarts left")

        solver.setMonitor(monitor)
        try:
            yield
        finally:
            solver.cancelMonitor()


#: Vectors a block Krylov solve of the brake builds per wanted pair (the progress line's ETA until the pairs
#: converge, which they do late): block Arnoldi 288 for 93 pairs at 1,323,816 DOFs and 390 for 120 at
#: 711,351; block Lanczos 400 for 125 real modes at 711,351 (docs/validation.md)
VECTORS_PER_PAIR = 3.1


def eta_seconds(elapsed: float, done: int, done_first: int, vectors: int, vectors_first: int, wanted: int,
                asked: int = 0, per_pair: float = VECTORS_PER_PAIR) -> float:
    """The seconds a block Krylov solve has left, ``elapsed`` after its first block (``done_first``
    converged pairs and ``vectors_first`` vectors then; ``done`` and ``vectors`` now, of ``wanted``
    pairs; ``asked``: the pairs asked for, nev, which the band's count only reaches as its Ritz values
    come in): the pairs' own rate, which counts the pairs that converge late as never coming, and, while
    the space is below ``per_pair`` × max(``wanted``, ``asked``) (:data:`VECTORS_PER_PAIR`; blocks of
    :data:`~fem_squeal.fe.eigen.block_krylov.OUT_OF_CORE_BLOCK` columns need more), the vectors still to build at
    their rate, whichever is less.  NaN before either can be measured.  Replayed on the 1.32M-DOF run out
    of core (94 asked, 93 in the band; the ratio is that run's, and 3.25 at 711k): with 36 / 108 / 180 / 228
    vectors built 386 / 287 / 177 / 104 s against 424 / 310 / 192 / 106 s that were left; the pairs' rate
    alone said 8038 s at 96 vectors (330 s left)."""
    by_pairs = elapsed * (wanted - done) / (done - done_first) if done > done_first else float("nan")
    expected = per_pair * max(wanted, asked)
    if vectors > vectors_first and vectors < expected:
        by_vectors = elapsed * (expected - vectors) / (vectors - vectors_first)
        return by_vectors if by_pairs != by_pairs else min(by_pairs, by_vectors)
    return by_pairs


@contextmanager
def block_progress(label: str, enabled: bool, comm, total: int, factor_seconds: float | None = None,
                   factorising: str = "factorising"):
    """A progress line of a block Krylov solve on rank 0 (the callback :func:`_block_lanczos` and
    :func:`_block_arnoldi` take, with (converged wanted pairs, vectors, wanted pairs, block columns); None when not
    ``enabled``): first ``factorising`` where the factorisation is still to come (``factor_seconds``
    None), then the converged pairs, the vectors and the seconds left (:func:`eta_seconds`; the
    factorisation's seconds shown apart).  Drawn full where the solve converged, left
    short where it stopped (issue 36: "120/120 pairs, 0.0 s" was drawn when block Arnoldi's memory rule
    refused it, before Krylov–Schur's minutes), with a line that says so where it had begun (its space
    spent: at 1.32M DOFs out of core the log was then silent for minutes of the solve that followed)."""
    if not enabled:
        yield None
        return
    bar = ProgressBar(total, label, unit=" pairs", enabled=comm.rank == 0, heartbeat=PROGRESS_HEARTBEAT)
    state: dict = {"factor": factor_seconds, "first": None, "done": False, "last": None}
    if factor_seconds is None:
        bar.update(0, extra=factorising)

    def step(done: int, k: int, wanted: int, width: int = 0) -> None:
        now = time.perf_counter()
        if state["first"] is None:               # the first block: the factorisation is over
            state["first"] = (now, done, k)
            if state["factor"] is None:
                state["factor"] = now - bar.t0
        t1, d1, k1 = state["first"]
        bar.total = float(max(wanted, 1))        # the band's or the threshold's pairs, where not nev
        state["done"], state["last"] = done >= wanted, (done, k, wanted)
        per_pair = OUT_OF_CORE_VECTORS_PER_PAIR if width >= OUT_OF_CORE_BLOCK else VECTORS_PER_PAIR
        bar.update(done, eta=eta_seconds(now - t1, done, d1, k, k1, wanted, total, per_pair),
                   extra=f"{k} vectors, factorised in {state['factor']:.1f} s")
    try:
        yield step
    except BaseException:
        bar.abandon()
        raise
    if state["done"]:
        bar.close()
        return
    if state["last"] is not None:
        done, k, wanted = state["last"]
        bar.note(f"stopped with {done} of {wanted} pairs converged after {k} vectors")
    bar.abandon()


def _zero_like(M: PETSc.Mat) -> PETSc.Mat:
    Z = M.duplicate()
    Z.zeroEntries()
    return Z
