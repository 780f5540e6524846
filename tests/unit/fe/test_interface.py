"""Patch tests of the interface operator G and the contact preload on two stacked blocks.

Tolerances: the slave quadrature (degree 4) integrates products of P2 traces exactly on flat
facets, and every field used below is a polynomial of degree ≤ 2 that P2 reproduces exactly on
both sides.  So these identities hold to round-off: 1e-12 relative (sums of ~10³ terms of O(1)).
"""
from __future__ import annotations

import functools

import numpy as np
import pytest
import ufl
from dolfinx import fem
from dolfinx.fem import petsc as fem_petsc
from mpi4py import MPI
from petsc4py import PETSc
from support.blocks import CONTACT_AREA, FACES, UPPER, two_blocks

from fem_squeal.fe import interface as itf

COMM = MPI.COMM_WORLD
RT = 1e-12


@functools.cache
def blocks_op(matching: bool = False, h_lower: float = 0.3, h_upper: float = 0.21):
    md = two_blocks(COMM, h_lower=h_lower, h_upper=h_upper, matching=matching)
    V = fem.VectorFunctionSpace(md.mesh, ("Lagrange", 2))
    op = itf.interface_operator(V, md.facet_tags, FACES["slave"], FACES["master"])
    return md, V, op


def vec_of(V, f) -> PETSc.Vec:
    u = fem.Function(V)
    u.interpolate(f)
    x = PETSc.Vec().createMPI((V.dofmap.index_map.size_local * 3, None), comm=COMM)
    x.array[:] = u.x.array[: x.getLocalSize()]
    return x


def body_field(md, V, part: int, value) -> PETSc.Vec:
    """A rigid translation ``value`` of one body only (the other is still)."""
    dofs = fem.locate_dofs_topological(V, 3, md.cell_tags.indices[md.cell_tags.values == part])
    u = fem.Function(V)
    u.x.array.reshape(-1, 3)[dofs] = value
    x = PETSc.Vec().createMPI((V.dofmap.index_map.size_local * 3, None), comm=COMM)
    x.array[:] = u.x.array[: x.getLocalSize()]
    return x


def apply(A: PETSc.Mat, x: PETSc.Vec) -> PETSc.Vec:
    y = A.createVecLeft()
    A.mult(x, y)
    return y


def gmax(v: PETSc.Vec) -> float:
    return v.norm(PETSc.NormType.INFINITY)


@pytest.mark.parametrize("matching", [False, True])
def test_area_and_initial_gap(matching):
    _, _, op = blocks_op(matching)
    assert op.area(COMM) == pytest.approx(CONTACT_AREA, rel=RT)
    assert COMM.allreduce(float(np.max(np.abs(op.gap0), initial=0.0)), op=MPI.MAX) < 1e-14
    n = COMM.allreduce(float(np.max(np.abs(op.normal - [0, 0, 1]), initial=0.0)), op=MPI.MAX)
    assert n < 1e-13  # master (lower block) outward normal is +z


@pytest.mark.parametrize("matching", [False, True])
def test_continuous_fields_give_zero_relative_displacement(matching):
    """Rigid motions and any quadratic field are continuous across the interface: G u = 0."""
    _, V, op = blocks_op(matching)
    fields = [lambda x: np.vstack([0.1 + 0 * x[0], -0.2 + 0 * x[0], 0.3 + 0 * x[0]]),
              lambda x: np.vstack([-x[1], x[0], 0 * x[0]]),                      # small rotation
              lambda x: np.vstack([x[0] ** 2 - x[1] * x[2], x[1] * x[0], x[2] ** 2 + x[0]])]
    for f in fields:
        x = vec_of(V, f)
        for G in (op.Gn, op.Gt1, op.Gt2):
            assert gmax(apply(G, x)) < 1e-13


@pytest.mark.parametrize("matching", [False, True])
def test_uniform_separation_force_is_kn_times_area(matching):
    md, V, op = blocks_op(matching)
    kn, delta = 3.0e9, 1e-4
    Kc = itf.contact_stiffness(op, kn)
    f = apply(Kc, body_field(md, V, 2, [0.0, 0.0, delta]))
    up = body_field(md, V, 2, [0.0, 0.0, 1.0])
    lo = body_field(md, V, 1, [0.0, 0.0, 1.0])
    assert f.dot(up) == pytest.approx(kn * CONTACT_AREA * delta, rel=RT)
    assert f.dot(lo) == pytest.approx(-kn * CONTACT_AREA * delta, rel=RT)
    # a tangential slip gives no normal force, and the tangential rows measure it exactly
    slip = body_field(md, V, 2, [1e-4, 0.0, 0.0])
    assert gmax(apply(op.Gn, slip)) < 1e-17
    g1, g2 = apply(op.Gt1, slip), apply(op.Gt2, slip)
    t = np.hypot(g1.array, g2.array)
    assert np.allclose(t, 1e-4, rtol=1e-12, atol=0)


def test_contact_stiffness_symmetric_psd_and_friction_sign():
    _, V, op = blocks_op(False)
    Kc = itf.contact_stiffness(op, 2.0e9)
    T = Kc.copy()
    T.transpose()
    T.axpy(-1.0, Kc, structure=PETSc.Mat.Structure.DIFFERENT_NONZERO_PATTERN)
    assert T.norm() <= 1e-14 * Kc.norm()
    rng = np.random.default_rng(COMM.rank)
    x = Kc.createVecRight()
    for _ in range(5):
        x.array[:] = rng.standard_normal(x.getLocalSize())
        assert x.dot(apply(Kc, x)) >= -1e-12 * Kc.norm() * x.dot(x)
    md, V, _ = blocks_op(False)
    # same mesh and partition (a second mesh build may be partitioned differently)
    back = itf.interface_operator(V, md.facet_tags, FACES["slave"], FACES["master"], sliding=-1.0)
    F, Fb = itf.friction_stiffness(op, 2.0e9, 0.4), itf.friction_stiffness(back, 2.0e9, 0.4)
    Fb.axpy(1.0, F, structure=PETSc.Mat.Structure.DIFFERENT_NONZERO_PATTERN)
    assert Fb.norm() <= 1e-14 * F.norm()


def test_friction_force_follows_the_master_motion():
    """Slave pressed by δ into the master: −K_f u on the slave is μ p ∫ s dA, s = e_θ(x)."""
    md, V, op = blocks_op(False)
    kn, mu, delta = 2.0e9, 0.4, 1e-5
    f = apply(itf.friction_stiffness(op, kn, mu), body_field(md, V, 2, [0.0, 0.0, -delta]))
    p = kn * delta
    # ∫ e_θ dA over the upper block footprint, by the slave quadrature itself (exact geometry)
    x = op.x
    r = np.hypot(x[:, 0], x[:, 1])
    es = np.stack([-x[:, 1] / r, x[:, 0] / r], axis=1)
    expect = COMM.allreduce(op.weight @ es, op=MPI.SUM) * mu * p
    got = [-f.dot(body_field(md, V, 2, e)) for e in ([1.0, 0, 0], [0, 1.0, 0])]
    assert got == pytest.approx(expect.tolist(), rel=1e-12)


@pytest.mark.parametrize("matching", [False, True])
def test_slave_block_equals_ufl_surface_form(matching):
    """The slave–slave block of K_c is ∫ k_n (u·n)(v·n) ds on the slave face, which UFL/FFCx
    assemble independently.  With matching meshes the master–master block equals the same
    form on the master patch too (same traces)."""
    md, V, op = blocks_op(matching)
    kn = 1.0
    Kc = itf.contact_stiffness(op, kn)
    u, v = ufl.TrialFunction(V), ufl.TestFunction(V)
    ds = ufl.Measure("ds", domain=md.mesh, subdomain_data=md.facet_tags)
    ez = fem.Constant(md.mesh, np.array([0.0, 0.0, 1.0]))
    a = fem.form(kn * ufl.dot(u, ez) * ufl.dot(v, ez) * ds(FACES["slave"]))
    A = fem_petsc.assemble_matrix(a)
    A.assemble()
    rng = np.random.default_rng(7 + COMM.rank)
    x = A.createVecRight()
    x.array[:] = rng.standard_normal(x.getLocalSize()) * body_field(md, V, 2, [1.0, 1.0, 1.0]).array
    assert x.dot(apply(Kc, x)) == pytest.approx(x.dot(apply(A, x)), rel=RT)
    if matching:
        X = ufl.SpatialCoordinate(md.mesh)
        x0, y0, _, dx_, dy_, _ = UPPER
        inside = ufl.And(ufl.And(ufl.gt(X[0], x0), ufl.lt(X[0], x0 + dx_)),
                         ufl.And(ufl.gt(X[1], y0), ufl.lt(X[1], y0 + dy_)))
        chi = ufl.conditional(inside, 1.0, 0.0)
        am = fem.form(kn * chi * ufl.dot(u, ez) * ufl.dot(v, ez) * ds(FACES["master"]))
        Am = fem_petsc.assemble_matrix(am)
        Am.assemble()
        x.array[:] = rng.standard_normal(x.getLocalSize()) * body_field(md, V, 1, [1.0, 1.0, 1.0]).array
        assert x.dot(apply(Kc, x)) == pytest.approx(x.dot(apply(Am, x)), rel=RT)


def test_non_matching_converges_to_matching():
    """Contact energy of a smooth non-polynomial gap (the lower body moves by
    w = 1e-3 sin 3x cos 4y along z, the upper one is still): the non-matching value approaches the
    matching one as the master mesh is refined (both approach ∫ k_n w² dA)."""
    def energy(matching, h_lower):
        md, V, op = blocks_op(matching, h_lower=h_lower, h_upper=0.1)
        dofs = fem.locate_dofs_topological(V, 3, md.cell_tags.indices[md.cell_tags.values == 1])
        X = V.tabulate_dof_coordinates()
        u = fem.Function(V)
        u.x.array.reshape(-1, 3)[dofs, 2] = 1e-3 * np.sin(3 * X[dofs, 0]) * np.cos(4 * X[dofs, 1])
        x = PETSc.Vec().createMPI((V.dofmap.index_map.size_local * 3, None), comm=COMM)
        x.array[:] = u.x.array[: x.getLocalSize()]
        return x.dot(apply(itf.contact_stiffness(op, 1.0), x))
    ref = energy(True, 0.1)
    x0, y0, _, dx_, dy_, _ = UPPER
    exact = 1e-6 * (0.5 * (dx_ - (np.sin(6 * (x0 + dx_)) - np.sin(6 * x0)) / 6)) * \
        (0.5 * (dy_ + (np.sin(8 * (y0 + dy_)) - np.sin(8 * y0)) / 8))
    assert ref == pytest.approx(exact, rel=1e-3)        # P2 interpolation error at h = 0.1
    errs = [abs(energy(False, h) - ref) / ref for h in (0.3, 0.15, 0.075)]
    assert errs[2] < errs[0] / 4, errs


@functools.cache
def preloaded(mu: float = 0.3, p: float = 1.0e6):
    from fem_squeal.fe.assembly import assemble_operators
    from fem_squeal.fe.model import GroundSpring, Interface, Material, ModelSpec, Pressure
    from fem_squeal.fe.preload import solve_preload

    md = two_blocks(COMM)
    spec = ModelSpec({"lower": Material(2e10, 0.3, 7000.0), "upper": Material(5e9, 0.25, 2500.0)},
                     clamped=("lower_bottom",),
                     interfaces=(Interface("pad", "slave", "master", "contact", kn=1e12, mu=mu, sliding=1),),
                     ground_springs=(GroundSpring("upper_sides", 0.0, 1e9),),
                     pressures=(Pressure("upper_top", p),))
    ops = assemble_operators(md, spec)
    return md, ops, solve_preload(ops)


def test_preload_balances_the_pressure():
    """Springs on the upper block act only across the axis, so the contact must carry the whole
    axial load: ∫ p_c dA = p × top area (Newton tolerance 1e-9)."""
    _, ops, pre = preloaded()
    assert pre.normal_force["pad"] == pytest.approx(1.0e6 * CONTACT_AREA, rel=1e-8)
    assert pre.contact_area["pad"] == pytest.approx(CONTACT_AREA, rel=RT)
    assert pre.iterations <= 3
    closed = COMM.allreduce(int(pre.active["pad"].sum()), op=MPI.SUM)
    assert closed == ops.contacts[0][1].n_global


def test_linearised_operator_reproduces_the_preload():
    """With a linear penalty and zero initial gap, (K + K_c(a) + K_f(a)) u_s = f exactly."""
    from fem_squeal.fe.assembly import linearise

    _, ops, pre = preloaded()
    lin = linearise(ops, pre.active)
    r = apply(lin.K_total(), pre.u)
    r.axpy(-1.0, ops.f)
    assert r.norm() <= 1e-9 * ops.f.norm()


def test_all_closed_route_equals_the_preload_when_everything_is_closed():
    from fem_squeal.fe.assembly import linearise

    _, ops, pre = preloaded()
    assert all(a.all() for a in pre.active.values())
    A = linearise(ops, pre.active).K_total()
    B = linearise(ops, None).K_total()
    B.axpy(-1.0, A, structure=PETSc.Mat.Structure.DIFFERENT_NONZERO_PATTERN)
    assert B.norm() <= 1e-14 * A.norm()


@pytest.mark.mpi
def test_interface_tests_pass_on_two_ranks_with_pairs_across_ranks(mpirun):
    """Every test of this file again under mpirun -n 2, where slave points meet master facets
    owned by the other rank (checked: n_remote > 0)."""
    import subprocess
    import sys
    from pathlib import Path

    from support.paths import ROOT
    from support.processes import clean_env

    p = subprocess.run(mpirun + [sys.executable, "-m", "pytest", "-q", "-x", "-p", "no:cacheprovider",
                                 "-m", "not mpi", str(Path(__file__).resolve())],
                       capture_output=True, text=True, timeout=900, env=clean_env(), cwd=ROOT)
    assert p.returncode == 0, p.stdout[-3000:] + p.stderr[-3000:]


def test_pairs_across_ranks_are_counted():
    _, _, op = blocks_op(False)
    if COMM.size > 1:
        assert op.n_remote > 0
    else:
        assert op.n_remote == 0


def test_pressure_projection_is_exact_for_linear_fields():
    """The L² projection on the slave surface reproduces a linear field at the surface nodes."""
    _, V, op = blocks_op(False)
    p = 1.0 + 2.0 * op.x[:, 0] + 3.0 * op.x[:, 1]
    dofs, vals = itf.project_to_nodes(op, p, COMM)
    imap = V.dofmap.index_map
    owned = V.tabulate_dof_coordinates()[: imap.size_local]
    gidx = imap.local_to_global(np.arange(imap.size_local, dtype=np.int32))
    parts = COMM.gather((gidx, owned), root=0)
    if COMM.rank == 0:
        coords = np.zeros((imap.size_global, 3))
        for g, c in parts:
            coords[g] = c
        x = coords[dofs]
        assert len(dofs) > 10
        assert np.allclose(vals, 1.0 + 2.0 * x[:, 0] + 3.0 * x[:, 1], rtol=1e-10, atol=1e-10)
        assert np.allclose(x[:, 2], 0.5)
