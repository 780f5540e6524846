"""Limit-cycle post-processing on the two-DOF model (seed 002 §3–4) and the segmented pad
(seed 004): regimes against disc speed."""
from __future__ import annotations

import numpy as np
import pytest

from fem_squeal.reduced.eigensolve import TWO_PI, quadratic_eigs
from fem_squeal.reduced.limit_cycle import detect_limit_cycle, dynamic_stability, mac, mode_cycle, space_time_svd
from fem_squeal.reduced.masa import linearise, static_equilibrium
from fem_squeal.reduced.segmented_pad import SegmentedPad, build, classify, simulate
from fem_squeal.reduced.transient import NewmarkHHT, from_masa, run_transient
from fem_squeal.reduced.two_dof import two_dof_model


@pytest.fixture(scope="module")
def cycle():
    """The damped two-DOF model (ζ 0.5 %, contact damping) grows from 3e-6 m into a limit cycle
    with intermittent contact (~0.15 s)."""
    mm = two_dof_model(cubic_share=0.3, zeta=0.005, c_max=500.0, depth=5e-6)
    eq = static_equilibrium(mm)
    K, C = linearise(mm, eq)
    lam, Y = quadratic_eigs(K, C, vectors=True)
    i = int(np.argmax(lam.real))
    dm = from_masa(mm, 1.0)
    y = Y[:, i] * 3e-6
    # 1e-5 s: 97 steps per period of the 1.03 kHz mode (HHT's period error (ωΔt)²/12 ≈ 3.5e-4); the
    # saturation time and the cycle frequency move by 1e-4 and 4e-3 from Δt = 4e-6 s (measured)
    res = run_transient(dm, eq.q + y.real, (lam[i] * y).real, 0.16, 1e-5)
    return dm, eq, K, C, lam, Y, i, res


def test_limit_cycle_detection(cycle):
    """Saturation is detected after the growth; the early envelope grows near Re λ (the fit
    spans the nonlinear onset, so 25 %), and the cycle frequency stays within 5 % of the CEA's
    (the contact opens for part of the cycle, which lowers the mean stiffness)."""
    dm, eq, K, C, lam, Y, i, res = cycle
    lc = detect_limit_cycle(res.t, res.q[:, 1])
    assert lc.saturated and 0.03 < lc.t_saturation < 0.15
    assert lc.frequency_hz == pytest.approx(lam[i].imag / TWO_PI, rel=0.05)
    assert lc.growth_rate == pytest.approx(lam[i].real, rel=0.25)
    assert (res.contact["belt.closed"][res.t > lc.t_saturation] == 0).any()   # contact loss in the cycle


def test_svd_mac_and_dynamic_stability(cycle):
    """Space–time SVD: the shapes times S Vᵀ rebuild the centred snapshots exactly; the
    strain-energy SVD's shapes are K-orthonormal; one shape carries > 90 % of the cycle.  MAC is
    1 for a complex multiple of a shape.  The tangent CEA along the cycle swings across the
    stability boundary (seed 002 Fig. 10: stable while the contact is open)."""
    dm, eq, K, C, lam, Y, i, res = cycle
    lc = detect_limit_cycle(res.t, res.q[:, 1])
    last = res.t >= res.t[-1] - 2 / lc.frequency_hz
    X = res.q[last] - res.q[last].mean(axis=0)
    plain = space_time_svd(res.q[last])
    assert np.allclose((plain.shapes * plain.singular) @ plain.time, X.T, atol=1e-12 * np.abs(X).max())
    svd = space_time_svd(res.q[last], weight=K)          # the symmetric part is the energy norm
    assert np.allclose(svd.shapes.T @ (0.5 * (K + K.T)) @ svd.shapes, np.eye(2), atol=1e-10)
    assert svd.energy_fraction()[0] > 0.9
    assert mac(Y[:, i:i + 1] * (2 - 3j), Y[:, i:i + 1])[0, 0] == pytest.approx(1.0, abs=1e-14)
    assert mac(np.array([[1.0], [0.0]]), np.array([[0.0], [1.0]]))[0, 0] == 0.0
    ds = dynamic_stability(NewmarkHHT(dm, 1e-6), res.t[last], res.q[last], res.v[last])
    top = ds.eigenvalues.real.max(axis=1)
    assert top.max() > 0 > top.min()


def test_mode_cycles_friction_work(cycle):
    """Seed 002 §4.2: along Re(αψe^(iωt)) about the static state the friction work per cycle
    is positive for the unstable mode (friction feeds it), and scales as α² while the contact
    stays closed (a bilinear form of the motion).  Eq. 7's re-equilibrated cycle converges."""
    dm, eq, K, C, lam, Y, i, res = cycle
    integ = NewmarkHHT(dm, 1e-6)
    psi, w = Y[:, i] / np.abs(Y[1, i]), lam[i].imag
    small = [mode_cycle(integ, eq.q, psi, w, a) for a in (1e-7, 2e-7)]
    assert small[0].friction_work > 0
    assert small[1].friction_work / small[0].friction_work == pytest.approx(4.0, rel=1e-3)
    eqc = mode_cycle(integ, eq.q, psi, w, 1e-6, equilibrium=True)
    assert eqc.converged.all()


def test_segmented_pad_regimes():
    """Seed 004: at low disc speed the elements stick and slip; well above v_d they slide
    without sticking (the flat μ_d branch does not feed an oscillation)."""
    pad = SegmentedPad()
    model = build(pad, 1.0)
    assert model.size == 28 and model.contacts[0].n_dir == 2
    slow = simulate(pad, 0.005, t_end=0.15)
    fast = simulate(pad, 0.3, t_end=0.15)
    assert all(r == "stick-slip" for r in slow.regime)
    assert all(r in ("steady", "periodic") for r in fast.regime)
    assert fast.fractions[:, 0].max() == 0.0
    # the elements' normal forces carry the plate load; over the last 50 samples (~4 ms, several
    # stick-slip events) the plate's inertia force averages out to within a few per cent
    assert slow.normal[-50:].sum(axis=1).mean() == pytest.approx(pad.force, rel=0.02)


def test_classify_and_bad_parameters():
    t = np.linspace(0, 1, 1001)
    w = np.zeros((1001, 1, 2))
    w[:, 0, 1] = -1.0 + 0.5 * np.sin(40 * t)          # always sliding, oscillating
    assert classify(w, 1.0, 1e-3, 3e-2)[0] == ["periodic"]
    w[:, 0, 1] = -0.02                                 # inside the transition band, steadily
    assert classify(w, 1.0, 1e-3, 3e-2)[0] == ["steady creep"]
    w[:, 0, 1] = -0.01 + 0.0095 * np.sin(40 * t)       # oscillating, dipping to 0.5 v_s: creep
    assert classify(w, 0.5, 1e-3, 3e-2)[0] == ["creep"]
    w[:, 0, 1] = -0.01 + 0.01 * np.sin(40 * t)         # reaching s = 0: stick-slip
    assert classify(w, 0.5, 1e-3, 3e-2)[0] == ["stick-slip"]
    w[:, 0, 1] = -0.5                                  # steady sliding above v_d
    assert classify(w, 0.5, 1e-3, 3e-2)[0] == ["steady"]
    with pytest.raises(ValueError, match="v_d"):
        SegmentedPad(v_s=0.05, v_d=0.01)
    with pytest.raises(ValueError, match="speed"):
        simulate(SegmentedPad(), 0.0)
