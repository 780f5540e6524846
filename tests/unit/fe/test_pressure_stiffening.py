"""The stress stiffening across brake pressures (issue 39, fem_squeal.fe.pressure_stiffening): on the two
blocks pressed together with an interference fit held by springs on the top (so that the preload u(s), and
its stress, is affine, not linear, in the pressure scale s), K_σ(u(s)) assembled from the state continued to
s equals the reduced model's affine term K_σ0 + (s − 1) K_σ,s at scales between and beyond the states the
slope was taken from; the parametric operators use each state's own K_σ; the named errors."""
from __future__ import annotations

import functools

import numpy as np
import pytest
from mpi4py import MPI
from support.blocks import two_blocks

from fem_squeal.fe.model import GroundSpring, Interface, Material, ModelSpec, Pressure
from fem_squeal.util.errors import ModelError

COMM = MPI.COMM_WORLD
MU = 0.3
SCALES = [0.5, 1.5, 2.0]        # continued from the scene's s = 1; the slope is taken at 2 (farthest)
INTERFERENCE = 1e-6             # initial overlap [m]: the closure at s = 1 is ~ p/k_n = 1 µm
K_TOP = 3e11                    # springs on the upper block's top [N/m³]: the overlap stresses both blocks


def spec() -> ModelSpec:
    return ModelSpec({"lower": Material(2e10, 0.3, 7000.0), "upper": Material(5e9, 0.25, 2500.0)},
                     clamped=("lower_bottom",),
                     interfaces=(Interface("pad", "slave", "master", "contact", kn=1e12, mu=MU, sliding=1),),
                     ground_springs=(GroundSpring("upper_sides", 0.0, 1e9), GroundSpring("upper_top", K_TOP, 0.0)),
                     pressures=(Pressure("upper_top", 1.0e6),))


@functools.cache
def model():
    """The preload at s = 1 and continued to SCALES, the operators linearised about s = 1 with the stress
    stiffening, the parametric operators with the pressure and the reduced model."""
    from fem_squeal.fe.assembly import assemble_operators, geometric_stiffness, linearise, operating_terms
    from fem_squeal.fe.preload import NewtonFactor, solve_preload
    from fem_squeal.fe.preload_continuation import continue_preload
    from fem_squeal.fe.pressure_stiffening import PressureStiffening
    from fem_squeal.fe.projection import ParametricOperators, build_basis, reduce

    md, sp = two_blocks(COMM), spec()
    ops = assemble_operators(md, sp)
    for _, op in ops.contacts:
        op.gap0[:] -= INTERFERENCE        # an interference fit: u(s) = s u_f + u_g, affine in s, and
    # u_g stresses the blocks (the springs hold the upper one): K_σ(u(s)) is not proportional to s
    factor = NewtonFactor()
    pre = solve_preload(ops, factor=factor)
    states = {st.scale: st.result for st in continue_preload(ops, SCALES, start=(1.0, pre.u), factor=factor)}
    lin = linearise(ops, pre.active)
    terms = operating_terms(lin, md, sp, stress_stiffening=True, u_static=pre.u)
    stiff = PressureStiffening({1.0: pre.u, **{s: r.u for s, r in states.items()}},
                               lambda u: geometric_stiffness(lin, md, sp, u))
    par = ParametricOperators(lin, sp, MU, [], preload=pre, operating=terms, pressure=stiff)
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
        assert d.norm() / ref > 1e-2          # the interference: u(s) is far from s u(1)
    Kg = par.pressure.at(2.0).copy()          # and so is its stress stiffening
    Kg.axpy(-2.0, par.operating.Ks0)
    assert Kg.norm() > 1e-2 * par.pressure.at(2.0).norm()
    Kg.destroy()


@pytest.mark.parametrize("scale", [0.5, 1.5])
def test_stress_stiffening_of_the_state_at_a_pressure_is_the_affine_reduced_term(scale):
    """Φᵀ (K_σ(u(s)) − K_σ(u(1))) Φ, K_σ assembled from the state continued to s, against the reduced
    model's (s − 1) K_σ,s (the slope from the state at 2): equal to round-off, between the sampled states
    (1.5) and outside them (0.5); the full-order matrices too."""
    from fem_squeal.fe.projection import project

    _, _, _, _, terms, par, basis, red = model()
    Ks = par.pressure.at(scale)
    D = Ks.copy()
    D.axpy(-1.0, terms.Ks0)
    full = project(D, basis.Phi)
    assert np.max(np.abs(full)) > 1e-3 * np.max(np.abs(project(terms.Ks0, basis.Phi)))
    affine = (scale - 1.0) * red.Ksp
    assert np.max(np.abs(full - affine)) <= 1e-9 * np.max(np.abs(full))
    D.axpy(-(scale - 1.0), par.pressure.slope)
    assert D.norm() <= 1e-9 * Ks.norm()
    D.destroy()
    K = par.terms({"pressure": scale})[0]
    assert any(A is Ks for A, _ in K) and not any(A is terms.Ks0 for A, _ in K)


def test_reduced_pressure_parameter_and_its_derivative():
    from support.operators import projection_mismatch

    _, _, _, _, _, par, basis, red = model()
    assert "pressure" in red.parameters and red.nominal()["pressure"] == 1.0
    assert "pressure" in par.parameters
    # K(p) of the full operators (the state's K_σ) projected against the reduced affine form
    assert max(projection_mismatch(par, basis.Phi, red, {"pressure": 1.5, "mu": 0.45})) <= 1e-10
    K1 = red.matrices({"pressure": np.array([1.0])})[0][0]
    assert np.array_equal(K1, red.matrices()[0][0])
    dK, dC = red.derivative("pressure")
    assert dC is None and np.array_equal(dK, red.Ksp)


def test_save_load_keeps_the_pressure_term(tmp_path):
    from fem_squeal.reduced.model import ReducedModel

    red = model()[-1]
    red.save(tmp_path / "m.npz")
    back = ReducedModel.load(tmp_path / "m.npz")
    assert "pressure" in back.parameters and np.array_equal(back.Ksp, red.Ksp)


def test_named_errors():
    from fem_squeal.fe.pressure_stiffening import PressureStiffening
    from fem_squeal.fe.projection import ParametricOperators

    _, lin, pre, states, _, par, _, red = model()
    with pytest.raises(ModelError, match=r"^pressure: no preload state at 1\.7 × loads\.pressure \(states at "
                                         r"\[0\.5, 1\.0, 1\.5, 2\.0\]\)"):
        par.terms({"pressure": 1.7})
    with pytest.raises(ModelError, match=r"^pressure: must be > 0"):
        red.matrices({"pressure": np.array([0.0])})
    with pytest.raises(ModelError, match=r"^pressure: the stress stiffening across pressures needs the scene's"):
        PressureStiffening({2.0: states[2.0].u}, lambda u: None)
    with pytest.raises(ModelError, match=r"^pressure: .* needs a preload state at another pressure scale"):
        PressureStiffening({1.0: pre.u}, lambda u: None)
    with pytest.raises(ModelError, match=r"^pressure: the pressure is a parameter of the stress stiffening"):
        ParametricOperators(lin, spec(), MU, [], preload=pre, pressure=par.pressure)
