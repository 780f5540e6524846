"""Eigenvalue sensitivities dλ/dp of the reduced model (fem_squeal.reduced.sensitivity).

* Ryzhik ring (seed 003): each pair of in-plane modes with k nodal diameters is the block
  K = ω_k²(I + gJ), J = [[0, 1], [−1, 0]], g = μνα_k, with λ = iω_k√(1 ∓ ig) in closed form (eq. 10):
  dλ/dμ and dλ/dE from the eigenvectors equal the derivative of the closed form, and
  d Re λ/dμ = Re λ/μ to O(g²) (Re λ is linear in μ, eq. 11).
* A random damped model with two parts (Rayleigh β) and friction: central finite differences.
* The Hoffmann two-DOF model near its exceptional point: κ_loc ≈ 1/√(2Δ) and the flag.
* The analysis section: defaults, errors naming the key.
"""
from __future__ import annotations

import numpy as np
import pytest

from fem_squeal.reduced.model import ReducedModel
from fem_squeal.reduced.sensitivity import KAPPA_COALESCENCE, parameter_values, ranking, sensitivities
from fem_squeal.reduced.sweep import solve_points
from fem_squeal.theory.ring_theory import RingSection, ryzhik_alpha, thin_ring_omega
from fem_squeal.util.errors import ModelError, UnknownNameError

RING = RingSection(R=0.05, b=0.005, h=0.004, E=3e9, nu=0.4, rho=1400.0)
KN, MU0 = 1e10, 0.3
KS = (2, 3, 4, 5, 6)


def ring_model() -> ReducedModel:
    """Block-diagonal pairs k = 2..6 of the Ryzhik ring; E.ring scales the elasticity (K0 = K_ring)."""
    w = np.array([thin_ring_omega(k, RING) for k in KS])
    g1 = np.array([RING.nu * ryzhik_alpha(k, RING, KN) for k in KS])     # g per unit μ
    m = 2 * len(KS)
    K0, Kf = np.zeros((m, m)), np.zeros((m, m))
    for j, (wk, gk) in enumerate(zip(w, g1)):
        s = slice(2 * j, 2 * j + 2)
        K0[s, s] = wk ** 2 * np.eye(2)
        Kf[s, s] = wk ** 2 * gk * np.array([[0.0, 1.0], [-1.0, 0.0]])
    return ReducedModel(K0=K0, Kf1=Kf, K_parts={"ring": K0.copy()}, E0={"ring": RING.E}, mu0=MU0)


def test_ring_closed_form():
    model = ring_model()
    lam = solve_points(model, {})[0]
    sens = sensitivities(model, modes=np.flatnonzero(lam.real > 0))
    assert len(sens) == len(KS)
    worst_mu = worst_E = worst_lin = 0.0
    for s, k in zip(sorted(sens, key=lambda s: s.freq_hz), KS):
        w, g1 = thin_ring_omega(k, RING), RING.nu * ryzhik_alpha(k, RING, KN)
        lam_c = 1j * w * np.sqrt(1 - 1j * g1 * MU0)                # unstable root of eq. 10
        assert abs(s.eigenvalue - lam_c) < 1e-9 * abs(lam_c)
        dmu = w * g1 / (2 * np.sqrt(1 - 1j * g1 * MU0))             # d/dμ of the closed form
        dE = 1j * w / (2 * np.sqrt(1 - 1j * g1 * MU0)) / RING.E     # θ = E/E0: λ = iω√(θ − ig)
        worst_mu = max(worst_mu, abs(s.d_lambda["mu"] - dmu) / abs(dmu))
        worst_E = max(worst_E, abs(s.d_lambda["E.ring"] - dE) / abs(dE))
        # Re λ linear in μ: d Re λ/dμ = Re λ/μ up to O(g²)
        g = g1 * MU0
        worst_lin = max(worst_lin, abs(s.d_lambda["mu"].real * MU0 / s.eigenvalue.real - 1) / g ** 2)
        assert not s.near_coalescence and s.kappa_local < 1.01
    print(f"ring: rel. error dλ/dμ {worst_mu:.1e}, dλ/dE {worst_E:.1e}; "
          f"|μ dReλ/dμ / Reλ − 1| / g² ≤ {worst_lin:.2f}")
    assert worst_mu < 1e-9 and worst_E < 1e-9
    assert worst_lin < 0.3          # exact ratio: 1 − g²/4 + O(g⁴)


def random_model(seed: int = 3, m: int = 12) -> ReducedModel:
    rng = np.random.default_rng(seed)
    w = np.sort(rng.uniform(1.0, 10.0, m))
    Q, _ = np.linalg.qr(rng.standard_normal((m, m)))
    K0 = (Q * w ** 2) @ Q.T
    A = rng.standard_normal((m, m))
    Ka = 0.3 * (A @ A.T) / m
    Kb = 0.2 * np.diag(rng.uniform(0.5, 1.0, m) * w ** 2)
    Kf = 0.5 * rng.standard_normal((m, m))
    C0 = 0.01 * np.diag(w)
    return ReducedModel(K0=K0, Kf1=Kf, C0=C0, K_parts={"a": Ka, "b": Kb}, E0={"a": 2e11, "b": 8e9},
                        beta={"a": 1e-3, "b": 2e-3}, mu0=0.35)


def test_finite_differences_damped():
    model = random_model()
    point = {"mu": 0.35, "E.a": 2.1e11, "E.b": 7.5e9}
    vals = parameter_values(model, point)
    sens = sensitivities(model, point)
    lam0 = solve_points(model, {k: np.array([v]) for k, v in point.items()})[0]
    worst = 0.0
    for p, v in vals.items():
        h = 1e-5 * abs(v)
        lp = solve_points(model, {**{k: np.array([x]) for k, x in point.items()}, p: np.array([v + h])})[0]
        lm = solve_points(model, {**{k: np.array([x]) for k, x in point.items()}, p: np.array([v - h])})[0]
        for s in sens:
            if s.near_coalescence:
                continue
            assert abs(lam0[s.index] - s.eigenvalue) < 1e-9 * abs(s.eigenvalue)
            fd = (lp[s.index] - lm[s.index]) / (2 * h)
            scale = abs(s.eigenvalue) / abs(v)       # relative to λ per relative change of p
            worst = max(worst, abs(s.d_lambda[p] - fd) / scale)
    print(f"damped random model: max |dλ/dp − central FD| · |p|/|λ| = {worst:.1e}")
    assert worst < 1e-7
    assert any(s.eigenvalue.real > 0 for s in sens)     # friction destabilises some of them


MU_C = 0.25    # the two-DOF Hoffmann model of fem_squeal.reduced.two_dof with its defaults


def hoffmann(k11=4.2e7, k22=3.0e7, k12=-2.0e6, kt=1.0e7, mu0=0.4) -> ReducedModel:
    """K + J = [[k11, k12 + μ kt], [k12, k22 + kt]] (unit mass): flutter for
    4k12(k12 + μkt) < −(k11 − k22 − kt)², i.e. μ > μ_c = (−(k11 − k22 − kt)²/(4k12) − k12)/kt = 0.25."""
    return ReducedModel(K0=np.array([[k11, k12], [k12, k22 + kt]]), Kf1=np.array([[0.0, kt], [0.0, 0.0]]),
                        mu0=mu0)


@pytest.mark.parametrize("side", [-1, 1])
def test_coalescence_flag(side):
    model = hoffmann()
    rows = []
    for delta in (1e-1, 1e-2, 1e-4, 1e-8):
        mu = MU_C * (1 + side * delta)
        s = sensitivities(model, {"mu": mu})
        k = max(x.kappa_local for x in s)
        rows.append((delta, k, k * np.sqrt(2 * delta)))
        assert all(x.near_coalescence == (x.kappa_local > KAPPA_COALESCENCE) for x in s)
        if delta <= 1e-4:
            assert all(x.near_coalescence for x in s)
            rec = s[0].as_dict(parameter_values(model, {"mu": mu}))
            assert rec["d_real_part"]["mu"] is None and ranking(rec) == []
        if delta >= 1e-1:
            assert not any(x.near_coalescence for x in s)
    print("Δ, κ_loc, κ_loc·√(2Δ):", [(d, f"{k:.3g}", f"{r:.3f}") for d, k, r in rows])
    c = rows[-1][2]
    for _, _, r in rows[1:]:
        assert abs(r / c - 1) < 0.02              # κ_loc ≈ c/√(2Δ) near the exceptional point
    assert 0.5 < c < 2.0                          # c = 0.79 here (1 for a symmetric coupling)


def test_bad_input_named():
    model = hoffmann()
    with pytest.raises(UnknownNameError, match="E.disc"):
        sensitivities(model, parameters=["E.disc"])
    with pytest.raises(ModelError, match="modes: index 5"):
        sensitivities(model, modes=[5])
    with pytest.raises(ModelError, match="kappa_max"):
        sensitivities(model, kappa_max=0.5)


def test_report_says_near_coalescence(tmp_path):
    """A mode at the exceptional point is reported as such, not as a large number (report and plot)."""
    from fem_squeal.app import plots
    from fem_squeal.app.analyses.sensitivity import report

    model = hoffmann()
    mu = MU_C * (1 + 1e-8)
    rec = sensitivities(model, {"mu": mu})[1].as_dict(parameter_values(model, {"mu": mu}))
    rec.update(unstable=True, ranking=[])
    html = report({"sensitivity": [rec]})
    assert "near a coalescence" in html and "derivative not defined" in html
    plots.tornado(tmp_path / "t.png", rec)
    assert (tmp_path / "t.png").stat().st_size > 1000


def test_full_model_ring_d_real_part_d_mu(ring_operators):
    """The full model (FE ring between two plates, left vectors from SLEPc): Re λ of each flutter pair is
    linear in μ (eq. 11), so μ ∂Re λ/∂μ = Re λ to O(g²) (g = μνα_k ≤ 0.05 here), and the imaginary part
    ∂f/∂μ is O(g) small: the same relation as the closed form above, on the FE eigenvectors."""

    from fem_squeal.fe.eigen import solve_complex_modes
    from fem_squeal.fe.model import Material, ModelSpec, RigidPlate
    from fem_squeal.fe.projection import ParametricOperators, full_sensitivities

    ops = ring_operators(mesh_size=0.004)
    spec = ModelSpec({"disc": Material(3e9, 0.4, 1400.0)}, (RigidPlate("top", KN, MU0, 1),
                                                               RigidPlate("bottom", KN, MU0, 1)))
    band = (100.0, 2000.0)
    cm = solve_complex_modes(ops.K_total(), ops.M, None, 12, 1000.0, band_hz=band)
    lam = cm.eigenvalues[cm.eigenvalues.real > 1e-6 * np.abs(cm.eigenvalues)]
    assert len(lam) >= 2
    par = ParametricOperators(ops, spec, MU0)
    sens = full_sensitivities(par, lam, ["mu"], band)
    worst = 0.0
    for s in sens:
        assert s.left_mismatch < 1e-8
        worst = max(worst, abs(MU0 * s.d_lambda["mu"].real / s.eigenvalue.real - 1))
    print(f"ring, full model: max |μ ∂Reλ/∂μ / Reλ − 1| = {worst:.1e} over {len(sens)} unstable modes")
    assert worst < 1e-3        # O(g²) (the closed form above: ≤ 0.3 g²); measured 3.6e-5 at mesh_size 4 mm
