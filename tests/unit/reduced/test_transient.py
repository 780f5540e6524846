"""Verification of the reduced transient solver (issue 6): linear SDOF properties of the scheme,
the closed-form stick–slip cycle of a mass on a belt, the CEA growth rate, the energy balance
and the order of convergence in Δt."""
from __future__ import annotations

import numpy as np
import pytest

from fem_squeal.reduced.eigensolve import quadratic_eigs
from fem_squeal.reduced.laws.contact import ExponentialLaw, UnilateralLaw
from fem_squeal.reduced.laws.friction import ElasticCoulomb, StribeckFriction
from fem_squeal.reduced.masa import linearise, static_equilibrium
from fem_squeal.reduced.transient import (
    DynamicModel,
    FrictionContact,
    NewmarkHHT,
    State,
    TransientError,
    from_masa,
    load_history,
    run_transient,
)
from fem_squeal.reduced.two_dof import two_dof_model


def _amplification(omega: float, dt: float, alpha: float) -> np.ndarray:
    """The 3×3 map (q, Δt v, Δt² a)ₙ → ()ₙ₊₁ of the integrator on q̈ + ω²q = 0, column by column."""
    integ = NewmarkHHT(DynamicModel(K=np.array([[omega ** 2]]), contacts=[]), dt, alpha=alpha, rtol=1e-14)
    A = np.zeros((3, 3))
    for j in range(3):
        e = np.eye(3)[j]
        s = State(0.0, np.array([e[0]]), np.array([e[1] / dt]), np.array([e[2] / dt ** 2]), [])
        new = integ.try_step(s, dt)[0]
        A[:, j] = [new.q[0], new.v[0] * dt, new.a[0] * dt ** 2]
    return np.linalg.eigvals(A)


def test_trapezoidal_frequency_and_energy():
    """α = 0: |z| = 1 (no numerical damping) and tan(ω_h Δt/2) = ωΔt/2 for the principal roots;
    a free run keeps E = ½v² + ½ω²q² to round-off (1e-12 relative over 1000 steps)."""
    for wdt in (0.05, 0.5, 2.0):
        z = _amplification(1.0, wdt, 0.0)
        z = z[np.argmax(np.abs(z.imag))]
        assert abs(abs(z) - 1) < 1e-12
        assert np.tan(abs(np.angle(z)) / 2) == pytest.approx(wdt / 2, rel=1e-12)
    w = 2 * np.pi * 100.0
    res = run_transient(DynamicModel(K=np.array([[w * w]]), contacts=[]), np.array([1e-3]), None, 0.1, 1e-4)
    E = res.total_energy()
    assert np.ptp(E) / E[0] < 1e-12


@pytest.mark.parametrize("alpha", [-0.05, -0.1, -0.3])
def test_hht_spectral_radius_at_infinity(alpha):
    """ρ∞ = (1 + α)/(1 − α): at ωΔt = 1e6 the largest root agrees to 1e-6 (O((ωΔt)⁻¹) away)."""
    rho = np.abs(_amplification(1.0, 1e6, alpha)).max()
    assert rho == pytest.approx((1 + alpha) / (1 - alpha), abs=1e-6)
    assert np.abs(_amplification(1.0, 0.1, alpha)).max() < 1.0   # and it does damp a resolved mode


def test_belt_stick_slip_closed_form():
    """Mass m on spring k, pressed with N onto a belt at speed V, Coulomb μ_s > μ_d.

    Closed form of the steady cycle (X₀ = (μ_s − μ_d)N/k, x_d = μ_d N/k, ω = √(k/m)):
    stick carries the mass at V until kx = μ_s N (x = x_s); slip is the harmonic arc
    x − x_d = X₀cos ωt + (V/ω)sin ωt until ẋ = V again, at x_d − X₀, after ωt = 2π − 2atan(X₀ω/V).
    Period T = 2X₀/V + (2π − 2atan(X₀ω/V))/ω, extrema x_d ± √(X₀² + (V/ω)²).
    Tolerances: stick onset/end is located to within a step, so the period within 2Δt and the
    extrema within VΔt; the stick spring k_t (critically damped) adds μ_s N/k_t = 6e-9 m."""
    m, k, N, V, mus, mud, kt = 1.0, 1e4, 100.0, 0.1, 0.6, 0.3, 1e10
    law = ElasticCoulomb(mus, mud, kt, 2 * np.sqrt(kt * m))
    cs = FrictionContact(D=np.array([[0.0, -1.0]]), T=np.array([[1.0, 0.0]]), d0=np.zeros(1),
                         normal=UnilateralLaw(k_l=1e10), friction=law,
                         V=np.array([[V]]), name="belt")
    model = DynamicModel(K=np.diag([k, 0.0]), contacts=[cs], M=m * np.eye(2), f=np.array([0.0, -N]))
    dt = 2e-5
    res = run_transient(model, np.array([0.0, -N / 1e10]), None, 0.3, dt)
    w, X0, xd = np.sqrt(k / m), (mus - mud) * N / k, mud * N / k
    A = np.hypot(X0, V / w)
    T = 2 * X0 / V + (2 * np.pi - 2 * np.arctan(X0 * w / V)) / w
    x, t = res.q[:, 0], res.t
    late = t > 0.12                      # after the first stick (the start is sliding from rest)
    assert abs(x[late].max() - (xd + A)) < V * dt
    assert abs(x[late].min() - (xd - A)) < V * dt
    up = np.where((x[:-1] < xd) & (x[1:] >= xd))[0]
    tc = t[up] - (x[up] - xd) * dt / (x[up + 1] - x[up])
    assert len(tc) >= 3
    assert np.abs(np.diff(tc)[1:] - T).max() < 2 * dt
    # the stick phase is real stick: the belt carries the mass; the only relative velocity is the
    # stick spring's creep k V/k_t = 1e-7 m/s (after the onset ringing, damped by c_t)
    stuck = res.contact["belt.stuck"][late].astype(bool)
    assert 0.3 < stuck.mean() < 0.9
    assert np.percentile(np.abs(res.contact["belt.w"][late][stuck]), 90) < 2 * k * V / kt


def _two_dof(cubic_share=0.3, **kw):
    mm = two_dof_model(cubic_share=cubic_share, **kw)
    eq = static_equilibrium(mm)
    K, C = linearise(mm, eq)
    lam, Y = quadratic_eigs(K, C, vectors=True)
    return mm, eq, K, C, lam, Y


def test_growth_rate_equals_cea_real_part():
    """A small free response started on the unstable CEA pair of the two-DOF model grows at
    Re λ.  The scheme's own rate is ln|z|/Δt with z = (1 + λΔt/2)/(1 − λΔt/2) (trapezoidal
    rule on the first-order form), |ln|z|/Δt − Re λ| = O(|λ|³Δt²); at |λ|Δt = 0.013 that is 2e-6
    relative, and the cubic remainder at amplitude/closure ≤ 1e-3 stays below 1e-4."""
    mm, eq, K, C, lam, Y = _two_dof()
    i = int(np.argmax(lam.real))
    dm = from_masa(mm, 1.0)
    integ = NewmarkHHT(dm, 2e-6)
    qs = integ.steady_sliding()
    assert np.allclose(qs, eq.q, atol=1e-12 * np.abs(eq.q).max())
    y = Y[:, i] * 1e-9
    dt = 2e-6
    res = run_transient(dm, qs + y.real, (lam[i] * y).real, 0.02, dt)
    # projection on the left eigenvector isolates the pair: η_n = c zⁿ
    Afo = np.block([[np.zeros((2, 2)), np.eye(2)], [-K, -(C if C is not None else np.zeros((2, 2)))]])
    mu, VL = np.linalg.eig(Afo.T)
    eta = np.column_stack([res.q - qs, res.v]) @ VL[:, np.argmin(abs(mu - lam[i]))]
    n0 = len(eta) // 4
    slope = np.polyfit(res.t[n0:], np.log(np.abs(eta[n0:])), 1)[0]
    assert lam[i].real > 100
    assert slope == pytest.approx(lam[i].real, rel=1e-4)
    z = (1 + lam[i] * dt / 2) / (1 - lam[i] * dt / 2)
    assert abs(np.log(abs(z)) / dt - lam[i].real) < abs(lam[i]) ** 3 * dt ** 2


def _contact_potential(law: UnilateralLaw, delta):
    d = np.maximum(delta, 0.0)
    return law.k_l * d ** 2 / 2 + law.k_nl * d ** 4 / 4


def test_energy_balance_into_limit_cycle():
    """The unstable two-DOF model grows into contact loss.

    (1) The discrete balance E − E₀ = W_ext + W_fric + W_normal − D holds to round-off
    (trapezoidal works of the forces the scheme balances; each step's Newton residual
    ‖R‖ ≤ rtol·ref leaks ≤ ‖Δq‖·rtol·ref, so with rtol = 1e-13 over ~200 oscillation
    half-cycles the leak is ≲ 1e-10 E).
    (2) The physical balance, W_normal = −ΔV_contact for the elastic law
    (V = k_l δ²/2 + k_nl δ⁴/4), holds to O(Δt²): its error drops ~4× when Δt halves."""
    mm, eq, K, C, lam, Y = _two_dof(zeta=0.002)
    dm = from_masa(mm, 1.0)
    i = int(np.argmax(lam.real))
    y = Y[:, i] * 5e-6
    errs = []
    for dt in (2e-6, 1e-6):
        res = run_transient(dm, eq.q + y.real, (lam[i] * y).real, 0.015, dt, rtol=1e-13)
        scale = res.total_energy().max()
        assert np.abs(res.energy_residual()).max() < 1e-10 * scale
        assert res.energy["W_friction"][-1] > 0.1 * scale       # friction feeds the vibration
        law = mm.contacts[0].law
        delta = mm.contacts[0].d0 + res.q @ mm.contacts[0].D.T
        assert (delta <= 0).any(), "the cycle should reach contact loss"
        Vc = _contact_potential(law, delta[:, 0])
        errs.append(np.abs(res.energy["W_normal"] + (Vc - Vc[0])).max() / scale)
    assert errs[1] < 0.4 * errs[0]
    assert errs[0] < 1e-3


def test_second_order_convergence():
    """Trapezoidal Newmark on the smooth (always closed) cubic two-DOF model: the error at
    t = 3 ms against a Δt/16 reference falls by 4× per halving (observed order 2 ± 0.15)."""
    mm, eq, K, C, lam, Y = _two_dof(zeta=0.01)
    dm = from_masa(mm, 1.0)
    y = Y[:, int(np.argmax(lam.real))] * 2e-6
    q0, v0 = eq.q + y.real, (lam.max() * y).real

    def final(dt):
        return run_transient(dm, q0, v0, 3e-3, dt, record_every=10 ** 6).q[-1]

    ref = final(1.25e-7)    # Δt/16 of the finest: its own error is 1/256 of the finest one
    e = [np.linalg.norm(final(dt) - ref) for dt in (8e-6, 4e-6, 2e-6)]
    orders = np.log2(np.array(e[:-1]) / np.array(e[1:]))
    assert np.all(np.abs(orders - 2) < 0.15), orders


def test_stribeck_law_and_exponential_contact_tangent():
    """Newton with the consistent tangent converges quadratically on smooth laws: a one-mass
    model with the exponential contact law and the Stribeck friction law, full tangent, needs at
    most 4 iterations per step to reach 1e-12."""
    cs = FrictionContact(D=np.array([[0.0, -1.0]]), T=np.array([[1.0, 0.0]]), d0=np.zeros(1),
                         normal=ExponentialLaw(p0=50.0, lam=1e6), friction=StribeckFriction(0.6, 0.3, 0.01, 0.05),
                         V=np.array([[0.02]]))
    model = DynamicModel(K=np.diag([1e5, 0.0]), contacts=[cs], M=np.eye(2) * 0.1, f=np.array([0.0, -100.0]))
    res = run_transient(model, np.zeros(2), np.zeros(2), 0.02, 1e-5, tangent="full", rtol=1e-12)
    assert res.stats["iterations"] <= 4 * res.stats["steps"]
    assert np.abs(res.energy_residual()).max() < 1e-9 * res.total_energy().max()


def test_checkpoint_resume_and_failure(tmp_path):
    """A run split by a checkpoint and resumed gives the records of the uninterrupted run
    bit for bit (with the full tangent; the modified one would restart with a fresh tangent and
    agree only to the Newton tolerance); a Newton failure names the step and saves the last
    good state."""
    mm, eq, K, C, lam, Y = _two_dof()
    dm = from_masa(mm, 1.0)
    y = Y[:, int(np.argmax(lam.real))] * 1e-7
    args = (dm, eq.q + y.real, (lam.max() * y).real)
    opts = dict(record_every=5, tangent="full")
    full = run_transient(*args, 4e-3, 2e-6, **opts)
    run_transient(*args, 2e-3, 2e-6, folder=tmp_path, checkpoint_every=100, **opts)
    resumed = run_transient(*args, 4e-3, 2e-6, folder=tmp_path, checkpoint_every=100, resume=True, **opts)
    assert np.array_equal(resumed.t, full.t)
    assert np.array_equal(resumed.q, full.q)
    assert len(load_history(tmp_path)["t"]) == len(full.t)
    with pytest.raises(TransientError, match="different dt"):
        run_transient(*args, 4e-3, 1e-6, folder=tmp_path, resume=True, **opts)
    with pytest.raises(TransientError, match=r"Newton did not converge.*last good state"):
        run_transient(*args, 4e-3, 2e-6, folder=tmp_path / "fail", max_iterations=1, rtol=1e-16)
    assert (tmp_path / "fail" / "checkpoint.npz").exists()


def test_adaptive_steps_on_contact_events():
    """Adaptive stepping halves steps where contacts open or close and gives the same cycle as a
    uniformly fine run (to the fine run's own Δt² error)."""
    mm, eq, K, C, lam, Y = _two_dof(zeta=0.002)
    dm = from_masa(mm, 1.0)
    y = Y[:, int(np.argmax(lam.real))] * 5e-6
    args = (dm, eq.q + y.real, (lam.max() * y).real, 0.015)
    fine = run_transient(*args, 1e-6, record_every=4)
    coarse = run_transient(*args, 4e-6, record_every=1)
    adapt = run_transient(*args, 4e-6, adaptive=True, max_halvings=3)
    assert adapt.stats["halvings"] > 0
    err = lambda r: np.abs(r.q[:, 1] - fine.q[:, 1]).max()  # noqa: E731
    assert err(adapt) < err(coarse)


def test_bad_input_names_the_field():
    with pytest.raises(TransientError, match="alpha"):
        NewmarkHHT(DynamicModel(K=np.eye(1), contacts=[]), 1e-6, alpha=0.2)
    with pytest.raises(TransientError, match="dt"):
        NewmarkHHT(DynamicModel(K=np.eye(1), contacts=[]), 0.0)
    with pytest.raises(TransientError, match=r"c.d0"):
        FrictionContact(D=np.ones((2, 1)), T=np.ones((2, 1)), d0=np.zeros(3), normal=None, name="c")
    with pytest.raises(ValueError, match="v_d"):
        StribeckFriction(0.6, 0.3, 0.05, 0.01)
