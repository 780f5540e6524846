"""The operators across brake pressures (issue 39, fem_squeal.fe.pressure_terms): on the two blocks pressed
together with a crowned contact (an initial overlap growing across x, so that the preload u(s), its stress
and the contact pressure are affine, not linear, in the pressure scale s), the stress stiffening K_σ(u(s))
and the friction damping C_d(p(s)) assembled from the state continued to s equal the reduced model's affine
terms K_σ0 + (s − 1) K_σ,s and C_d + (s − 1) C_d,s at scales between and beyond the states the slopes were
taken from; the parametric operators use each state's own operators; the named errors."""
from __future__ import annotations

import functools
from types import SimpleNamespace

import numpy as np
import pytest
from mpi4py import MPI
from support.blocks import UPPER, two_blocks

from fem_squeal.fe.model import GroundSpring, Interface, Material, ModelSpec, Pressure
from fem_squeal.util.errors import ModelError

COMM = MPI.COMM_WORLD
MU, W0 = 0.3, 20.0             # friction coefficient, disc speed [rad/s] (friction damping ∝ p|μ|/V)
SCALES = [0.5, 1.5, 2.0]        # continued from the scene's s = 1; the slope is taken at 2 (farthest)
CROWN = 1e-6                    # initial overlap at the ends of the upper block [m] (the closure p/k_n ~ 1 µm)


def spec() -> ModelSpec:
    return ModelSpec({"lower": Material(2e10, 0.3, 7000.0), "upper": Material(5e9, 0.25, 2500.0)},
                     clamped=("lower_bottom",),
                     interfaces=(Interface("pad", "slave", "master", "contact", kn=1e12, mu=MU, sliding=1,
                                           friction_damping=True, speed=W0),),
                     ground_springs=(GroundSpring("upper_sides", 0.0, 1e9),),
                     pressures=(Pressure("upper_top", 1.0e6),))


@functools.cache
def model():
    """The preload at s = 1 and continued to SCALES, the operators linearised about s = 1 with the stress
    stiffening and the friction damping, the parametric operators with the pressure and the reduced model."""
    from fem_squeal.fe.assembly import assemble_operators, geometric_stiffness, linearise, operating_terms
    from fem_squeal.fe.preload import NewtonFactor, friction_damping, solve_preload
    from fem_squeal.fe.preload_continuation import continue_preload
    from fem_squeal.fe.pressure_terms import PressureTerms
    from fem_squeal.fe.projection import ParametricOperators, build_basis, reduce

    md, sp = two_blocks(COMM), spec()
    ops = assemble_operators(md, sp)
    x0, half = UPPER[0] + 0.5 * UPPER[3], 0.5 * UPPER[3]
    for _, op in ops.contacts:             # u(s) = s u_f + u_g, affine in s; u_g (the crown's own, a
        op.gap0[:] -= CROWN * ((op.x[:, 0] - x0) / half) ** 2  # self-equilibrated pressure) stresses the blocks
    factor = NewtonFactor()
    pre = solve_preload(ops, factor=factor)
    states = {st.scale: st.result for st in continue_preload(ops, SCALES, start=(1.0, pre.u), factor=factor)}
    lin = linearise(ops, pre.active)
    Cd = friction_damping(lin, md, sp, None, pre.pressure)
    lin = lin._replace(C=Cd, Cd=Cd)
    terms = operating_terms(lin, md, sp, stress_stiffening=True, u_static=pre.u)
    across = PressureTerms({1.0: pre, **states}, lambda u: geometric_stiffness(lin, md, sp, u),
                           lambda p: friction_damping(lin, md, sp, None, p))
    par = ParametricOperators(lin, sp, MU, [], preload=pre, operating=terms, speed0=W0, pressure=across)
    basis = build_basis(lin, par, 1500.0, n_start=10)
    return md, lin, pre, states, terms, par, basis, reduce(lin, par, basis, pre)


def test_the_continued_states_keep_the_contact_set_and_are_not_proportional():
    _, _, pre, states, _, par, _, _ = model()
    assert par.pressure.far == 2.0
    for s, r in states.items():
        assert np.array_equal(r.active["pad"], pre.active["pad"])
        d = pre.u.copy()
        d.scale(s)
        ref = d.norm()
        d.axpy(-1.0, r.u)
        assert d.norm() / ref > 1e-3          # the crown: u(s) is not s u(1)
    for A, A1 in ((par.pressure.stiffness_at(2.0), par.operating.Ks0), (par.pressure.damping_at(2.0), par.ops.Cd)):
        D = A.copy()                          # and so are its stress stiffening and friction damping
        D.axpy(-2.0, A1)
        assert D.norm() > 1e-3 * A.norm()
        D.destroy()


@pytest.mark.parametrize("scale", [0.5, 1.5])
@pytest.mark.parametrize("term", ["stiffness", "damping"])
def test_operators_of_the_state_at_a_pressure_are_the_affine_reduced_terms(term, scale):
    """Φᵀ (A(s) − A(1)) Φ, A(s) = K_σ(u(s)) or C_d(p(s)) assembled from the state continued to s, against
    the reduced model's (s − 1) K_σ,s or (s − 1) C_d,s (slopes from the state at 2): equal to round-off,
    between the sampled states (1.5) and outside them (0.5); the full-order matrices too."""
    from fem_squeal.fe.projection import project

    _, _, _, _, terms, par, basis, red = model()
    A, A1, slope, reduced = ((par.pressure.stiffness_at(scale), terms.Ks0, par.pressure.stiffness_slope, red.Ksp)
                             if term == "stiffness" else
                             (par.pressure.damping_at(scale), par.ops.Cd, par.pressure.damping_slope, red.Cdp))
    D = A.copy()
    D.axpy(-1.0, A1)
    full = project(D, basis.Phi)
    assert np.max(np.abs(full)) > 0.1 * np.max(np.abs(project(A1, basis.Phi)))
    assert np.max(np.abs(full - (scale - 1.0) * reduced)) <= 1e-9 * np.max(np.abs(full))
    D.axpy(-(scale - 1.0), slope)
    assert D.norm() <= 1e-9 * A.norm()
    D.destroy()
    K, C = par.terms({"pressure": scale})
    used = K if term == "stiffness" else C
    assert any(B is A for B, _ in used) and (term == "damping" or not any(B is A1 for B, _ in used))


def test_reduced_pressure_parameter_and_its_derivative():
    from support.operators import projection_mismatch

    _, _, _, _, _, par, basis, red = model()
    assert "pressure" in red.parameters and red.nominal()["pressure"] == 1.0
    assert "pressure" in par.parameters
    # K(p), C(p) of the full operators (the state's K_σ, C_d) projected against the reduced affine form
    for point in ({"pressure": 1.5, "mu": 0.45}, {"pressure": 0.5, "mu": -0.2, "speed": 3 * W0}):
        assert max(projection_mismatch(par, basis.Phi, red, point)) <= 1e-10
    K1, C1 = red.matrices({"pressure": np.array([1.0])})
    assert np.array_equal(K1, red.matrices()[0]) and np.array_equal(C1, red.matrices()[1])
    dK, dC = red.derivative("pressure", {"mu": 0.6, "speed": 2 * W0})
    assert np.array_equal(dK, red.Ksp) and np.allclose(dC, (0.6 / MU) * 0.5 * red.Cdp, rtol=1e-14)
    # d/dμ and d/dΩ of the friction damping at a pressure: that pressure's C_d + (s − 1) C_d,s
    h = 1e-6
    for name, x0 in (("mu", 0.45), ("speed", 1.5 * W0)):
        point = {"pressure": 1.8, "mu": 0.45, "speed": 1.5 * W0}
        dC = red.derivative(name, point)[1]
        up, dn = ({k: np.array([v + (d * h * x0 if k == name else 0.0)]) for k, v in point.items()}
                  for d in (1, -1))
        fd = (red.matrices(up)[1][0] - red.matrices(dn)[1][0]) / (2 * h * x0)
        assert np.max(np.abs(dC - fd)) <= 1e-6 * np.max(np.abs(dC))


def test_save_load_keeps_the_pressure_term(tmp_path):
    from fem_squeal.reduced.model import ReducedModel

    red = model()[-1]
    red.save(tmp_path / "m.npz")
    back = ReducedModel.load(tmp_path / "m.npz")
    assert "pressure" in back.parameters
    assert np.array_equal(back.Ksp, red.Ksp) and np.array_equal(back.Cdp, red.Cdp)


def test_named_errors():
    from fem_squeal.fe.pressure_terms import PressureTerms
    from fem_squeal.fe.projection import ParametricOperators

    _, lin, pre, states, _, par, _, red = model()
    with pytest.raises(ModelError, match=r"^pressure: no preload state at 1\.7 × loads\.pressure \(states at "
                                         r"\[0\.5, 1\.0, 1\.5, 2\.0\]\)"):
        par.terms({"pressure": 1.7})
    with pytest.raises(ModelError, match=r"^pressure: must be > 0"):
        red.matrices({"pressure": np.array([0.0])})
    with pytest.raises(ModelError, match=r"^pressure: the operators across pressures need the scene's preload"):
        PressureTerms({2.0: states[2.0]}, lambda u: None)
    with pytest.raises(ModelError, match=r"^pressure: .* need a preload state at another pressure scale"):
        PressureTerms({1.0: pre}, lambda u: None)
    with pytest.raises(ModelError, match=r"^pressure: no operator depends on the pressure"):
        PressureTerms({1.0: pre, 2.0: states[2.0]})
    with pytest.raises(ModelError, match=r"^pressure: the stress stiffening K_σ \(preload\.geometric_stiffness\) "
                                         r"is not in these operators"):
        ParametricOperators(lin, spec(), MU, [], preload=pre, speed0=W0, pressure=par.pressure)
    with pytest.raises(ModelError, match=r"^pressure: the friction damping C_d \(friction_damping\) grows with "
                                         r"the pressure, but the pressure terms lack it"):
        ParametricOperators(lin, spec(), MU, [], preload=pre, operating=par.operating, speed0=W0,
                            pressure=SimpleNamespace(stiffness=par.pressure.stiffness, damping=None))
