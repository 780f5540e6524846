"""The serial factorisation's fill-reducing order (AMD or METIS on the node graph) and the block masses
assembled from one scalar mass: both must leave every number as it was, to round-off."""
from __future__ import annotations

import numpy as np
import pytest
from support.ring import ring_mesh, ring_operators

from fem_squeal.fe import ordering
from fem_squeal.fe.eigen import solve_real_modes
from fem_squeal.util.errors import ModelError

needs_metis = pytest.mark.skipif(not ordering.metis_available(), reason="libmetis not found")


@needs_metis
def test_nested_dissection_permutes_whole_nodes():
    ops = ring_operators(kn=0, clamped=("inner",))
    p = ordering.fill_reducing_order(ops.K, how="metis")
    n = ops.K.getSize()[0]
    assert np.array_equal(np.sort(p), np.arange(n))
    blocks = p.reshape(-1, 3)            # each node's three rows stay together, in order
    assert np.all(blocks % 3 == np.arange(3)) and np.all(blocks[:, 1:] - blocks[:, :1] == [1, 2])


def test_node_graph_is_the_mesh_connectivity():
    """Two nodes are neighbours in K's node graph exactly when a cell holds both (P2: the 10
    nodes of a tetrahedron); no self-loops, symmetric."""
    ops = ring_operators(kn=0, clamped=("inner",))
    indptr, indices = ordering.node_graph(ops.K, 3)
    got = set(zip(np.repeat(np.arange(len(indptr) - 1), np.diff(indptr)).tolist(), indices.tolist()))
    cells = ops.V.dofmap.list.array.reshape(-1, ops.V.dofmap.dof_layout.num_dofs)
    want = {(int(a), int(b)) for c in cells for a in c for b in c if a != b}
    assert got == want


def test_permuted_matrix_is_p_a_pt():
    ops = ring_operators(kn=0, clamped=("inner",))
    n = ops.K.getSize()[0]
    p = np.random.default_rng(1).permutation(n)
    B = ordering.permuted(ops.K, p)
    x = ops.K.createVecRight()
    x.setRandom()
    y, yp, xp = ops.K.createVecLeft(), B.createVecLeft(), B.createVecRight()
    ops.K.mult(x, y)
    xp.array[:] = x.array_r[p]
    B.mult(xp, yp)
    # B(i, j) = K(p[i], p[j]): (B x[p])_i = (K x)_{p[i]}, to round-off of the sums' order
    assert np.max(np.abs(yp.array_r - y.array_r[p])) <= 1e-14 * np.max(np.abs(y.array_r))


@needs_metis
@pytest.mark.parametrize("block, how", [(None, "auto"), (0, "auto"), (None, "metis"), (None, "amd")])
def test_node_order_gives_the_modes_of_cholmods_own(block, how):
    """Our node orders (``auto``, the default; ``metis``; ``amd``), CHOLMOD keeping them, against
    CHOLMOD's own analysis
    (``ordering solver``), by block Lanczos and by Krylov–Schur (``block_size 0``): the same
    frequencies to 1e-10 (both converge to ~1e-14, eigenvalue error ~ residual²) and vectors in the
    caller's order (their residuals are computed with the caller's K and M, so a vector left in
    the permuted order would fail the 1e-8 bound by O(1)); the mode shapes are the same up to sign
    and the rotation inside the ring's double eigenvalues: each vector lies in the other run's
    span of its frequency's modes (M-projection 1 to 1e-8)."""
    ops = ring_operators(kn=0, clamped=("inner",))
    opts = {} if block is None else {"a_block_size": block, "b_block_size": block}
    a = solve_real_modes(ops.K, ops.M, 12, 0.0, prefix="a_", options={**opts, "a_ordering": how})
    b = solve_real_modes(ops.K, ops.M, 12, 0.0, prefix="b_", options={**opts, "b_ordering": "solver"})
    assert a.solver == b.solver == "cholmod"
    assert np.max(np.abs(a.freqs_hz / b.freqs_hz - 1)) < 1e-10
    assert np.all(a.residuals < 1e-8) and np.all(b.residuals < 1e-8)
    Xa = np.column_stack([v.array_r for v in a.vectors])
    MXb = np.column_stack([_apply(ops.M, v) for v in b.vectors])
    for j in range(len(a.freqs_hz)):
        twins = np.flatnonzero(np.abs(b.freqs_hz / a.freqs_hz[j] - 1) < 1e-6)
        c = MXb[:, twins].T @ Xa[:, j]        # M-orthonormal twins: ‖c‖ = 1 if x_a lies in their span
        assert abs(np.linalg.norm(c) - 1) < 1e-8


def _apply(A, v):
    y = A.createVecLeft()
    A.mult(v, y)
    return y.array_r.copy()


def test_unknown_ordering_is_refused_by_name():
    ops = ring_operators(kn=0, clamped=("inner",))
    with pytest.raises(ModelError, match="c_ordering"):
        solve_real_modes(ops.K, ops.M, 4, 0.0, prefix="c_", options={"c_ordering": "colamd"})


@needs_metis
def test_auto_order_runs_metis_only_where_it_pays():
    """``auto``: AMD's order where METIS's expected time exceeds half of AMD's factorisation, else
    METIS's.  The clamped P2 disc of the speed benchmark: 26k DOFs (187k graph entries, AMD 1.94
    GFlop) keeps AMD, 87k (671k, 33.2 GFlop) takes METIS; and on the test ring (small) auto is AMD."""
    assert not ordering.metis_pays(187_272, 1.94e9) and ordering.metis_pays(671_082, 33.2e9)
    ops = ring_operators(kn=0, clamped=("inner",))
    auto, amd, metis = (ordering.fill_reducing_order(ops.K, how=h) for h in ("auto", "amd", "metis"))
    assert np.array_equal(auto, amd) and not np.array_equal(auto, metis)
    with pytest.raises(ValueError, match="colamd"):
        ordering.fill_reducing_order(ops.K, how="colamd")


# ------------------------------------------------------------------ block masses from the scalar mass

def _mass_differences() -> dict:
    """The largest relative difference between the block masses of ``assemble_operators``
    and the vector forms ∫ ρ u·v dx and ∫ ρ (u·a)(v·a) dx assembled on the same space with the same
    Dirichlet conditions (diagonal 0), and whether the block masses store exactly the vector masses'
    non-zero entries.  The ring is clamped on its inner face and fixed in x and z on its outer face,
    and the axis is tilted, so that the axial mass has full 3×3 blocks."""
    import ufl
    from mpi4py import MPI
    from petsc4py import PETSc

    from fem_squeal.fe import assembly, forms
    from fem_squeal.fe.model import FixedFace, Material, ModelSpec

    axis = (0.6, 0.0, 0.8)
    spec = ModelSpec({"disc": Material(3e9, 0.4, 1400.0)}, (), ("inner",), axis=axis,
                     fixed=(FixedFace("outer", ("x", "z")),))
    md = ring_mesh()
    ops = assembly.assemble_operators(md, spec)
    bcs, _ = assembly.dirichlet_conditions(ops.V, md, spec)
    u, v = ufl.TrialFunction(ops.V), ufl.TestFunction(ops.V)
    a = ufl.as_vector(axis)
    out = {}
    for name, new, form in (("M", ops.M, forms.mass_form(u, v, 1400.0, ufl.dx)),
                            ("Mz", ops.M_axial, forms.axial_mass_form(u, v, 1400.0, ufl.dx, a))):
        f = assembly._compile(form, None)
        old = assembly._assemble(f, f, bcs, 0.0)
        d = old.copy()
        d.axpy(-1.0, new, structure=PETSc.Mat.Structure.DIFFERENT_NONZERO_PATTERN)
        out[name] = MPI.COMM_WORLD.allreduce(d.norm(PETSc.NormType.INFINITY) / old.norm(PETSc.NormType.INFINITY),
                                             op=MPI.MAX)
        out[name + "_same_pattern"] = MPI.COMM_WORLD.allreduce(_entries(new) == _entries(old, nonzero=True),
                                                               op=MPI.LAND)
    return out


def _entries(A, nonzero: bool = False) -> set[tuple[int, int]]:
    """(local row, global column) of the stored (``nonzero``: non-zero) entries of A's rows."""
    ai, aj, av = A.getValuesCSR()
    rows = np.repeat(np.arange(len(ai) - 1), np.diff(ai))
    keep = av != 0 if nonzero else np.ones(len(aj), bool)
    return set(zip(rows[keep].tolist(), aj[keep].tolist()))


def test_block_masses_equal_the_vector_forms():
    """M and M_axial from one scalar assembly equal the vector forms' to round-off, with the Dirichlet
    rows and columns (a clamp, and a face fixed in two components) left out and no stored zeros.
    (One rank: on more, the vector forms themselves are assembled.)  Round-off: the same positive
    quadrature terms summed in another order differ by at most (n - 1) ε of their sum, n the terms
    of an entry (up to ~30 cells of a P2 node's patch x 14 points = 420): 1e-13.  (1e-14 was too
    tight: 1.36e-14 was measured on an AVX-512 machine.)"""
    s = _mass_differences()
    assert s["M"] < 1e-13 and s["Mz"] < 1e-13
    assert s["M_same_pattern"] and s["Mz_same_pattern"]
