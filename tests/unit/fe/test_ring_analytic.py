"""Verification of the ring against seed 003 (Ryzhik) and the corrected theory of
``fem_squeal.theory.ring_theory`` (derivation: docs/ring_theory.md)."""
from __future__ import annotations

import math

import numpy as np
import pytest
from support.ring import ring_operators

from fem_squeal.fe.descriptors import CircumferentialBasis
from fem_squeal.fe.eigen import solve_complex_modes, solve_real_modes
from fem_squeal.theory import ring_theory as rt

BAND = (100.0, 5000.0)
KS = range(2, 7)


def section(width=0.005, thickness=0.004, nu=0.4):
    return rt.RingSection(0.05, width, thickness, 3e9, nu, 1400.0)


def cea_by_k(ops, nev=16, target=2500.0):
    """{k: (unstable λ, stable partner λ, travelling direction of the unstable one)} for k = 2..6."""
    cm = solve_complex_modes(ops.K_total(), ops.M, None, nev, target, band_hz=BAND)
    basis = CircumferentialBasis(ops.V, ops.M, ops.M_axial)
    out: dict[int, list] = {}
    for lam, xr, xi in zip(cm.eigenvalues, cm.vectors_re, cm.vectors_im):
        d = basis.describe(xr, xi)
        if d.in_plane_share > 0.99 and d.nodal_diameter in KS:
            out.setdefault(d.nodal_diameter, []).append((lam, d.travelling_direction))
    assert sorted(out) == list(KS), f"in-plane pairs found for k = {sorted(out)}"
    res = {}
    for k, pair in out.items():
        assert len(pair) == 2, f"k={k}: {pair}"
        pair.sort(key=lambda p: -p[0].real)
        res[k] = (pair[0][0], pair[1][0], pair[0][1])
    return res


@pytest.fixture(scope="module")
def default_ring():
    return cea_by_k(ring_operators())


# ---------------------------------------------------------------------------------------------
# 1. Frequencies of the free ring against the thin-ring formula (seed 003 eq. 7 at μ = 0)
# ---------------------------------------------------------------------------------------------
def free_ring_freqs(width):
    """Mean FE frequency of the in-plane pairs k = 2, 3 of a free ring (no plates), h = 0.8 b."""
    ops = ring_operators(width=width, thickness=0.8 * width, mesh_size=0.6 * width, kn=0.0)
    s = section(width, 0.8 * width)
    rm = solve_real_modes(ops.K, ops.M, 24, rt.thin_ring_omega(3, s) / (2 * math.pi))
    basis = CircumferentialBasis(ops.V, ops.M, ops.M_axial)
    found: dict[int, list[float]] = {}
    for f, x in zip(rm.freqs_hz, rm.vectors):
        d = basis.describe(x)
        if f > 1.0 and d.in_plane_share > 0.95 and d.nodal_diameter in (2, 3):
            found.setdefault(d.nodal_diameter, []).append(f)
    assert all(len(found.get(k, [])) == 2 for k in (2, 3)), found
    return {k: np.mean(v) for k, v in found.items()}, s


def test_free_ring_frequencies_converge_to_thin_ring_theory_as_b_over_R_vanishes():
    errs = {}
    for width in (0.005, 0.0025):
        fe, s = free_ring_freqs(width)
        errs[width] = {k: abs(fe[k] / (rt.thin_ring_omega(k, s) / (2 * math.pi)) - 1) for k in (2, 3)}
    for k in (2, 3):
        big, small = errs[0.005][k], errs[0.0025][k]
        # Thin-ring theory omits shear and rotary inertia, O((k b/R)^2): 0.43 % (k=2) and 1.2 %
        # (k=3) at b/R = 0.1.  Halving b/R must divide the error by ~4; we require > 3 to leave
        # room for the FE discretisation error (< 0.02 % at 0.6 b, P2 curved).
        assert big < 0.015
        assert small < big / 3, (k, big, small)


# ---------------------------------------------------------------------------------------------
# 2. Growth rates against Ryzhik eqs. 10-11 and the corrected formula
# ---------------------------------------------------------------------------------------------
def test_growth_rates_match_corrected_ring_formula_on_a_fine_mesh():
    """Corrected formula (extension + spring restraint + shear) at the FE frequency: its residual
    is O((kb/R)^4) and through-width effects, measured <= 0.2 % for k = 2..6 at b/R = 0.1 and
    0.05; this mesh (58k DOFs) adds < 0.1 % discretisation error.  Hence 0.5 %."""
    res = cea_by_k(ring_operators(mesh_size=0.0015), nev=24)
    s = section()
    for k in KS:
        lam = res[k][0]
        ratio = lam.real / rt.corrected_growth_rate(k, s, 1e10, 0.3, omega=lam.imag)
        assert abs(ratio - 1) < 5e-3, (k, ratio)
        # Ryzhik's inextensible formula alone is off by the ring-extension factor 1 + 2k²/(k⁴−1)
        # at low k (×1.50 at k = 2) and by the shear share at high k; record that it is not 1.
    ryz2 = res[2][0].real / rt.ryzhik_growth_rate(2, s, 1e10, 0.3)
    assert ryz2 == pytest.approx(1 + 8 / 15, rel=0.03)


def test_each_pair_becomes_a_quadruple(default_ring):
    for up, down, _ in default_ring.values():
        assert up.real > 0 > down.real
        # σ+iω and −σ+iω come from θ and conj(θ) of the same real EPS: mirror to round-off
        assert abs(up.real + down.real) < 1e-8 * abs(up)
        assert abs(up.imag - down.imag) < 1e-8 * abs(up)


def pair_splitting(ops):
    """δ_k = ω₁² − ω₂² of the frictionless pair k (the mesh breaks the exact degeneracy)."""
    rm = solve_real_modes(ops.K, ops.M, 16, 2500.0)
    basis = CircumferentialBasis(ops.V, ops.M, ops.M_axial)
    w2: dict[int, list[float]] = {}
    for om2, x in zip(rm.omega2, rm.vectors):
        d = basis.describe(x)
        if d.in_plane_share > 0.99 and d.nodal_diameter in KS:
            w2.setdefault(d.nodal_diameter, []).append(om2)
    return {k: abs(v[0] - v[1]) for k, v in w2.items()}


def test_growth_rate_is_linear_in_mu(default_ring):
    """For a pair with frictionless ω₁² ≠ ω₂² (split by δ) and antisymmetric coupling μb,
    λ² = −ω̄² ± i q with q² + δ²/4 = μ²b², q = |Im λ²| = 2 Re λ Im λ.  So q² + δ²/4 is exactly
    quadratic in μ; Re λ itself is linear in μ only once δ ≪ μb (0.45 % off at k = 6 here)."""
    half = cea_by_k(ring_operators(mu=0.15))
    delta = pair_splitting(ring_operators())
    for k in KS:
        q2 = [(2 * r[k][0].real * r[k][0].imag) ** 2 + delta[k] ** 2 / 4 for r in (half, default_ring)]
        # The 2×2 model is exact up to coupling with other modes, O(g²) <= 2e-4 relative.
        assert q2[0] / q2[1] == pytest.approx(0.25, rel=2e-4), (k, q2[0] / q2[1])
        assert half[k][0].real / default_ring[k][0].real == pytest.approx(0.5, rel=1e-2)


def test_growth_rate_vanishes_without_poisson_contraction():
    res = cea_by_k(ring_operators(nu=0.0))
    for k, (up, _down, _) in res.items():
        # ν = 0: in-plane modes have u_z ≡ 0, K_f φ = 0, so friction only couples one way
        # (triangular) and the in-plane eigenvalues stay imaginary to round-off.
        assert abs(up.real) < 1e-8 * abs(up), (k, up)


def test_growth_rate_scales_with_poisson_ratio_as_predicted(default_ring):
    low = cea_by_k(ring_operators(nu=0.2))
    for k in KS:
        fe = low[k][0].real / default_ring[k][0].real
        th = (rt.corrected_growth_rate(k, section(nu=0.2), 1e10, 0.3, omega=low[k][0].imag)
              / rt.corrected_growth_rate(k, section(nu=0.4), 1e10, 0.3, omega=default_ring[k][0].imag))
        # Re λ ∝ ν to leading order (exactly 0.5 for ν 0.4 → 0.2); the spring, shear and
        # frequency terms move the ratio by a few %, which the corrected formula tracks to 0.3 %.
        assert fe == pytest.approx(0.5, rel=0.05)
        assert fe == pytest.approx(th, rel=3e-3), (k, fe, th)


def test_opposite_sliding_on_the_two_faces_cancels_the_instability(default_ring):
    res = cea_by_k(ring_operators(sliding=(1, -1)))
    for k in KS:
        # Cancellation is exact for a mesh symmetric about z = 0; the unstructured mesh breaks
        # that symmetry at the discretisation level, which leaves < 1 % of the one-sided σ.
        assert abs(res[k][0].real) < 1e-2 * default_ring[k][0].real, (k, res[k][0])


def test_reversing_the_sliding_flips_the_wave_and_keeps_the_growth_rate(default_ring):
    rev = cea_by_k(ring_operators(sliding=(-1, -1)))
    for k in KS:
        assert default_ring[k][2] == +1 and rev[k][2] == -1
        # Mirror symmetry θ → −θ holds up to the mesh's asymmetry (pair splitting ~1e-4).
        assert rev[k][0].real == pytest.approx(default_ring[k][0].real, rel=1e-3)
