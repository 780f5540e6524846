"""Frequency-dependent loss factors on the reduced model: a fixed point in frequency per mode.

A part p with a loss factor η_p(f) (a shim's table at one temperature,
:class:`~fem_squeal.reduced.laws.loss_factor.LossTable`) damps a mode with η_p at the mode's own
frequency.  The mode's eigenvalue λ solves the nonlinear eigenproblem

    T(λ) y = (λ²I + λC + K_r + i Σ_p η_p(|Im λ|/2π) θ_p K_p) y = 0

(θ_p = E_p/E_p⁰): λ is an eigenvalue of the QEP with η frozen at η(|Im λ|/2π), the fixed point in
frequency of the mode.  Each mode j is found from its pair (λ_j, y_j) of a start solve (η at a
reference frequency) by residual inverse iteration on T (Neumaier 1985: one m × m LU, factorised again
only where the convergence slows, η evaluated at each iterate's own frequency inside the scalar
equation for λ; :func:`_mode`), until |λ_{k+1} − λ_k| ≤ tol·|λ_{k+1}| (converged), or ``max_iterations``
(not converged: reported, with the last iterate), or until f leaves a table's frequency range (not
converged: ``left_table``).  A mode that ends on the eigenvalue of an earlier one has lost its track
(``merged``: not converged).  A mode whose start frequency gives the start η (a constant table) is
its start pair: the constant-η eigenvalues bit for bit, converged at the first iteration.
It replaced a fixed point that solved the whole reduced QEP at every iterate's η and followed the mode
by its MAC: the Ryzhik ring's operating matrix (192 vectors, 36 band modes) took 7.7 s a condition
with it, and lost two modes' tracks near 9.5 kHz.
"""
from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass

import numpy as np
import scipy.linalg

from fem_squeal.reduced.eigensolve import TWO_PI
from fem_squeal.util.errors import ModelError

#: η of every table part → (K, C) of the reduced model with those loss factors (C None: undamped)
Matrices = Callable[[Mapping[str, float]], tuple[np.ndarray, np.ndarray | None]]


@dataclass
class FixedPointResult:
    """Per mode (the ``modes`` asked, in their order): the eigenvalue at the fixed point (the last
    iterate where not converged), the iterations, whether it converged, whether it left a table's
    frequency range, and η of every part at its final frequency; ``solves``: the dense solves (the start
    QEP and the modes' m × m factorisations)."""

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


def _affine_in_eta(matrices: Matrices, parts: list[str]) -> tuple[np.ndarray, np.ndarray | None, list[np.ndarray]]:
    """(K₀, C, [D_p]) with K(η) = K₀ + Σ_p η_p D_p: the reduced stiffness is affine in the loss factors
    (i η_p θ_p K_p), the damping does not depend on them."""
    K0, C = matrices({p: 0.0 for p in parts})
    D = [matrices({q: float(q == p) for q in parts})[0] - K0 for p in parts]
    return np.asarray(K0, complex), C, D


def scalar_root(a2: complex, a1: complex, a0: complex, terms: Sequence[tuple[Callable[[float], float], complex]],
                lam: complex, tol: float = 1e-15, max_iterations: int = 200) -> complex:
    """The root near ``lam`` of a2λ² + a1λ + a0 + Σ_p η_p(|Im λ|/2π) a_p = 0, ``terms`` the pairs (η_p, a_p):
    the scalar equation of residual inverse iteration on T(λ), solved by the fixed point in f (here, on
    the reduced model, and in :mod:`fem_squeal.fe.projection.loss_nep`, on the full one)."""
    for _ in range(max_iterations):
        f = abs(lam.imag) / TWO_PI
        roots = np.roots([a2, a1, a0 + sum(float(law(f)) * a for law, a in terms)])
        new = complex(roots[np.argmin(np.abs(roots - lam))])
        if abs(new - lam) <= tol * abs(new):
            return new
        lam = new
    return lam


def _mode(K0: np.ndarray, C: np.ndarray | None, D: list[np.ndarray], laws: list[Callable[[float], float]],
          lam: complex, y: np.ndarray, tol: float, max_iterations: int) -> tuple[complex, int, bool, int]:
    """One mode of T(λ) = λ²I + λC + K₀ + Σ_p η_p(|Im λ|/2π) D_p from (λ, y) by residual inverse iteration
    (Neumaier 1985; as :mod:`fem_squeal.fe.projection.loss_nep` on the full model): w = T(σ)⁻ᴴc, λ the root
    of wᴴT(λ)x = 0 (η at the root's own frequency), x ← x − T(σ)⁻¹T(λ)x; T(σ) factorised again at the
    current λ when a step shrinks by less than 10 (linear convergence, rate |λ − σ|/gap).  Returns (λ,
    iterations, converged, factorisations); raises the laws' ModelError when f leaves a table."""
    m = K0.shape[0]
    eye = np.eye(m)

    def T(s: complex) -> np.ndarray:
        f = abs(s.imag) / TWO_PI
        A = s * s * eye + K0 + sum(float(law(f)) * Dp for law, Dp in zip(laws, D))
        return A + s * C if C is not None else A

    c = y / np.linalg.norm(y)
    x = c / np.vdot(c, c)
    lu, n_lu, last = None, 0, np.inf
    for k in range(max_iterations):
        if lu is None:
            lu = scipy.linalg.lu_factor(T(lam), check_finite=False)
            w = scipy.linalg.lu_solve(lu, c, trans=2, check_finite=False)
            n_lu += 1
        Cx = C @ x if C is not None else np.zeros(m)
        new = scalar_root(np.vdot(w, x), np.vdot(w, Cx), np.vdot(w, K0 @ x),
                          [(law, np.vdot(w, Dp @ x)) for law, Dp in zip(laws, D)], lam, max_iterations=100)
        x = x - scipy.linalg.lu_solve(lu, T(new) @ x, check_finite=False)
        x = x / np.vdot(c, x)
        step = abs(new - lam)
        lam = new
        if step <= tol * abs(lam):
            return lam, k + 1, True, n_lu
        if step > 0.1 * last:
            lu = None
        last = step
    return lam, max_iterations, False, n_lu


def fixed_point(matrices: Matrices, laws: Mapping[str, Callable[[float], float]], start: np.ndarray,
                vectors: np.ndarray, modes: Sequence[int], *, tol: float = 1e-10,
                max_iterations: int = 50, start_eta: Mapping[str, float] | None = None) -> FixedPointResult:
    """The fixed point in frequency (module docstring) of modes ``modes`` of a start solve (eigenvalues
    ``start`` (m,), unit vectors ``vectors`` (m, m) of the reduced QEP at the loss factors ``start_eta``):
    each mode's λ with λ an eigenvalue of the QEP at η(|Im λ|/2π), from its start pair by residual inverse
    iteration on its own m × m factorisation (:func:`_mode`; a start where η(f) is ``start_eta`` is
    already the answer); ``laws``: part → η_p(f) (raising a ModelError outside its table)."""
    if not tol > 0 or max_iterations < 1:
        raise ModelError(f"fixed point: tol must be > 0 and max_iterations >= 1 (got {tol}, {max_iterations})")
    parts = list(laws)
    K0, C, D = _affine_in_eta(matrices, parts)
    fs = [laws[p] for p in parts]
    n = len(modes)
    lam_out = np.empty(n, complex)
    its, conv, left = np.zeros(n, int), np.zeros(n, bool), np.zeros(n, bool)
    eta_out = {p: np.full(n, np.nan) for p in parts}
    n_lu = 0
    for q, j in enumerate(modes):
        lam = complex(start[j])
        try:
            at_start = {p: float(laws[p](abs(lam.imag) / TWO_PI)) for p in parts}
            if start_eta is not None and all(at_start[p] == start_eta.get(p) for p in parts):
                lam_out[q], its[q], conv[q] = lam, 1, True
            else:
                lam_out[q], its[q], conv[q], lus = _mode(K0, C, D, fs, lam, vectors[:, j], tol, max_iterations)
                n_lu += lus
            for p in parts:
                eta_out[p][q] = float(laws[p](abs(lam_out[q].imag) / TWO_PI))
        except ModelError:
            left[q], lam_out[q] = True, lam
    # two modes that end on one eigenvalue: the later one lost its track (not converged, reported)
    merged = np.zeros(n, bool)
    for q in range(1, n):
        if np.any(np.abs(lam_out[:q] - lam_out[q]) <= 10 * tol * abs(lam_out[q])):
            merged[q], conv[q] = True, False
    return FixedPointResult(np.asarray(start)[list(modes)], lam_out, its, conv, left, eta_out, 1 + n_lu, merged)
