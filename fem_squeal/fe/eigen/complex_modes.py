"""Complex modes of λ²M + λC + K: the undamped problem as a linear EPS (block Arnoldi, or Krylov-
Schur), the damped one by PEP (TOAR), in a band."""
from __future__ import annotations

import time

import numpy as np
from petsc4py import PETSc
from slepc4py import SLEPc

from fem_squeal.fe import kernels
from fem_squeal.fe.dense import block_solve, product_of
from fem_squeal.fe.eigen.block_krylov import (
    BEYOND,
    OUT_OF_CORE_BLOCK,
    OUT_OF_CORE_VECTORS_PER_PAIR,
    _block_arnoldi,
    vector_room,
)
from fem_squeal.fe.eigen.options import (
    PEP_OPTIONS,
    _progress,
    _shift_invert_eps,
    _zero_like,
    block_columns,
    block_progress,
    eps_defaults,
)
from fem_squeal.fe.eigen.results import TWO_PI, ComplexModes, _check, _sort_key, normalised_residuals
from fem_squeal.fe.factorisation import LU, scoped_options, user_option
from fem_squeal.util.errors import ModelError
from fem_squeal.util.memory import release_freed_memory


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
    defaults = eps_defaults(prefix, LU, None if method == "linear" else PEP_OPTIONS)
    with scoped_options(defaults, options):      # the user's options over these, for this solve only
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
            radius = band_radius(target_hz, band_hz) if method == "linear" else None
            # the factorisation is the longest silent phase (348k DOFs: 17-22 s): the bar says it runs
            with block_progress("CEA", progress, comm.tompi4py(), nev,
                                factorising=f"factorising the operator shifted to {target_hz:.0f} Hz") as step:
                solver.setUp()          # the factorisation of the shifted operator
                t1 = time.perf_counter()
                got = _cea_block(solver, K, M, nev, (TWO_PI * target_hz) ** 2, tol, prefix, step,
                                 radius) if method == "linear" else None
            stop = {"band": False}
            if got is not None:
                for val, x in zip(got[0], got[1].T):
                    xr, xi = K.createVecRight(), K.createVecRight()
                    xr.array[:], xi.array[:] = x.real, x.imag
                    lams.append(1j * np.sqrt(val))
                    xrs.append(xr)
                    xis.append(xi)
                nconv = 0
                algorithm = f"block Arnoldi, {got[2]} columns"
            else:
                algorithm = "Krylov-Schur" if method == "linear" else "TOAR"
                with _progress(solver, nev if method == "linear" else 2 * nev, "CEA", progress):
                    stop = _band_stop(solver, (TWO_PI * target_hz) ** 2, radius)
                    solver.solve()
                nconv = solver.getConverged()
                if stop["band"]:
                    algorithm += ", stopped at the band"
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
            release_freed_memory()      # the factorisation's heap blocks (fem_squeal.util.memory)
    lams = np.array(lams, dtype=complex)
    n_found = len(lams)
    if band_hz is not None:
        f = lams.imag / TWO_PI
        keep = np.flatnonzero((f >= band_hz[0]) & (f <= band_hz[1]))
        for j in sorted(set(range(n_found)) - set(keep.tolist())):
            xrs[j].destroy()
            xis[j].destroy()
        lams, xrs, xis = lams[keep], [xrs[i] for i in keep], [xis[i] for i in keep]
    res = normalised_residuals(K, C, M, lams, xrs, xis)
    order = _sort_key(lams)
    lams, res = lams[order], res[order]
    xrs, xis = [xrs[i] for i in order], [xis[i] for i in order]
    what = f"complex-mode {'EPS' if method == 'linear' else 'PEP'} (prefix {prefix!r})"
    # block Arnoldi (or Krylov–Schur's band stop) returns fewer than nev where the band's pairs and
    # BEYOND more converged first
    short = got is not None or stop["band"]
    _check(n_found, n_found if short else nev, res, max_residual, what, lams.imag / TWO_PI)
    kernels.note("complex_modes", f"{method}, {algorithm.split(',')[0]}")
    if got is not None:                 # the block width (wider where the factor is read from files)
        kernels.note("block_arnoldi", f"{got[2]} columns")
    return ComplexModes(lams, xrs, xis, res, method, seconds, algorithm)


# options that configure SLEPc's own iteration: given, the CEA runs it (they would not apply to the block path)
SLEPC_SOLVER_OPTIONS = ("type", "ncv", "mpd", "max_it", "krylovschur_restart", "krylovschur_locking")


def band_radius(target_hz: float, band_hz: tuple[float, float] | None) -> float | None:
    """The radius about σ = (2π target)² of the disc in ν = ω² that holds the band ``band_hz`` (None: no
    band): max(σ − ν_lo, ν_hi − σ).  Block Arnoldi stops once the Ritz values in it and
    :data:`~fem_squeal.fe.eigen.block_krylov.BEYOND` more have converged, where that is before ``nev``.
    A pair of the band with growth rate a has ν = ω² − a² − 2iaω, off the real axis by 2aω: one within
    2a²/ω of a band end (0.3 Hz at a = 300/s, 16 kHz) lies just outside the disc, among the BEYOND
    pairs, which are then returned too (the results keep the band's pairs of those returned)."""
    if band_hz is None:
        return None
    sigma, lo, hi = ((TWO_PI * f) ** 2 for f in (target_hz, *band_hz))
    return max(sigma - lo, hi - sigma)


def _band_stop(eps: SLEPc.EPS, sigma: float, radius: float | None) -> dict:
    """Krylov–Schur's stopping test for a band (the rule of block Arnoldi's ``radius``): stop once no
    Ritz value in the disc |ν − σ| ≤ ``radius`` is unconverged and :data:`BEYOND` converged ones lie
    beyond it, where that is before ``nev``.  The Ritz values are the monitor's, θ = 1/(ν − σ) of
    the shift-and-invert operator, converged ones first; the monitor runs after the stopping test
    of a restart, so the test reads the previous restart's (one restart late, on the safe side).
    Returns the state: ``band`` True once it stopped the solve.  Nothing is set without a band."""
    state = {"band": False, "seen": None}
    if radius is None:
        return state

    def monitor(_eps, _its, nconv, eig, _errest):
        state["seen"] = (nconv, np.abs(np.asarray(eig, dtype=complex)))

    def stopping(_eps, its, max_it, nconv, nev):
        if nconv >= nev:
            return SLEPc.EPS.ConvergedReason.CONVERGED_TOL
        if its >= max_it:
            return SLEPc.EPS.ConvergedReason.DIVERGED_ITS
        if state["seen"] is not None:
            k, size = state["seen"]
            inside = size * radius >= 1.0              # |ν − σ| = 1/|θ| ≤ radius
            if k <= nconv and not inside[k:].any() and np.count_nonzero(~inside[:k]) >= BEYOND:
                state["band"] = True
                return SLEPc.EPS.ConvergedReason.CONVERGED_USER
        return SLEPc.EPS.ConvergedReason.ITERATING
    eps.setMonitor(monitor)
    eps.setStoppingTest(stopping)
    return state


def _cea_block(eps: SLEPc.EPS, K: PETSc.Mat, M: PETSc.Mat, nev: int, sigma: float, tol: float, prefix: str,
               step=None, radius: float | None = None) -> tuple[np.ndarray, np.ndarray, int] | None:
    """The linear CEA's pairs by block Arnoldi (:func:`_block_arnoldi`) on the factorisation the
    set-up EPS holds, where it is a direct one (``preonly`` + LU/Cholesky), ``<prefix>block_size``
    is not 0 and no option of SLEPc's own iteration is given (:data:`SLEPC_SOLVER_OPTIONS`): (ν, the
    vectors, the block's columns), None otherwise or where it does not converge (then the EPS solves as
    before).  The columns: ``<prefix>block_size`` where given, else :func:`block_size`, widened to
    :data:`OUT_OF_CORE_BLOCK` where MUMPS's factor is out of core and the memory rule leaves room for
    :data:`OUT_OF_CORE_VECTORS_PER_PAIR` vectors per pair.  ``radius``: the band's disc
    (:func:`band_radius`): fewer than ``nev`` pairs where those in it converge first.  ``step``: the
    progress callback (:func:`~fem_squeal.fe.eigen.options.block_progress`).
    Measured on the brake corner (163k DOFs, 1 rank, 60 modes, tol 1e-10): see docs/validation.md."""
    b = block_columns(nev, prefix)
    ksp = eps.getST().getKSP()
    if (b <= 0 or ksp.getType() != "preonly" or ksp.getPC().getType() not in ("lu", "cholesky")
            or any(user_option(f"{prefix}eps_{o}") is not None for o in SLEPC_SOLVER_OPTIONS)):
        return None
    comm = K.getComm().tompi4py()
    F = ksp.getPC().getFactorMatrix()
    if (not PETSc.Options().hasName(f"{prefix}block_size") and ksp.getPC().getFactorSolverType() == "mumps"
            and F.getMumpsIcntl(22) == 1
            and vector_room(comm, K.getLocalSize()[0]) >= OUT_OF_CORE_VECTORS_PER_PAIR * nev):
        b = max(b, OUT_OF_CORE_BLOCK)       # each solve reads the factor back from its files, whatever its width
    got = _block_arnoldi(block_solve(F), product_of(M), comm, K.getOwnershipRange(), K.getSize()[0], nev, sigma,
                         tol, b, step, radius)
    return None if got is None else (*got, b)
