"""Mode coupling: which real modes make up a complex mode (the engineer's "coupling pair").

A complex mode x with coefficients c = ΦᵀMx on M-orthonormal real modes Φ (for the full CEA:
:mod:`fem_squeal.fe.coupling`; for the reduced model, whose basis Φ is M-orthonormal with the real
modes first, c is the modal part of the eigenvector's basis coordinates q, and ‖x‖²_M = ‖q‖²) has

    participation of real mode i    p_i = 100 |c_i|² / Σ_j |c_j|²   [%]   (Σ_i p_i = 100)
    outside the real modes          r   = 1 − Σ_j |c_j|² / ‖x‖²_M          (the basis-norm residual)

r is the share of the mode's M-norm (its kinetic energy) that the real modes kept do not represent:
0 to round-off when they span x; a few per cent where static corrections or modes above the cut
carry part of it.  The coupling pair is the two real modes of largest p.  Real modes of equal
frequency (the cos/sin pair of an axisymmetric disc) are any orthonormal basis of their eigenspace:
their individual p_i depend on it (on the solver, on the number of ranks), their sum does not
(:func:`group_sums`).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg

#: the real modes every coupling of fem_squeal is read on unless told otherwise: those of the reduced basis
#: (the μ sweep's, the map's, the operating matrix's) and of the projected CEA, so that a real mode has one
#: number in every table of a run (numbered by frequency: up to the order inside a degenerate pair, and as
#: far as both cuts reach; results.json: cea_coupling.basis)
FRICTIONLESS_MODES = ("real modes of the frictionless symmetric K (elasticity, springs, closed contacts) and M, "
                      "those of the reduced basis and the projected CEA, numbered from 0 by frequency")


@dataclass
class RealModeCoefficients:
    """Coefficients c = ΦᵀMx of complex modes on real modes (``coefficients[i, j]``: real mode i,
    complex mode j), the real modes' frequencies and each complex mode's M-norm ‖x‖²_M.  The real
    modes themselves (rank-local rows, for their descriptors) are ``Phi`` or, where ``rotation`` is
    given, ``Phi @ rotation`` (a basis block spanning them: the projected CEA's, :meth:`columns`)."""

    freqs_hz: np.ndarray          # (n_real,) ascending
    coefficients: np.ndarray      # (n_real, n_modes) complex
    norms: np.ndarray             # (n_modes,) x^H M x
    f_max_hz: float               # every real mode up to this frequency is in Φ
    Phi: np.ndarray | None = None
    rotation: np.ndarray | None = None
    basis: str = ""               # what the real modes are (the report's words)

    def columns(self, which: list[int]) -> np.ndarray:
        """The real modes ``which`` (rank-local rows)."""
        return self.Phi[:, which] if self.rotation is None else self.Phi @ self.rotation[:, which]


def participation(C: np.ndarray, norms: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(p [%], r): the participation of each real mode (rows of ``C``) in each complex mode (its
    columns) and the share of each complex mode's M-norm (``norms`` = ‖x‖²_M) outside the real modes."""
    C = np.atleast_2d(C)
    e = np.abs(C) ** 2
    total = e.sum(axis=0)
    p = 100.0 * e / np.where(total > 0, total, 1.0)
    r = 1.0 - total / np.where(np.asarray(norms) > 0, norms, 1.0)
    return p, r


def modal_part(Y: np.ndarray, n_modes: int) -> tuple[np.ndarray, np.ndarray]:
    """(c, ‖x‖²_M) of reduced eigenvectors ``Y`` (columns; basis M-orthonormal, real modes first):
    c = Y[:n_modes], ‖x‖²_M = ‖y‖²."""
    return Y[:n_modes], np.sum(np.abs(Y) ** 2, axis=0)


def summary(p: np.ndarray, r: float, freqs_hz: np.ndarray, min_percent: float = 1.0, top: int = 8) -> dict:
    """One complex mode's coupling (its column ``p`` of :func:`participation`, its outside share ``r``):
    the real modes of participation ≥ ``min_percent`` (at most ``top``, largest first; the largest
    always), their frequencies, the pair (the first two of them: one mode where a single real mode
    carries the complex mode) and the label "real modes 43 (48 %) and 44 (41 %)"."""
    order = np.lexsort((np.arange(len(p)), -np.round(p, 6)))    # ties (a pair split 50/50) by index
    keep = [int(i) for i in order[:top] if p[i] >= min_percent] or [int(i) for i in order[:1]]
    percent = [float(p[i]) for i in keep]
    return {"real_modes": keep, "percent": percent, "real_freqs_hz": [float(freqs_hz[i]) for i in keep],
            "outside": float(r), "pair": keep[:2], "label": label(keep, percent)}


def label(modes: list[int], percent: list[float]) -> str:
    """"real modes 43 (48 %) and 44 (41 %)" (or "real mode 3 (99 %)" for one)."""
    parts = [f"{i} ({q:.0f} %)" for i, q in zip(modes[:2], percent[:2])]
    return "real mode " + parts[0] if len(parts) == 1 else "real modes " + " and ".join(parts)


def degenerate_groups(freqs_hz: np.ndarray, rtol: float = 1e-3, rigid_hz: float = 1.0) -> list[list[int]]:
    """Real modes grouped by frequency (consecutive modes within ``rtol`` of each other: a degenerate
    pair of an axisymmetric part, split by the mesh's round-off or slightly by its asymmetry; and the
    rigid-body modes, |f| < ``rigid_hz``, whose computed frequencies are round-off around 0)."""
    groups: list[list[int]] = []
    f = np.asarray(freqs_hz)
    for i in range(len(f)):
        if groups and (abs(f[i] - f[groups[-1][-1]]) <= rtol * max(abs(f[i]), 1.0)
                       or max(abs(f[i]), abs(f[groups[-1][-1]])) < rigid_hz):
            groups[-1].append(i)
        else:
            groups.append([i])
    return groups


def group_sums(p: np.ndarray, groups: list[list[int]]) -> np.ndarray:
    """The participations summed over each group of :func:`degenerate_groups` (rows: groups): the
    numbers that do not depend on the basis chosen inside a degenerate eigenspace."""
    return np.array([p[g].sum(axis=0) for g in groups])


def basis_modes(K0: np.ndarray, n_modes: int) -> tuple[np.ndarray, np.ndarray]:
    """The real modes in the reduced basis: its first ``n_modes`` columns span the nominal frictionless
    modes (M-orthonormal, but rotated among themselves by the basis' orthonormalisation), so the modes
    are their combinations V of ½(K₀ + K₀ᵀ)_nn V = V diag(ω²) (M = I there).  Returns the frequencies
    [Hz] (ascending) and V (n_modes × n_modes, orthonormal columns)."""
    A = np.asarray(K0)[:n_modes, :n_modes]
    w2, V = np.linalg.eigh(0.5 * (A + A.T))
    return np.sign(w2) * np.sqrt(np.abs(w2)) / (2 * np.pi), V


def coupling_at(solve, value: float, target: complex, modes: tuple[np.ndarray, np.ndarray]) -> dict:
    """The coupling (:func:`summary`) on the real modes ``modes`` = (frequencies, V) of :func:`basis_modes`
    of the reduced model's eigenvalue nearest ``target`` at parameter ``value`` (``solve(p) -> (λ, Y)``:
    the reduced eigenpairs, columns of Y).  For a change of stability, take a grid value next to it on
    its unstable side and the tracked eigenvalue there (:func:`fem_squeal.app.analyses.sweep`): a
    coalescence is an exceptional point, where the eigenvector is determined to √ε only."""
    freqs_hz, V = modes
    lam, Y = solve(value)
    j = int(np.argmin(np.abs(lam - target)))
    c, norms = modal_part(Y[:, [j]], V.shape[0])
    p, r = participation(V.T @ c, norms)
    return summary(p[:, 0], float(r[0]), freqs_hz)


def eigenvector(K: np.ndarray, C: np.ndarray | None, lam: complex, iterations: int = 2) -> np.ndarray:
    """The right eigenvector y of (λ²I + λC + K) y = 0 (reduced, M = I) at a known eigenvalue λ, by inverse
    iteration with the shift λ(1 + 10⁻¹³) (an exact λ may give an exactly singular LU): the other
    eigenvectors' parts shrink by |δ/gap| per step, δ ≈ 10⁻¹³|λ| plus the eigenvalue's own round-off.
    Costs one LU of m × m (milliseconds at m = 300) instead of the whole eigenvector matrix."""
    m = K.shape[0]
    s = complex(lam) * (1.0 + 1e-13)
    A = s * s * np.eye(m) + K + (s * C if C is not None else 0.0)
    lu = scipy.linalg.lu_factor(A, check_finite=False)
    y = np.random.default_rng(3).standard_normal(m) + 0j
    for _ in range(iterations):
        y = scipy.linalg.lu_solve(lu, y / np.linalg.norm(y), check_finite=False)
    return y / np.linalg.norm(y)


def coupling_of(K: np.ndarray, C: np.ndarray | None, lam: complex, modes: tuple[np.ndarray, np.ndarray]) -> dict:
    """The coupling (:func:`summary`) of the reduced model's eigenvalue ``lam`` of (λ²I + λC + K), given
    its matrices at the point, on the real modes ``modes`` = (frequencies, V) of :func:`basis_modes`."""
    freqs_hz, V = modes
    c, norms = modal_part(eigenvector(K, C, lam)[:, None], V.shape[0])
    p, r = participation(V.T @ c, norms)
    return summary(p[:, 0], float(r[0]), freqs_hz)
