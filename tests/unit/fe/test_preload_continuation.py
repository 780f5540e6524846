"""Pressure continuation of the preload (fem_squeal.fe.preload_continuation) on the two-block contact:
the states at several pressure scales equal separate cold solves (with a cubic penalty, so that the
response is not linear in the pressure and the continued solves take Newton steps), the continued solves
update the kept factorisation instead of refactorising, a cached state is accepted without a Newton step,
and a pressure scale <= 0 is refused by name before any solve."""
from __future__ import annotations

import functools

import numpy as np
import pytest
from mpi4py import MPI
from support.blocks import two_blocks

from fem_squeal.fe.assembly import assemble_operators
from fem_squeal.fe.model import GapProfile, GroundSpring, Interface, Material, ModelSpec, Pressure
from fem_squeal.util.errors import ModelError

COMM = MPI.COMM_WORLD
K3 = 1e24           # cubic penalty [N/m⁵]: k₃g³ ≈ k_n g at the nominal closure g ≈ 1 µm
SCALES = [2.0, 0.5, 1.0]


@functools.cache
def blocks_ops(interference: float = 0.0):
    """The two blocks; ``interference`` [m]: the upper block's face stands that far proud (g₀ −= it)."""
    gap = GapProfile(offset=-interference)
    spec = ModelSpec({"lower": Material(2e10, 0.3, 7000.0), "upper": Material(5e9, 0.25, 2500.0)},
                     clamped=("lower_bottom",),
                     interfaces=(Interface("pad", "slave", "master", "contact", kn=1e12, mu=0.3, sliding=1,
                                           initial_gap=gap),),
                     ground_springs=(GroundSpring("upper_sides", 0.0, 1e9),),
                     pressures=(Pressure("upper_top", 1.0e6),))
    return assemble_operators(two_blocks(COMM), spec)


def rel(a, b) -> float:
    d = a.copy()
    d.axpy(-1.0, b)
    return d.norm() / b.norm()


@pytest.fixture(scope="module")
def continued():
    from fem_squeal.fe.preload_continuation import continue_preload

    return continue_preload(blocks_ops(), SCALES, k3=K3)


def test_continued_states_are_the_separate_solves(continued):
    from fem_squeal.fe.preload import solve_preload

    ops = blocks_ops()
    assert [st.scale for st in continued] == SCALES and not any(st.cached for st in continued)
    first = min(continued, key=lambda st: st.scale)
    assert 1 <= first.result.factorisations <= 2          # the cold solve (max_factorisations = 2)
    for st in continued[:2]:
        cold = solve_preload(ops, k3=K3, scale=st.scale)
        assert rel(st.result.u, cold.u) < 1e-8
        assert st.result.normal_force["pad"] == pytest.approx(cold.normal_force["pad"], rel=1e-8)
        assert np.array_equal(st.result.active["pad"], cold.active["pad"])
        if st is not first:              # updates of the kept factorisation, no new one
            assert st.result.factorisations == 0 and st.result.iterations >= 1
        cold.u.destroy()
    # the cubic penalty makes the response nonlinear in p: u(2) is not 2 u(1)
    u1, u2 = continued[2].result.u.copy(), continued[0].result.u
    u1.scale(2.0)
    assert rel(u1, u2) > 1e-3


def test_the_tangent_predictor_is_the_state_while_the_contact_set_holds():
    """With the face 1 µm proud (every point closed at every pressure here) the linear penalty's state is
    affine in the pressure scale, not proportional to it: the continued start u(s') + (s − s') J⁻¹f is
    the state itself, accepted without a Newton step (the scaled start (s/s') u(s') was not: it took
    one), and equal to the cold solve to the preload's tolerance (‖R‖ ≤ 1e-9‖f‖ both)."""
    from fem_squeal.fe.preload import solve_preload
    from fem_squeal.fe.preload_continuation import continue_preload

    ops = blocks_ops(1e-6)
    states = continue_preload(ops, [1.0, 2.0, 3.0])
    assert all(st.result.active["pad"].all() for st in states)
    assert [st.result.iterations for st in states[1:]] == [0, 0]
    for st in states[1:]:
        cold = solve_preload(ops, scale=st.scale)
        assert rel(st.result.u, cold.u) < 1e-8
        cold.u.destroy()
    scaled = states[0].result.u.copy()
    scaled.scale(2.0)
    assert rel(scaled, states[1].result.u) > 1e-3          # the interference: not proportional
    for obj in [scaled, *(st.result.u for st in states)]:
        obj.destroy()


def test_cached_states_need_no_newton_step(continued, tmp_path):
    from fem_squeal.fe.preload_continuation import StateCache, continue_preload

    ops = blocks_ops()
    cache = StateCache(tmp_path, "blocks", {"k3": K3}, COMM)
    first = continue_preload(ops, SCALES[:1], k3=K3, cache=cache)
    again = continue_preload(ops, SCALES[:1], k3=K3, cache=cache)
    assert [st.cached for st in again] == [True] and [st.result.iterations for st in again] == [0]
    for a, b in zip(first, again):
        assert rel(a.result.u, b.result.u) == 0.0
    other = StateCache(tmp_path, "blocks", {"k3": 2 * K3}, COMM)      # other settings: another key
    assert other.key(2.0) != cache.key(2.0)


def test_bad_pressure_is_named_before_any_solve():
    from fem_squeal.fe.preload import solve_preload
    from fem_squeal.fe.preload_continuation import continue_preload

    with pytest.raises(ModelError, match=r"^pressure: must be > 0 \(a scale of loads\.pressure; got -1\)"):
        continue_preload(blocks_ops(), [1.0, -1.0])
    with pytest.raises(ModelError, match=r"^preload: the load scale must be > 0"):
        solve_preload(blocks_ops(), scale=0.0)


def test_a_symmetric_continuation_reaches_the_same_states():
    """preload.jacobian "symmetric" through a continuation: the frictionless Cholesky of the first solve
    preconditions the later pressures' GMRES steps too (kept in the continuation's factor; the cost rule may
    still refactorise it, numerically), and every state is the cold "update" solve's (the cubic penalty:
    Newton steps at every pressure), as the default's are."""
    from fem_squeal.fe.preload import solve_preload
    from fem_squeal.fe.preload_continuation import continue_preload

    ops = blocks_ops()
    states = continue_preload(ops, SCALES, k3=K3, jacobian="symmetric")
    first = min(states, key=lambda st: st.scale)
    assert 1 <= first.result.factorisations <= 2 and first.result.jacobian == "symmetric"
    for st in states:
        cold = solve_preload(ops, k3=K3, scale=st.scale)
        assert rel(st.result.u, cold.u) < 1e-8
        assert np.array_equal(st.result.active["pad"], cold.active["pad"])
        if st is not first:
            assert st.result.jacobian == "symmetric" and st.result.iterations >= 1
            assert st.result.krylov_iterations > 0 and st.result.update_columns == 0
        cold.u.destroy()
