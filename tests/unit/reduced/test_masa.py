"""MASA on the reduced layer: AFT against closed forms, the contact law, the static equilibrium,
continuity with the CEA, sweep break and stationary amplitudes, elements (seed 000)."""
from __future__ import annotations

import numpy as np
import pytest

from fem_squeal.reduced.aft import IMPACTS, PERMANENT, cubic_remainder_stiffness, first_harmonic
from fem_squeal.reduced.eigensolve import quadratic_eigs
from fem_squeal.reduced.laws.contact import UnilateralLaw, tune_cubic
from fem_squeal.reduced.masa import (
    ContactSet,
    MasaError,
    MasaModel,
    MasaProblem,
    aggregate,
    polar_patches,
    run_masa,
    static_equilibrium,
)
from fem_squeal.reduced.two_dof import two_dof_model

K_L, K_NL, D0 = 2e6, 3e15, 1e-5
LAW = UnilateralLaw(k_l=np.array([K_L]), k_nl=np.array([K_NL]))


def _k(law, d0, A, phase=0.0, n=64, omega=1e4):
    h = first_harmonic(law, np.array([d0]), np.array([A * np.cos(phase)]), np.array([A * np.sin(phase)]), omega, n)
    return h.k[0], h.c[0]


def test_aft_without_loss_is_three_quarters_knl_a2():
    # the remainder is a trigonometric polynomial of degree 3: N >= 8 samples integrate it exactly
    for A in (1e-7, 5e-6, 9.9e-6):
        k, c = _k(LAW, D0, A, phase=0.7, n=8)
        assert k == pytest.approx(0.75 * K_NL * A * A, rel=1e-12)
        assert abs(c) * 1e4 * A < 1e-12 * abs(k) * A + 1e-300   # elastic law: no hysteresis
    assert cubic_remainder_stiffness(K_L, K_NL, D0, 5e-6) == pytest.approx(0.75 * K_NL * 25e-12, rel=1e-13)


@pytest.mark.parametrize("A", [1.5e-5, 2e-5, 5e-5])
def test_aft_with_contact_loss_converges_to_the_closed_form(A):
    exact = cubic_remainder_stiffness(K_L, K_NL, D0, A)
    errs = [abs(_k(LAW, D0, A, n=n)[0] - exact) / abs(exact) for n in (16, 32, 64, 128, 256)]
    # the force has a kink where contact is lost (slope k_l): the trapezoidal rule on a periodic
    # function with a derivative jump converges as N^-2 (the kink's position relative to the
    # samples makes single steps irregular, so test the overall drop over a factor 16 in N)
    assert errs[-1] < errs[0] / 40
    assert errs[-1] < 1e-4
    # any phase of the motion gives the same k (the law does not know the time origin)
    assert _k(LAW, D0, A, phase=1.1, n=1024)[0] == pytest.approx(exact, rel=1e-5)
    # without the linear part the force is C² at contact loss: much faster convergence
    cubic = UnilateralLaw(k_l=np.array([0.0]), k_nl=np.array([K_NL]))
    ex3 = cubic_remainder_stiffness(0.0, K_NL, D0, A)
    assert abs(_k(cubic, D0, A, n=128)[0] - ex3) < 1e-6 * abs(ex3)
    # an elastic law stays free of hysteresis with contact loss too
    k, c = _k(LAW, D0, A, phase=0.3, n=128)
    assert abs(c * 1e4) < 1e-12 * abs(k)


def test_aft_damped_law_gives_c_from_the_curvature_of_the_damping():
    # c(δ) = c_max(3δ²/l² − 2δ³/l³) is a cubic inside 0 < δ < l: the remainder [c(δ_s+Δ) − c(δ_s)]Δ̇
    # has the first harmonic c_eq Δ̇ with c_eq = c''(δ_s) A²/8 exactly, and no stiffness part
    depth, cm, ds, A = 1e-4, 500.0, 4e-5, 1.5e-5
    law = UnilateralLaw(k_l=np.array([K_L]), k_nl=np.array([0.0]), c_max=np.array([cm]), depth=np.array([depth]))
    k, c = _k(law, ds, A, phase=0.4, n=32)
    c2 = cm * (6 / depth ** 2 - 12 * ds / depth ** 3)
    assert c == pytest.approx(c2 * A * A / 8, rel=1e-10)
    assert abs(k) < 1e-10 * K_L
    assert law.force(np.array([-1e-6, 0.0]), 3.0).tolist() == [0.0, 0.0]


def test_tune_cubic_reproduces_stiffness_and_preload():
    k_l, k_nl, d0 = tune_cubic(np.array([1e7, 2e7, 3e7]), np.array([100.0, 0.0, 50.0]), 0.4)
    law = UnilateralLaw(k_l=k_l, k_nl=k_nl)
    assert law.stiffness(d0)[[0, 2]] == pytest.approx([1e7, 3e7])
    assert k_l[1] == 2e7 and k_nl[1] == 0 and d0[1] == 0                 # element 1 carries no load
    assert law.force(d0)[[0, 2]] == pytest.approx([100.0, 50.0])
    assert 3 * k_nl[0] * d0[0] ** 2 == pytest.approx(0.4e7)
    with pytest.raises(ValueError, match="cubic_share"):
        tune_cubic(1e7, 1.0, 1.5)
    with pytest.raises(ValueError, match="k_l"):
        UnilateralLaw(k_l=-1.0)


def test_static_equilibrium_newton_with_line_search():
    m = two_dof_model()
    eq = static_equilibrium(m)
    _, _, ds = tune_cubic(1e7, 100.0, 0.3)
    assert eq.closure[0][0] == pytest.approx(float(ds), rel=1e-9)
    assert eq.residual <= 1e-10 and eq.iterations <= 8
    # from far away (contact open, 100× the static closure): the line search keeps it on track
    far = static_equilibrium(m, q0=np.array([0.0, 100 * ds]))
    assert far.q == pytest.approx(eq.q, rel=1e-8, abs=1e-15)
    with pytest.raises(MasaError, match="after 1 Newton"):
        static_equilibrium(m, max_iterations=1)
    free = MasaModel(K=np.diag([0.0, 1.0]), contacts=m.contacts, f=np.array([1.0, 0.0]))
    with pytest.raises(MasaError, match="singular tangent"):
        static_equilibrium(free)


@pytest.fixture(scope="module")
def problem():
    m = two_dof_model()
    return MasaProblem(m, static_equilibrium(m), (0.0, 5000.0))


def test_cea_and_continuity_at_zero_amplitude(problem):
    inst = problem.instabilities()
    assert len(inst) == 1 and 1000 < inst[0].freq_hz < 1050 and inst[0].lam.real > 100
    lam0 = quadratic_eigs(problem.K)
    lam, _, status, amp = problem.state(inst[0].y, inst[0].lam.imag, 0.0)
    assert np.array_equal(lam, lam0[lam0.imag > 0])                # p = 0 is the CEA itself
    tiny = problem.state(inst[0].y, inst[0].lam.imag, 1e-9 * problem.loss_amplitude(inst[0]))[0]
    assert np.max(np.abs(tiny - lam) / np.abs(lam)) < 1e-12        # and p → 0 tends to it
    assert status.tolist() == [PERMANENT] and amp == 0


def test_cubic_regime_matches_the_describing_function(problem):
    inst = problem.instabilities()[0]
    p = 0.6 * problem.loss_amplitude(inst)
    lam, _, status, a = problem.state(inst.y, inst.lam.imag, p)
    cs = problem.model.contacts[0]
    K = problem.K + 0.75 * cs.law.k_nl[0] * a ** 2 * np.outer(cs.B[0], cs.D[0])  # ¾ k_nl A²
    ref = quadratic_eigs(K)
    assert lam == pytest.approx(ref[ref.imag > 0], rel=1e-12)
    assert status.tolist() == [PERMANENT]


def test_sweep_break_and_stationary_amplitude(problem):
    inst = problem.instabilities()
    pl = problem.loss_amplitude(inst[0])
    p = np.linspace(0.0, 6 * pl, 61)
    full = run_masa(problem, inst, p, sweep_break=False)[0]
    brk = run_masa(problem, inst, p, sweep_break=True)[0]
    assert full.amplitudes.size == 61 and brk.amplitudes.size < 61
    assert len(full.stationary) == 1 and brk.stationary == pytest.approx(full.stationary, rel=1e-12)
    p_st = full.stationary[0]
    assert pl < p_st < 6 * pl and brk.broke_at >= p_st
    n = brk.amplitudes.size
    assert brk.tracked == pytest.approx(full.tracked[:n], rel=1e-12)
    # the stationary amplitude is a zero of the real part (10 bisections of a 0.1 p_loss step)
    lam = problem.state(inst[0].y, inst[0].lam.imag, p_st)[0]
    assert np.max(lam.real) < 0.01 * inst[0].lam.real
    assert set(np.unique(full.status[p > 1.01 * pl])) == {IMPACTS}
    # the shape-updated variant runs from the same CEA and differs only at finite amplitude
    upd = run_masa(problem, inst, p[:10], sweep_break=False, update_shape=True)[0]
    assert upd.tracked[0] == full.tracked[0] and upd.update_shape


def test_elements_from_points():
    rng = np.random.default_rng(1)
    n, m = 12, 5
    r, th = np.repeat([0.1, 0.12], 6), np.tile(np.linspace(0.2, 1.0, 6), 2)   # 2 radii × 6 angles
    x = np.c_[r * np.cos(th), r * np.sin(th), np.zeros(n)]
    law = UnilateralLaw(k_l=np.full(n, 1e6), k_nl=np.full(n, 1e14))
    cs = ContactSet(D=rng.normal(size=(n, m)), T=rng.normal(size=(n, m)), d0=rng.normal(size=n) * 1e-6, law=law,
                    mu=0.3, weight=rng.uniform(1, 2, n), x=x)
    same = aggregate(cs, np.arange(n)[::-1])                 # one point per element: the points again
    order = np.arange(n)[::-1]
    assert np.allclose(same.D[order], cs.D) and np.allclose(same.law.k_l, 1e6)
    lab = polar_patches(x, 2, 3)
    assert len(np.unique(lab)) == 6
    el = aggregate(cs, lab)
    assert el.law.k_l.sum() == pytest.approx(n * 1e6) and el.weight.sum() == pytest.approx(cs.weight.sum())
    with pytest.raises(MasaError, match="labels"):
        aggregate(cs, lab[:-1])


def test_bad_input_is_named():
    m = two_dof_model()
    with pytest.raises(MasaError, match="K: must be square"):
        MasaModel(K=np.zeros((2, 3)), contacts=m.contacts)
    with pytest.raises(MasaError, match="contacts"):
        MasaModel(K=np.eye(2), contacts=[])
    with pytest.raises(MasaError, match=r"belt.T"):
        ContactSet(D=np.zeros((1, 2)), T=np.zeros((2, 2)), d0=np.zeros(1), law=LAW, name="belt")
    prob = MasaProblem(m, static_equilibrium(m), (0, 5000))
    with pytest.raises(MasaError, match="amplitudes"):
        run_masa(prob, prob.instabilities(), [0.0, 2.0, 1.0])
    with pytest.raises(MasaError, match="band_hz"):
        MasaProblem(m, static_equilibrium(m), (5000, 10))
