r"""Analytic in-plane eigenvalues of a thin ring between two rigid plates (seed 003, Ryzhik).

Notation: mean radius R, radial width b, axial thickness h, A = bh, I = hb³/12, ρ_lin = ρA,
penalty stiffness k_n = C_p [N/m³] on each face, friction μ, Poisson's ratio ν, k the number of
nodal diameters (k ≥ 2).

Ryzhik (seed 003)
-----------------
Inextensible thin ring, eq. 7:  ω_k² = EI/(ρ_lin R⁴) · k²(k²−1)²/(k²+1),  α_k = C_p R/(k E).
Eq. 10:  λ = ±ω_k·½√(2√(1+g²)−2) ± iω_k·½√(2√(1+g²)+2),  g = μνα_k;  eq. 11: Re λ ≈ ½ μ ν α_k ω_k.

Correction used by fem_squeal (derivation in docs/ring_theory.md)
----------------------------------------------------------------
1. **Ring extension.** With the extensible thin ring (membrane strain ε₀ = (v'+w)/R, rotation
   ψ = (v−w')/R, curvature χ = ψ'/R, strain ε(u) = ε₀ + uχ at radial offset u) a mode is
   v = V cos kφ, w = W sin kφ with r = W/V from the 2×2 ring eigenproblem
       S = [[k²(1+β), −k(1+βk²)], [−k(1+βk²), 1+βk⁴]],   β = I/(A R²),  Ω² = ρR²ω²/E.
   The Poisson thickness change is driven by the *whole* strain ε(u), and the friction it
   modulates acts on the tangential displacement v + uψ of the face.  Besides the bending
   product χψ (Ryzhik's moment m) this gives a membrane product ε₀·v, which the inextensible
   model drops (ε₀ = 0) although ε₀ = O(β) multiplies a displacement v = O(1/β) larger than uψ:
       g/(μν) = (C_p R/E) · [(k − r) + βk(1 − kr)²] / [(r − k)² + βk²(1 − kr)²].
   In the inextensible limit r → k this is C_p R/(kE) = α_k; to first order in β it is
   α_k · (1 + 2k²/(k⁴−1)): +53 % at k = 2, +22 % at k = 3, +13 % at k = 4, independent of b/R.
2. **Spring restraint of the contraction.** The face pressure p = C_p Δh/2 pushes back on the
   thickness change: ε_zz = −νε − p(1−ν²)/E, so Δh = −νεh·f_s with
       f_s = 1/(1 + C_p h (1−ν²)/(2E)).
   The springs also store energy C_p ν² f_s² h/(2E) per unit of strain energy, stiffening the
   mode: ω² → ω²(1 + e_s), g → g/(1 + e_s).
3. **Shear.** Only the bending (and membrane) strain contracts the section; in a Timoshenko
   ring a share s_k/(1+s_k) of the strain energy of mode k is shear, s_k = E I k²/(κ G A R²)
   (κ = 10(1+ν)/(12+11ν), Cowper's rectangle), so g → g/(1 + s_k).  s_k = 1.1 % at k = 2 and
   9.8 % at k = 6 on the default ring: it is what makes the inextensible formula drift with k.
Growth rates are compared at the FE frequency (Re λ = ω_FE·½√(2√(1+g²)−2)), so the frequency
error of thin-ring theory (tested separately) does not enter the coupling test.  What remains is
O((kb/R)⁴) and the through-width variation of the contraction; the tests check that
FE / corrected → 1 as b/R → 0.
"""
from __future__ import annotations

import math
from typing import NamedTuple


class RingSection(NamedTuple):
    """Ring data in SI units."""

    R: float       # mean radius [m]
    b: float       # radial width [m]
    h: float       # axial thickness [m]
    E: float       # Young's modulus [Pa]
    nu: float      # Poisson's ratio
    rho: float     # density [kg/m³]

    @property
    def A(self) -> float:
        return self.b * self.h

    @property
    def I(self) -> float:  # noqa: E743
        return self.h * self.b ** 3 / 12.0

    @property
    def beta(self) -> float:
        """Slenderness β = I/(A R²) = (b/R)²/12."""
        return self.I / (self.A * self.R ** 2)


def thin_ring_omega(k: int, s: RingSection) -> float:
    """Inextensible thin-ring in-plane flexural ω_k [rad/s] (seed 003 eq. 7)."""
    return math.sqrt(s.E * s.I / (s.rho * s.A * s.R ** 4) * k ** 2 * (k ** 2 - 1) ** 2 / (k ** 2 + 1))


def ryzhik_alpha(k: int, s: RingSection, kn: float) -> float:
    """α_k = C_p R/(k E) (seed 003 eq. 7 with ω_k substituted)."""
    return kn * s.R / (k * s.E)


def growth_rate_from_coupling(omega: float, g: float) -> float:
    """Re λ = ω·½√(2√(1+g²) − 2) for λ² + ω²(1 ± i g) = 0 (seed 003 eq. 10)."""
    return omega * 0.5 * math.sqrt(2.0 * math.sqrt(1.0 + g * g) - 2.0)


def ryzhik_growth_rate(k: int, s: RingSection, kn: float, mu: float) -> float:
    """Seed 003 eq. 10 with the thin-ring ω_k and g = μ ν α_k (≈ ½ μ ν α_k ω_k, eq. 11)."""
    return growth_rate_from_coupling(thin_ring_omega(k, s), mu * s.nu * ryzhik_alpha(k, s, kn))


def extensible_ring_mode(k: int, s: RingSection) -> tuple[float, float]:
    """Lower (flexural) root of the extensible thin ring: (ω [rad/s], r = W/V)."""
    b = s.beta
    a11, a12, a22 = k * k * (1 + b), -k * (1 + b * k * k), 1 + b * k ** 4
    tr, det = a11 + a22, a11 * a22 - a12 * a12
    om2 = 0.5 * (tr - math.sqrt(tr * tr - 4 * det))
    r = (a11 - om2) / (-a12)
    return math.sqrt(om2 * s.E / (s.rho * s.R ** 2)), r


def spring_factors(s: RingSection, kn: float) -> tuple[float, float]:
    """(f_s, e_s): restraint of the Poisson contraction and relative spring energy (see module doc)."""
    f_s = 1.0 / (1.0 + kn * s.h * (1 - s.nu ** 2) / (2 * s.E))
    e_s = kn * s.nu ** 2 * f_s ** 2 * s.h / (2 * s.E)
    return f_s, e_s


def shear_ratio(k: int, s: RingSection) -> float:
    """s_k = E I k² / (κ G A R²): shear over bending strain energy of mode k (Timoshenko)."""
    kappa = 10 * (1 + s.nu) / (12 + 11 * s.nu)
    G = s.E / (2 * (1 + s.nu))
    return s.E * s.I * k * k / (kappa * G * s.A * s.R ** 2)


def corrected_coupling(k: int, s: RingSection, kn: float, mu: float) -> float:
    """g = μν(C_p R/E) · [(k−r) + βk(1−kr)²]/[(r−k)² + βk²(1−kr)²] · f_s/(1+e_s) · 1/(1+s_k)."""
    _, r = extensible_ring_mode(k, s)
    b = s.beta
    shape = ((k - r) + b * k * (1 - k * r) ** 2) / ((r - k) ** 2 + b * k * k * (1 - k * r) ** 2)
    f_s, e_s = spring_factors(s, kn)
    return mu * s.nu * kn * s.R / s.E * shape * f_s / (1 + e_s) / (1 + shear_ratio(k, s))


def corrected_omega(k: int, s: RingSection, kn: float) -> float:
    """Extensible thin-ring ω with the spring stiffening √(1+e_s)."""
    return extensible_ring_mode(k, s)[0] * math.sqrt(1 + spring_factors(s, kn)[1])


def corrected_growth_rate(k: int, s: RingSection, kn: float, mu: float,
                          omega: float | None = None) -> float:
    """Re λ of pair k with items 1–3 of the module doc, at ``omega`` (default: corrected_omega)."""
    om = corrected_omega(k, s, kn) if omega is None else omega
    return growth_rate_from_coupling(om, corrected_coupling(k, s, kn, mu))
