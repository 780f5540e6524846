"""Modal projection of the full operators (the PETSc/SLEPc side of the reduced layer).

Basis (issue 4; seed 001 §2.2 eq. 5 generalised):

* the real modes of the frictionless system K φ = ω² M φ (K with the closed contact springs,
  symmetric) below ``f_cut``;
* modes at sampled parameter values (a part's Young's modulus at the ends of its range), so that
  the basis stays accurate across a design of experiments;
* static correction vectors (K + σM)⁻¹ K_f Φ: the quasi-static response to the friction forces of
  each mode, which the truncated modes cannot represent (measured on the ring with k_n 1e11,
  μ 1: the modal error stalls at 1.5e-3 with 160 modes, 40 modes + 40 corrections give 3e-7);
* all of it M-orthonormalised with deflation: a vector whose part outside the span of the others
  is below ``rtol`` of its M-norm adds nothing and is dropped.

The reduced matrices Φᵀ A Φ are formed with PETSc sparse × dense products and summed over the
ranks, so every rank holds the same :class:`~fem_squeal.reduced.model.ReducedModel`.
"""
from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np
from mpi4py import MPI
from petsc4py import PETSc

from fem_squeal.fe.assembly import Operators, _add, _owned_global_rows
from fem_squeal.fe.eigen import DIRECT_SOLVER_OPTIONS, TWO_PI, set_options, solve_real_modes
from fem_squeal.fe.model import ModelSpec, common_mu  # noqa: F401  (common_mu: re-exported)
from fem_squeal.reduced.masa import polar_patches
from fem_squeal.reduced.model import MU, ContactRestriction, ReducedModel, e_param
from fem_squeal.reduced.sweep import solve_points
from fem_squeal.util.errors import ModelError, ReductionError, UnknownNameError


@dataclass
class Basis:
    """Mass-orthonormal basis Φ (rank-local owned rows) and where its vectors come from."""

    Phi: np.ndarray               # (n_local, m)
    n_global: int
    modal_hz: np.ndarray          # frequencies of the nominal frictionless modes included
    counts: dict = field(default_factory=dict)  # modes, sampled modes, static corrections, dropped

    @property
    def size(self) -> int:
        return self.Phi.shape[1]


def _dense(comm, local: np.ndarray, n_global: int) -> PETSc.Mat:
    D = PETSc.Mat().createDense(((local.shape[0], n_global), (PETSc.DECIDE, local.shape[1])),
                                array=np.ascontiguousarray(local), comm=comm)
    D.assemble()
    return D


def apply(A: PETSc.Mat, Phi: np.ndarray) -> np.ndarray:
    """A Φ, rank-local rows (n_local, m)."""
    comm = A.getComm().tompi4py()
    D = _dense(comm, Phi, A.getSize()[1])
    P = A.matMult(D)
    out = P.getDenseArray().copy()
    D.destroy()
    P.destroy()
    return out


def gram(comm, X: np.ndarray, Y: np.ndarray) -> np.ndarray:
    """Xᵀ Y summed over the ranks."""
    return comm.allreduce(X.T @ Y, op=MPI.SUM)


def project(A: PETSc.Mat, Phi: np.ndarray) -> np.ndarray:
    """Φᵀ A Φ (m × m, the same on every rank)."""
    return gram(A.getComm().tompi4py(), Phi, apply(A, Phi))


def m_orthonormalise(M: PETSc.Mat, V: np.ndarray, rtol: float = 1e-8, Phi: np.ndarray | None = None
                     ) -> tuple[np.ndarray, int]:
    """Extend the M-orthonormal ``Phi`` (or start afresh) by span(V), with deflation; returns
    (basis, number of dropped directions).

    Each column of V is M-orthogonalised against Phi (two passes of block Gram–Schmidt) and
    scaled by its original M-norm; then G = WᵀMW = Q diag(s) Qᵀ and directions with s < rtol²
    (new content below ``rtol`` of the vector) are dropped, W Q s^(-1/2) is appended.  A final
    pass makes ΦᵀMΦ = I to round-off."""
    comm = M.getComm().tompi4py()
    # collective calls depend on column counts only: a rank may own no rows of V
    extend = Phi is not None and Phi.shape[1] > 0
    norms = np.sqrt(np.maximum(comm.allreduce(np.einsum("ij,ij->j", V, apply(M, V)), op=MPI.SUM), 0.0))
    ok = norms > 0
    W = V[:, ok] / norms[ok]
    dropped = int(np.sum(~ok))
    for _ in range(2 if extend else 0):
        W = W - Phi @ gram(comm, Phi, apply(M, W))
    G = gram(comm, W, apply(M, W))
    s, Q = np.linalg.eigh(0.5 * (G + G.T))
    keep = s > rtol ** 2
    dropped += int(np.sum(~keep))
    W = W @ (Q[:, keep] / np.sqrt(s[keep]))
    if extend:
        W = W - Phi @ gram(comm, Phi, apply(M, W))
        W = np.hstack([Phi, W])
    G = gram(comm, W, apply(M, W))
    L = np.linalg.cholesky(0.5 * (G + G.T))
    return np.linalg.solve(L, W.T).T, dropped


def _local_array(vecs: list[PETSc.Vec]) -> np.ndarray:
    return np.column_stack([v.array_r for v in vecs]) if vecs else np.zeros((0, 0))


def modes_below(K: PETSc.Mat, M: PETSc.Mat, f_cut_hz: float, *, n_start: int = 20, options=None,
                prefix: str = "basis_", max_modes: int = 2000):
    """Every real mode with f ≤ ``f_cut_hz`` (shift-invert near 0; the count grows until the
    highest converged mode lies above the cut).  Returns (ω² array, local (n_local, n) array)."""
    nev = n_start
    target = 1e-3 * f_cut_hz  # a small positive shift: K may be singular (free bodies)
    while True:
        rm = solve_real_modes(K, M, nev, target, options=options, prefix=prefix, progress=True)
        f = rm.freqs_hz
        if f[-1] > f_cut_hz or nev >= max_modes:
            keep = f <= f_cut_hz
            Phi = _local_array([v for v, k in zip(rm.vectors, keep) if k])
            for v in rm.vectors:
                v.destroy()
            return rm.omega2[keep], Phi
        for v in rm.vectors:
            v.destroy()
        # extrapolate the count to the cut (N ∝ f^1.5, between plates ∝ f² and beams ∝ f), with a
        # margin, but at most ×2.5 per try: a large overshoot costs more than one more solve
        grow = (f_cut_hz / max(f[-1], 1e-9)) ** 1.5 * 1.1
        nev = int(min(max_modes, nev * min(max(grow, 1.3), 2.5) + 4))


def _solver(A: PETSc.Mat, options, prefix: str) -> PETSc.KSP:
    set_options(prefix, options, {k.removeprefix("st_"): v for k, v in DIRECT_SOLVER_OPTIONS.items()})
    ksp = PETSc.KSP().create(A.getComm())
    ksp.setOptionsPrefix(prefix)
    ksp.setOperators(A)
    ksp.setFromOptions()
    return ksp


def static_correction(K: PETSc.Mat, M: PETSc.Mat, F: np.ndarray, sigma: float, options=None,
                      prefix: str = "basis_static_") -> np.ndarray:
    """(K + σM)⁻¹ F for the rank-local columns F (one factorisation, all right-hand sides)."""
    A = K.copy()
    A.axpy(sigma, M, structure=PETSc.Mat.Structure.SUBSET_NONZERO_PATTERN)
    ksp = _solver(A, options, prefix)
    b, x = A.createVecs()
    out = np.empty_like(F)
    try:
        for j in range(F.shape[1]):
            b.array[:] = F[:, j]
            ksp.solve(b, x)
            out[:, j] = x.array_r
    finally:
        ksp.destroy()
        A.destroy()
        b.destroy()
        x.destroy()
    return out


class ParametricOperators:
    """Full-order K(p), C(p) of the affine form (module docstring of :mod:`fem_squeal.reduced.model`):
    used to verify the reduced model and to sample modes at parameter values."""

    def __init__(self, ops: Operators, spec: ModelSpec, mu0: float, parts: list[str] | None = None):
        self.ops, self.mu0 = ops, mu0
        self.parts = list(parts) if parts is not None else list(ops.K_parts or {})
        missing = [p for p in self.parts if not ops.K_parts or p not in ops.K_parts]
        if missing:
            raise UnknownNameError(f"parameters: no stiffness of part(s) {missing} (assemble with parts=True)")
        bc_rows = _owned_global_rows(ops.K, ops.V, ops.bc_dofs)
        self.K_parts = {}
        for p in self.parts:
            A = ops.K_parts[p].copy()
            A.zeroRowsColumns(bc_rows, diag=0.0)  # the clamped rows of K keep their unit diagonal
            self.K_parts[p] = A
        self.E0 = {p: spec.materials[p].E for p in self.parts}
        self.beta = {p: spec.materials[p].rayleigh_beta for p in self.parts}

    def matrices(self, params: Mapping[str, float]) -> tuple[PETSc.Mat, PETSc.Mat | None]:
        """New K(p) (with friction) and C(p) (None if undamped) for parameter values ``params``."""
        known = {MU, *(e_param(p) for p in self.parts)}
        unknown = sorted(set(params) - known)
        if unknown:
            raise UnknownNameError(f"{unknown[0]}: not a parameter; parameters: {sorted(known)}")
        K = self.ops.K.copy()
        C = self.ops.C.copy() if self.ops.C is not None else None
        mu = params.get(MU, self.mu0)
        if self.ops.Kf is not None and self.mu0 != 0:
            _add(K, self.ops.Kf, mu / self.mu0)
        for p in self.parts:
            d = params.get(e_param(p), self.E0[p]) / self.E0[p] - 1.0
            if d != 0:
                _add(K, self.K_parts[p], d)
                if self.beta[p] > 0:
                    if C is None:
                        C = self.K_parts[p].copy()
                        C.scale(self.beta[p] * d)
                    else:
                        _add(C, self.K_parts[p], self.beta[p] * d)
        return K, C

    def frictionless(self, params: Mapping[str, float]) -> PETSc.Mat:
        return self.matrices({**params, MU: 0.0})[0]

    def destroy(self):
        for A in self.K_parts.values():
            A.destroy()


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


def restrict_contacts(ops: Operators, Phi: np.ndarray, preload=None) -> dict[str, ContactRestriction]:
    """G_n Φ and G_t Φ of every contact interface (all points on every rank, canonical order)."""
    out = {}
    for it, op in ops.contacts:
        comm = op.Gn.getComm().tompi4py()
        x = _gather_rows(comm, op.x)
        o = canonical_order(x)
        g0 = _gather_rows(comm, op.gap0)[o]
        g = _gather_rows(comm, preload.gap[it.name])[o] if preload is not None else g0
        act = _gather_rows(comm, preload.active[it.name])[o] if preload is not None else np.ones(op.n_global, bool)
        pres = _gather_rows(comm, preload.pressure[it.name])[o] if preload is not None else None
        out[it.name] = ContactRestriction(
            Gn=_gather_rows(comm, apply(op.Gn, Phi))[o], Gt=_gather_rows(comm, apply(op.Gt1, Phi))[o],
            weight=_gather_rows(comm, op.weight)[o], kn=it.kn, mu=it.mu, sliding=float(it.sliding),
            gap=g, active=act.astype(bool), gap0=g0, x=x[o], pressure=pres)
    return out


def build_basis(ops: Operators, par: ParametricOperators, f_cut_hz: float, *,
                samples: list[dict[str, float]] = (), static: bool = True, sigma_hz: float | None = None,
                options=None, prefix: str = "basis_", rtol: float = 1e-8, enrich_rtol: float = 1e-3,
                n_start: int = 20, extra: np.ndarray | None = None) -> Basis:
    """Frictionless modes ≤ ``f_cut_hz`` at the nominal point and at each of ``samples``, plus the
    static corrections (K + σM)⁻¹ K_f Φ (of all the modes kept), M-orthonormalised (see the module
    docstring); sampled modes add only their directions beyond ``enrich_rtol`` (the corrections
    are kept whole: truncating them at 1e-3 raised the ring's error at μ = 1 from 1.5e-6 to 5e-5).
    ``n_start``: first guess of the number of modes below the cut; ``extra``: more vectors (local
    rows), kept whole, e.g. the preload displacement and contact attachments for MASA."""
    if not f_cut_hz > 0:
        raise ModelError(f"f_cut_hz: must be > 0 (got {f_cut_hz})")
    w2, V = modes_below(ops.K, ops.M, f_cut_hz, n_start=n_start, options=options, prefix=prefix)
    Phi, dropped = m_orthonormalise(ops.M, V, rtol)
    n_sample = 0
    for s in samples:
        K = par.frictionless(s)
        _, Vs = modes_below(K, ops.M, f_cut_hz, n_start=int(1.15 * V.shape[1]) + 4, options=options,
                            prefix=prefix)
        K.destroy()
        # only what the sampled modes add beyond ``enrich_rtol`` of their norm: eigenvalue errors
        # are quadratic in the subspace error for well-separated modes, but near a coalescence
        # (non-normal) they are not: 1e-2 gave 1.0e-3 on the brake at a map corner, 1e-3 is the default
        size = Phi.shape[1]
        Phi, d = m_orthonormalise(ops.M, Vs, enrich_rtol, Phi)
        n_sample += Phi.shape[1] - size
        dropped += d
    n_static = 0
    if static and ops.Kf is not None:
        sigma = (TWO_PI * (sigma_hz if sigma_hz is not None else 0.1 * f_cut_hz)) ** 2
        S = static_correction(ops.K, ops.M, apply(ops.Kf, Phi), sigma, options, prefix + "static_")
        size = Phi.shape[1]
        Phi, d = m_orthonormalise(ops.M, S, rtol, Phi)  # corrections: all of their new content
        n_static = Phi.shape[1] - size
        dropped += d
    n_extra = 0
    if extra is not None and extra.shape[1]:
        size = Phi.shape[1]
        Phi, d = m_orthonormalise(ops.M, extra, rtol, Phi)
        n_extra = Phi.shape[1] - size
        dropped += d
    return Basis(Phi, ops.K.getSize()[0], np.sqrt(np.abs(w2)) / TWO_PI,
                 {"modes": int(V.shape[1]), "sampled_modes": n_sample, "static": n_static, "extra": n_extra,
                  "dropped": dropped, "size": int(Phi.shape[1])})


def contact_attachments(ops: Operators, patches: tuple[int, int], sigma_hz: float, options=None,
                        prefix: str = "basis_attach_", axis=(0.0, 0.0, 1.0)) -> np.ndarray:
    """(K + σM)⁻¹ (G_n + μG_t)ᵀ W 1_j: the static response to a unit pressure (with its friction
    drag) on patch j of every contact interface, the patches being an n_radial × n_angular polar
    grid over each slave surface (:func:`fem_squeal.reduced.masa.polar_patches`).  These carry
    the local contact deformation that the nonlinear contact forces of MASA excite."""

    loads = []
    bc_local = np.asarray(ops.bc_dofs, dtype=int)
    for it, op in ops.contacts:
        comm = op.Gn.getComm().tompi4py()
        sizes = comm.allgather(len(op.weight))
        labels = polar_patches(_gather_rows(comm, op.x), patches[0], patches[1], axis)
        start = sum(sizes[:comm.rank])
        mine = labels[start:start + sizes[comm.rank]]
        row, b, t = op.Gn.createVecLeft(), op.Gn.createVecRight(), op.Gn.createVecRight()
        for j in range(patches[0] * patches[1]):
            if not np.any(labels == j):
                continue
            row.array[:] = op.weight * (mine == j)
            op.Gn.multTranspose(row, b)
            if it.has_friction:
                op.Gt1.multTranspose(row, t)
                b.axpy(it.mu, t)
            col = b.array_r.copy()
            col[bc_local[bc_local < len(col)]] = 0.0
            loads.append(col)
        for v in (row, b, t):
            v.destroy()
    if not loads:
        return np.zeros((ops.K.getLocalSize()[0], 0))
    return static_correction(ops.K, ops.M, np.column_stack(loads), (TWO_PI * sigma_hz) ** 2, options, prefix)


def reduce(ops: Operators, par: ParametricOperators, basis: Basis, preload=None) -> ReducedModel:
    """The affine reduced model on ``basis`` (module docstring of :mod:`fem_squeal.reduced.model`)."""
    Phi = basis.Phi
    K0 = project(ops.K, Phi)
    Kf1 = project(ops.Kf, Phi) / par.mu0 if ops.Kf is not None and par.mu0 != 0 else None
    C0 = project(ops.C, Phi) if ops.C is not None else None
    M = project(ops.M, Phi)
    err = np.max(np.abs(M - np.eye(basis.size)))
    if err > 1e-8:
        raise ReductionError(f"basis: not M-orthonormal (max |ΦᵀMΦ − I| = {err:.1e})")
    comm = ops.K.getComm().tompi4py()
    f = comm.allreduce(Phi.T @ ops.f.array_r, op=MPI.SUM) if ops.f is not None else None
    q_s = None
    if preload is not None:
        Mu = ops.M.createVecLeft()
        ops.M.mult(preload.u, Mu)
        q_s = comm.allreduce(Phi.T @ Mu.array_r, op=MPI.SUM)
        Mu.destroy()
    return ReducedModel(K0=K0, Kf1=Kf1, C0=C0, K_parts={p: project(A, Phi) for p, A in par.K_parts.items()},
                        E0=dict(par.E0), beta=dict(par.beta), mu0=par.mu0,
                        contacts=restrict_contacts(ops, Phi, preload), info=dict(basis.counts), f=f, q_static=q_s)


def lifted_residuals(par: ParametricOperators, Phi: np.ndarray, params: Mapping[str, float],
                     lam: np.ndarray, Y: np.ndarray) -> np.ndarray:
    """Backward error of each lifted pair (λ, x = Φy) in the full problem:
    η = ‖(λ²M + λC + K)x‖ / ((|λ|²‖M‖ + |λ|‖C‖ + ‖K‖)‖x‖), ∞-norms of the matrices, 2-norms of
    the vectors (Tisseur's normwise backward error of a polynomial eigenpair)."""
    K, C = par.matrices(params)
    comm = K.getComm().tompi4py()
    M = par.ops.M
    nK, nM = K.norm(PETSc.NormType.INFINITY), M.norm(PETSc.NormType.INFINITY)
    nC = C.norm(PETSc.NormType.INFINITY) if C is not None else 0.0
    X = Phi @ Y  # complex local rows
    KX = apply(K, X.real) + 1j * apply(K, X.imag)
    MX = apply(M, X.real) + 1j * apply(M, X.imag)
    R = KX + MX * lam[None, :] ** 2
    if C is not None:
        R += (apply(C, X.real) + 1j * apply(C, X.imag)) * lam[None, :]
        C.destroy()
    K.destroy()
    r = np.sqrt(comm.allreduce(np.sum(np.abs(R) ** 2, axis=0), op=MPI.SUM))
    x = np.sqrt(comm.allreduce(np.sum(np.abs(X) ** 2, axis=0), op=MPI.SUM))
    a = np.abs(lam)
    return r / ((a ** 2 * nM + a * nC + nK) * x)


@dataclass
class ReductionReport:
    """How the basis was grown: one row per round, and whether the change met ``tol``."""

    rounds: list[dict]
    converged: bool
    tol: float
    estimate: float               # max relative change of the watched eigenvalues in the last round
    residuals: list[dict]         # lifted backward errors of the unstable pairs at the check points

    def as_dict(self) -> dict:
        return {"rounds": self.rounds, "converged": self.converged, "tol": self.tol,
                "estimated_error": self.estimate, "lifted_residuals": self.residuals}


def _in_band(lam: np.ndarray, band_hz) -> np.ndarray:
    """Eigenvalues with frequency in the band, above 1e-3 of its top (rigid-body modes of free
    parts sit at λ ≈ 0, where a relative change means nothing)."""
    f = lam.imag / TWO_PI
    return lam[(f >= max(band_hz[0], 1e-3 * band_hz[1])) & (f <= band_hz[1])]


def _watched(lam: np.ndarray, growth_tol: float) -> np.ndarray:
    bad = lam.real > growth_tol * np.abs(lam)
    return lam[bad] if bad.any() else lam


def relative_change(new: np.ndarray, old: np.ndarray) -> float:
    """max over ``new`` of the distance to the nearest of ``old``, relative to |λ|."""
    if new.size == 0:
        return 0.0
    if old.size == 0:
        return np.inf
    return float(np.max(np.min(np.abs(new[:, None] - old[None, :]), axis=1) / np.abs(new)))


def adaptive_reduce(ops: Operators, par: ParametricOperators, band_hz: tuple[float, float],
                    check_points: list[dict[str, float]], *, tol: float = 1e-3,
                    cut_factors: tuple[float, ...] = (1.25, 1.6, 2.0, 2.5), samples=(), static: bool = True,
                    sigma_hz: float | None = None, growth_tol: float = 1e-6, enrich_rtol: float = 1e-3,
                    preload=None, options=None, log=None, extra: np.ndarray | None = None
                    ) -> tuple[ReducedModel, Basis, ReductionReport]:
    """Grow the basis (modes up to factor × the band's top, for each factor in turn) until the
    unstable eigenvalues in the band (all of them where none is unstable) at ``check_points``
    move by less than ``tol`` (relative) between two rounds.  The model of the last round is
    returned, with the change as its error estimate and the lifted residuals of its unstable
    pairs.  Raises :class:`ReductionError` with the history if ``tol`` is never met."""

    if len(cut_factors) < 2 or any(b <= a for a, b in zip(cut_factors, cut_factors[1:])):
        raise ModelError(f"cut_factors: need at least 2 increasing factors (got {list(cut_factors)})")
    rounds, prev, change, n_start = [], None, np.inf, 20
    comm = ops.K.getComm().tompi4py()
    for factor in cut_factors:
        t = MPI.Wtime()
        basis = build_basis(ops, par, factor * band_hz[1], samples=list(samples), static=static,
                            sigma_hz=sigma_hz, options=options, n_start=n_start, enrich_rtol=enrich_rtol,
                            extra=extra)
        n_start = basis.counts["modes"]
        model = reduce(ops, par, basis, preload)
        lams = [_in_band(solve_points(model, {k: np.array([v]) for k, v in p.items()})[0], band_hz)
                for p in check_points]
        if prev is not None:
            change = max(relative_change(_watched(a, growth_tol), b) for a, b in zip(lams, prev))
        rounds.append({"cut_hz": factor * band_hz[1], **basis.counts, "change": change,
                       "seconds": comm.allreduce(MPI.Wtime() - t, op=MPI.MAX)})
        if log:
            log(f"[fem_squeal] reduced basis: modes <= {factor * band_hz[1]:.0f} Hz, size {basis.size}, "
                f"change {change:.1e} ({rounds[-1]['seconds']:.1f} s)")
        prev = lams
        if len(rounds) < len(cut_factors):  # guess the next round's count (N ∝ f^1.5)
            nxt = cut_factors[len(rounds)]
            n_start = int(n_start * (nxt / factor) ** 1.5 * 1.1) + 4
        if change <= tol:
            break
    converged = change <= tol
    if not converged:
        raise ReductionError(
            f"reduced basis: eigenvalues still moved by {change:.1e} > tol {tol:.0e} with modes up to "
            f"{cut_factors[-1]:g} × {band_hz[1]:g} Hz; rounds: " +
            "; ".join(f"{r['size']} vectors: {r['change']:.1e}" for r in rounds) +
            " (raise analyses.reduced.cut_factors or tol)")
    residuals = []
    for p in check_points:
        lam, Y = solve_points(model, {k: np.array([v]) for k, v in p.items()}, vectors=True)
        lam, Y = lam[0], Y[0]
        f = lam.imag / TWO_PI
        sel = (f >= band_hz[0]) & (f <= band_hz[1]) & (lam.real > growth_tol * np.abs(lam))
        eta = lifted_residuals(par, basis.Phi, p, lam[sel], Y[:, sel]) if sel.any() else np.zeros(0)
        residuals.append({"point": p, "freq_hz": f[sel], "real_part": lam[sel].real, "backward_error": eta})
    model.info.update(cut_hz=rounds[-1]["cut_hz"], estimated_error=change)
    return model, basis, ReductionReport(rounds, converged, tol, change, residuals)
