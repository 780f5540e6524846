"""The complex eigenvalue analysis of a whole band by projection onto real modes (as Abaqus's and
ANSYS's QRDAMP CEA), every pair checked in the full model and the basis enriched until it passes.

1. Basis Φ (:func:`~fem_squeal.fe.projection.reductor.build_basis`, the reduced model's): the real
   modes of the symmetric part K φ = ω² M φ up to ``cut_factor`` × the band top, plus the static
   corrections (K − ω_c²M)⁻¹ A Φ of the terms the modes do not span (A = K_f, C_d, G), M-orthonormal.
2. The reduced quadratic (λ²I + λΦᵀCΦ + ΦᵀKΦ) y = 0, K and C the CEA's own (friction, rotation,
   prestress), solved densely (:func:`fem_squeal.reduced.eigensolve.quadratic_eigs`).
3. Every pair with Im λ/2π in the band (widened by :data:`EDGE`) lifted, x = Φy, and its residual
   taken in the full model, as the full CEA's: ρ = ‖(λ²M + λC + K)x‖₂ / (‖K‖_∞ ‖x‖₂).
4. Where ρ > ``max_residual``: the basis grows by (K − ω_c²M)⁻¹ r (real and imaginary parts of each
   residual r, one correction step of inverse iteration on the factorisation of step 1) and steps
   2–4 repeat, at most ``max_rounds`` times.

The pairs returned are :class:`~fem_squeal.fe.eigen.ComplexModes` as the full CEA's (M-normalised
vectors, sorted the same way), with a :class:`ProjectionReport`.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from mpi4py import MPI
from petsc4py import PETSc
from scipy.linalg import solve_triangular

from fem_squeal.fe.assembly import OperatingTerms, Operators
from fem_squeal.fe.dense import apply, apply_transpose, gram, matmul_f
from fem_squeal.fe.eigen import TWO_PI, ComplexModes, drop_zeros
from fem_squeal.fe.eigen.results import _check, _sort_key, normalised_residuals
from fem_squeal.fe.projection.basis import _new_block, _orthonormality, _stack, project
from fem_squeal.fe.projection.reductor import build_basis
from fem_squeal.fe.projection.shifted import ShiftedSolver, count_below, modes_below
from fem_squeal.reduced.eigensolve import quadratic_eigs
from fem_squeal.reduced.mode_coupling import FRICTIONLESS_MODES, RealModeCoefficients, basis_modes, modal_part
from fem_squeal.util.errors import EigenSolveError, ModelError, ReductionError

#: default number of enrichment rounds before the projection gives up
MAX_ROUNDS = 6
#: the enrichment keeps the directions of (K − ω_c²M)⁻¹r whose part outside the basis exceeds this share of
#: their M-norm (:func:`~fem_squeal.fe.projection.basis._new_block`).  At 1e-8 (the modes' and corrections'
#: deflation) the ring's basis lost its M-orthonormality to 3.4e-5 in two rounds: the Gram matrix of a
#: direction with a new part of 1e-7 is known to ε only, its scaling by s^(-1/2) is not
ENRICH_RTOL = 1e-6
#: pairs checked beyond the band by this share of its top (a pair may cross the edge as the basis grows)
EDGE = 0.01

@dataclass
class ProjectionReport:
    """How the projected CEA ran: the cut, the basis (its counts), one row per round, the worst residual."""

    cut_hz: float
    sigma_hz: float
    counts: dict
    rounds: list[dict] = field(default_factory=list)
    worst_residual: float = np.inf  # ρ, the full CEA's residual, of the pairs returned
    worst_relative: float = np.inf  # η, relative to λ²M, of the last round's pairs in the band
    n_real_in_band: int = 0          # real modes of the symmetric part in the band (solved for the basis)
    coupling: RealModeCoefficients | None = None  # the pairs on the basis's real modes (:func:`modal_coupling`)

    def as_dict(self) -> dict:
        return {"cut_hz": self.cut_hz, "shift_hz": self.sigma_hz, "basis_size": self.counts["size"],
                "basis": dict(self.counts), "enrichment_rounds": len(self.rounds) - 1,
                "worst_residual": self.worst_residual, "worst_relative_residual": self.worst_relative,
                "n_real_modes_in_band": self.n_real_in_band,
                "rounds": self.rounds}


def modal_coupling(K: PETSc.Mat, W: np.ndarray, Y: np.ndarray, f_max_hz: float) -> RealModeCoefficients:
    """The pairs x = Φy (columns of ``Y``) on the real modes of (K, M) up to ``f_max_hz`` that the basis's
    first columns ``W`` span (M-orthonormal, a rotation of them: :func:`~.basis._new_block`): with
    WᵀKW = Q diag(ω²) Qᵀ the modes are WQ, and Φ being M-orthonormal with W first, c = Qᵀ y[:n] and
    ‖x‖²_M = ‖y‖² (:mod:`fem_squeal.fe.coupling`, without its real-mode solve).  One product K W."""
    freqs_hz, Q = basis_modes(project(K, W), W.shape[1])
    c, norms = modal_part(Y, W.shape[1])
    return RealModeCoefficients(freqs_hz, Q.T @ c, norms, float(f_max_hz), W, Q, basis=FRICTIONLESS_MODES)


def auto_method(ops: Operators, band_hz: tuple[float, float], min_dofs: int, min_modes: int, options=None,
                prefix: str = "cea_count_") -> tuple[str, str]:
    """("projection" or "full", why): the projection where the model has at least ``min_dofs`` DOFs
    and at least ``min_modes`` real modes below the band top (the negative inertia of K − ω_top²M,
    :func:`count_below`: one LDLᵀ factorisation, made only above ``min_dofs``); the full CEA otherwise
    (small models, narrow bands: a few shift-invert solves cost less than the real modes to the cut)."""
    n = ops.K.getSize()[0]
    if n < min_dofs:
        return "full", f"{n} DOFs < {min_dofs}: the full CEA"
    count = count_below(ops.K, ops.M, band_hz[1], options, prefix)
    if count < min_modes:
        return "full", f"{n} DOFs, {count} real modes below {band_hz[1]:g} Hz < {min_modes}: the full CEA"
    return "projection", (f"{n} DOFs >= {min_dofs} and {count} real modes below {band_hz[1]:g} Hz >= "
                          f"{min_modes}: the projection")


def _in_band(lam: np.ndarray, band_hz, edge: float = 0.0) -> np.ndarray:
    f = lam.imag / TWO_PI
    lo, hi = band_hz
    return (f >= lo * (1.0 - edge)) & (f <= hi * (1.0 + edge))


def _grow_mass(comm, Mr: np.ndarray | None, Phi: np.ndarray, last: tuple[np.ndarray, np.ndarray]) -> np.ndarray:
    """ΦᵀMΦ of the basis Φ whose last block is ``last`` (W, MW), from ``Mr`` of the columns before it
    (None: Φ is W): I to round-off, taken into account by the reduced solve rather than assumed (its
    products cost n·m·k per round; the whole n·m² took 58 s of the 78k-DOF brake's projection)."""
    W, MW = last
    if Mr is None:
        return gram(comm, W, MW)
    B = gram(comm, Phi[:, :Mr.shape[0]], MW)
    return np.block([[Mr, B], [B.T, gram(comm, W, MW)]])


def _reduced_pairs(Kr: np.ndarray, Cr: np.ndarray | None, Mr: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(λ, Y) of (λ²Mr + λCr + Kr) y = 0: with Mr = L Lᵀ, :func:`quadratic_eigs` of L⁻¹(·)L⁻ᵀ and y = L⁻ᵀz."""
    L = np.linalg.cholesky(0.5 * (Mr + Mr.T))
    tr = lambda A: solve_triangular(L, solve_triangular(L, A, lower=True).T, lower=True).T  # noqa: E731
    lam, Z = quadratic_eigs(tr(Kr), tr(Cr) if Cr is not None else None, vectors=True)
    return lam, solve_triangular(L.T, Z, lower=False)


def _grow(Ar: np.ndarray, A: PETSc.Mat, Phi: np.ndarray, W: np.ndarray) -> np.ndarray:
    """[Φ W]ᵀ A [Φ W] from Ar = ΦᵀAΦ: the blocks ΦᵀAW, WᵀAΦ = (AᵀW)ᵀΦ and WᵀAW (A need not be symmetric)."""
    comm = A.getComm().tompi4py()
    AW = apply(A, W)
    return np.block([[Ar, gram(comm, Phi, AW)], [gram(comm, apply_transpose(A, W), Phi), gram(comm, W, AW)]])


def _lift(Phi: np.ndarray, Y: np.ndarray) -> np.ndarray:
    """x = Φ y for complex Y as the real array [Φ Re Y, Φ Im Y] (column-major, as :func:`apply` takes)."""
    return matmul_f(Phi, np.hstack([Y.real, Y.imag]))


def full_residuals(K: PETSc.Mat, C: PETSc.Mat | None, M: PETSc.Mat, lam: np.ndarray, XX: np.ndarray,
                   norm_K: float, mass_diagonal: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Residual vectors r = (λ²M + λC + K)x (rank-local rows, complex) of the pairs (λ_j, x_j), x given
    as [Re X, Im X]; ρ_j = ‖r_j‖₂ / (‖K‖_∞ ‖x_j‖₂), the full CEA's residual; and the residual relative to
    the inertia term, η_j = ‖D^(-1/2) r_j‖₂ / (|λ_j|² ‖x_j‖_M), D = diag(M) (``mass_diagonal``, local
    rows; ∞ leaves a row out): ‖r‖_(M⁻¹) up to the (mesh-independent) conditioning of D⁻¹M, so η
    bounds the relative change of λ² that makes (λ, x) exact to first order.  ρ is not such a measure:
    ‖K‖_∞ (stiff springs, the smallest elements) exceeds ω²‖M‖_∞ by 1e6 or more at the lowest modes."""
    comm = K.getComm().tompi4py()
    k = lam.size
    cplx = lambda A: A[:, :k] + 1j * A[:, k:]  # noqa: E731
    MX = apply(M, XX)
    R = cplx(apply(K, XX)) + lam ** 2 * cplx(MX)
    if C is not None:
        R += lam * cplx(apply(C, XX))
    sums = lambda A: comm.allreduce(np.sum(A, axis=0), op=MPI.SUM)  # noqa: E731
    r = np.sqrt(sums(np.abs(R) ** 2))
    x = np.sqrt(sums(XX ** 2))
    xm = np.sqrt(np.maximum(sums(XX * MX), 0.0))
    rd = np.sqrt(sums(np.abs(R) ** 2 / mass_diagonal[:, None]))
    return R, r / (norm_K * np.hypot(x[:k], x[k:])), rd / (np.abs(lam) ** 2 * np.hypot(xm[:k], xm[k:]))


def projected_complex_modes(ops: Operators, K: PETSc.Mat, C: PETSc.Mat | None, band_hz: tuple[float, float], *,
                            cut_factor: float, tol: float, operating: OperatingTerms | None = None,
                            sigma_hz: float | None = None, max_residual: float = 1e-8,
                            max_rounds: int = MAX_ROUNDS, options=None, prefix: str = "cea_projection_",
                            log=None) -> tuple[ComplexModes, ProjectionReport]:
    """The complex modes of (λ²M + λC + K)x = 0 with Im λ/2π in ``band_hz``, all of them, by projection
    (module docstring): ``ops`` gives M, the symmetric K whose modes span the basis and the terms of
    the static corrections (with the gyroscopic G of ``operating``); ``K``, ``C`` are the CEA's.
    ``cut_factor``: the modes up to this factor × the band top; ``sigma_hz``: the corrections' shift
    (K + sign(s)(2πs)²M); not set: −(band centre), K − ω_c²M.
    The basis is enriched while a pair in the band has ρ > ``max_residual`` (the full CEA's check) or
    η > ``tol`` (:func:`full_residuals`).  Raises :class:`EigenSolveError` when a pair still has
    ρ > ``max_residual`` after ``max_rounds`` enrichments, or η > ``tol`` (the report says which)."""
    if not cut_factor > 1.0:
        raise ModelError(f"cut_factor: must be > 1 (got {cut_factor})")
    comm = K.getComm().tompi4py()
    wall = lambda t0: comm.allreduce(MPI.Wtime() - t0, op=MPI.MAX)  # noqa: E731
    M = ops.M
    top = band_hz[1]
    cut = cut_factor * top
    sigma_hz = sigma_hz if sigma_hz is not None else -0.5 * (band_hz[0] + band_hz[1])
    seconds: dict[str, float] = {}
    t0 = MPI.Wtime()
    solver = ShiftedSolver(ops.K, M, np.sign(sigma_hz) * (TWO_PI * sigma_hz) ** 2, options, prefix + "static_")
    seconds["factor"] = wall(t0)
    Mz = drop_zeros(M)
    try:
        t0 = MPI.Wtime()
        w2, V = modes_below(ops.K, M, cut, n_start=128, options=options, prefix=prefix, solver=solver)
        seconds["real_modes"] = wall(t0)
        f_real = np.sqrt(np.abs(w2)) / TWO_PI
        t0 = MPI.Wtime()
        basis = build_basis(ops, None, cut, static=True, sigma_hz=sigma_hz, modes=(w2, V), solver=solver,
                            operating=operating)
        del V
        seconds["basis"] = wall(t0)
        report = ProjectionReport(cut, sigma_hz, dict(basis.counts, enrichment=0),
                                  n_real_in_band=int(np.sum((f_real >= band_hz[0]) & (f_real <= top))))
        norm_K = K.norm(PETSc.NormType.INFINITY)
        diag = M.getDiagonal()
        # rows without mass (clamped DOFs: there x = 0 and r = 0 to round-off) left out of η
        mass_diagonal = np.where(diag.array_r > 0, diag.array_r, np.inf)
        diag.destroy()
        blocks = [(basis.Phi, apply(Mz, basis.Phi))]
        seconds.update(project=0.0, dense=0.0, residuals=0.0, enrich=0.0)
        Mr = None
        for rnd in range(max_rounds + 1):
            t0 = MPI.Wtime()
            Phi = blocks[0][0] if len(blocks) == 1 else _stack([b[0] for b in blocks], blocks[0][0].shape[0])
            if rnd == 0:
                Kr, Cr = project(K, Phi), (project(C, Phi) if C is not None else None)
            else:   # the new block's rows and columns only
                Kr = _grow(Kr, K, Phi[:, :Kr.shape[0]], blocks[-1][0])
                Cr = _grow(Cr, C, Phi[:, :Cr.shape[0]], blocks[-1][0]) if C is not None else None
            seconds["project"] += wall(t0)
            t0 = MPI.Wtime()
            Mr = _grow_mass(comm, Mr, Phi, blocks[-1])
            lam, Y = _reduced_pairs(Kr, Cr, Mr)
            sel = _in_band(lam, band_hz, EDGE)
            lam, Y = lam[sel], Y[:, sel]
            seconds["dense"] += wall(t0)
            t0 = MPI.Wtime()
            XX = _lift(Phi, Y)
            R, rho, eta = full_residuals(K, C, M, lam, XX, norm_K, mass_diagonal)
            seconds["residuals"] += wall(t0)
            inside = _in_band(lam, band_hz)
            worst = float(np.max(rho[inside], initial=0.0))
            report.worst_relative = float(np.max(eta[inside], initial=0.0))
            bad = (rho > max_residual) | (eta > tol)
            report.rounds.append({"size": int(Phi.shape[1]), "pairs_in_band": int(inside.sum()),
                                  "worst_residual": worst, "worst_relative_residual": report.worst_relative,
                                  "above_tol": int(bad.sum())})
            if log:
                log(f"[fem_squeal] projected CEA: round {rnd}, basis {Phi.shape[1]}, {int(inside.sum())} pairs "
                    f"in band, worst residual {worst:.1e} (relative to λ²M {report.worst_relative:.1e}), "
                    f"{int(bad.sum())} above tolerance")
            if not bad.any() or rnd == max_rounds:
                break
            t0 = MPI.Wtime()
            T = solver.solve(np.asfortranarray(np.hstack([R[:, bad].real, R[:, bad].imag])))
            del R
            W, MW, dropped = _new_block(Mz, T, ENRICH_RTOL, blocks, owned=True)
            seconds["enrich"] += wall(t0)
            if W.shape[1] == 0:
                break
            blocks.append((W, MW))
            report.counts["enrichment"] += int(W.shape[1])
            report.counts["dropped"] += dropped
        report.counts["size"] = int(Phi.shape[1])
        err = _orthonormality(comm, blocks)
        if err > 1e-8:
            raise ReductionError(f"projected CEA: basis not M-orthonormal (max |ΦᵀMΦ − I| = {err:.1e})")
    finally:
        solver.destroy()
        if Mz is not M:
            Mz.destroy()
    t0 = MPI.Wtime()
    lam, XX, Y = lam[inside], XX[:, np.concatenate([inside, inside])], Y[:, inside]
    k = lam.size
    xrs, xis = [], []
    for j in range(k):
        xr, xi = K.createVecRight(), K.createVecRight()
        xr.array[:], xi.array[:] = XX[:, j], XX[:, k + j]
        xrs.append(xr)
        xis.append(xi)
    res = normalised_residuals(K, C, M, lam, xrs, xis)
    order = _sort_key(lam)
    lam, res = lam[order], res[order]
    xrs, xis = [xrs[i] for i in order], [xis[i] for i in order]
    report.worst_residual = float(np.max(res, initial=0.0))
    # the modes lead the basis (build_basis: its first block, whole: M-orthonormal eigenvectors drop nothing);
    # a copy of them, so that the rest of the basis is freed on return
    report.coupling = modal_coupling(ops.K, np.array(blocks[0][0][:, :report.counts["modes"]], order="F"),
                                     Y[:, order], cut)
    seconds["vectors"] = wall(t0)
    what = (f"projected CEA (prefix {prefix!r}, basis {report.counts['size']}, modes <= {cut:.0f} Hz, "
            f"{len(report.rounds) - 1} enrichment rounds; raise analyses.cea.cut_factor or use method "
            "'linear'/'pep')")
    try:
        _check(k, 0, res, max_residual, what, lam.imag / TWO_PI)
        if report.worst_relative > tol:
            raise EigenSolveError(f"{what}: residual relative to λ²M {report.worst_relative:.1e} > tol {tol:.0e}")
    except EigenSolveError:
        for v in xrs + xis:
            v.destroy()
        raise
    algorithm = (f"{report.counts['modes']} real modes <= {cut:.0f} Hz + {report.counts['static']} "
                 f"static corrections + {report.counts['enrichment']} enrichment vectors")
    seconds["solve"] = sum(v for key, v in seconds.items() if key != "factor")
    return ComplexModes(lam, xrs, xis, res, "projection", seconds, algorithm), report

