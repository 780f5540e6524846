"""First-harmonic linearisation of the contact remainder by alternating frequency–time (AFT).

Seed 000 eqs. 8 and 15–18.  About the static closure δ_s of an element, a first-harmonic motion
Δδ(t) = δ_c cos ωt + δ_s' sin ωt makes the nonlinear remainder of its normal force

    r(t) = F(δ_s + Δδ, Δδ̇) − F(δ_s, 0) − ∂_δF(δ_s) Δδ − ∂_δ̇F(δ_s) Δδ̇          (eq. 8, one element)

which is sampled at N instants of a period; its first Fourier coefficients τ_c, τ_s give

    k = (δ_c τ_c + δ_s' τ_s) / (δ_c² + δ_s'²),   c = (δ_s' τ_c − δ_c τ_s) / (ω (δ_c² + δ_s'²))    (eq. 18)

so that r₁(t) = k Δδ + c Δδ̇ (eq. 17).  The tangential remainder is μ r (Coulomb while sliding),
hence k^{t,n} = μ k^{n,n} and c^{t,n} = μ c^{n,n}.  Everything is vectorised over the elements.
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np

from fem_squeal.reduced.laws.contact import UnilateralLaw
from fem_squeal.util.errors import ModelError

NO_CONTACT, PERMANENT, IMPACTS = 0, 1, 2
STATUS_NAMES = {NO_CONTACT: "no contact", PERMANENT: "permanent contact", IMPACTS: "impacts"}


class Harmonic(NamedTuple):
    k: np.ndarray        # equivalent stiffness of the remainder per element [N/m]
    c: np.ndarray        # equivalent damping [N s/m]
    tau_c: np.ndarray    # first Fourier coefficients of r
    tau_s: np.ndarray


def _trig(n_samples: int) -> tuple[np.ndarray, np.ndarray]:
    """cos θ_k, sin θ_k at θ_k = 2πk/N, built mirror-symmetric (θ_{N−k} = −θ_k bit for bit)."""
    if n_samples < 4:
        raise ModelError(f"n_samples: must be >= 4 (got {n_samples})")
    k = np.arange(n_samples)
    kk = np.minimum(k, n_samples - k)
    th = 2.0 * np.pi * kk / n_samples
    return np.cos(th), np.where(k <= n_samples // 2, 1.0, -1.0) * np.sin(th) * (kk > 0) * (2 * kk != n_samples)


def first_harmonic(law: UnilateralLaw, d_static: np.ndarray, dc: np.ndarray, ds: np.ndarray,
                   omega: float, n_samples: int = 64) -> Harmonic:
    """k and c of eq. 18 for every element (arrays of shape (n_elements,)); see module docstring.

    Each element is sampled in its own phase, Δδ = a cos θ with a = |(δ_c, δ_s')| (k and c do
    not depend on the time origin): the sample set is then mirror-symmetric, so an elastic law
    gives c = 0 to round-off for any N, and the coefficients are rotated back for τ_c, τ_s."""
    cos, sin = _trig(n_samples)
    d_static, dc, ds = (np.asarray(a, float) for a in (d_static, dc, ds))
    a = np.hypot(dc, ds)
    dd = a[:, None] * cos                                            # Δδ(θ_k)
    vv = -omega * a[:, None] * sin                                   # Δδ̇(θ_k)
    r = law.remainder(d_static[:, None], dd, vv)
    tc = (2.0 / n_samples) * (r @ cos)                               # in the element's phase
    ts = (2.0 / n_samples) * (r @ sin)
    moving = a > 0
    den = np.where(moving, a, 1.0)
    k = np.where(moving, tc / den, 0.0)
    c = np.where(moving, -ts / (omega * den), 0.0) if omega > 0 else np.zeros_like(k)
    cphi, sphi = np.where(moving, dc / den, 1.0), np.where(moving, ds / den, 0.0)
    return Harmonic(k, c, tc * cphi - ts * sphi, tc * sphi + ts * cphi)


def contact_status(d_static: np.ndarray, amplitude: np.ndarray) -> np.ndarray:
    """Per element over a cycle of δ_s + a cos(ωt + φ): NO_CONTACT (never closed), PERMANENT
    (closed throughout) or IMPACTS (contact lost during part of the cycle)."""
    lo, hi = d_static - amplitude, d_static + amplitude
    return np.where(lo > 0, PERMANENT, np.where(hi > 0, IMPACTS, NO_CONTACT)).astype(np.int8)


def _cos_power_integrals(x: np.ndarray, n: int) -> list[np.ndarray]:
    """I_k = ∫₀ˣ cosᵏθ dθ for k = 0..n (I_k = cosᵏ⁻¹x sin x / k + (k−1)/k I_{k−2})."""
    c, s = np.cos(x), np.sin(x)
    out = [x, s]
    for k in range(2, n + 1):
        out.append(c ** (k - 1) * s / k + (k - 1) / k * out[k - 2])
    return out


def cubic_remainder_stiffness(k_l, k_nl, d0, amplitude) -> np.ndarray:
    """Closed form of k (eq. 18) for the elastic law F = k_l δ + k_nl δ³ (δ > 0) and the motion
    δ(θ) = δ₀ + A cos θ.  Contact holds for |θ| < θ* = arccos(−δ₀/A) (θ* = π without loss), so

        k = (2/(πA)) [k_l(δ₀I₁ + A I₂) + k_nl(δ₀³I₁ + 3δ₀²A I₂ + 3δ₀A²I₃ + A³I₄)] − ∂F(δ₀),

    I_j = ∫₀^θ* cosʲθ dθ.  Without loss of contact (A ≤ δ₀) this is ¾ k_nl A²."""
    k_l, k_nl, d0, A = np.broadcast_arrays(*(np.asarray(a, float) for a in (k_l, k_nl, d0, amplitude)))
    Asafe = np.where(A > 0, A, 1.0)
    theta = np.arccos(np.clip(-d0 / Asafe, -1.0, 1.0))
    _, I1, I2, I3, I4 = _cos_power_integrals(theta, 4)
    cubic = d0 ** 3 * I1 + 3 * d0 ** 2 * A * I2 + 3 * d0 * A ** 2 * I3 + A ** 3 * I4
    full = (2.0 / (np.pi * Asafe)) * (k_l * (d0 * I1 + A * I2) + k_nl * cubic)
    tangent = np.where(d0 > 0, k_l + 3 * k_nl * d0 ** 2, 0.0)
    return np.where(A > 0, full - tangent, 0.0)
