"""The serial cell-integral assembler (``fe.cell_assembly``) against dolfinx's own assembly.

Both add the same element matrices in the same cell order, so the matrices must be equal to the last
bit: pattern, values, the Dirichlet rows and columns (zero, ``diagonal`` on the diagonal), block size
and local-to-global map.  Checked on a P2 ring with two materials on two halves of the cells, a
clamped face and a face fixed in one component only; on the scalar mass; on a form over part of
the cells (rows of the other nodes empty, as in dolfinx's pattern); and the forms it must leave to
dolfinx (facet integrals, coefficients)."""
from __future__ import annotations

import functools

import numpy as np
import pytest
import scipy.sparse as sp
import ufl
from dolfinx import fem
from dolfinx import mesh as dmesh
from dolfinx.fem import petsc as fem_petsc
from mpi4py import MPI
from petsc4py import PETSc

from fem_squeal.fe import cell_assembly, forms
from fem_squeal.fe.assembly import _compile, dirichlet_conditions
from fem_squeal.fe.model import FixedFace, Material, ModelSpec

pytestmark = pytest.mark.skipif(MPI.COMM_WORLD.size > 1, reason="the cell assembler is serial")
SPEC = ModelSpec({"disc": Material(3e9, 0.4, 1400.0)}, clamped=("bottom",), fixed=(FixedFace("top", ("x",)),))


@functools.cache
def ring_case():
    from support.ring import ring_mesh

    md = ring_mesh(mesh_size=0.004)
    mesh = md.mesh
    cells = np.arange(mesh.topology.index_map(3).size_local, dtype=np.int32)
    halves = np.where(dmesh.compute_midpoints(mesh, 3, cells)[:, 0] < 0.0, 1, 2).astype(np.int32)
    tags = dmesh.meshtags(mesh, 3, cells, halves)
    V = fem.VectorFunctionSpace(mesh, ("Lagrange", 2))
    bcs, bc_dofs = dirichlet_conditions(V, md, SPEC)
    return md, V, ufl.Measure("dx", domain=mesh, subdomain_data=tags), bcs, bc_dofs


def dolfinx_matrix(form, bcs, diagonal: float) -> PETSc.Mat:
    A = fem_petsc.create_matrix(form)
    fem_petsc.assemble_matrix(A, form, bcs=bcs, diagonal=diagonal)
    A.assemble()
    return A


def assert_same(A: PETSc.Mat, B: PETSc.Mat) -> None:
    for a, b in zip(A.getValuesCSR(), B.getValuesCSR()):
        assert a.dtype == b.dtype and np.array_equal(a, b)
    assert A.getBlockSize() == B.getBlockSize()
    la, lb = A.getLGMap()[0], B.getLGMap()[0]
    assert la.getBlockSize() == lb.getBlockSize() and np.array_equal(la.getIndices(), lb.getIndices())


def stiffness(V, dx, parts=(1, 2)):
    u, v = ufl.TrialFunction(V), ufl.TestFunction(V)
    mats = {1: Material(3e9, 0.4, 1400.0), 2: Material(210e9, 0.3, 7850.0)}
    return functools.reduce(lambda a, b: a + b,
                            [forms.material_stiffness_form(u, v, mats[p], dx(p)) for p in parts])


def test_two_materials_and_dirichlet_rows_equal_dolfinx_bit_for_bit():
    md, V, dx, bcs, bc_dofs = ring_case()
    f = _compile(stiffness(V, dx), None)
    fast = cell_assembly.assemble_matrix(f, bc_dofs, 1.0)
    assert fast is not None
    assert_same(fast, dolfinx_matrix(f, bcs, 1.0))
    # the face fixed in x only: its y and z rows are ordinary rows
    d = fast.getDiagonal().array
    assert np.all(d[bc_dofs] == 1.0) and np.any(np.bincount(bc_dofs // 3) == 1)


def test_scalar_mass_and_a_part_of_the_cells():
    md, V, dx, bcs, bc_dofs = ring_case()
    S = fem.FunctionSpace(md.mesh, ("Lagrange", 2))
    p, q = ufl.TrialFunction(S), ufl.TestFunction(S)
    fm = _compile(forms.mass_form(p, q, 1400.0, dx(1)) + forms.mass_form(p, q, 7850.0, dx(2)), None)
    assert_same(cell_assembly.assemble_matrix(fm, np.zeros(0, np.int32), 0.0), dolfinx_matrix(fm, [], 0.0))
    half = _compile(stiffness(V, dx, parts=(2,)), None)   # rows of the nodes of half 1 only: empty
    fast = cell_assembly.assemble_matrix(half, np.zeros(0, np.int32), 0.0)
    assert_same(fast, dolfinx_matrix(half, [], 0.0))
    assert np.any(np.diff(fast.getValuesCSR()[0]) == 0)


def test_a_form_over_all_cells_without_subdomains():
    """``dx`` without a subdomain (integral id −1: every cell) on the unclamped space."""
    md, V, dx, bcs, bc_dofs = ring_case()
    u, v = ufl.TrialFunction(V), ufl.TestFunction(V)
    f = _compile(ufl.inner(ufl.grad(u), ufl.grad(v)) * ufl.dx(domain=md.mesh), None)
    assert_same(cell_assembly.assemble_matrix(f, np.zeros(0, np.int32), 0.0), dolfinx_matrix(f, [], 0.0))


def test_the_matrix_takes_later_additions_like_dolfinx_s():
    """MAT_SORTED_FULL is switched off after the pattern is written: a later MatSetValues adds one
    entry, not a row; a new non-zero is an error, as on dolfinx's matrix."""
    md, V, dx, bcs, bc_dofs = ring_case()
    f = _compile(stiffness(V, dx), None)
    A, B = cell_assembly.assemble_matrix(f, bc_dofs, 1.0), dolfinx_matrix(f, bcs, 1.0)
    for M in (A, B):
        M.setValuesLocal([4], [5], [2.5], addv=PETSc.InsertMode.ADD_VALUES)
        M.assemble()
    assert_same(A, B)
    with pytest.raises(PETSc.Error):
        A.setValue(0, A.getSize()[1] - 1, 1.0, addv=PETSc.InsertMode.ADD_VALUES)
        A.assemble()


def test_forms_left_to_dolfinx():
    md, V, dx, bcs, bc_dofs = ring_case()
    u, v = ufl.TrialFunction(V), ufl.TestFunction(V)
    facet = _compile(ufl.inner(u, v) * ufl.ds(domain=md.mesh), None)
    w = fem.Function(V)
    coefficient = _compile(ufl.inner(w, w) * ufl.inner(u, v) * ufl.dx(domain=md.mesh), None)
    assert cell_assembly.assemble_matrix(facet, np.zeros(0, np.int32), 0.0) is None
    assert cell_assembly.assemble_matrix(coefficient, np.zeros(0, np.int32), 0.0) is None


def test_kronecker_equals_scipy_kron_without_the_dropped_rows_and_columns():
    """A ⊗ W with a full W, a W with zero entries and a random set of dropped DOFs: the entries of
    scipy's ``kron`` (the same single products W(c, d)·A(i, j)) on the kept rows and columns, no
    explicit zeros from W's zero entries, and the layout of the matrix it is given."""
    md, V, dx, bcs, bc_dofs = ring_case()
    S = fem.FunctionSpace(md.mesh, ("Lagrange", 2))
    p, q = ufl.TrialFunction(S), ufl.TestFunction(S)
    fm = _compile(forms.mass_form(p, q, 1400.0, dx(1)) + forms.mass_form(p, q, 7850.0, dx(2)), None)
    Ms = cell_assembly.assemble_matrix(fm, np.zeros(0, np.int32), 0.0)
    like = cell_assembly.assemble_matrix(_compile(stiffness(V, dx), None), bc_dofs, 1.0)
    ai, aj, av = Ms.getValuesCSR()
    n = 3 * Ms.getSize()[0]
    drop = np.random.default_rng(1).random(n) < 0.05
    for W in (np.arange(1.0, 10.0).reshape(3, 3), np.outer([0.0, 0.6, 0.8], [0.0, 0.6, 0.8])):
        M = cell_assembly.kronecker(Ms, W, drop, like)
        ref = sp.kron(sp.csr_matrix((av, aj, ai)), sp.csr_matrix(W)).tocsr()
        keep = sp.diags((~drop).astype(float))
        ref = (keep @ ref @ keep).tocsr()
        ref.eliminate_zeros()
        ref.sort_indices()
        mi, mj, mv = M.getValuesCSR()
        assert np.array_equal(mi, ref.indptr) and np.array_equal(mj, ref.indices) and np.array_equal(mv, ref.data)
        assert M.getBlockSize() == 3 and M.getSizes() == like.getSizes()


def test_kronecker_rows_equals_the_serial_expansion():
    """The expansion from each rank's rows (:func:`cell_assembly.kronecker_rows`, the path of N
    ranks) on one rank: the serial expansion's matrix entry for entry (the same single products in
    the same row order), dropped DOFs given by their global numbers."""
    md, V, dx, bcs, bc_dofs = ring_case()
    S = fem.FunctionSpace(md.mesh, ("Lagrange", 2))
    p, q = ufl.TrialFunction(S), ufl.TestFunction(S)
    Ms = cell_assembly.assemble_matrix(_compile(forms.mass_form(p, q, 1400.0, dx(1)), None), np.zeros(0, np.int32),
                                       0.0)
    like = cell_assembly.assemble_matrix(_compile(stiffness(V, dx), None), bc_dofs, 1.0)
    drop = np.random.default_rng(2).random(3 * Ms.getSize()[0]) < 0.05
    for W in (np.arange(1.0, 10.0).reshape(3, 3), np.outer([0.0, 0.6, 0.8], [0.0, 0.6, 0.8])):
        A = cell_assembly.kronecker(Ms, W, drop, like)
        B = cell_assembly.kronecker_rows(Ms, W, np.flatnonzero(drop), like)
        for a, b in zip(A.getValuesCSR(), B.getValuesCSR()):
            assert np.array_equal(a, b)
        assert B.getBlockSize() == 3 and B.getSizes() == like.getSizes()
