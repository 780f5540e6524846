"""C3D8R's per-cell corrections (fem_squeal.fe.c3d8r, added to the assembled K and M on each rank's owned
cells) give the same operators on 1 and 2 ranks."""
from __future__ import annotations

import numpy as np
import pytest
from support.ranks import two_rank_signature


def signature() -> dict:
    """K u and M u for the nodal field u(x) = (sin 3x, cos 2y, sin(x + z)) on a distorted 4 × 2 × 2 box of
    C3D8R hexahedra clamped at x = 0, keyed by (node coordinates, component) in a rank-independent order
    (rank 0 gathers)."""
    from dolfinx import mesh as dmesh
    from mpi4py import MPI

    from fem_squeal.fe.assembly import assemble_operators
    from fem_squeal.fe.model import Material, ModelSpec
    from geometry.gmsh_io import MeshData

    comm = MPI.COMM_WORLD
    mesh = dmesh.create_box(comm, [[0, 0, 0], [2, 1, 1]], [4, 2, 2], dmesh.CellType.hexahedron,
                            ghost_mode=dmesh.GhostMode.shared_facet)
    x = mesh.geometry.x
    x[:, :3] += 0.08 * np.sin(np.stack([3.1 * x[:, 1] + x[:, 2], 2.3 * x[:, 0] + x[:, 2], 1.7 * x[:, 0] + x[:, 1]],
                                       axis=1) * 2.0) * np.minimum(x[:, :1], 1.0)
    tdim = 3
    n = mesh.topology.index_map(tdim).size_local + mesh.topology.index_map(tdim).num_ghosts
    cells = np.arange(n, dtype=np.int32)
    ct = dmesh.meshtags(mesh, tdim, cells, np.ones_like(cells))
    mesh.topology.create_connectivity(tdim - 1, tdim)
    facets = dmesh.exterior_facet_indices(mesh.topology)
    mid = dmesh.compute_midpoints(mesh, tdim - 1, facets)
    ft = dmesh.meshtags(mesh, tdim - 1, facets, np.where(mid[:, 0] < 1e-9, 1, 2).astype(np.int32))
    md = MeshData(mesh, ct, ft, {"b": 1}, {"clamp": 1, "rest": 2})
    ops = assemble_operators(md, ModelSpec({"b": Material(2.1e11, 0.3, 7800.0)}, (), ("clamp",), 1, c3d8r=True))
    owned = ops.V.dofmap.index_map.size_local
    xd = ops.V.tabulate_dof_coordinates()[:owned]
    u = ops.K.createVecRight()
    field = [np.sin(3 * xd[:, 0]), np.cos(2 * xd[:, 1]), np.sin(xd[:, 0] + xd[:, 2])]
    u.array[:] = np.stack(field, axis=1).ravel()
    out = {}
    for name, A in (("K", ops.K), ("M", ops.M)):
        y = A.createVecLeft()
        A.mult(u, y)
        rows = comm.gather((xd, y.array.reshape(-1, 3).copy()), root=0)
        if comm.rank == 0:
            xs = np.vstack([r[0] for r in rows])
            ys = np.vstack([r[1] for r in rows])
            order = np.lexsort(np.round(xs, 9).T[::-1])
            out["x"] = xs[order].tolist()
            out[name] = ys[order].tolist()
    return out


@pytest.mark.mpi
@pytest.mark.slow
def test_c3d8r_operators_are_the_same_on_1_and_2_ranks(mpirun, tmp_path):
    """K u and M u on 2 ranks equal the serial ones to 1e-12 of the largest entry (sums in another order)."""
    two = two_rank_signature(mpirun, "test_c3d8r_ranks", tmp_path / "sig.json")
    one = signature()
    assert np.allclose(one["x"], two["x"], rtol=0, atol=1e-12)
    for name in ("K", "M"):
        a, b = np.array(one[name]), np.array(two[name])
        assert np.max(np.abs(a - b)) <= 1e-12 * np.max(np.abs(a)), name
