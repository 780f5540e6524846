"""Frequency-dependent loss factors on the reduced model: a fixed point in frequency per mode.

A part p with a loss factor η_p(f) (a shim's table at one temperature,
:class:`~fem_squeal.reduced.laws.loss_factor.LossTable`) damps a mode with η_p at the mode's own
frequency.  The mode's eigenvalue λ solves the nonlinear eigenproblem

    T(λ) y = (λ²I + λC + K_r + i Σ_p η_p(|Im λ|/2π) θ_p K_p) y = 0

(θ_p = E_p/E_p⁰), found per mode j by the fixed point

    f_k = |Im λ_k|/2π,   η_p = η_p(f_k),   λ_{k+1} = the eigenvalue of the reduced QEP with η frozen that
                                           continues mode j (largest MAC of its vector with y_k among the
                                           eigenvalues nearest λ_k)

until |λ_{k+1} − λ_k| ≤ tol·|λ_{k+1}| (converged), or ``max_iterations`` (not converged: reported, with
the last iterate), or until f leaves a table's frequency range (not converged: ``left_table``).  A mode
that ends on the eigenvalue of an earlier one has lost its track (``merged``: not converged).  The
QEPs of equal η are solved once (a constant table: one solve for every mode, which returns the
constant-η eigenvalues bit for bit, converged at the first iteration).
"""
from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from fem_squeal.reduced.eigensolve import TWO_PI, quadratic_eigs
from fem_squeal.util.errors import ModelError

#: η of every table part → (K, C) of the reduced model with those loss factors (C None: undamped)
Matrices = Callable[[Mapping[str, float]], tuple[np.ndarray, np.ndarray | None]]


@dataclass
class FixedPointResult:
    """Per mode (the ``modes`` asked, in their order): the eigenvalue at the fixed point (the last
    iterate where not converged), the iterations (QEP solves along its path), whether it converged,
    whether it left a table's frequency range, and η of every part at its final frequency."""

    start: np.ndarray
    eigenvalues: np.ndarray
    iterations: np.ndarray
    converged: np.ndarray
    left_table: np.ndarray
    eta: dict[str, np.ndarray]
    solves: int
    merged: np.ndarray | None = None       # ended on the eigenvalue of an earlier mode (tracking lost)

    def summary(self) -> dict:
        """For results.json: counts, the iterations, and the modes that did not converge."""
        bad = np.flatnonzero(~self.converged)
        merged = self.merged if self.merged is not None else np.zeros(self.converged.shape, bool)
        return {"modes": int(self.eigenvalues.size), "converged": int(self.converged.sum()),
                "max_iterations_used": int(self.iterations.max(initial=0)), "qep_solves": int(self.solves),
                "not_converged": [{"frequency_hz": float(abs(self.eigenvalues[j].imag) / TWO_PI),
                                   "iterations": int(self.iterations[j]), "left_table": bool(self.left_table[j]),
                                   "merged": bool(merged[j])} for j in bad]}


def _solve(matrices: Matrices, eta: Mapping[str, float]) -> tuple[np.ndarray, np.ndarray]:
    K, C = matrices(eta)
    return quadratic_eigs(K[None], None if C is None else C[None], vectors=True)


def _follow(lam: np.ndarray, Y: np.ndarray, lam0: complex, y0: np.ndarray, nearest: int = 4) -> int:
    """The index of the eigenvalue that continues (λ₀, y₀): the largest MAC |y₀ᴴy|² / (‖y₀‖²‖y‖²)
    among the ``nearest`` eigenvalues closest to λ₀ (ties: the closest)."""
    near = np.argsort(np.abs(lam - lam0), kind="stable")[:nearest]
    mac = np.abs(y0.conj() @ Y[:, near]) ** 2 / (np.vdot(y0, y0).real * np.sum(np.abs(Y[:, near]) ** 2, axis=0))
    return int(near[np.argmax(np.round(mac, 12))])


def fixed_point(matrices: Matrices, laws: Mapping[str, Callable[[float], float]], start: np.ndarray,
                vectors: np.ndarray, modes: Sequence[int], *, tol: float = 1e-10,
                max_iterations: int = 50) -> FixedPointResult:
    """The fixed point in frequency (module docstring) of modes ``modes`` of a start solve (eigenvalues
    ``start`` (m,), unit vectors ``vectors`` (m, m) of the reduced QEP at the start η); ``laws``: part →
    η_p(f) (raising a ModelError outside its table)."""
    if not tol > 0 or max_iterations < 1:
        raise ModelError(f"fixed point: tol must be > 0 and max_iterations >= 1 (got {tol}, {max_iterations})")
    cache: dict[tuple, tuple[np.ndarray, np.ndarray]] = {}
    parts = list(laws)
    n = len(modes)
    lam_out = np.empty(n, complex)
    its, conv, left = np.zeros(n, int), np.zeros(n, bool), np.zeros(n, bool)
    eta_out = {p: np.full(n, np.nan) for p in parts}
    for q, j in enumerate(modes):
        lam, y = complex(start[j]), vectors[:, j]
        for k in range(max_iterations):
            f = abs(lam.imag) / TWO_PI
            try:
                eta = {p: float(laws[p](f)) for p in parts}
            except ModelError:
                left[q] = True
                break
            for p in parts:
                eta_out[p][q] = eta[p]
            key = tuple(eta[p] for p in parts)
            if key not in cache:
                cache[key] = _solve(matrices, eta)
            lams, Y = cache[key]
            i = _follow(lams[0], Y[0], lam, y)
            new, y = complex(lams[0][i]), Y[0][:, i]
            its[q] = k + 1
            done = abs(new - lam) <= tol * abs(new)
            lam = new
            if done:
                conv[q] = True
                break
        lam_out[q] = lam
    # two modes that end on one eigenvalue: the later one lost its track (not converged, reported)
    merged = np.zeros(n, bool)
    for q in range(1, n):
        if np.any(np.abs(lam_out[:q] - lam_out[q]) <= 10 * tol * abs(lam_out[q])):
            merged[q], conv[q] = True, False
    return FixedPointResult(np.asarray(start)[list(modes)], lam_out, its, conv, left, eta_out, len(cache), merged)
