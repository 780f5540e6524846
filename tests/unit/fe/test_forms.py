"""Unit tests of the UFL forms through their assembled matrices (exact properties)."""
from __future__ import annotations

import math

import numpy as np
import pytest
import ufl
from dolfinx.fem import petsc as fem_petsc
from mpi4py import MPI
from petsc4py import PETSc

R, B, H = 0.05, 0.005, 0.004
RI, RO = R - B / 2, R + B / 2
AREA = math.pi * (RO ** 2 - RI ** 2)
# Curved P2 geometry reproduces the ring's areas and volume to ~1e-7 relative at this mesh
# (interpolation error of the circle, O(h^3)); 1e-5 leaves margin and still catches any lost facet.
GEOM_TOL = 1e-5


def field(ops, fn) -> PETSc.Vec:
    """Interpolate the nodal vector field fn(x) -> (n, 3) into a PETSc vector (owned DOFs)."""
    n = ops.V.dofmap.index_map.size_local
    x = ops.V.tabulate_dof_coordinates()[:n]
    v = ops.K.createVecRight()
    v.array[:] = fn(x).ravel()
    return v


def quad(A, u, v=None):
    v = u if v is None else v
    y = A.createVecLeft()
    A.mult(u, y)
    return v.dot(y)


def rigid_modes(ops):
    return [field(ops, lambda x, d=d: np.tile(np.eye(3)[d], (len(x), 1))) for d in range(3)] + [
        field(ops, lambda x: np.stack([-x[:, 1], x[:, 0], 0 * x[:, 0]], 1)),
        field(ops, lambda x: np.stack([0 * x[:, 0], -x[:, 2], x[:, 1]], 1)),
        field(ops, lambda x: np.stack([x[:, 2], 0 * x[:, 0], -x[:, 0]], 1))]


def test_rigid_body_modes_have_zero_strain_energy(ring_operators):
    ops = ring_operators(kn=0.0)
    scale = ops.K.norm(PETSc.NormType.INFINITY)
    for u in rigid_modes(ops):
        y = ops.K.createVecLeft()
        ops.K.mult(u, y)
        # K u for a rigid motion is zero up to round-off of the assembly (~1e-16 ‖K‖ ‖u‖ per entry)
        assert y.norm() <= 1e-10 * scale * u.norm()


def test_in_plane_rigid_modes_stay_free_between_plates(ring_operators):
    ops = ring_operators()
    for u in rigid_modes(ops)[:2] + rigid_modes(ops)[3:4]:   # x, y translation, rotation about z
        assert abs(quad(ops.K, u)) <= 1e-10 * ops.K.norm(PETSc.NormType.INFINITY) * u.dot(u)
    uz = rigid_modes(ops)[2]
    # u_z = 1 closes the top gap by 1 and opens the bottom by 1: energy kn·A on each face
    assert quad(ops.K, uz) == pytest.approx(2 * 1e10 * AREA, rel=GEOM_TOL)


def test_mass_matrix_gives_the_ring_mass(ring_operators):
    ops = ring_operators(kn=0.0)
    ux = rigid_modes(ops)[0]
    assert quad(ops.M, ux) == pytest.approx(1400.0 * AREA * H, rel=GEOM_TOL)
    # the axial mass sees only u_z
    assert quad(ops.M_axial, ux) == pytest.approx(0.0, abs=1e-14)
    uz = rigid_modes(ops)[2]
    assert quad(ops.M_axial, uz) == pytest.approx(quad(ops.M, uz), rel=1e-12)


@pytest.mark.parametrize("sliding", [1, -1])
def test_friction_form_moment_and_sign(sliding, ring_operators):
    """u = e_z closes the top face only (bottom plate: sliding 0).  The friction traction
    μ kn (u·n) s with s = sliding·e_θ does virtual work on the rotation v = r e_θ of
    sliding·μ kn ∫_top r dA = sliding·μ kn 2π(r_o³ − r_i³)/3."""
    ops = ring_operators(sliding=(sliding, 0))
    uz, rot = rigid_modes(ops)[2], rigid_modes(ops)[3]
    expect = sliding * 0.3 * 1e10 * 2 * math.pi * (RO ** 3 - RI ** 3) / 3
    # Operators.Kf is the friction stiffness as it enters the operator: −a_f
    assert -quad(ops.Kf, uz, rot) == pytest.approx(expect, rel=GEOM_TOL)
    # asymmetric: a rotation does not close the gap, so it produces no friction force
    assert abs(quad(ops.Kf, rot, uz)) <= 1e-10 * abs(expect)


def test_friction_cancels_for_opposite_sliding_under_uniform_closure(ring_operators):
    ops = ring_operators(sliding=(1, -1))
    uz, rot = rigid_modes(ops)[2], rigid_modes(ops)[3]
    # u_z = 1: top u·n = +1 with s = +e_θ, bottom u·n = −1 with s = −e_θ: same torque twice
    expect = 2 * 0.3 * 1e10 * 2 * math.pi * (RO ** 3 - RI ** 3) / 3
    assert -quad(ops.Kf, uz, rot) == pytest.approx(expect, rel=GEOM_TOL)
    ops2 = ring_operators(sliding=(1, 1))
    assert abs(quad(ops2.Kf, uz, rot)) <= 1e-8 * expect


def test_rayleigh_damping_matrix(ring_operators):
    ops = ring_operators(alpha=3.0, beta=1e-6)
    ref = ring_operators(kn=0.0)
    for u in rigid_modes(ops)[:3]:
        # C u = α M u for a rigid translation (K u = 0)
        assert quad(ops.C, u) == pytest.approx(3.0 * quad(ref.M, u), rel=1e-12)


def test_p1_warns_about_locking(ring_operators):
    with pytest.warns(UserWarning, match="lock"):
        ring_operators(mesh_size=0.004, degree=1, kn=0.0)


def test_transversely_isotropic_stiffness(ring_mesh):
    """The Voigt form: equal constants reproduce the isotropic matrix; uniform axial strain ε_z
    and shear γ_xz store ½C₃₃ε²V and ½C₅₅γ²V with C from inverting the compliance (1e-12)."""
    from dolfinx import fem

    from fem_squeal.fe import forms
    from fem_squeal.fe.model import Material

    md = ring_mesh()
    V = fem.VectorFunctionSpace(md.mesh, ("Lagrange", 2))
    u, v = ufl.TrialFunction(V), ufl.TestFunction(V)
    iso = Material(3e9, 0.4, 1400.0)
    same = Material(3e9, 0.4, 1400.0, E_axial=3e9, nu_axial=0.4, G_axial=3e9 / 2.8)
    ti = Material(8e9, 0.3, 2500.0, E_axial=3e9, nu_axial=0.15, G_axial=1.5e9)

    def mat(m):
        A = fem_petsc.assemble_matrix(fem.form(forms.material_stiffness_form(u, v, m, ufl.dx)))
        A.assemble()
        return A
    A, B = mat(iso), mat(same)
    B.axpy(-1.0, A)
    assert B.norm() <= 1e-12 * A.norm()
    C = ti.voigt_stiffness()
    K = mat(ti)
    vol = fem.assemble_scalar(fem.form(fem.Constant(md.mesh, 1.0) * ufl.dx(domain=md.mesh)))
    for field, c in ((lambda x: np.vstack([0 * x[0], 0 * x[0], 1e-3 * x[2]]), C[2, 2]),
                     (lambda x: np.vstack([1e-3 * x[2], 0 * x[0], 0 * x[0]]), C[4, 4])):
        f = fem.Function(V)
        f.interpolate(field)
        x = K.createVecRight()
        x.array[:] = f.x.array[: x.getLocalSize()]
        y = K.createVecLeft()
        K.mult(x, y)
        assert 0.5 * x.dot(y) == pytest.approx(0.5 * c * 1e-6 * MPI.COMM_WORLD.allreduce(vol), rel=1e-10)
    with pytest.raises(ValueError, match="nu_axial"):
        Material(8e9, 0.3, 2500.0, E_axial=3e9, nu_axial=0.9, G_axial=1.5e9)


def test_oriented_orthotropic_stiffness(ring_mesh):
    """Material frames: a cylindrical frame about z of a material transversely isotropic about its local 3
    axis assembles the global transversely isotropic matrix (1e-12 on the same rule: the rotation about z
    leaves it unchanged); a rectangular frame that permutes the axes gives the relabelled constants' stiffness,
    the 21 ANISO constants of a rotated stiffness give it back; non-positive-definite constants and an
    orientation on an isotropic material are named errors."""
    from dolfinx import fem

    from fem_squeal.fe import forms
    from fem_squeal.fe.model import ANISO_ORDER, ENGINEERING_CONSTANTS, Material

    md = ring_mesh()
    V = fem.VectorFunctionSpace(md.mesh, ("Lagrange", 2))
    u, v = ufl.TrialFunction(V), ufl.TestFunction(V)

    def mat(m):
        dx = ufl.dx(metadata={"quadrature_degree": 6})
        A = fem_petsc.assemble_matrix(fem.form(forms.material_stiffness_form(u, v, m, dx)))
        A.assemble()
        return A

    ti = Material(8e9, 0.3, 2500.0, E_axial=3e9, nu_axial=0.15, G_axial=1.5e9)
    eng = dict(zip(ENGINEERING_CONSTANTS, (8e9, 8e9, 3e9, 0.3, 0.4, 0.4, 8e9 / 2.6, 1.5e9, 1.5e9)))
    cyl = {"system": "cylindrical", "a": [0, 0, 0], "b": [0, 0, 1]}
    A, B = mat(ti), mat(Material(None, None, 2500.0, **eng, orientation=cyl))
    B.axpy(-1.0, A)
    assert B.norm() <= 1e-12 * A.norm()
    orth = dict(zip(ENGINEERING_CONSTANTS, (10e9, 4e9, 2e9, 0.25, 0.2, 0.3, 3e9, 1e9, 0.8e9)))
    # local 1 = global y, local 2 = −x, local 3 = z: E_x = E2, E_y = E1, ν_xy = ν21 = ν12 E2/E1, G_xz = G23
    rect = Material(None, None, 2500.0, **orth, orientation={"system": "rectangular", "a": [0, 1, 0],
                                                             "b": [-1, 0, 0]})
    relabel = dict(zip(ENGINEERING_CONSTANTS, (4e9, 10e9, 2e9, 0.1, 0.3, 0.2, 3e9, 0.8e9, 1e9)))
    Cr = forms.rotated_voigt(rect.local_stiffness(), rect.orientation.frame())
    assert np.allclose(Cr, Material(None, None, 2500.0, **relabel).local_stiffness(), rtol=0, atol=1e-12 * 1e10)
    tilted = Material(None, None, 2500.0, **orth, orientation={"system": "rectangular", "a": [1, 0.5, 0.2],
                                                               "b": [-0.3, 1, 0.1]})
    Cg = forms.rotated_voigt(tilted.local_stiffness(), tilted.orientation.frame())
    assert np.count_nonzero(np.abs(Cg) > 1e-6 * np.abs(Cg).max()) == 36
    Cd = Material(None, None, 2500.0, D=[Cg[i, j] for i, j in ANISO_ORDER]).local_stiffness()
    assert np.allclose(Cd, Cg, rtol=0, atol=1e-14 * np.abs(Cg).max())
    with pytest.raises(ValueError, match="nu12, nu13, nu23: the constants give a stiffness that is not positive"):
        Material(None, None, 2500.0, **{**orth, "nu23": 4.0})
    with pytest.raises(ValueError, match="orientation: only for an orthotropic"):
        Material(8e9, 0.3, 2500.0, orientation=cyl)


def test_point_load_at_a_node(ring_mesh):
    """loads.point: F lands on the three DOFs of the node at the point (summed over ranks: F), and a point
    that is no node is a named error."""
    from dolfinx import fem, la

    from fem_squeal.fe.assembly import add_point_loads
    from fem_squeal.fe.model import PointLoad
    from fem_squeal.util.errors import ModelError

    md = ring_mesh()
    V = fem.VectorFunctionSpace(md.mesh, ("Lagrange", 2))
    x = md.mesh.comm.bcast(V.tabulate_dof_coordinates()[0].tolist(), root=0)
    f = la.create_petsc_vector(V.dofmap.index_map, 3)
    f.set(0.0)
    add_point_loads(f, V, [PointLoad("p", x, (1.0, -2.0, 3.0))])
    a = f.array_r.reshape(-1, 3)
    hit = np.flatnonzero(np.abs(a).sum(axis=1))
    assert md.mesh.comm.allreduce(a.sum(axis=0), op=MPI.SUM).tolist() == [1.0, -2.0, 3.0]
    assert all(np.allclose(V.tabulate_dof_coordinates()[i], x) for i in hit)
    with pytest.raises(ModelError, match=r"loads.point.q: no node of the mesh at \[0.0, 0.0, 0.0\]"):
        add_point_loads(f, V, [PointLoad("q", (0, 0, 0), (1, 0, 0))])


def test_quadrature_degree_is_honoured(ring_mesh):
    """discretisation.quadrature_degree reaches FFCx (it was silently ignored as a form-compiler
    parameter): the P2 mass on curved P2 cells is a degree-7 polynomial, so degree 7 and the
    default integrate it alike, while the 4-point rule (degree 2) under-integrates it (ccx's C3D10)."""
    from fem_squeal.fe.assembly import assemble_operators
    from fem_squeal.fe.model import Material, ModelSpec

    md = ring_mesh(mesh_size=0.004)
    norms = {}
    for qd in (None, 7, 2):
        ops = assemble_operators(md, ModelSpec({"disc": Material(3e9, 0.4, 1400.0)}, quadrature_degree=qd))
        norms[qd] = ops.M.norm(PETSc.NormType.FROBENIUS)
    assert norms[7] == pytest.approx(norms[None], rel=1e-12)
    assert abs(norms[2] / norms[None] - 1) > 1e-4
