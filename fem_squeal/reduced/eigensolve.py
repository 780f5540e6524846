"""Dense quadratic eigen-solves of the reduced model, batched over parameter points.

(λ²I + λC + K)y = 0 with I the reduced mass (mass-orthonormal basis).  Undamped (C = 0): the
m eigenvalues θ of K give λ = i√θ (principal root, Im λ ≥ 0; a flutter pair θ, θ̄ gives the two
roots ±σ + iω); a real θ < 0 (divergence) gives the unstable root +√|θ|.  Damped: the companion
form [[0, I], [−K, −C]] of size 2m; the m roots with the largest imaginary parts are kept (one of
each conjugate pair).  K may be complex (a loss factor η: K(1 + iη)); the roots are then no longer
in conjugate pairs and the m kept are those of the positive frequencies (module docstring of
:mod:`fem_squeal.reduced.model`).  Either way every point returns m eigenvalues, sorted by frequency, and
(optionally) the m-vectors y, unit 2-norm (= unit mass norm of the lifted Φy).
"""
from __future__ import annotations

import numpy as np
from scipy.linalg import eig

TWO_PI = 2.0 * np.pi


def _roots_from_theta(theta: np.ndarray) -> np.ndarray:
    lam = 1j * np.sqrt(theta.astype(complex))
    div = (np.abs(theta.imag) <= 1e-14 * np.abs(theta)) & (theta.real < 0)
    return np.where(div, np.sqrt(np.abs(theta.real)) + 0j, lam)


def quadratic_eigs(K: np.ndarray, C: np.ndarray | None = None, vectors: bool = False):
    """Eigenvalues λ (…, m), sorted by Im λ then Re λ, of λ²I + λC + K for stacks K (…, m, m).

    ``vectors``: also the eigenvectors Y (…, m, m), column j for λ_j, unit 2-norm."""
    K = np.asarray(K)
    m = K.shape[-1]
    if C is None:
        if vectors:
            theta, Y = np.linalg.eig(K)
        else:
            theta, Y = np.linalg.eigvals(K), None
        lam = _roots_from_theta(theta)
    else:
        shape = K.shape[:-2]
        A = np.zeros(shape + (2 * m, 2 * m), np.result_type(K, np.asarray(C), float))
        A[..., :m, m:] = np.eye(m)
        A[..., m:, :m] = -K
        A[..., m:, m:] = -np.asarray(C)
        if vectors:
            mu, Z = np.linalg.eig(A)
        else:
            mu, Z = np.linalg.eigvals(A), None
        keep = np.argsort(-mu.imag - 1e-9 * mu.real, axis=-1, kind="stable")[..., :m]
        lam = np.take_along_axis(mu, keep, axis=-1)
        if vectors:
            Y = np.take_along_axis(Z[..., :m, :], keep[..., None, :], axis=-1)
            Y = Y / np.linalg.norm(Y, axis=-2, keepdims=True)
    order = np.lexsort((lam.real, np.round(lam.imag, 9)), axis=-1)
    lam = np.take_along_axis(lam, order, axis=-1)
    if not vectors:
        return lam
    Y = np.take_along_axis(Y, order[..., None, :], axis=-1)
    return lam, Y


#: a band's elastic modes start at this share of its top: below it sit the rigid-body modes of free parts
#: (λ ≈ 0, f of round-off), where a relative error or a growth rate Re λ > growth_tol|λ| means nothing
RIGID_SHARE = 1e-3


def band_centre_hz(band_hz) -> float:
    """The root mean square of the band's ends, √((f₀² + f₁²)/2) [Hz]: the target that a shift-and-invert
    eigensolve of the band centres on (ω² halfway between the ends')."""
    return float(np.sqrt(0.5 * (band_hz[0] ** 2 + band_hz[1] ** 2)))


def in_band(lam: np.ndarray, band_hz) -> np.ndarray:
    """The mask of eigenvalues with f = Im λ/2π in ``band_hz``, above :data:`RIGID_SHARE` of its top."""
    f = np.asarray(lam).imag / TWO_PI
    return (f >= max(band_hz[0], RIGID_SHARE * band_hz[1])) & (f <= band_hz[1])


def unstable(lam: np.ndarray, growth_tol: float = 1e-6) -> np.ndarray:
    """Re λ > growth_tol·|λ| (i.e. damping ratio ζ < −growth_tol).

    The default 1e-6 sits well above the round-off of a dense eigen-solve (~1e-12 relative for
    the bases used here) and well below any growth an NVH engineer acts on (ζ ~ −1e-3)."""
    return lam.real > growth_tol * np.abs(lam)


def eig_left_right(K: np.ndarray, C: np.ndarray | None = None):
    """Eigenvalues λ (m, sorted as :func:`~fem_squeal.reduced.eigensolve.quadratic_eigs`) of
    λ²I + λC + K with right and left eigenvectors X, Y (columns), from the companion form
    (right vector [x; λx], left vector [(λI + C)ᴴy; y] of A = [[0, I], [−K, −C]]).  K may be
    complex (a loss factor): the m roots with the largest Im λ are kept, as in quadratic_eigs."""
    K = np.asarray(K)
    K = K.astype(np.result_type(K, float))
    m = K.shape[0]
    Cm = np.zeros_like(K) if C is None else np.asarray(C)
    A = np.zeros((2 * m, 2 * m), np.result_type(K, Cm))
    A[:m, m:] = np.eye(m)
    A[m:, :m] = -K
    A[m:, m:] = -Cm
    mu, WL, WR = eig(A, left=True, right=True)
    keep = np.argsort(-mu.imag - 1e-9 * mu.real, kind="stable")[:m]
    lam, X, Y = mu[keep], WR[:m, keep], WL[m:, keep]
    order = np.lexsort((lam.real, np.round(lam.imag, 9)))
    return lam[order], X[:, order], Y[:, order]


def condition_numbers(K: np.ndarray, C: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Eigenvalues λ (as :func:`quadratic_eigs`: m of them, sorted) of λ²I + λC + K and their
    condition numbers (Tisseur 2000, Theorem 5; 2-norms, relative perturbations of K, C, I)

        κ(λ) = (|λ|² + |λ|‖C‖ + ‖K‖) ‖x‖ ‖y‖ / (|λ| |yᴴ(2λI + C)x|)

    with x, y the right and left eigenvectors, taken from the companion form A = [[0, I], [−K, −C]]:
    its right vector is [x; λx] and its left vector [(λI + C)ᴴy; y].  κ is ~1 for a well-separated
    eigenvalue of a normal problem and grows as |μ − μ_c|^(−1/2) towards an exceptional point
    (two eigenvalues and their eigenvectors coalesce, yᴴ(2λI + C)x → 0); there the eigenvalue
    error of a backward-stable solve is ~κ ε."""
    K = np.asarray(K)
    K = K.astype(np.result_type(K, float))
    Cm = np.zeros_like(K) if C is None else np.asarray(C)
    lam, X, Y = eig_left_right(K, C)
    nK, nC = np.linalg.norm(K, 2), np.linalg.norm(Cm, 2)
    al = np.abs(lam)
    den = al * np.abs(np.einsum("ij,ij->j", Y.conj(), 2 * lam * X + Cm @ X))
    num = (al ** 2 + al * nC + nK) * np.linalg.norm(X, axis=0) * np.linalg.norm(Y, axis=0)
    return lam, np.where(den > 0, num / np.where(den > 0, den, 1.0), np.inf)
