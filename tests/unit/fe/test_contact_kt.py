"""Tangential penalty k_t of contacts and rigid plates (``interfaces.<name>.kt``).

In the sliding state k_t acts across the sliding direction only, along t₂ = n × s (n = ±e_z on the
flat faces used here, s = e_θ): so, with δ a uniform relative displacement,

* a rigid rotation about the axis (a slip along s everywhere) does no work: W = 0;
* a normal displacement does no work on k_t (that is k_n's);
* translations along x and along y do W_x + W_y = k_t A δ², since (e_x·t₂)² + (e_y·t₂)² = 1
  at every point (t₂ ⊥ e_z is a unit in-plane vector); with sliding = 0 (stick) each does k_t A δ².

These are pointwise identities at the quadrature points, so they hold to round-off (1e-12).
"""
from __future__ import annotations

import functools

import numpy as np
import pytest
from dolfinx import fem
from mpi4py import MPI
from petsc4py import PETSc
from support.blocks import CONTACT_AREA, UPPER, two_blocks
from support.ring import ring_mesh

from fem_squeal.fe.assembly import assemble_operators, contact_matrices, linearise
from fem_squeal.fe.model import GroundSpring, Interface, Material, ModelSpec, Pressure, RigidPlate

COMM = MPI.COMM_WORLD
RT = 1e-12
KT, DELTA = 3.0e9, 1.0e-6


def vec(V, f, part_cells=None) -> PETSc.Vec:
    """PETSc vector of the field f (only on the cells ``part_cells`` if given; 0 elsewhere)."""
    u = fem.Function(V)
    if part_cells is None:
        u.interpolate(f)
    else:
        u.interpolate(f, part_cells)
    x = PETSc.Vec().createMPI((V.dofmap.index_map.size_local * 3, None), comm=V.mesh.comm)
    x.array[:] = u.x.array[: x.getLocalSize()]
    return x


def work(A: PETSc.Mat, x: PETSc.Vec) -> float:
    y = A.createVecLeft()
    A.mult(x, y)
    return x.dot(y)


def translation(d):
    return lambda x: np.outer(np.asarray(d, float) * DELTA, np.ones(x.shape[1]))


def rotation(x):   # rigid rotation about the z axis, DELTA at r = 1: a slip along e_θ everywhere
    return DELTA * np.vstack([-x[1], x[0], 0.0 * x[0]])


# ------------------------------------------------------------------ rigid plates (UFL facet forms)
@functools.cache
def ring_kt(sliding: int, kt: float):
    md = ring_mesh(mesh_size=0.004)
    plates = tuple(RigidPlate(f, 1e10, 0.3, sliding, kt) for f in ("top", "bottom"))
    return md, assemble_operators(md, ModelSpec({"disc": Material(3e9, 0.4, 1400.0)}, plates))


def plate_area(md) -> float:
    import ufl
    ds = ufl.Measure("ds", domain=md.mesh, subdomain_data=md.facet_tags)
    a = fem.form(1.0 * (ds(md.faces["top"]) + ds(md.faces["bottom"])))
    return md.mesh.comm.allreduce(fem.assemble_scalar(a), op=MPI.SUM)


def plate_kt_matrix(sliding: int) -> tuple:
    md, ops = ring_kt(sliding, KT)
    _, ops0 = ring_kt(sliding, 0.0)
    A = ops.K.copy()
    A.axpy(-1.0, ops0.K, structure=PETSc.Mat.Structure.DIFFERENT_NONZERO_PATTERN)
    return md, ops, ops0, A


@pytest.mark.parametrize("sliding", [1, -1])
def test_plate_kt_does_no_work_along_the_sliding_direction(sliding):
    md, ops, ops0, A = plate_kt_matrix(sliding)
    scale = KT * plate_area(md) * DELTA ** 2
    assert abs(work(A, vec(ops.V, rotation))) <= RT * scale
    assert abs(work(A, vec(ops.V, translation((0, 0, 1))))) <= RT * scale
    wx, wy = (work(A, vec(ops.V, translation(d))) for d in ((1, 0, 0), (0, 1, 0)))
    assert wx + wy == pytest.approx(scale, rel=RT)
    assert wx == pytest.approx(0.5 * scale, rel=2e-2)     # ∫ cos²θ dA = A/2 on the (meshed) ring
    # μ-independent and symmetric: K_f is untouched, A = Aᵀ
    F = ops.Kf.copy()
    F.axpy(-1.0, ops0.Kf, structure=PETSc.Mat.Structure.DIFFERENT_NONZERO_PATTERN)
    assert F.norm() == 0.0
    assert A.isSymmetric(RT * A.norm())


def test_plate_kt_sticking_acts_on_the_whole_tangent_plane():
    md, ops, _, A = plate_kt_matrix(0)
    scale = KT * plate_area(md) * DELTA ** 2
    assert work(A, vec(ops.V, translation((1, 0, 0)))) == pytest.approx(scale, rel=RT)
    assert work(A, vec(ops.V, translation((0, 1, 0)))) == pytest.approx(scale, rel=RT)
    assert abs(work(A, vec(ops.V, translation((0, 0, 1))))) <= RT * scale


def test_plate_kt_zero_is_the_seed_model():
    """kt = 0 assembles the very same K as before (no term is added)."""
    md, ops = ring_kt(1, 0.0)
    plates = tuple(RigidPlate(f, 1e10, 0.3, 1) for f in ("top", "bottom"))
    ref = assemble_operators(md, ModelSpec({"disc": Material(3e9, 0.4, 1400.0)}, plates))
    D = ops.K.copy()
    D.axpy(-1.0, ref.K, structure=PETSc.Mat.Structure.DIFFERENT_NONZERO_PATTERN)
    assert D.norm() == 0.0


def test_plate_kt_raises_the_in_plane_frequencies():
    """The plates' k_t (across e_θ: radial) stiffens the in-plane (radial) ring modes."""
    from fem_squeal.fe.eigen import solve_real_modes

    f = []
    for kt in (0.0, 1e9):
        _, ops = ring_kt(0, kt) if kt == 0 else ring_kt(1, kt)
        rm = solve_real_modes(ops.K, ops.M, 8, 500.0)
        f.append(rm.freqs_hz)
    # rigid-body modes (|f| < 1e-2 Hz: round-off of ω² ≈ 0, of either sign) count as 0 Hz
    f = [np.where(np.abs(x) < 1e-2, 0.0, x) for x in f]
    assert np.all(f[1] >= f[0] * (1 - 1e-9)) and np.max(f[1][f[0] > 0] / f[0][f[0] > 0]) > 1.01


# ------------------------------------------------------------------ deformable contact (operator G)
def blocks_spec(kt: float, sliding: int = 1, mu: float = 0.3) -> ModelSpec:
    return ModelSpec({"lower": Material(2e10, 0.3, 7000.0), "upper": Material(5e9, 0.25, 2500.0)},
                     clamped=("lower_bottom",),
                     interfaces=(Interface("pad", "slave", "master", "contact", kn=1e12, kt=kt, mu=mu,
                                           sliding=sliding),),
                     ground_springs=(GroundSpring("upper_sides", 0.0, 1e9),),
                     pressures=(Pressure("upper_top", 1.0e6),))


@functools.cache
def blocks(kt: float, sliding: int = 1):
    md = two_blocks(COMM)
    return md, assemble_operators(md, blocks_spec(kt, sliding))


def contact_kt_matrix(sliding: int):
    md, ops = blocks(KT, sliding)
    _, ops0 = blocks(0.0, sliding)
    Kc, Kf = contact_matrices(ops)
    Kc0, Kf0 = contact_matrices(ops0)
    Kc.axpy(-1.0, Kc0, structure=PETSc.Mat.Structure.DIFFERENT_NONZERO_PATTERN)
    if Kf is not None:
        Kf.axpy(-1.0, Kf0, structure=PETSc.Mat.Structure.DIFFERENT_NONZERO_PATTERN)
    return md, ops, Kc, Kf


def upper_cells(md):
    return md.cell_tags.indices[md.cell_tags.values == 2]


def test_contact_kt_does_no_work_for_a_slip_along_s_and_kt_A_delta2_across():
    md, ops, A, F = contact_kt_matrix(1)
    assert F.norm() == 0.0                     # μ-independent: nothing goes to K_f
    scale = KT * CONTACT_AREA * DELTA ** 2
    up = upper_cells(md)
    # the pad turns about the disc axis (relative slip along e_θ = s at every slave point)
    assert abs(work(A, vec(ops.V, rotation, up))) <= RT * scale
    assert abs(work(A, vec(ops.V, translation((0, 0, 1)), up))) <= RT * scale
    wx, wy = (work(A, vec(ops.V, translation(d), up)) for d in ((1, 0, 0), (0, 1, 0)))
    assert wx + wy == pytest.approx(scale, rel=RT)
    # t₂ = e_z × e_θ = −e_r: W_x = k_t δ² ∫ x²/r² dA (t₁ would give ∫ y²/r² dA: 0.44 vs 0.56 of A)
    from scipy.integrate import dblquad
    x0, y0, _, dx, dy, _ = UPPER
    ref, _ = dblquad(lambda y, x: x * x / (x * x + y * y), x0, x0 + dx, y0, y0 + dy, epsabs=1e-13, epsrel=1e-13)
    assert wx == pytest.approx(KT * DELTA ** 2 * ref, rel=1e-5)   # degree-4 rule on a rational integrand
    assert A.isSymmetric(RT * A.norm())


def test_contact_kt_sticking_acts_on_both_tangents():
    md, ops, A, _ = contact_kt_matrix(0)
    scale = KT * CONTACT_AREA * DELTA ** 2
    up = upper_cells(md)
    for d in ((1, 0, 0), (0, 1, 0)):
        assert work(A, vec(ops.V, translation(d), up)) == pytest.approx(scale, rel=RT)
    assert abs(work(A, vec(ops.V, translation((0, 0, 1)), up))) <= RT * scale


def test_contact_kt_acts_on_closed_points_only():
    """Open points (dσ/dg = 0) carry neither k_n nor k_t."""
    md, ops = blocks(KT, 1)
    op = ops.contacts[0][1]
    Kc, _ = contact_matrices(ops, {"pad": np.zeros(len(op.weight))})
    assert Kc.norm() == 0.0


@functools.cache
def preloaded(kt: float):
    from fem_squeal.fe.preload import solve_preload
    md = two_blocks(COMM)
    # an oblique pressure load would need a traction; a sideways ground spring offset is simpler:
    # the in-plane friction drag μp along e_θ loads the pad sideways, so t₂ sees a displacement too
    ops = assemble_operators(md, blocks_spec(kt))
    return ops, solve_preload(ops)


@pytest.mark.parametrize("kt", [0.0, KT])
def test_preload_with_kt_is_reproduced_by_the_linearised_operator(kt):
    """The preload residual and Jacobian carry the same k_t term: (K + K_c(a) + K_f(a)) u_s = f."""
    ops, pre = preloaded(kt)
    lin = linearise(ops, pre.active)
    r = lin.K_total().createVecLeft()
    lin.K_total().mult(pre.u, r)
    r.axpy(-1.0, ops.f)
    assert r.norm() <= 1e-9 * ops.f.norm()
    assert pre.iterations <= 3


def test_preload_kt_resists_the_sideways_displacement():
    """The friction drag pulls the pad along e_θ; k_t resists only the part of its motion across e_θ."""
    ops0, p0 = preloaded(0.0)
    ops1, p1 = preloaded(KT)
    op0, op1 = ops0.contacts[0][1], ops1.contacts[0][1]

    def rel(op, u, G):
        v = G.createVecLeft()
        G.mult(u, v)
        return COMM.allreduce(float(op.weight @ v.array ** 2), op=MPI.SUM)

    t2_0, t2_1 = rel(op0, p0.u, op0.Gt2), rel(op1, p1.u, op1.Gt2)
    assert t2_1 < 0.5 * t2_0
    assert p1.normal_force["pad"] == pytest.approx(p0.normal_force["pad"], rel=1e-6)


# ------------------------------------------------------------------ 1 rank against 2 ranks
def signature() -> dict:
    """Numbers that must not depend on the partition: of a ring between k_t plates held in x and y on
    its inner face, the energies xᵀKx, xᵀK_f x of a fixed smooth field and the real modes of K
    (symmetric: well-conditioned eigenvalues); of the two blocks with a k_t contact, the preload and
    the CEA.  (The ring's flutter eigenvalues are not compared: a Ryzhik quadruple sits next to a
    double eigenvalue, where the eigensolver's tolerance 1e-10 moves λ by ~1e-5 relative from one
    partition to another; the seed model does the same without k_t.)"""
    from fem_squeal.fe.eigen import solve_complex_modes, solve_real_modes
    from fem_squeal.fe.model import FixedFace

    # mesh_size 0.004 (> the thickness) is not used here: gmsh 4.8 meshes that ring differently from
    # one run to the next (3317 to 3328 nodes for the same 1457 cells), 0.003 is reproducible
    md = ring_mesh(mesh_size=0.003)
    plates = tuple(RigidPlate(f, 1e10, 0.3, 1, 1e9) for f in ("top", "bottom"))
    ops = assemble_operators(md, ModelSpec({"disc": Material(3e9, 0.4, 1400.0)}, plates,
                                           fixed=(FixedFace("inner", ("x", "y")),)))
    x = vec(ops.V, lambda p: np.vstack([np.sin(40 * p[0]), np.cos(30 * p[1]), 100 * p[0] * p[2]]))
    rm_ring = solve_real_modes(ops.K, ops.M, 8, 9000.0)
    bops, pre = preloaded(KT)
    lin = linearise(bops, pre.active)
    rm = solve_real_modes(linearise(bops, pre.active, friction=False).K, bops.M, 6, 100.0)
    cb = solve_complex_modes(lin.K_total(), bops.M, None, 6, 100.0)
    lam = cb.eigenvalues
    return {"ring_xKx": work(ops.K, x), "ring_xKfx": work(ops.Kf, x), "ring_w2": rm_ring.omega2.tolist(),
            "normal_force": pre.normal_force["pad"], "u_norm": pre.u.norm(),
            "blocks_w2": rm.omega2.tolist(), "blocks_re": lam.real.tolist(), "blocks_im": lam.imag.tolist()}


def _close(a, b, rel):
    a, b = np.asarray(a, float), np.asarray(b, float)
    return a.shape == b.shape and np.all(np.abs(a - b) <= rel * np.maximum(np.abs(b), 1e-300))


@pytest.mark.mpi
def test_two_ranks_give_the_same_numbers(mpirun, tmp_path):
    from support.ranks import assert_same_spectrum, two_rank_signature

    if COMM.size > 1:
        pytest.skip("compares a serial run with an mpirun -n 2 child")
    par, ser = two_rank_signature(mpirun, "test_contact_kt", tmp_path / "sig.json"), signature()
    for key in ("ring_xKx", "ring_xKfx", "ring_w2", "blocks_w2"):
        assert _close(par[key], ser[key], 1e-8), key
    assert _close(par["normal_force"], ser["normal_force"], 1e-8) and _close(par["u_norm"], ser["u_norm"], 1e-8)
    assert _close(par["blocks_w2"], ser["blocks_w2"], 1e-8)
    assert_same_spectrum(ser, par, "blocks_", 1e-8)     # every eigenvalue has its twin within 1e-8 |λ|


# ------------------------------------------------------------------ reduced model and MASA
def test_reduced_model_and_masa_keep_kt():
    """k_t is μ-independent: the reduction puts it in K₀ (Φᵀ K_t Φ, not in K_f1), and MASA takes only
    the normal penalty and its friction out of K, so its tangent at the static equilibrium (p = 0)
    is the reduced K(μ) with k_t (the preload displacement is in the basis: exact to the Newton
    tolerance)."""
    from fem_squeal.fe import interface as itf
    from fem_squeal.fe.assembly import _owned_global_rows
    from fem_squeal.fe.projection import ParametricOperators, build_basis, project, reduce
    from fem_squeal.reduced import masa

    ops, pre = preloaded(KT)
    lin = linearise(ops, pre.active)
    par = ParametricOperators(lin, blocks_spec(KT), 0.3)
    basis = build_basis(lin, par, 3000.0, extra=pre.u.array_r.copy()[:, None], n_start=10)
    rm = reduce(lin, par, basis, pre)
    # K₀ = Φᵀ (K + K_c + K_t) Φ with K_t = G_t₂ᵀ diag(k_t w χ) G_t₂ on the closed points
    (it, op), = ops.contacts
    closed = pre.active[it.name].astype(float)
    bc_rows = _owned_global_rows(ops.K, ops.V, ops.bc_dofs)
    K = ops.K.copy()
    for A in (itf.contact_stiffness(op, it.kn * closed), itf.tangential_stiffness(op, it.kt * closed)):
        A.zeroRowsColumns(bc_rows, diag=0.0)
        K.axpy(1.0, A, structure=PETSc.Mat.Structure.DIFFERENT_NONZERO_PATTERN)
    K0 = project(K, basis.Phi)
    assert np.max(np.abs(rm.K0 - K0)) <= 1e-9 * np.max(np.abs(K0))
    mm = masa.from_reduced(rm)
    K_masa, _ = masa.linearise(mm, masa.static_equilibrium(mm, rm.q_static))
    K_red = rm.matrices()[0][0]
    assert np.max(np.abs(K_masa - K_red)) <= 1e-7 * np.max(np.abs(K_red))
