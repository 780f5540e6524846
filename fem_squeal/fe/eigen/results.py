"""The results of the eigensolvers (real modes, complex modes) and their checks: the relative residual
of a quadratic eigenpair, the ordering of eigenvalues, the M-normalisation, the check of a solve's
pairs."""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from mpi4py import MPI
from petsc4py import PETSc

from fem_squeal.fe.dense import apply
from fem_squeal.util.errors import EigenSolveError

TWO_PI = 2.0 * np.pi



@dataclass
class RealModes:
    """Real modes of K φ = ω² M φ, M-normalised (φᵀMφ = 1)."""

    omega2: np.ndarray            # ω² [rad²/s²], ascending
    vectors: list[PETSc.Vec]
    residuals: np.ndarray         # ‖Kφ − ω²Mφ‖ / (‖K‖ ‖φ‖)
    solver: str = ""              # the factorisation used: "cholmod", "cholmod-substructured" or "mumps"
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
    algorithm: str = ""    # "block Arnoldi, <b> columns", "Krylov-Schur" (", stopped at the band") or "TOAR"

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


def _add_times(A, cr: float, ci: float, xr: PETSc.Vec, xi: PETSc.Vec, rr: PETSc.Vec, ri: PETSc.Vec,
               t: PETSc.Vec) -> None:
    """rr + i ri += (cr + i ci) A (xr + i xi), in real arithmetic (t: workspace)."""
    A.mult(xr, t)
    rr.axpy(cr, t)
    ri.axpy(ci, t)
    A.mult(xi, t)
    rr.axpy(-ci, t)
    ri.axpy(cr, t)


def quadratic_residual(K, C, M, lam: complex, xr: PETSc.Vec, xi: PETSc.Vec) -> float:
    """‖(λ²M + λC + K)x‖₂ / (‖K‖_∞ ‖x‖₂) for x = xr + i xi, in real arithmetic."""
    a, b = lam.real, lam.imag
    l2r, l2i = a * a - b * b, 2 * a * b
    rr, ri, t = xr.duplicate(), xr.duplicate(), xr.duplicate()
    K.mult(xr, rr)
    K.mult(xi, ri)
    _add_times(M, l2r, l2i, xr, xi, rr, ri, t)
    if C is not None:
        _add_times(C, a, b, xr, xi, rr, ri, t)
    num = np.hypot(rr.norm(), ri.norm())
    den = _norm_inf(K) * np.hypot(xr.norm(), xi.norm())
    for w in (rr, ri, t):
        w.destroy()
    return float(num / den)


def _squares(Z: np.ndarray) -> np.ndarray:
    """Σ_i |Z_ij|² per column (this rank's rows)."""
    return np.einsum("ij,ij->j", Z.real, Z.real) + np.einsum("ij,ij->j", Z.imag, Z.imag)


#: pairs per block of :func:`normalised_residuals` (the block and its products: 5 arrays of 2 columns per pair)
RESIDUAL_BLOCK = 32


def normalised_residuals(K: PETSc.Mat, C: PETSc.Mat | None, M: PETSc.Mat, lams: np.ndarray,
                         xrs: list[PETSc.Vec], xis: list[PETSc.Vec]) -> np.ndarray:
    """Every pair (λ_j, x_j = xr_j + i xi_j) M-normalised in place, x^H M x = 1 with the phase making
    xᵀMx real and ≥ 0 (a fixed, mesh-independent convention: a standing mode becomes real), and its
    residual ‖(λ²M + λC + K)x‖₂ / (‖K‖_∞ ‖x‖₂) as :func:`quadratic_residual` gives it, on blocks of
    :data:`RESIDUAL_BLOCK` pairs: one block product with K, M (and C) and one sum over the ranks per
    block, instead of six products, ten reductions and ‖K‖_∞ per pair (brake corner, 348k DOFs, 2 ranks,
    91 pairs: 7.4 s before)."""
    comm = M.getComm().tompi4py()
    k_inf = _norm_inf(K)
    res = np.empty(len(lams))
    for a in range(0, len(lams), RESIDUAL_BLOCK):
        js = range(a, min(a + RESIDUAL_BLOCK, len(lams)))
        X = np.empty((M.getLocalSize()[0], 2 * len(js)), order="F")
        for c, j in enumerate(js):
            X[:, 2 * c], X[:, 2 * c + 1] = xrs[j].array_r, xis[j].array_r
        MX = apply(M, X)
        xr, xi, mr, mi = X[:, 0::2], X[:, 1::2], MX[:, 0::2], MX[:, 1::2]
        dots = comm.allreduce(np.stack([np.einsum("ij,ij->j", xr, mr), np.einsum("ij,ij->j", xi, mi),
                                        np.einsum("ij,ij->j", xr, mi)]), op=MPI.SUM)
        mass = dots[0] + dots[1]
        q = (dots[0] - dots[1]) + 2j * dots[2]               # xᵀMx (no conjugate): its phase is removed
        phase = np.where(np.abs(q) > 1e-14 * mass, np.exp(-0.5j * np.angle(q)), 1.0)
        s = phase / np.sqrt(mass)
        Xc = (xr + 1j * xi) * s                               # x ← s x; M x, K x follow linearly
        MXc = (mr + 1j * mi) * s
        for c, j in enumerate(js):
            xrs[j].array[:], xis[j].array[:] = Xc[:, c].real, Xc[:, c].imag
        X[:, 0::2], X[:, 1::2] = Xc.real, Xc.imag
        KX = apply(K, X)
        lam = np.asarray(lams[a:a + len(js)], dtype=complex)
        R = KX[:, 0::2] + 1j * KX[:, 1::2] + lam ** 2 * MXc
        if C is not None:
            CX = apply(C, X)
            R += lam * (CX[:, 0::2] + 1j * CX[:, 1::2])
        sums = comm.allreduce(np.stack([_squares(R), _squares(Xc)]), op=MPI.SUM)
        res[a:a + len(js)] = np.sqrt(sums[0]) / (k_inf * np.sqrt(sums[1]))
    return res


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
