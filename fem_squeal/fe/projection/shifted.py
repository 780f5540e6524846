"""The shifted factorisation K − σM shared by the basis' modes, static corrections and modal
derivatives; real modes below a cut; the inertia count."""
from __future__ import annotations

import numpy as np
from petsc4py import PETSc

from fem_squeal.fe.dense import block_solve
from fem_squeal.fe.eigen import TWO_PI, modes_on_factor, solve_real_modes
from fem_squeal.fe.eigen.slicing import sliced_modes
from fem_squeal.fe.factorisation import CHOLESKY, factor_solver, scoped_options, user_option
from fem_squeal.fe.projection.basis import _local_array
from fem_squeal.util.errors import ModelError

#: convergence of the basis modes (shift-inverted residual, SLEPc's criterion; the real-mode analysis
#: takes 1e-7): they only span the basis, to which their derivatives and the static corrections are
#: added and on which the model is a Galerkin projection.  Measured on the 50k-DOF brake (91 modes
#: ≤ 16 kHz): 1e-7 / 1e-6 / 1e-5: 1.60 / 1.52 / 1.42 s, frequencies within 2.8e-11 of 1e-7's, pair
#: residuals ‖Kx − λMx‖/(‖K‖‖x‖) ≤ 2.4e-9 / 2.0e-8 / 1.3e-7; the reduced model's error at the
#: design corners unchanged (docs/validation.md, "Fifth pass").
BASIS_MODE_TOL = 1e-5
BASIS_MODE_RESIDUAL = 1e-6   # the pairs' residual bound beyond which Krylov–Schur takes over (8× the measured)
#: The negative inertia of K − σM: MUMPS LDLᵀ with ICNTL(13) = 1 (no ScaLAPACK root) and ICNTL(24) = 1
#: (null pivot detection), as its inertia needs.
INERTIA = CHOLESKY.with_(icntl={13: 1, 24: 1})
#: K + σM for blocks of columns: MUMPS LDLᵀ taking its right-hand sides 64 at a time (ICNTL(27); its
#: default of 32 for MatMatSolve): the 50k-DOF brake's 172 columns 0.43 → 0.38 s, the factorisation the same.
SHIFTED = CHOLESKY.with_(icntl={27: 64})
#: slices of the spectrum slicing in :func:`modes_below` (``<prefix>slices``; 0: one shift near 0, as before).
#: Off: slower wherever measured (issue 36; benchmarks/real_mode_slicing.py and the same calls on the
#: projection's K and M, brake corner, modes ≤ 24 kHz, methods compared within one process on a shared
#: machine): 78k DOFs, 1 rank: one shift (CHOLMOD) 19.6 s, 2/3 slices 26.3/39.3 s (a quieter run; a loaded one:
#: 115 s, 2/3/4 slices 238/234/219 s); 2 ranks: one shift (the
#: band-centre factorisation) 117 s, 3 slices 446 s; 163k DOFs, 1 rank: 37.2 s against 102.7 s (2 slices; loaded:
#: 241 s against 871 s with 3);
#: SLEPc's own slicing (EPSSetInterval, MUMPS LDLᵀ) 782 s against 83 s at 78k.  Each slice's MUMPS
#: LDLᵀ costs more than CHOLMOD's LLᵀ near 0 and its solves more than CHOLMOD's, and one block Lanczos
#: space for ~160 modes still fits :data:`~fem_squeal.fe.eigen.BLOCK_MEMORY` at these sizes; the
#: slices pay where it no longer does (then one shift falls back to Krylov–Schur): not measured here.
SLICES = 0


def _slices(prefix: str, options) -> int:
    """``<prefix>slices`` from the scene's PETSc options or the command line, else :data:`SLICES`."""
    with scoped_options({}, options):
        value = user_option(f"{prefix}slices")
    try:
        return SLICES if value is None else int(value)
    except ValueError:
        raise ModelError(f"{prefix}slices: must be an integer >= 0 (got {value!r})") from None


def count_guess(n: int, f_hz: float, f_cut_hz: float) -> float:
    """The modes up to ``f_cut_hz`` guessed from ``n`` up to ``f_hz``: N ∝ f^1.5 (between plates, ∝ f², and
    beams, ∝ f) with a 10 % margin.  The brake corner (348k and 711k DOFs): 91 complex pairs ≤ 16 kHz give
    139.9 for the 125 real modes ≤ 20 kHz."""
    return n * ((f_cut_hz / max(f_hz, 1e-9)) ** 1.5 * 1.1)


def modes_below(K: PETSc.Mat, M: PETSc.Mat, f_cut_hz: float, *, n_start: int = 20, options=None,
                prefix: str = "basis_", max_modes: int = 2000, solver: ShiftedSolver | None = None,
                slices: int | None = None):
    """Every real mode with f ≤ ``f_cut_hz`` (shift-invert near 0): block Lanczos converges the modes
    below the cut and two above it (``f_max_hz`` of :func:`solve_real_modes`; ``n_start``, a guess
    of their number, sets its block size); where Krylov–Schur takes over, the count grows until the
    highest converged mode lies above the cut.  ``solver``: a factorisation of K + σM at hand, used
    instead of a new one where MUMPS would factorise anyway (more than one rank;
    :func:`fem_squeal.fe.eigen.modes_on_factor`; on one rank CHOLMOD's factorisation near 0 and its
    solves cost less than MUMPS's solves).  ``slices`` (None: ``<prefix>slices``, :data:`SLICES`): at
    least 1, spectrum slicing instead (:func:`fem_squeal.fe.eigen.slicing.sliced_modes`: a MUMPS LDLᵀ
    per slice, its inertia proving the slice's count), the paths above where it does not answer.
    Returns (ω² array, local (n_local, n) array)."""
    def local(rm) -> tuple[np.ndarray, np.ndarray]:
        keep = rm.freqs_hz <= f_cut_hz
        Phi = _local_array([v for v, k in zip(rm.vectors, keep) if k])
        for v in rm.vectors:
            v.destroy()
        return rm.omega2[keep], Phi

    slices = _slices(prefix, options) if slices is None else slices
    if slices < 0:
        raise ModelError(f"{prefix}slices: must be >= 0 (got {slices})")
    if slices > 0:
        rm, _ = sliced_modes(K, M, f_cut_hz, slices, tol=BASIS_MODE_TOL, max_residual=BASIS_MODE_RESIDUAL,
                             options=options, prefix=prefix + "slice_", progress=True)
        if rm is not None:
            return local(rm)
    if solver is not None and solver.factor is not None and K.getComm().getSize() > 1:
        rm = modes_on_factor(solver.solve, K, M, -solver.sigma, f_cut_hz, n_start, tol=BASIS_MODE_TOL,
                             max_residual=BASIS_MODE_RESIDUAL)
        if rm is not None and rm.freqs_hz[-1] > f_cut_hz:
            return local(rm)
        for v in rm.vectors if rm is not None else ():
            v.destroy()
    nev = n_start
    # a negative shift σ = −(2π·0.05 f_cut)²: K may be singular (free bodies), and K + |σ|M is then
    # still positive definite (CHOLMOD's LLᵀ).  The ring between plates (3 rigid-body modes, f_cut
    # 8 kHz, 128 pairs asked): σ = +(2π·1e-3 f_cut)² was indefinite (MUMPS, and Krylov–Schur for all
    # 128 pairs: 41 s); −(2π·1e-3 f_cut)² left the rigid modes' 1/(λ − σ) 2000× the others' and block
    # Lanczos missed its residuals (Krylov–Schur: 30 s); −(2π·{0.01 … 0.3} f_cut)²: block Lanczos,
    # 23 modes, 3.9–4.6 s (a loaded machine)
    target = -0.05 * f_cut_hz
    definite = None           # K − σM: not known; False once a solve fell back from CHOLMOD to MUMPS
    while True:
        rm = solve_real_modes(K, M, nev, target, options=options, prefix=prefix, progress=True, f_max_hz=f_cut_hz,
                              tol=BASIS_MODE_TOL, max_residual=BASIS_MODE_RESIDUAL, positive_definite=definite)
        definite = None if rm.solver.startswith("cholmod") else False
        f = rm.freqs_hz
        if f[-1] > f_cut_hz or nev >= max_modes:
            return local(rm)
        for v in rm.vectors:
            v.destroy()
        # extrapolate the count to the cut (count_guess), but at most ×2.5 per try: a large overshoot
        # costs more than one more solve
        nev = int(min(max_modes, min(max(count_guess(nev, f[-1], f_cut_hz), 1.3 * nev), 2.5 * nev) + 4))


def count_below(K: PETSc.Mat, M: PETSc.Mat, f_hz: float, options=None, prefix: str = "basis_count_") -> int:
    """The number of modes with f < ``f_hz``: the negative inertia of K − (2πf)²M (Sylvester's law;
    one MUMPS LDLᵀ factorisation, ICNTL(13) = 1 and ICNTL(24) = 1 as its inertia needs).  A check of
    the modes a solve returns (tests); :func:`adaptive_reduce` no longer counts before solving."""
    A = K.copy()
    A.axpy(-(TWO_PI * f_hz) ** 2, M, structure=PETSc.Mat.Structure.SUBSET_NONZERO_PATTERN)
    A.setOption(PETSc.Mat.Option.SYMMETRIC, True)
    try:
        ksp = factor_solver(A, INERTIA, prefix, options)
        try:
            return int(ksp.getPC().getFactorMatrix().getInertia()[0])
        finally:
            ksp.destroy()
    finally:
        A.destroy()


class ShiftedSolver:
    """(K + σM)⁻¹ applied to blocks of columns with one sparse factorisation (K symmetric, as the
    frictionless stiffness is: MUMPS Cholesky by default, ``<prefix>pc_type`` overrides).  The
    columns go to the factor's multiple-right-hand-side solve (MatMatSolve) in blocks of
    ``block``: measured on the 50k-DOF brake, 13–26 ms per column against 52–83 ms one at a time."""

    def __init__(self, K: PETSc.Mat, M: PETSc.Mat, sigma: float, options=None,
                 prefix: str = "basis_static_", block: int = 64):
        self.sigma, self.block = sigma, block
        self.A = K.copy()
        self.A.axpy(sigma, M, structure=PETSc.Mat.Structure.SUBSET_NONZERO_PATTERN)
        self.A.setOption(PETSc.Mat.Option.SYMMETRIC, True)
        self.ksp = factor_solver(self.A, SHIFTED, prefix, options)
        pc = self.ksp.getPC()
        self.factor = pc.getFactorMatrix() if self.ksp.getType() == "preonly" and \
            pc.getType() in ("lu", "cholesky") else None

    def solve(self, F: np.ndarray) -> np.ndarray:
        """(K + σM)⁻¹ F for the rank-local columns F (n_local, k)."""
        out = np.empty_like(F)
        if self.factor is None:  # an iterative or non-factor solver: one column at a time
            b, x = self.A.createVecs()
            for j in range(F.shape[1]):
                b.array[:] = F[:, j]
                self.ksp.solve(b, x)
                out[:, j] = x.array_r
            b.destroy()
            x.destroy()
            return out
        solve = block_solve(self.factor)
        for s in range(0, F.shape[1], self.block):
            out[:, s:s + self.block] = solve(F[:, s:s + self.block])
        return out

    def destroy(self):
        self.ksp.destroy()
        self.A.destroy()


def static_correction(K: PETSc.Mat, M: PETSc.Mat, F: np.ndarray, sigma: float, options=None,
                      prefix: str = "basis_static_") -> np.ndarray:
    """(K + σM)⁻¹ F for the rank-local columns F (one factorisation, all right-hand sides)."""
    solver = ShiftedSolver(K, M, sigma, options, prefix)
    try:
        return solver.solve(F)
    finally:
        solver.destroy()
