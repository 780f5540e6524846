"""Stress stiffening (issue 20 item 5): K_σ = ∫ σ₀_ij ∂_i u_k ∂_j v_k dx of a static stress σ₀, and the
centrifugal prestress of a spinning disc.

Model: steel annular disc r 0.05–0.15 m, h 0.01 m, P2 curved tetrahedra (mesh size 0.04 m).
"""
from __future__ import annotations

import functools

import numpy as np
import pytest
from mpi4py import MPI
from petsc4py import PETSc
from support.operators import bilinear, nodal_vector

R_I, R_O, H = 0.05, 0.15, 0.01
E, NU, RHO = 2.1e11, 0.3, 7850.0


@functools.cache
def disc(clamped: bool):
    from fem_squeal.fe.assembly import assemble_operators
    from fem_squeal.fe.model import Material, ModelSpec
    from geometry import annular_disc_mesh

    md = annular_disc_mesh(MPI.COMM_WORLD, mean_radius=0.5 * (R_I + R_O), width=R_O - R_I, thickness=H,
                           mesh_size=0.04, order=2)
    spec = ModelSpec({"disc": Material(E, NU, RHO)}, clamped=("inner",) if clamped else ())
    return md, spec, assemble_operators(md, spec)




def _mesh_integral(md, f) -> float:
    import ufl
    from dolfinx import fem

    x = ufl.SpatialCoordinate(md.mesh)
    return md.mesh.comm.allreduce(fem.assemble_scalar(fem.form(f(x) * ufl.dx(domain=md.mesh))), op=MPI.SUM)


def test_uniform_tension_gives_the_string_term():
    """u₀ = ε (x, −νy, −νz) is a uniform uniaxial stress σ_xx = Eε, and w = (0, 0, x) a transverse
    rotation: wᵀK_σw = σ_xx ∫ (∂_x w_z)² dV = Eε V, the string stiffness of the tension (both fields are
    linear in x, so the isoparametric P2 space holds them exactly, curved cells too)."""
    from fem_squeal.fe.assembly import geometric_stiffness

    md, spec, ops = disc(False)
    eps = 1e-4
    u0 = nodal_vector(ops, lambda x, y, z: (eps * x, -NU * eps * y, -NU * eps * z))
    Ks = geometric_stiffness(ops, md, spec, u0)
    w = nodal_vector(ops, lambda x, y, z: (0 * x, 0 * y, x))
    exact = E * eps * np.pi * H * (R_O ** 2 - R_I ** 2)
    on_mesh = E * eps * _mesh_integral(md, lambda x: 1.0 + 0 * x[0])   # Eε × the curved mesh's volume
    assert abs(bilinear(Ks, w, w) / on_mesh - 1) < 1e-12                  # exact integrand: round-off only
    assert abs(on_mesh / exact - 1) < 1e-3                             # curved P2 geometry of mesh size 0.04
    # the tension does not stiffen a rotation about x: v = (0, 0, y) has ∂_x v = 0
    v = nodal_vector(ops, lambda x, y, z: (0 * x, 0 * y, y))
    assert abs(bilinear(Ks, v, v)) < 1e-12 * abs(bilinear(Ks, w, w))


def test_geometric_stiffness_is_symmetric_linear_and_zero_without_stress():
    from fem_squeal.fe.assembly import geometric_stiffness

    md, spec, ops = disc(True)
    rng = np.random.default_rng(3)
    u0 = ops.K.createVecRight()
    u0.array[:] = 1e-5 * rng.standard_normal(u0.getLocalSize())
    Ks = geometric_stiffness(ops, md, spec, u0)
    T = Ks.copy()
    T.axpy(-1.0, Ks.transpose(PETSc.Mat()), structure=PETSc.Mat.Structure.DIFFERENT_NONZERO_PATTERN)
    scale = Ks.norm(PETSc.NormType.INFINITY)
    assert T.norm(PETSc.NormType.INFINITY) <= 1e-14 * scale    # σ₀ symmetric: the form is, term by term
    u0.scale(2.0)
    K2 = geometric_stiffness(ops, md, spec, u0)
    K2.axpy(-2.0, Ks, structure=PETSc.Mat.Structure.DIFFERENT_NONZERO_PATTERN)
    assert K2.norm(PETSc.NormType.INFINITY) <= 1e-13 * scale   # linear in σ₀: round-off
    u0.set(0.0)
    assert geometric_stiffness(ops, md, spec, u0).norm(PETSc.NormType.INFINITY) == 0.0


def _lame_clamped_disc(r, speed):
    """Plane-stress rotating annulus, u(r_i) = 0, σ_r(r_o) = 0: u = C₁r + C₂/r − (1 − ν²)ρΩ²r³/(8E)."""
    q = RHO * speed ** 2
    A = np.array([[R_I, 1 / R_I], [(1 + NU), -(1 - NU) / R_O ** 2]])
    b = np.array([(1 - NU ** 2) * q * R_I ** 3 / (8 * E), (1 - NU ** 2) / E * (3 + NU) * q * R_O ** 2 / 8])
    c1, c2 = np.linalg.solve(A, b)
    return c1 * r + c2 / r - (1 - NU ** 2) * q * r ** 3 / (8 * E)


def test_centrifugal_prestress_and_spin_stiffening():
    """The static response to the centrifugal load Ω² f_c against Lamé's plane-stress disc (h/r_o = 1/15:
    plane stress and the clamp's 3D corner are within 2 %), and the rise of the bending frequencies
    with Ω: ω² = ω₀² + αΩ² + O(Ω⁴), so the rise at 2Ω is 4 times that at Ω."""
    from fem_squeal.fe.assembly import geometric_stiffness, rotation_matrices, static_displacement
    from fem_squeal.fe.eigen import solve_real_modes

    md, spec, ops = disc(True)
    rot = rotation_matrices(ops, md, spec, ["disc"], "rotating")
    speed = 300.0
    f = rot.f.copy()
    f.scale(speed ** 2)
    uc = static_displacement(ops.K, f)
    n = ops.V.dofmap.index_map.size_local
    x = ops.V.tabulate_dof_coordinates()[:n]
    r = np.hypot(x[:, 0], x[:, 1])
    ur = (uc.array.reshape(-1, 3)[:, 0] * x[:, 0] + uc.array.reshape(-1, 3)[:, 1] * x[:, 1]) / r
    outer = np.abs(r - R_O) < 1e-6
    mean = MPI.COMM_WORLD.allreduce(float(ur[outer].sum()), op=MPI.SUM) / \
        MPI.COMM_WORLD.allreduce(int(outer.sum()), op=MPI.SUM)
    assert abs(mean / _lame_clamped_disc(R_O, speed) - 1) < 0.02
    K1 = geometric_stiffness(ops, md, spec, uc)           # K_σ per (300 rad/s)²
    rises = []
    for scale in (0.25, 1.0):                               # Ω = 150 and 300 rad/s
        K = ops.K.copy()
        K.axpy(scale, K1, structure=PETSc.Mat.Structure.DIFFERENT_NONZERO_PATTERN)
        rises.append(solve_real_modes(K, ops.M, 6, 0.0).omega2)
    w0 = solve_real_modes(ops.K, ops.M, 6, 0.0).omega2
    d1, d2 = rises[0] - w0, rises[1] - w0
    assert np.all(d1 > 0)                                   # tension stiffens every mode
    # (Δω² at 2Ω) / (Δω² at Ω) = 4 + O(Ω²): the second-order term is below 1 % at these speeds
    assert np.all(np.abs(d2 / d1 / 4 - 1) < 1e-2)


@pytest.mark.parametrize("gyroscopic", [False, True])
def test_operating_operators_off_and_on(gyroscopic):
    """Both keys off: the CEA's K and C are those of before (existing scenes keep their numbers);
    stress stiffening without any load or speed adds nothing."""
    from fem_squeal.fe.assembly import operating_operators

    md, spec, ops = disc(True)
    K, C, info = operating_operators(ops, md, spec)
    assert K is ops.K and C is ops.C and info == {}
    K, C, info = operating_operators(ops, md, spec, speed=200.0, gyroscopic=gyroscopic, stress_stiffening=True)
    assert ("geometric_stiffness_norm" in info) == gyroscopic   # no load: σ₀ only from the spin
    assert (C is not None) == gyroscopic
