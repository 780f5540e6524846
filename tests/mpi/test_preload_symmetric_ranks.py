"""The preload's "symmetric" Jacobian (issue 36) on 2 ranks: MUMPS LDLᵀ of the frictionless Jacobian
preconditions GMRES where one rank uses CHOLMOD, and the state is the same: the closed points, the
interfaces' normal forces and ‖u‖ within the issue's 1e-10 relative, and on each rank count the state of
the default path (LU, Woodbury and GMRES) within 1e-10 in displacement."""
from __future__ import annotations

import pytest
from support.ranks import two_rank_signature

SETS = ["geometry.mesh_size=0.016"]


def signature() -> dict:
    from mpi4py import MPI
    from support.paths import ROOT

    from fem_squeal.app.analyses.mesh import build_mesh
    from fem_squeal.app.scene import load_scene, model_spec
    from fem_squeal.fe import kernels
    from fem_squeal.fe.assembly import assemble_operators
    from fem_squeal.fe.preload import solve_preload

    comm = MPI.COMM_WORLD
    scene = load_scene(ROOT / "scenes" / "brake_corner_cea.toml", SETS)
    ops = assemble_operators(build_mesh(comm, scene), model_spec(scene), parts=False)
    kernels.tally(reset=True)
    sym = solve_preload(ops, jacobian="symmetric")
    paths = kernels.tally()["newton_step"]
    up = solve_preload(ops, jacobian="update")
    du = sym.u.copy()
    du.axpy(-1.0, up.u)
    out = {"ranks": comm.size, "jacobian": sym.jacobian, "paths": sorted(paths),
           "closed": [int(comm.allreduce(int(a.sum()))) for a in sym.active.values()],
           "normal_force": list(sym.normal_force.values()), "u_norm": sym.u.norm(),
           "against_update": du.norm() / up.u.norm(), "residual": sym.history[-1][1]}
    for v in (du, sym.u, up.u):
        v.destroy()
    return out


@pytest.mark.mpi
def test_symmetric_preload_on_two_ranks_as_on_one(mpirun, tmp_path):
    one = signature()
    two = two_rank_signature(mpirun, "test_preload_symmetric_ranks", tmp_path / "sig.json")
    assert one["ranks"] == 1 and two["ranks"] == 2
    assert one["paths"] == ["kept symmetric factorisation, GMRES", "symmetric factorisation (cholmod), GMRES"]
    assert two["paths"] == ["kept symmetric factorisation, GMRES", "symmetric factorisation (mumps), GMRES"]
    assert one["jacobian"] == two["jacobian"] == "symmetric"
    assert one["closed"] == two["closed"]
    for sig in (one, two):
        assert sig["against_update"] <= 1e-10 and sig["residual"] <= 1e-9
    assert two["u_norm"] == pytest.approx(one["u_norm"], rel=1e-10)
    assert two["normal_force"] == pytest.approx(one["normal_force"], rel=1e-10)
