"""Contact sets that change with the pressure (issue 39) on 2 ranks: the two blocks of
tests/unit/fe/test_pressure_contact_states.py, serial and under ``mpirun -n 2``.  The states' closed points
(gathered in the rank-independent row order the reduced model keeps) are the same; the operators moved to
another state (``relinearise``: a collective step that a rank without a changed point must still take) are
those linearised about it afresh; and the reduced model at each pressure is the projection of the full
operators about that pressure's state, on 2 ranks as on 1 (1e-10: round-off of the projections).  Where
few points change, the state's modes enter the basis as static derivatives, to the serial bound on 2 ranks."""
from __future__ import annotations

import pytest
from support.ranks import two_rank_signature

NEAR = (0.9, 1.1)      # pressures that change few points: the static-derivative path


def signature() -> dict:
    """Closed points per state, the model's contact_states, relinearise against linearise (relative norm of
    the difference, K and K_f) and the reduced K at each pressure against the projection (relative)."""
    import numpy as np
    from mpi4py import MPI
    from support import contact_blocks as t

    from fem_squeal.fe.assembly import linearise, relinearise
    from fem_squeal.fe.projection import ParametricOperators, project

    ops, lin, pre, states, _, basis, red = t.model()
    out = {"ranks": MPI.COMM_WORLD.size,
           "closed": [t.closed(states[0.5].active), t.closed(pre.active), t.closed(states[2.0].active)],
           "masks": {str(s): {n: a.astype(int).tolist() for n, a in st.items()}
                     for s, st in red.contact_states.items()},
           "relinearise": [], "projection": []}
    for s in t.SCALES:
        moved, fresh = relinearise(lin, pre.active, states[s].active), linearise(ops, states[s].active)
        for A, B in ((moved.K, fresh.K), (moved.Kf, fresh.Kf)):
            D = A.copy()
            D.axpy(-1.0, B)
            out["relinearise"].append(D.norm() / B.norm())
            D.destroy()
        par = ParametricOperators(moved, t.spec(), t.MU, [], preload=states[s])
        K = par.matrices({"mu": t.MU})[0]
        P = project(K, basis.Phi)
        R = red.matrices({"mu": np.array([t.MU]), "pressure": np.array([s])})[0][0]
        out["projection"].append(float(np.max(np.abs(R - P)) / np.max(np.abs(P))))
        for X in (K, moved.K, moved.Kf, fresh.K, fresh.Kf):
            X.destroy()
        par.destroy()
    out["near_outside"] = near_outside()
    return out


def near_outside() -> list[float]:
    """The largest share of the M-norm of a frictionless mode about each NEAR state that lies outside the
    basis of the model built with those states (their modes enter as static derivatives)."""
    from support import contact_blocks as t

    _, lin, pre, states, _, basis, _ = t.model(False, NEAR)
    return [float(t.outside(lin, pre, states[s], basis).max()) for s in NEAR]


@pytest.mark.mpi
def test_contact_states_on_two_ranks_as_on_one(mpirun, tmp_path):
    one = signature()
    two = two_rank_signature(mpirun, "test_contact_states_ranks", tmp_path / "sig.json")
    assert one["ranks"] == 1 and two["ranks"] == 2
    assert one["closed"] == two["closed"] and one["closed"][0] < one["closed"][1] < one["closed"][2]
    assert one["masks"] == two["masks"]
    for sig in (one, two):
        assert max(sig["relinearise"]) <= 1e-13
        assert max(sig["projection"]) <= 1e-10
        assert max(sig["near_outside"]) <= 2.5e-3     # as serially (tests/unit/fe/test_pressure_contact_states)
