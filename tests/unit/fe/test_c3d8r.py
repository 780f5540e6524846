"""CalculiX's C3D8R (fem_squeal.fe.c3d8r): the element matrices against ccx 2.20's own, the patch test of
the one-point part and what the hourglass stiffness leaves free, and the assembly on a small mesh."""
from __future__ import annotations

import shutil
import subprocess

import numpy as np
import pytest

from fem_squeal.fe import c3d8r

#: a distorted hexahedron in CalculiX/Abaqus node order (nodes 1-4 at ζ = -1, 5-8 at ζ = +1)
X_CCX = np.array([[0.035, 0.082, 0.033], [1.87, 0.091, 0.045], [1.946, 1.058, 0.036], [0.029, 1.003, 0.055],
                  [-0.074, -0.016, 0.452], [2.06, 0.004, 0.471], [1.922, 0.974, 0.501], [-0.028, 1.129, 0.601]])
E, NU, RHO = 100.0, 0.2, 7.0
#: dolfinx node k <- CalculiX node PERM[k] (dolfinx: lexicographic; CalculiX: counter-clockwise faces)
PERM = [0, 1, 3, 2, 4, 5, 7, 6]
#: ccx 2.20 (Debian calculix-ccx 2.20) on this element alone, E = 100, ν = 0.2, ρ = 7, C3D8R, step
#: "*FREQUENCY, SOLVER=MATRIXSTORAGE": the .sti file's diagonal, its rows 1 and 14 (DOF 1.1 and 5.2;
#: DOF order node.direction), and the .mas file's (1, 1) entry.
CCX_DIAGONAL = [15.471523200525, 17.409656889691, 33.854462650876, 16.082555370245, 18.36949734964,
                35.446791813095, 13.954880356522, 17.321292007664, 28.726511609376, 16.333209203258,
                20.198074681531, 33.243839656107, 16.480811890522, 20.78579575405, 33.765303755771,
                14.406799142392, 17.922734730803, 29.425076353793, 16.825340465395, 18.86369108125,
                35.470975662461, 15.199685469658, 17.379259526309, 33.295795543357]
CCX_ROW_1 = [15.471523200525, 1.6868102385891, 4.3474422233421, 11.972412782737, -0.26386344915805,
             -0.71806536256188, 6.8196335816391, -1.7954239269152, -0.95532056343928, 10.38160412719,
             0.23162695004225, 4.5707046998597, -7.6123353066739, 1.9639156395037, 1.0122291046547,
             -9.9574305445905, -0.17622653884617, -4.1950656977823, -15.306065806806, -1.9316791403879,
             -4.8648684419525, -11.76934203402, 0.28484022717222, 0.80294403787944]
CCX_ROW_14 = [1.9639156395037, -4.6742255158473, -0.31335084269172, 0.2209302949533, -5.5905177856347,
              -0.41640398399367, -2.1550737224967, -18.16284329351, 8.9792599037459, -0.37014066654937,
              -18.603290428641, 9.7190961119249, 2.3705936435448, 20.78579575405, -9.9080644943733,
              0.38686157093186, 17.273882581359, -9.1500089774749, -2.2213832719487, 3.971693804223,
              0.60537236644203, -0.19570348793889, 4.9995048840025, 0.48409991642076]
CCX_MASS_11 = 0.0997246499375


def ccx_order(A: np.ndarray) -> np.ndarray:
    """A (24 × 24, dolfinx node order) in CalculiX's node order."""
    inv = np.argsort(PERM)
    idx = (inv[:, None] * 3 + np.arange(3)).ravel()
    return A[np.ix_(idx, idx)]


def element(X=X_CCX):
    Xd = X[PERM][None]
    one = np.ones(1)
    K = c3d8r.element_stiffness(Xd, E * one, NU * one)[0]
    M = c3d8r.vector_mass(c3d8r.element_mass(Xd, RHO * one), np.eye(3))[0]
    return ccx_order(K), ccx_order(M)


def test_element_matrices_are_ccx_220s():
    """Stiffness (mean strain + hourglass) and the one-point mass of a distorted element equal ccx 2.20's
    .sti/.mas to rounding (its files print 14 digits)."""
    K, M = element()
    scale = np.abs(K).max()
    assert np.abs(np.diag(K) - CCX_DIAGONAL).max() < 1e-12 * scale
    assert np.abs(K[0] - CCX_ROW_1).max() < 1e-12 * scale
    assert np.abs(K[13] - CCX_ROW_14).max() < 1e-12 * scale
    V, _ = c3d8r.mean_strain(X_CCX[PERM][None])
    assert M[0, 0] == pytest.approx(CCX_MASS_11, rel=1e-12)
    assert M[0, 0] == pytest.approx(RHO * V[0] / 64, rel=1e-14)
    assert np.allclose(M, np.kron(np.ones((8, 8)), np.eye(3)) * M[0, 0], rtol=0, atol=1e-15)


@pytest.mark.slow
@pytest.mark.skipif(shutil.which("ccx") is None, reason="needs CalculiX (ccx)")
def test_element_matrices_against_a_ccx_run(tmp_path):
    """The whole 24 × 24 K and M against the ccx on this machine (MATRIXSTORAGE)."""
    nodes = "\n".join(f"{i + 1}, {x}, {y}, {z}" for i, (x, y, z) in enumerate(X_CCX.tolist()))
    (tmp_path / "t.inp").write_text(
        f"*NODE\n{nodes}\n*ELEMENT, TYPE=C3D8R, ELSET=E\n1, 1,2,3,4,5,6,7,8\n*MATERIAL, NAME=S\n*ELASTIC\n"
        f"{E}, {NU}\n*DENSITY\n{RHO}\n*SOLID SECTION, ELSET=E, MATERIAL=S\n*STEP\n"
        "*FREQUENCY, SOLVER=MATRIXSTORAGE\n4\n*END STEP\n")
    subprocess.run(["ccx", "-i", "t"], cwd=tmp_path, check=True, capture_output=True,
                   env={"OMP_NUM_THREADS": "1", "PATH": "/usr/bin:/bin"})

    def read(name):
        A = np.zeros((24, 24))
        for line in (tmp_path / name).read_text().splitlines():
            i, j, v = line.split()
            A[int(i) - 1, int(j) - 1] = A[int(j) - 1, int(i) - 1] = float(v)
        return A
    K, M = element()
    assert np.abs(K - read("t.sti")).max() < 1e-12 * np.abs(K).max()
    assert np.abs(M - read("t.mas")).max() < 1e-12 * np.abs(M).max()


def linear_field(X, G, c=(0.3, -0.2, 0.1)):
    """Nodal values (24,) of u(x) = c + G x."""
    return (np.asarray(c) + X @ np.asarray(G).T).ravel()


def test_patch_test_and_what_the_hourglass_stiffness_leaves_free():
    """The mean-strain part integrates a linear field's energy exactly (V ε:Dε); the hourglass stiffness
    leaves translations and fields linear in z free on any element, every linear field on a
    parallelepiped; ccx 2.20's hourglass vectors keep only the z term of Flanagan-Belytschko's
    projection, so on a distorted element it resists fields linear in x or y, rotations too."""
    rng = np.random.default_rng(3)
    Xd = X_CCX[PERM]
    one = np.ones(1)
    lam, mu = c3d8r.lame(E * one, NU * one)
    V, B = c3d8r.mean_strain(Xd[None])
    K1 = c3d8r.isotropic_stiffness(V, B, lam, mu)[0]
    Khg = c3d8r.hourglass_stiffness(Xd[None], E * one)[0]
    for _ in range(3):
        G = rng.standard_normal((3, 3))
        eps = (G + G.T) / 2
        u = linear_field(Xd, G)
        exact = V[0] * (lam[0] * np.trace(eps) ** 2 + 2 * mu[0] * np.sum(eps * eps))
        assert u @ K1 @ u == pytest.approx(exact, rel=1e-12)
        uz = linear_field(Xd, np.outer(rng.standard_normal(3), [0, 0, 1]))
        assert abs(uz @ Khg @ uz) < 1e-13 * np.abs(Khg).max()
    rot_z = linear_field(Xd, [[0, -1, 0], [1, 0, 0], [0, 0, 0]])
    assert rot_z @ Khg @ rot_z > 1e-4 * np.abs(Khg).max()           # ccx 2.20's z-only projection
    # a parallelepiped: every linear field, rotations included, is free of hourglass energy
    P = c3d8r.NODES @ np.array([[1.0, 0.2, 0.1], [0.3, 0.8, -0.1], [0.1, 0.2, 0.5]]) + 0.4
    Kp = c3d8r.element_stiffness(P[None], E * one, NU * one)[0]
    Kp_hg = c3d8r.hourglass_stiffness(P[None], E * one)[0]
    for G in ([[0, -1, 0], [1, 0, 0], [0, 0, 0]], [[0, 0, 1], [0, 0, 0], [-1, 0, 0]], rng.standard_normal((3, 3))):
        u = linear_field(P, G)
        assert abs(u @ Kp_hg @ u) < 1e-13 * np.abs(Kp_hg).max() * (u @ u)
    w = np.linalg.eigvalsh(Kp)
    assert np.sum(np.abs(w) < 1e-12 * w.max()) == 6                 # rigid modes only: hourglass modes held


def test_corrections_vanish_on_affine_cells_but_the_hourglass_part():
    """On a parallelepiped the centre gradient is the mean gradient and V_c = V: the correction to UFL's
    one-point forms is the hourglass stiffness alone and no mass."""
    P = (c3d8r.NODES @ np.array([[1.0, 0.2, 0.1], [0.3, 0.8, -0.1], [0.1, 0.2, 0.5]]))[None]
    one = np.ones(1)
    dK, dM = c3d8r.corrections(P, E * one, NU * one, RHO * one)
    assert np.abs(dK - c3d8r.hourglass_stiffness(P, E * one)).max() < 1e-13 * np.abs(dK).max()
    assert np.abs(dM).max() < 1e-15


@pytest.fixture(scope="module")
def small_model():
    """A 2 × 1 × 1 box of distorted Q1 hexahedra clamped at x = 0, assembled as C3D8R."""
    from dolfinx import mesh as dmesh
    from mpi4py import MPI

    from fem_squeal.fe.assembly import assemble_operators
    from fem_squeal.fe.model import Material, ModelSpec
    from geometry.gmsh_io import MeshData

    mesh = dmesh.create_box(MPI.COMM_WORLD, [[0, 0, 0], [2, 1, 1]], [2, 1, 1], dmesh.CellType.hexahedron)
    x = mesh.geometry.x
    x[:, :3] += 0.1 * np.sin(np.arange(x.size).reshape(-1, 3) * [1.3, 2.1, 0.7])
    cells = np.arange(mesh.topology.index_map(3).size_local, dtype=np.int32)
    ct = dmesh.meshtags(mesh, 3, cells, np.ones_like(cells))
    mesh.topology.create_connectivity(2, 3)
    facets = dmesh.exterior_facet_indices(mesh.topology)
    mid = dmesh.compute_midpoints(mesh, 2, facets)
    ft = dmesh.meshtags(mesh, 2, facets, np.where(mid[:, 0] < 0.2, 1, 2).astype(np.int32))
    md = MeshData(mesh, ct, ft, {"b": 1}, {"clamp": 1, "rest": 2})
    spec = ModelSpec({"b": Material(E, NU, RHO)}, (), ("clamp",), 1, c3d8r=True)
    return md, spec, assemble_operators(md, spec)


def test_assembled_operators_are_the_element_matrices(small_model):
    """K and M assembled (UFL one-point forms + corrections) equal the NumPy element matrices summed over
    the cells, with the clamped rows and columns replaced by the identity in K and zero in M."""
    _, _, ops = small_model
    K = ops.K.convert("dense").getDenseArray()
    M = ops.M.convert("dense").getDenseArray()
    X, glob, _ = c3d8r.cell_dofs(ops.V)
    one = np.ones(len(X))
    Ke = c3d8r.element_stiffness(X, E * one, NU * one)
    Me = c3d8r.vector_mass(c3d8r.element_mass(X, RHO * one), np.eye(3))
    Kn, Mn = np.zeros_like(K), np.zeros_like(M)
    for c in range(len(X)):
        Kn[np.ix_(glob[c], glob[c])] += Ke[c]
        Mn[np.ix_(glob[c], glob[c])] += Me[c]
    bc = ops.bc_dofs
    for A in (Kn, Mn):
        A[bc, :] = 0
        A[:, bc] = 0
    Kn[bc, bc] = 1.0
    assert len(bc) == 12
    assert np.abs(K - Kn).max() < 1e-13 * np.abs(Kn).max()
    assert np.abs(M - Mn).max() < 1e-13 * np.abs(Mn).max()


def test_c3d8r_needs_degree_1_and_isotropic_materials(small_model):
    import dataclasses

    from fem_squeal.fe.assembly import assemble_operators
    from fem_squeal.util.errors import ModelError

    md, spec, _ = small_model
    with pytest.raises(ModelError, match="discretisation.degree = 1"):
        assemble_operators(md, dataclasses.replace(spec, degree=2))
