"""The compiled cell assembly on 2 and 3 ranks (fe.cell_assembly.assemble_matrix: each rank's local
rows, the ghost rows summed into their owners' and written into PETSc's two parts) against dolfinx's
assembly of the same forms: the clamped ring's two-material stiffness with its Dirichlet rows and
columns (diagonal 1), and the scalar mass over half of the cells (no Dirichlet DOFs, rows of the
other half empty).  On 3 ranks a node can be held by every rank, so an owner sums two other
ranks' rows into its own."""
from __future__ import annotations

import pytest
from support.ranks import two_rank_signature


def signature() -> dict:
    """For each form: the largest difference of the two matrices relative to the largest entry,
    both matrices' entries that are not zero, the diagonal on the Dirichlet rows, and the path."""
    import numpy as np
    import ufl
    from dolfinx import fem
    from dolfinx import mesh as dmesh
    from dolfinx.fem import petsc as fem_petsc
    from mpi4py import MPI
    from petsc4py import PETSc
    from support.ring import ring_mesh

    from fem_squeal.fe import cell_assembly, forms
    from fem_squeal.fe.assembly import _compile, dirichlet_conditions
    from fem_squeal.fe.model import FixedFace, Material, ModelSpec

    comm = MPI.COMM_WORLD
    md = ring_mesh(mesh_size=0.004)
    mesh = md.mesh
    cells = np.arange(mesh.topology.index_map(3).size_local, dtype=np.int32)
    halves = np.where(dmesh.compute_midpoints(mesh, 3, cells)[:, 0] < 0.0, 1, 2).astype(np.int32)
    dx = ufl.Measure("dx", domain=mesh, subdomain_data=dmesh.meshtags(mesh, 3, cells, halves))
    V = fem.VectorFunctionSpace(mesh, ("Lagrange", 2))
    spec = ModelSpec({"disc": Material(3e9, 0.4, 1400.0)}, clamped=("bottom",), fixed=(FixedFace("top", ("x",)),))
    bcs, bc_dofs = dirichlet_conditions(V, md, spec)
    u, v = ufl.TrialFunction(V), ufl.TestFunction(V)
    mats = {1: Material(3e9, 0.4, 1400.0), 2: Material(210e9, 0.3, 7850.0)}
    a_K = forms.material_stiffness_form(u, v, mats[1], dx(1)) + forms.material_stiffness_form(u, v, mats[2], dx(2))
    S = fem.FunctionSpace(mesh, ("Lagrange", 2))
    p, q = ufl.TrialFunction(S), ufl.TestFunction(S)
    out = {"ranks": comm.size}
    n_owned = V.dofmap.index_map.size_local * V.dofmap.index_map_bs
    for name, form, bc, dofs, diag in (("K", _compile(a_K, None), bcs, bc_dofs, 1.0),
                                       ("Ms_half", _compile(forms.mass_form(p, q, 7850.0, dx(2)), None), [],
                                        np.zeros(0, np.int32), 0.0)):
        A = cell_assembly.assemble_matrix(form, dofs, diag)
        B = fem_petsc.create_matrix(form)
        fem_petsc.assemble_matrix(B, form, bcs=bc, diagonal=diag)
        B.assemble()
        D = A.copy()
        D.axpy(-1.0, B, structure=PETSc.Mat.Structure.DIFFERENT_NONZERO_PATTERN)
        owned_bc = np.asarray(dofs)[np.asarray(dofs) < n_owned]
        rel = D.norm(PETSc.NormType.INFINITY) / B.norm(PETSc.NormType.INFINITY)
        stored = [comm.allreduce(len(X.getValuesCSR()[1]), op=MPI.SUM) for X in (A, B)]
        # the local-to-global map and the pattern take dolfinx's own additions (as the facet
        # integrals are added): the form once more, through MatSetValuesLocal, doubles the matrix
        # (dolfinx inserts the Dirichlet rows' diagonal: it stays `diag`)
        owned_bc = np.asarray(dofs)[np.asarray(dofs) < n_owned]
        fem_petsc.assemble_matrix(A, form, bcs=bc, diagonal=diag)
        A.assemble()
        D = A.copy()
        D.axpy(-2.0, B, structure=PETSc.Mat.Structure.DIFFERENT_NONZERO_PATTERN)
        ip, ind, dv = D.getValuesCSR()
        rows = np.repeat(np.arange(len(ip) - 1), np.diff(ip))
        dv[np.isin(rows, owned_bc) & (ind == rows + D.getOwnershipRange()[0])] += diag
        row_sums = np.bincount(rows, weights=np.abs(dv), minlength=len(ip) - 1)
        twice = comm.allreduce(float(np.max(row_sums, initial=0.0)), op=MPI.MAX)
        out[name] = {"rel": rel, "stored": stored,
                     "rel_twice": twice / B.norm(PETSc.NormType.INFINITY),
                     "nonzero": [comm.allreduce(int(np.count_nonzero(X.getValuesCSR()[2])), op=MPI.SUM)
                                 for X in (A, B)],
                     "type": A.getType(), "bs": [A.getBlockSize(), B.getBlockSize()],
                     "bc_diagonal": comm.allreduce(bool(np.all(A.getDiagonal().array[owned_bc] == diag)),
                                                   op=MPI.LAND),
                     "bc_rows": comm.allreduce(len(owned_bc), op=MPI.SUM)}
    return out


@pytest.mark.mpi
@pytest.mark.parametrize("ranks", [2, 3])
def test_two_rank_compiled_assembly_equals_dolfinx_s(mpirun, tmp_path, ranks):
    """The same element matrices added in the same order on each rank; a row shared by the ranks
    sums the other ranks' parts at the owner in one addition each where dolfinx adds them cell by
    cell: a few ε of the row sums (bound 1e-14; the 255k disc and the brake measured ≤ 7e-17).
    The same stored entries as dolfinx's pattern (a missing one would make dolfinx's second
    assembly fail, an extra one would count), the same entries that are not zero, the Dirichlet
    rows' diagonal exact."""
    sig = two_rank_signature(mpirun[:2] + [str(ranks)] + mpirun[3:], "test_cell_assembly_ranks",
                             tmp_path / "sig.json")
    assert sig["ranks"] == ranks
    for name in ("K", "Ms_half"):
        s = sig[name]
        assert s["type"] == "mpiaij" and s["bs"][0] == s["bs"][1]
        assert s["rel"] <= 1e-14, (name, s["rel"])
        assert s["rel_twice"] <= 1e-14, (name, s["rel_twice"])
        assert s["stored"][0] == s["stored"][1]
        assert s["nonzero"][0] == s["nonzero"][1]
        assert s["bc_diagonal"]
    assert sig["K"]["bc_rows"] > 0
