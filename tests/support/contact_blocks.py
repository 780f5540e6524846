"""The two blocks pressed together through a crowned, tilted contact whose closed points change with the
pressure (issue 39): the model of tests/unit/fe/test_pressure_contact_states.py and
tests/mpi/test_contact_states_ranks.py.  The upper block's face rises by CROWN = 300 µm towards its ends
across x, against the block's own closure p h/E = 80 µm, so only its middle touches; ``initial_gap`` tilts it
by 2 µm over its length (which the free block turns away).  Half the pressure opens part of the face, twice
the pressure closes more of it."""
from __future__ import annotations

import functools

import numpy as np
from mpi4py import MPI

from fem_squeal.fe.model import GapProfile, GroundSpring, Interface, Material, ModelSpec, Pressure
from support.blocks import UPPER, two_blocks

COMM = MPI.COMM_WORLD
MU = 0.3
SCALES = [0.5, 2.0]
TILT = GapProfile(offset=0.0, gradient=(2e-6 / UPPER[3], 0.0, 0.0))   # 2 µm over the face, about its centre
CROWN = 3e-4                    # the face's rise at its ends [m], against the block's own closure p h/E = 80 µm


W0 = 20.0                       # disc speed of the damped variant [rad/s] (friction damping ∝ p|μ|/V)


def spec(damped: bool = False) -> ModelSpec:
    """The blocks; ``damped``: the contact with friction damping (at W0), which grows with the pressure."""
    return ModelSpec({"lower": Material(2e10, 0.3, 7000.0), "upper": Material(5e9, 0.25, 2500.0)},
                     clamped=("lower_bottom",),
                     interfaces=(Interface("pad", "slave", "master", "contact", kn=1e12, kt=1e10, mu=MU,
                                           sliding=1, initial_gap=TILT, friction_damping=damped,
                                           speed=W0 if damped else 0.0),),
                     ground_springs=(GroundSpring("upper_sides", 0.0, 1e9),),
                     pressures=(Pressure("upper_top", 1.0e6),))


def damping_terms(lin, damped: bool, states: dict):
    """The friction damping across the states (a new PressureTerms) of the damped variant, else None."""
    from fem_squeal.fe.preload import friction_damping
    from fem_squeal.fe.pressure_terms import PressureTerms

    if not damped:
        return None
    md, sp = two_blocks(COMM), spec(True)
    return PressureTerms(states, None, lambda p: friction_damping(lin, md, sp, None, p))


#: adaptive_reduce's report of each model (its arguments as key), beside model()'s cached tuple
REPORTS: dict = {}


@functools.cache
def model(damped: bool = False, scales: tuple[float, ...] = tuple(SCALES)):
    """The raw operators, the preload at s = 1 and its continuation to ``scales``, the operators linearised
    about s = 1 (``damped``: with the friction damping, and the pressure a parameter through it), the basis
    with the states' modes and the reduced model (adaptive_reduce)."""
    from fem_squeal.fe.assembly import assemble_operators, linearise
    from fem_squeal.fe.preload import NewtonFactor, friction_damping, solve_preload
    from fem_squeal.fe.preload_continuation import continue_preload
    from fem_squeal.fe.projection import ParametricOperators, adaptive_reduce

    md, sp = two_blocks(COMM), spec(damped)
    ops = assemble_operators(md, sp)
    (_, op), = ops.contacts
    tilted = op.gap0.copy()                # the mesh's gap and the tilt (checked below)
    op.gap0[:] += CROWN * ((op.x[:, 0] - UPPER[0] - 0.5 * UPPER[3]) / (0.5 * UPPER[3])) ** 2
    factor = NewtonFactor()
    pre = solve_preload(ops, factor=factor)
    states = {st.scale: st.result for st in continue_preload(ops, scales, start=(1.0, pre.u), factor=factor)}
    lin = linearise(ops, pre.active)
    if damped:
        Cd = friction_damping(lin, md, sp, None, pre.pressure)
        lin = lin._replace(C=Cd, Cd=Cd)
    par = ParametricOperators(lin, sp, MU, [], preload=pre, speed0=W0 if damped else 0.0,
                              pressure=damping_terms(lin, damped, {1.0: pre, **states}))
    red, basis, REPORTS[damped, scales] = adaptive_reduce(lin, par, (0.0, 800.0), [{"mu": MU}], tol=1e-2,
                                                          preload=pre, states=states)
    return ops, lin, pre, states, tilted, basis, red


def closed(active) -> int:
    return COMM.allreduce(int(np.sum(active["pad"])), op=MPI.SUM)


def outside(lin, pre, state, basis) -> np.ndarray:
    """‖(I − ΦΦᵀM)v‖_M / ‖v‖_M of each frictionless mode v about ``state`` to the band's top (800 Hz):
    how much of the state's modes the basis misses (collective)."""
    from fem_squeal.fe.assembly import relinearise
    from fem_squeal.fe.dense import apply
    from fem_squeal.fe.projection.shifted import modes_below

    at = relinearise(lin, pre.active, state.active)
    try:
        _, V = modes_below(at.K, at.M, 800.0, n_start=10)
    finally:
        for X in (at.K, at.Kf):
            X.destroy()
    assert V.shape[1] >= 5
    MV = apply(lin.M, V)
    R = V - basis.Phi @ COMM.allreduce(basis.Phi.T @ MV)
    num = COMM.allreduce(np.einsum("ij,ij->j", R, apply(lin.M, R)))
    return np.sqrt(num / COMM.allreduce(np.einsum("ij,ij->j", V, MV)))
