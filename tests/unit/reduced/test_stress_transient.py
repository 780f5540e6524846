"""Stress tests of the reduced transient integrator (benchmark: benchmarks/transient_order.py):
order 2 on a linear oscillator, the energy balance over a long run with contact and friction,
bounded response and HHT damping of the high mode at Δt ≫ its period."""
from __future__ import annotations

import sys

import numpy as np
import pytest
from support.paths import ROOT

from fem_squeal.reduced.eigensolve import quadratic_eigs
from fem_squeal.reduced.masa import linearise, static_equilibrium
from fem_squeal.reduced.transient import DynamicModel, from_masa, run_transient
from fem_squeal.reduced.two_dof import two_dof_model

sys.path.insert(0, str(ROOT / "benchmarks"))
import transient_order  # noqa: E402  (the belt of its section 3c: stick spring ω_t = 1e5 rad/s)


@pytest.mark.parametrize("zeta,alpha", [(0.0, 0.0), (0.0, -0.1), (0.02, 0.0), (0.02, -1 / 3)])
def test_second_order_on_the_linear_oscillator(zeta, alpha):
    """q̈ + 2ζωq̇ + ω²q = 0 (100 Hz, q₀ = 1 mm) over 10 periods against the exact solution; error =
    max over the steps.  HHT-α (γ = ½ − α, β = (1 − α)²/4) is second order for every α.  The
    fit over Δt = T/40, T/80, T/160 has the next term O((ωΔt)²) ≈ 2.5 % relative at T/40 (phase
    error (ωΔt)²/12·ωt plus its square), which moves the slope by < 0.02; the benchmark measures
    1.98–2.00 for α = 0, −0.1, −1/3 and ζ = 0, 0.02, so |p − 2| < 0.05 (the Newton tolerance,
    rtol 1e-12, is 1e-8 below the finest error)."""
    w = 2 * np.pi * 100.0
    T = 2 * np.pi / w
    model = DynamicModel(K=np.array([[w * w]]), contacts=[], C=None if zeta == 0 else np.array([[2 * zeta * w]]))
    wd = w * np.sqrt(1 - zeta ** 2)
    q0 = 1e-3
    errs, dts = [], [T / 40, T / 80, T / 160]
    for dt in dts:
        res = run_transient(model, np.array([q0]), None, 10 * T, dt, alpha=alpha, rtol=1e-12,
                            record_elements=False)
        exact = np.exp(-zeta * w * res.t) * q0 * (np.cos(wd * res.t) + zeta * w / wd * np.sin(wd * res.t))
        errs.append(np.abs(res.q[:, 0] - exact).max() / q0)
    p = np.polyfit(np.log(dts), np.log(errs), 1)[0]
    assert abs(p - 2) < 0.05, (p, errs)
    assert errs[-1] < 2e-2          # and the constant is sane (0.8–1.2 % at T/160)


@pytest.fixture(scope="module")
def limit_cycle():
    """The two-DOF mode-coupling model (cubic unilateral contact, constant friction, ζ = 0.5 %)
    pushed along its unstable CEA mode beyond contact loss: it grows into a limit cycle that
    opens the contact every cycle; 1e4 steps of 4 µs (0.04 s, ~40 cycles)."""
    mm = two_dof_model(cubic_share=0.3, zeta=0.005)
    eq = static_equilibrium(mm)
    K, C = linearise(mm, eq)
    lam, Y = quadratic_eigs(K, C, vectors=True)
    i = int(np.argmax(lam.real))
    y = Y[:, i] * 3e-5
    res = run_transient(from_masa(mm, 1.0), eq.q + y.real, (lam[i] * y).real, 0.04, 4e-6, record_every=5,
                        record_elements=False)
    return mm, res


def test_energy_balance_over_ten_thousand_steps_with_contact_and_friction(limit_cycle):
    """Discrete balance (α = 0): E − E₀ − (W_ext + W_fric + W_normal − D) collects only the Newton
    residuals, Δqᵀ(r₀ + r₁)/2 per step with ‖r‖ ≤ rtol·ref and ref ≥ ‖Mv‖/Δt; as ‖Δq‖ ≈ ‖v‖Δt
    each step leaks ≤ rtol‖v‖² ≤ 2 rtol·max E_kin, so over n steps ≤ 2 n rtol max E_kin = 2e-5
    max E_kin = 3.2e-5 J here (rtol 1e-9, n = 1e4; measured 1.8e-7 J, i.e. 1.1e-7 of the
    vibration energy, and 1.3e-6 of it after 1e5 steps in the benchmark).
    Physical balance (contact potential V_c = k_lδ²/2 + k_nlδ⁴/4 instead of the discrete normal
    work): O(Δt²) quadrature error per impact, bounded, not drifting — 1.2e-4 of the vibration
    energy after 1e4 steps and still 1.2e-4 max over 1e5 steps in the benchmark; 1e-3 allows 8×."""
    mm, res = limit_cycle
    n = res.stats["steps"]
    assert n == 10000
    E = res.total_energy()
    Ek = res.energy["kinetic"]
    scale = E.max() - E.min()
    assert np.abs(res.energy_residual()).max() <= 2 * n * 1e-9 * Ek.max()
    # the run does exercise contact loss and friction
    cs = mm.contacts[0]
    delta = cs.d0[0] + res.q @ cs.D[0]
    assert 0.2 < (delta <= 0).mean() < 0.8
    assert res.energy["W_friction"][-1] > 0.5 * scale and res.energy["D_damping"][-1] > 0.1 * scale
    d = np.maximum(delta, 0.0)
    Vc = float(cs.law.k_l[0]) * d ** 2 / 2 + float(cs.law.k_nl[0]) * d ** 4 / 4
    e = res.energy
    phys = E + Vc - E[0] - Vc[0] - (e["W_ext"] + e["W_friction"] - e["D_damping"] + e["W_skew"])
    assert np.abs(phys).max() < 1e-3 * scale


@pytest.mark.parametrize("alpha", [0.0, -0.1])
def test_bounded_at_hundred_times_the_shortest_period(alpha):
    """Undamped 2-DOF with modes at 1 Hz and 10 kHz, Δt = 100 T_high (ω_hΔt = 628), 200 steps
    from q₀ = (1, 1) mm at rest.  Unconditional stability: the high mode's displacement never
    exceeds q₀.  α = 0: the amplification matrix has |z| = 1, so its energy norm
    √(q² + (v/ω)²) is kept to round-off (×(ω_hΔt)² ≈ 4e5 of 1e-16: bound 1e-8).  α = −0.1: it
    decays by ρ ≈ ρ∞ = (1+α)/(1−α) = 0.818 per step (ρ²⁰⁰ = 4e-18; measured 3e-15, the first
    steps' velocity overshoot ≈ 0.19|α|ω_hΔt = 11.6 q₀ω_h included), bound 1e-10.  The
    resolved 1 Hz mode (ω_lΔt = 0.063) keeps its energy within 1e-4 (HHT dissipation
    ∝ |α|(ωΔt)³ per cycle)."""
    wl, wh = 2 * np.pi * 1.0, 2 * np.pi * 1e4
    dt = 100 * 2 * np.pi / wh
    model = DynamicModel(K=np.diag([wl ** 2, wh ** 2]), contacts=[])
    q0 = np.array([1e-3, 1e-3])
    res = run_transient(model, q0, None, 200 * dt, dt, alpha=alpha, record_elements=False)
    assert res.stats["steps"] == 200 and np.all(np.isfinite(res.q)) and np.all(np.isfinite(res.v))
    assert np.abs(res.q[:, 1]).max() <= q0[1] * (1 + 1e-12)
    amp = np.hypot(res.q[:, 1], res.v[:, 1] / wh) / q0[1]
    if alpha == 0:
        assert np.abs(amp - 1).max() < 1e-8
    else:
        assert amp[-1] < 1e-10
        assert np.abs(res.v[:, 1]).max() / wh / q0[1] < 0.2 * abs(alpha) * wh * dt   # the overshoot, bounded
    El = 0.5 * res.v[:, 0] ** 2 + 0.5 * wl ** 2 * res.q[:, 0] ** 2
    assert abs(El[-1] / El[0] - 1) < 1e-4


def test_unresolved_stick_spring_warns():
    """ω_t Δt = 50 silently turned the belt's stick–slip into pure sliding (benchmarks/transient_order.py
    4c); ω_t Δt = 2 (the closed-form test's step) is resolved and must not warn."""
    import warnings

    from fem_squeal.reduced.transient import NewmarkHHT

    model, _ = transient_order.belt()
    with pytest.warns(RuntimeWarning, match="stick springs"):
        NewmarkHHT(model, 5e-4)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        NewmarkHHT(model, 2e-5)


def test_t_end_must_be_whole_steps():
    from fem_squeal.reduced.transient import TransientError, run_transient

    model, q0 = transient_order.belt()
    with pytest.raises(TransientError, match="t_end"):
        run_transient(model, q0, None, 2.5e-4, 1e-4)
    with pytest.raises(TransientError, match="t_end"):
        run_transient(model, q0, None, 0.4e-4, 1e-4)
