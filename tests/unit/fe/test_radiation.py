"""ERP (fem_squeal.fe.radiation) against closed forms on a small box: a rigid piston face and a
simply-supported plate mode; the radiating surface without the faces a contact partner covers."""
from __future__ import annotations

import math

import numpy as np
import pytest
from dolfinx import mesh as dmesh
from mpi4py import MPI

from fem_squeal.fe.model import Material, ModelSpec, RigidPlate
from fem_squeal.fe.radiation import RHO_C_AIR, quadratic_forms, radiated_power, radiating_facets, surface_matrix
from geometry.gmsh_io import MeshData

A, B, H, RHO = 0.04, 0.03, 0.002, 7850.0
FACES = {"bottom": 1, "top": 2, "sides": 3}


@pytest.fixture(scope="module")
def box():
    """A 40 × 30 × 2 mm box of P2 tetrahedra: its mesh data (faces bottom, top, sides), V and M."""
    from fem_squeal.fe.assembly import assemble_operators

    mesh = dmesh.create_box(MPI.COMM_WORLD, [[0, 0, 0], [A, B, H]], [8, 6, 1], dmesh.CellType.tetrahedron)
    tdim = mesh.topology.dim
    mesh.topology.create_connectivity(tdim - 1, tdim)
    facets = dmesh.exterior_facet_indices(mesh.topology)
    mid = dmesh.compute_midpoints(mesh, tdim - 1, facets)
    values = np.where(mid[:, 2] < 1e-9, 1, np.where(mid[:, 2] > H - 1e-9, 2, 3)).astype(np.int32)
    ft = dmesh.meshtags(mesh, tdim - 1, facets, values)
    cells = np.arange(mesh.topology.index_map(tdim).size_local + mesh.topology.index_map(tdim).num_ghosts,
                      dtype=np.int32)
    ct = dmesh.meshtags(mesh, tdim, cells, np.ones_like(cells))
    md = MeshData(mesh, ct, ft, {"plate": 1}, dict(FACES))
    spec = ModelSpec({"plate": Material(2.1e11, 0.3, RHO)}, (), (), 2)
    return md, spec, assemble_operators(md, spec)


def nodal(ops, fn):
    n = ops.V.dofmap.index_map.size_local
    x = ops.V.tabulate_dof_coordinates()[:n]
    v = ops.K.createVecRight()
    v.array[:] = np.asarray(fn(x[:, 0], x[:, 1], x[:, 2])).T.ravel()
    return v


def test_rigid_piston_face_radiates_half_rho_c_area_v_squared(box):
    """A rigid translation along z with only the top face radiating: ERP = ½ρcσ A v² with v from the
    kinetic energy T = ½ m v² (m = ρ a b h): ERP = ρc σ A T / m; σ = 0.5 halves it."""
    md, spec, ops = box
    x = nodal(ops, lambda x, y, z: (0 * x, 0 * x, 1 + 0 * x))
    mass = RHO * A * B * H
    for sigma in (1.0, 0.5):
        P, area = radiated_power(ops.V, md, spec, ops.M, [(x, None)], energy=2.0, efficiency={"plate": sigma},
                                 exclude_faces=("bottom",))
        v2 = 2 * 2.0 / mass
        assert area == pytest.approx(A * B + 2 * (A + B) * H, rel=1e-12)
        assert P[0] == pytest.approx(0.5 * RHO_C_AIR * sigma * A * B * v2, rel=1e-10)


def test_simply_supported_plate_mode_normalisation(box):
    """w = sin(πx/a) sin(πy/b): ∫_top w² dA = A/4 (P2 interpolation error only), and with the top face
    alone radiating ERP = ρc T (A/4)/(ρ h A/4) = ρc T/(ρ h) at kinetic energy T."""
    md, spec, ops = box
    w = nodal(ops, lambda x, y, z: (0 * x, 0 * x, np.sin(math.pi * x / A) * np.sin(math.pi * y / B)))
    facets = radiating_facets(md, spec, exclude_faces=("bottom", "sides"))
    S, area = surface_matrix(ops.V, md, facets)
    assert area == pytest.approx(A * B, rel=1e-12)
    assert quadratic_forms(S, [(w, None)])[0] == pytest.approx(A * B / 4, rel=2e-3)
    S.destroy()
    P, _ = radiated_power(ops.V, md, spec, ops.M, [(w, None)], exclude_faces=("bottom", "sides"))
    assert P[0] == pytest.approx(RHO_C_AIR / (RHO * H), rel=3e-3)


def test_complex_shape_uses_the_modulus_of_the_normal_velocity(box):
    """x = w (1 + i): |v_n|² doubles and so does x^H M x: the same ERP as w alone; x = w + i·(in-plane)
    adds mass but no normal motion."""
    md, spec, ops = box
    w = nodal(ops, lambda x, y, z: (0 * x, 0 * x, np.sin(math.pi * x / A) * np.sin(math.pi * y / B)))
    t = nodal(ops, lambda x, y, z: (np.sin(math.pi * x / A) * np.sin(math.pi * y / B), 0 * x, 0 * x))
    P, _ = radiated_power(ops.V, md, spec, ops.M, [(w, None), (w, w), (w, t)], exclude_faces=("bottom",))
    assert P[1] == pytest.approx(P[0], rel=1e-12)
    mw, mt = quadratic_forms(ops.M, [(w, None), (t, None)])
    assert P[2] == pytest.approx(P[0] * mw / (mw + mt), rel=1e-6)


def test_plate_faces_and_named_faces_do_not_radiate(box):
    """A rigid plate's face leaves the surface; an unknown face name is an error naming the key."""
    md, spec, ops = box
    plated = ModelSpec(spec.materials, (RigidPlate("top", 1e10, 0.0, 0),), (), 2)
    area = surface_matrix(ops.V, md, radiating_facets(md, plated))[1]
    assert area == pytest.approx(A * B + 2 * (A + B) * H, rel=1e-12)
    with pytest.raises(Exception, match="exclude_faces: face 'lid' not in mesh"):
        radiating_facets(md, spec, exclude_faces=("lid",))


def test_efficiency_of_an_unknown_part_is_an_error(box):
    md, spec, ops = box
    with pytest.raises(Exception, match=r"radiation.efficiency.pad: no such part"):
        surface_matrix(ops.V, md, radiating_facets(md, spec), {"pad": 0.5})
