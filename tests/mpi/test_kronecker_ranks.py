"""The vector masses on 2 ranks from the scalar mass (fe.cell_assembly.kronecker_rows through
fe.assembly.compiled._block_masses) against dolfinx's assembly of the vector mass forms."""
from __future__ import annotations

import pytest
from support.ranks import two_rank_signature


def signature() -> dict:
    """On the clamped ring: the mass matrix of ``assemble_operators`` (the expansion) and dolfinx's
    assembly of ∫ρ u·v with the same Dirichlet conditions (diagonal 0): their largest difference
    relative to the largest entry, and each one's number of entries that are not zero."""
    import numpy as np
    import ufl
    from dolfinx import fem
    from dolfinx.fem import petsc as fem_petsc
    from mpi4py import MPI
    from petsc4py import PETSc
    from support.ring import ring_operators

    from fem_squeal.fe import forms, kernels

    comm = MPI.COMM_WORLD
    ops = ring_operators(kn=0, clamped=("bottom",))
    V = ops.V
    u, v = ufl.TrialFunction(V), ufl.TestFunction(V)
    a = fem.form(forms.mass_form(u, v, 1400.0, ufl.dx(domain=V.mesh)))
    zero = fem.Function(V)
    blocks = np.unique(np.asarray(ops.bc_dofs) // V.dofmap.index_map_bs).astype(np.int32)
    B = fem_petsc.create_matrix(a)
    fem_petsc.assemble_matrix(B, a, bcs=[fem.dirichletbc(zero, blocks)], diagonal=0.0)
    B.assemble()
    D = ops.M.copy()
    D.axpy(-1.0, B, structure=PETSc.Mat.Structure.DIFFERENT_NONZERO_PATTERN)
    nonzero = [comm.allreduce(int(np.count_nonzero(A.getValuesCSR()[2])), op=MPI.SUM) for A in (ops.M, B)]
    return {"ranks": comm.size, "rel": D.norm(PETSc.NormType.INFINITY) / B.norm(PETSc.NormType.INFINITY),
            "nonzero": nonzero, "paths": sorted(kernels.tally().get("assembly", {}))}


@pytest.mark.mpi
def test_two_rank_masses_equal_dolfinx_s(mpirun, tmp_path):
    """The same integrals summed in another order (the scalar element matrices, then the product
    with δ_cd, against the vector form's own): equal to a few ε of the row sums (bound 1e-14,
    measured ~1e-16), with the same entries that are not zero."""
    sig = two_rank_signature(mpirun, "test_kronecker_ranks", tmp_path / "sig.json")
    assert sig["ranks"] == 2 and "kronecker, rank-local rows" in sig["paths"]
    assert sig["rel"] <= 1e-14
    assert sig["nonzero"][0] == sig["nonzero"][1]
