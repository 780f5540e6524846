"""Full-order eigenvalues and their parameter derivatives (right and left vectors): the references of
the reduced model's."""
from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
from mpi4py import MPI

from fem_squeal.fe.eigen import (
    TWO_PI,
    solve_complex_modes,
    solve_left_vectors,
)
from fem_squeal.fe.projection.parametric import ParametricOperators, parameter_derivative
from fem_squeal.util.errors import EigenSolveError, ModelError


@dataclass
class FullSensitivity:
    """dλ/dp of one eigenvalue of the full model from its right and left eigenvectors."""

    eigenvalue: complex
    d_lambda: dict[str, complex]
    left_mismatch: float          # |λ of the transposed problem − λ| / |λ|
    residual: float               # the CEA's relative residual of the right vector


def full_sensitivities(par: ParametricOperators, eigenvalues: np.ndarray, names: list[str], band_hz,
                       *, options=None, prefix: str = "sens_", progress: bool = False) -> list[FullSensitivity]:
    """dλ/dp = −yᴴ(λ²∂M + λ∂C + ∂K)x / yᴴ(2λM + C)x (∂M = 0 here) of the full model at the nominal
    point, for the eigenvalues of the full CEA nearest ``eigenvalues`` (e.g. the reduced model's
    selected modes): x from the CEA (:func:`~fem_squeal.fe.eigen.solve_complex_modes` in ``band_hz``),
    y from the transposed problem (:func:`~fem_squeal.fe.eigen.solve_left_vectors`), both at the
    same shift.  A nominal loss factor (complex K) is not supported by the real-scalar CEA."""
    if any(v != 0 for v in par.eta0.values()):
        raise ModelError("full-order sensitivities: a part has a loss factor eta > 0 at the nominal point; the "
                         "real-scalar CEA has no complex stiffness (use the reduced sensitivities)")
    K, C = par.matrices({})
    M = par.ops.M
    want = np.asarray(eigenvalues, complex)
    f = want.imag / TWO_PI
    # the shift at the wanted modes (nearest first), 0.5 % off: a shift on an eigenvalue makes K − σM singular
    target = 1.005 * float(np.sqrt(np.mean(f ** 2)))
    nev = len(want) + 4
    for attempt in range(4):   # more pairs until every wanted eigenvalue has its own full one within 1 %
        cm = solve_complex_modes(K, M, C, nev, target, band_hz=tuple(band_hz), options=options, prefix=prefix,
                                 progress=progress)
        pick = [int(np.argmin(np.abs(cm.eigenvalues - x))) for x in want] if cm.eigenvalues.size else []
        ok = len(pick) == len(want) and len(set(pick)) == len(pick) and \
            all(abs(cm.eigenvalues[j] - x) <= 1e-2 * abs(x) for j, x in zip(pick, want))
        if ok or attempt == 3:
            break
        for v in (*cm.vectors_re, *cm.vectors_im):
            v.destroy()
        nev *= 2
    if not ok:
        raise EigenSolveError(f"full-order sensitivities: the full CEA ({nev} pairs near {target:.0f} Hz) has no "
                              "distinct eigenvalue within 1 % of each of " +
                              ", ".join(f"{x.imag / TWO_PI:.1f} Hz" for x in want))
    lam = cm.eigenvalues[pick]
    left = solve_left_vectors(K, M, C, lam, target, band_hz=tuple(band_hz), options=options,
                              prefix=prefix + "left_", progress=progress)
    derivs = {n: parameter_derivative(par, n) for n in names}
    tmp_r, tmp_i = K.createVecLeft(), K.createVecLeft()

    def zt(zr, zi, A, xr, xi) -> complex:
        """zᵀ A x for complex z, x given by their real and imaginary parts."""
        A.mult(xr, tmp_r)
        A.mult(xi, tmp_i)
        return complex(zr.dot(tmp_r) - zi.dot(tmp_i), zr.dot(tmp_i) + zi.dot(tmp_r))

    out = []
    try:
        for j, k in enumerate(pick):
            xr, xi, zr, zi, li = cm.vectors_re[k], cm.vectors_im[k], left.vectors_re[j], left.vectors_im[j], lam[j]
            den = 2 * li * zt(zr, zi, M, xr, xi) + (zt(zr, zi, C, xr, xi) if C is not None else 0.0)
            d = {}
            for n, (dK, dC, factor) in derivs.items():
                num = zt(zr, zi, dK, xr, xi) + (li * zt(zr, zi, dC, xr, xi) if dC is not None else 0.0)
                d[n] = complex(-factor * num / den)
            out.append(FullSensitivity(complex(li), d, float(left.mismatch[j]), float(cm.residuals[k])))
    finally:
        for A in (tmp_r, tmp_i, K, C, *cm.vectors_re, *cm.vectors_im, *left.vectors_re, *left.vectors_im,
                  *(m for dK, dC, _ in derivs.values() for m in (dK, dC))):
            if A is not None:
                A.destroy()
    return out


def full_modes(par: ParametricOperators, point: Mapping[str, float], nev: int, target_hz: float, *,
               band_hz: tuple[float, float] | None = None, options=None, prefix: str = "verify_",
               progress: bool = False, vectors: bool = False):
    """Eigenvalues (Im λ > 0, in ``band_hz``) of the full λ²M + λC + K(p) at ``point``: the CEA of
    :meth:`ParametricOperators.matrices`, or, when a part has a loss factor (K complex), the real
    problem of twice the size (:meth:`ParametricOperators.real_equivalent`) with 2·``nev`` pairs,
    of which those of Q(λ) are kept: their vectors are [x; −ix], i.e. ‖a − ib‖ ≪ ‖a + ib‖ for the
    halves a, b of the vector (those of Q̄, the mirrored spurious roots of K(1 − iη), are [x; ix]).
    ``vectors``: also the eigenvectors x (rank-local rows, complex, one column per eigenvalue)."""
    Ki = par.loss_stiffness(point)
    if Ki is None:
        K, C = par.matrices(point)
        M, n_ask = par.ops.M, nev
    else:
        Ki.destroy()
        K, C, M = par.real_equivalent(point)
        n_ask = 2 * nev
    cm = solve_complex_modes(K, M, C, n_ask, target_hz, band_hz=band_hz, options=options, prefix=prefix,
                             progress=progress)
    lam = cm.eigenvalues
    X = [xr.array_r + 1j * xi.array_r for xr, xi in zip(cm.vectors_re, cm.vectors_im)] if vectors else None
    if Ki is not None:
        comm = K.getComm().tompi4py()
        n = K.getLocalSize()[0] // 2
        keep = []
        for xr, xi in zip(cm.vectors_re, cm.vectors_im):
            v = xr.array_r + 1j * xi.array_r
            a, b = v[:n], v[n:]
            q, qbar = comm.allreduce(np.array([np.sum(np.abs(a - 1j * b) ** 2), np.sum(np.abs(a + 1j * b) ** 2)]),
                                     op=MPI.SUM)
            keep.append(q < qbar)
        lam = lam[np.array(keep, bool)]
        if vectors:
            X = [x[:n] for x, k in zip(X, keep) if k]
        M.destroy()
    for A in (K, C, *cm.vectors_re, *cm.vectors_im):
        if A is not None:
            A.destroy()
    if not vectors:
        return lam
    return lam, (np.column_stack(X) if X else np.zeros((par.ops.K.getLocalSize()[0], 0), complex))
