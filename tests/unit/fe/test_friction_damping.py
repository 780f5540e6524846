"""Friction-induced damping (``interfaces.<name>.friction_damping``, Abaqus FRICTION DAMPING=YES).

About a sliding state at speed V the friction force F = −μ(|v_rel|) p v_rel/|v_rel| gains velocity
terms: C = p μ/V t₂t₂ᵀ + p dμ/dV ssᵀ per unit area (derivation: fem_squeal.fe.preload.friction_damping).
Checked here: C against a central finite difference of the friction force itself (contact operator and
plate form), the sign of the eigenvalue shift (a constant μ damps, a falling μ(V) destabilises), the seed
scenes untouched when the keys are absent, the reduced model against the full CEA, 1 vs 2 ranks and the
named scene errors.
"""
from __future__ import annotations

import copy
import functools

import numpy as np
import pytest
from dolfinx import fem
from mpi4py import MPI
from petsc4py import PETSc
from support.blocks import two_blocks
from support.paths import ROOT
from support.ring import ring_mesh

from fem_squeal.fe.assembly import assemble_operators, linearise
from fem_squeal.fe.model import (
    FixedFace,
    GroundSpring,
    Interface,
    Material,
    ModelSpec,
    Pressure,
    RigidPlate,
    sliding_speed,
    speed_friction,
)
from fem_squeal.reduced.laws.friction import StribeckFriction
from fem_squeal.util.errors import SceneError

COMM = MPI.COMM_WORLD
OMEGA = 1.0            # rad/s: the block contact lies at r = 0.14 .. 1.06 m, so V = 0.14 .. 1.06 m/s
FALLING = StribeckFriction(mu_s=0.5, mu_d=0.3, v_s=0.1, v_d=1.5)   # falling branch over the whole pad


def vec(V, f) -> PETSc.Vec:
    u = fem.Function(V)
    u.interpolate(f)
    x = PETSc.Vec().createMPI((V.dofmap.index_map.size_local * 3, None), comm=V.mesh.comm)
    x.array[:] = u.x.array[: x.getLocalSize()]
    return x


def smooth(p):     # a smooth velocity field with every component and no symmetry
    return np.vstack([np.sin(3 * p[0] + 1) + p[2], np.cos(2 * p[1]) - p[0] * p[2], 0.5 * p[0] * p[1] + p[2]])


def blocks_spec(law=None, friction_damping: bool = True, mu: float = 0.3) -> ModelSpec:
    return ModelSpec({"lower": Material(2e10, 0.3, 7000.0), "upper": Material(5e9, 0.25, 2500.0)},
                     clamped=("lower_bottom",),
                     interfaces=(Interface("pad", "slave", "master", "contact", kn=1e12, mu=mu, sliding=1,
                                           friction_damping=friction_damping, law=law, speed=OMEGA),),
                     ground_springs=(GroundSpring("upper_sides", 0.0, 1e9),),
                     pressures=(Pressure("upper_top", 1.0e6),))


@functools.cache
def preloaded(law=None, friction_damping: bool = True):
    from fem_squeal.fe.preload import friction_damping as damping
    from fem_squeal.fe.preload import solve_preload

    md = two_blocks(COMM)
    spec = blocks_spec(law, friction_damping, mu=0.3 if law is None else float(law.mu_d))
    ops = assemble_operators(md, spec)
    pre = solve_preload(ops)
    lin = linearise(ops, pre.active)
    return md, spec, ops, pre, lin, damping(ops, md, spec, pre.u, pre.pressure)


# ------------------------------------------------------------------ C against a finite difference
def contact_friction_force(op, it, p, xdot: PETSc.Vec) -> PETSc.Vec:
    """Σ_q w_q (G_t₁ᵀ F_t₁ + G_t₂ᵀ F_t₂) with F = −μ(|v|) p v/|v|, v = (G_t₁ẋ − V) t₁ + (G_t₂ẋ) t₂ the
    slave's velocity relative to the master (the full nonlinear force, not its linearisation)."""
    a, b = op.Gt1.createVecLeft(), op.Gt2.createVecLeft()
    op.Gt1.mult(xdot, a)
    op.Gt2.mult(xdot, b)
    V = sliding_speed(op.x, it.speed)
    w = np.column_stack([a.array - V, b.array])
    if it.law is None:
        F = -it.mu * p[:, None] * w / np.linalg.norm(w, axis=1)[:, None]
    else:     # the transient's own evaluation of the law (its sign convention: f opposes the slip w)
        F = it.law.evaluate(p, w, -w, None, None)[0]
    out = xdot.duplicate()
    out.set(0.0)
    for G, Fi, tmp in ((op.Gt1, F[:, 0], a), (op.Gt2, F[:, 1], b)):
        tmp.array[:] = op.weight * Fi
        G.multTransposeAdd(tmp, out, out)
    return out


@pytest.mark.parametrize("law", [None, FALLING], ids=["constant", "stribeck"])
def test_contact_damping_is_the_derivative_of_the_friction_force(law):
    from fem_squeal.fe.interface import friction_damping_matrix

    md, spec, ops, pre, lin, _ = preloaded(law)
    (it, op), = ops.contacts
    p = pre.pressure["pad"]
    V = sliding_speed(op.x, it.speed)
    C = friction_damping_matrix(op, p, *speed_friction(it.mu, it.law, V), V)
    xdot = vec(ops.V, smooth)
    xdot.scale(1e-3 / xdot.norm(PETSc.NormType.INFINITY))     # |G ẋ| ≪ V = 0.14 .. 1.06 m/s
    eps = 1.0
    fp = contact_friction_force(op, it, p, xdot)
    xm = xdot.copy()
    xm.scale(-1.0)
    fm = contact_friction_force(op, it, p, xm)
    fd = fp.copy()
    fd.axpy(-1.0, fm)
    fd.scale(-0.5 / eps)                     # −∂F/∂ẋ · ẋ: the force moved to the left-hand side
    Cx = C.createVecLeft()
    C.mult(xdot, Cx)
    err = fd.copy()
    err.axpy(-1.0, Cx)
    # central difference: error O(|Gẋ|²/V²) ≈ 1e-3²/0.14² = 5e-5 relative at the innermost points
    assert err.norm() <= 1e-4 * Cx.norm()
    assert Cx.norm() > 0
    if law is None:
        assert C.isSymmetric(1e-12 * C.norm())         # p μ/V t₂t₂ᵀ: symmetric positive semidefinite
        assert xdot.dot(Cx) > 0


def test_law_jacobian_of_the_transient_agrees():
    """−p ∂f/∂w of StribeckFriction.evaluate at the sliding state is diag(p μ', p μ/V) in (s, t₂)."""
    V = np.array([0.05, 0.3, 0.9, 2.0])
    p = np.array([1.0, 2.0, 3.0, 4.0])
    w = np.column_stack([-V, 0 * V])               # the structure slides backwards relative to the disc
    J = FALLING.evaluate(p, w, -w, None, None)[3]
    mu, dmu = speed_friction(0.0, FALLING, V)
    assert np.allclose(-J[:, 0, 0], p * dmu, rtol=1e-13, atol=0)
    assert np.allclose(-J[:, 1, 1], p * mu / V, rtol=1e-13, atol=0)
    assert np.all(J[:, 0, 1] == 0) and np.any(dmu < 0) and np.any(dmu > 0)


def plate_model(law=None):
    md = ring_mesh(mesh_size=0.004)
    plates = (RigidPlate("bottom", 1e10, 0.3 if law is None else float(law.mu_d), 1, friction_damping=True,
                         law=law, speed=20.0),)
    spec = ModelSpec({"disc": Material(3e9, 0.4, 1400.0)}, plates, fixed=(FixedFace("inner", ("x", "y")),),
                     pressures=(Pressure("top", 1e5),))
    return md, spec, assemble_operators(md, spec)


def test_plate_damping_is_the_derivative_of_the_friction_force():
    """Plate form against a central difference of ∫ F(u̇)·v ds, F = −μ p w/|w|, w = u̇_τ − V s (UFL)."""
    import ufl

    from fem_squeal.fe.forms import circumferential_direction
    from fem_squeal.fe.preload import friction_damping, static_displacement

    md, spec, ops = plate_model()
    u = static_displacement(ops)
    C = friction_damping(ops, md, spec, u, None)
    pl = spec.plates[0]
    Vh = ops.V
    uh, vdot = fem.Function(Vh), fem.Function(Vh)
    uh.x.array[: u.getLocalSize()] = u.array_r
    uh.x.scatter_forward()
    v = ufl.TestFunction(Vh)
    n, x = ufl.FacetNormal(Vh.mesh), ufl.SpatialCoordinate(Vh.mesh)
    ds = ufl.Measure("ds", domain=Vh.mesh, subdomain_data=md.facet_tags, metadata={"quadrature_degree": 8})
    s = circumferential_direction(x, 1.0)
    p = pl.kn * ufl.max_value(ufl.dot(uh, n), 0.0)
    wv = vdot - ufl.dot(vdot, n) * n - pl.speed * ufl.sqrt(x[0] ** 2 + x[1] ** 2) * s
    force = fem.form(-pl.mu * p * ufl.dot(wv, v) / ufl.sqrt(ufl.dot(wv, wv)) * ds(md.faces["bottom"]))
    xdot = vec(Vh, smooth)
    xdot.scale(1e-3 / xdot.norm(PETSc.NormType.INFINITY))     # ≪ V = 20 rad/s · 0.0475 m ≈ 0.95 m/s
    own = ops.bc_dofs[ops.bc_dofs < xdot.getLocalSize()]
    xdot.array[own] = 0.0                        # a velocity the held DOFs (inner face: x, y) can have

    def F(sign):
        vdot.x.array[: xdot.getLocalSize()] = sign * xdot.array_r
        vdot.x.scatter_forward()
        b = fem.petsc.assemble_vector(force)
        b.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
        return b

    import dolfinx.fem.petsc  # noqa: F401  (fem.petsc)
    fd = F(1.0)
    fd.axpy(-1.0, F(-1.0))
    fd.scale(-0.5)
    fd.array[own] = 0.0                          # C_d is zero on the held DOFs (inner face: x, y)
    Cx = C.createVecLeft()
    C.mult(xdot, Cx)
    err = fd.copy()
    err.axpy(-1.0, Cx)
    assert err.norm() <= 1e-5 * Cx.norm()        # O((1e-3/0.95)²) ≈ 1e-6 relative
    assert xdot.dot(Cx) > 0


def test_plate_falling_law_damps_negatively_along_s():
    """A rigid rotation (relative velocity along s only) sees p dμ/dV < 0 from a falling law: negative work."""
    law = StribeckFriction(mu_s=0.5, mu_d=0.3, v_s=0.1, v_d=1.5)
    from fem_squeal.fe.preload import friction_damping, static_displacement

    md, spec, ops = plate_model(law)
    C = friction_damping(ops, md, spec, static_displacement(ops), None)
    rot = vec(ops.V, lambda x: np.vstack([-x[1], x[0], 0 * x[0]]))
    across = vec(ops.V, lambda x: np.vstack([x[0], x[1], 0 * x[0]]))      # radial: along t₂
    for y, sign in ((rot, -1.0), (across, 1.0)):
        Cy = C.createVecLeft()
        C.mult(y, Cy)
        assert sign * y.dot(Cy) > 0


# ------------------------------------------------------------------ eigenvalues: sign of the shift
def damped_eigenvalues(law, n=8):
    from fem_squeal.fe.eigen import solve_complex_modes

    _, _, ops, _, lin, Cd = preloaded(law)
    # PEP on both (C = 0 and C_d), the same target: the same lowest modes
    und = solve_complex_modes(lin.K_total(), ops.M, None, n, 1.0, method="pep")
    dam = solve_complex_modes(lin.K_total(), ops.M, Cd, n, 1.0, method="pep")
    return und.eigenvalues, dam.eigenvalues


@pytest.mark.parametrize("law", [None, FALLING], ids=["constant", "stribeck"])
def test_damping_moves_eigenvalues_left_for_constant_mu_and_right_for_a_falling_law(law):
    """The blocks carry one flutter pair near 640 Hz (Re ±173 /s without C_d).  A constant μ (t₂ term,
    C_d ⪰ 0) moves every mode left: the flutter growth falls, the lowest mode becomes damped.  A
    falling μ(V) (dμ/dV < 0 over the whole pad) moves the flutter growth up and the lowest mode, a
    sliding-direction mode of the pad, to Re > 0: a new instability."""
    und, dam = damped_eigenvalues(law)
    und, dam = und[und.imag > 0], dam[dam.imag > 0]
    lowest = dam[np.argmin(np.abs(dam))]
    scale = 1e-6 * np.max(np.abs(und))           # below it Re λ is eigensolver round-off (tol 1e-10)
    if law is None:
        assert np.max(dam.real) < np.max(und.real) - 1.0
        assert np.sum(dam.real > scale) == np.sum(und.real > scale) == 1
        assert lowest.real < -1.0
    else:
        assert np.max(dam.real) > np.max(und.real) + 1.0
        assert np.sum(dam.real > scale) == np.sum(und.real > scale) + 1
        assert lowest.real > 1.0


# ------------------------------------------------------------------ unchanged without the keys
def test_seed_scenes_build_the_same_model_without_the_new_keys():
    """The seed scenes' model is the very dataclass they built before (no law, no damping, speed 0),
    so every assembled matrix and eigenvalue is unchanged (the code paths test ``law is None``)."""
    from fem_squeal.app.scene import load_scene, model_spec

    spec = model_spec(load_scene(ROOT / "scenes" / "ryzhik_ring.toml"))
    assert spec.plates == (RigidPlate("top", 1e10, 0.3, 1, name="top_plate"),
                           RigidPlate("bottom", 1e10, 0.3, 1, name="bottom_plate"))
    spec = model_spec(load_scene(ROOT / "scenes" / "brake_corner_cea.toml"))
    pads = [i for i in spec.interfaces if i.kind == "contact"]
    assert pads and all(i.law is None and not i.friction_damping and i.speed == 0 for i in pads)


def test_ring_eigenvalues_identical_with_friction_damping_off():
    """A plate with friction_damping = false (and a speed, here unused) assembles the seed operators
    bit for bit: the ring's K_f and its complex eigenvalues are identical."""
    from fem_squeal.fe.eigen import solve_complex_modes

    md = ring_mesh(mesh_size=0.004)
    mat = {"disc": Material(3e9, 0.4, 1400.0)}
    ref = assemble_operators(md, ModelSpec(mat, tuple(RigidPlate(f, 1e10, 0.3, 1) for f in ("top", "bottom"))))
    plates = tuple(RigidPlate(f, 1e10, 0.3, 1, speed=50.0) for f in ("top", "bottom"))
    ops = assemble_operators(md, ModelSpec(mat, plates))
    D = ops.Kf.copy()
    D.axpy(-1.0, ref.Kf, structure=PETSc.Mat.Structure.DIFFERENT_NONZERO_PATTERN)
    assert D.norm() == 0.0
    a = solve_complex_modes(ops.K_total(), ops.M, None, 6, 1500.0).eigenvalues
    b = solve_complex_modes(ref.K_total(), ref.M, None, 6, 1500.0).eigenvalues
    assert np.array_equal(a, b)


# ------------------------------------------------------------------ named errors
def ring_scene(**over):
    raw = {"geometry": {"builder": "annular_disc", "mean_radius": 0.05, "width": 0.005, "thickness": 0.004,
                        "mesh_size": 0.002},
           "materials": {"disc": {"E": 3e9, "nu": 0.4, "rho": 1400}},
           "interfaces": {"bottom_plate": {"type": "rigid_plate", "face": "bottom", "kn": 1e10, "mu": 0.3,
                                           "friction_damping": True}},
           "loads": {"pressure": {"top": {"face": "top", "p": 1e5}}},
           "boundary": {"fixed": {"inner": {"face": "inner", "components": ["x", "y"]}}},
           "operating": {"speed": 20.0},
           "analyses": {"cea": {}}}
    for path, value in over.items():
        node = raw
        keys = path.split("__")
        for k in keys[:-1]:
            node = node[k]
        if value is None:
            del node[keys[-1]]
        else:
            node[keys[-1]] = value
    return raw


def test_valid_scene_builds_the_damped_plate():
    from fem_squeal.app.scene import model_spec, validate

    spec = model_spec(validate(ring_scene()))
    assert spec.plates[0].friction_damping and spec.plates[0].speed == 20.0 and spec.plates[0].law is None
    law = model_spec(validate(ring_scene(interfaces__bottom_plate__friction="stribeck",
                                           interfaces__bottom_plate__mu_s=0.5))).plates[0]
    assert law.law == StribeckFriction(0.5, 0.3, 1e-3, 1e-2) and law.mu == 0.3


@pytest.mark.parametrize("over, message", [
    ({"operating__speed": 0.0},
     "operating.speed: must be > 0 when interfaces.bottom_plate.friction_damping is true"),
    ({"interfaces__bottom_plate__friction_damping": False}, "operating.speed: 20.0 but nothing uses it"),
    ({"interfaces__bottom_plate__sliding": 0}, "interfaces.bottom_plate.friction_damping: needs sliding"),
    ({"interfaces__bottom_plate__mu": 0.0},
     "interfaces.bottom_plate.friction_damping: needs mu > 0 or a μ(V) law"),
    ({"loads__pressure": {}}, "interfaces.bottom_plate.friction_damping: needs loads.pressure"),
    ({"interfaces__bottom_plate__friction": "coulomb"}, "interfaces.bottom_plate.friction: must be one of"),
    ({"interfaces__bottom_plate__friction": "stribeck", "operating__speed": 0.0,
      "interfaces__bottom_plate__friction_damping": False},
     "operating.speed: must be > 0 when interfaces.bottom_plate.friction = 'stribeck'"),
    ({"interfaces__bottom_plate__friction": "stribeck", "interfaces__bottom_plate__v_d": 1e-3},
     "interfaces.bottom_plate.v_d: must be > v_s"),
])
def test_named_scene_errors(over, message):
    from fem_squeal.app.scene import validate

    with pytest.raises(SceneError) as e:
        validate(ring_scene(**over))
    assert message in str(e.value)


def test_contact_friction_damping_needs_the_nonlinear_preload_and_no_transient():
    from fem_squeal.app.scene import validate

    raw = ring_scene()
    raw["interfaces"] = {"pad": {"type": "contact", "slave": "top", "master": "bottom", "kn": 1e12, "mu": 0.3,
                                 "friction_damping": True}}
    bad = copy.deepcopy(raw)
    bad["preload"] = {"mode": "all_closed"}
    with pytest.raises(SceneError, match=r"interfaces.pad.friction_damping: needs preload.mode = 'nonlinear'"):
        validate(bad)
    validate(raw)
    bad = copy.deepcopy(raw)
    bad["analyses"] = {"transient": {}}
    with pytest.raises(SceneError, match=r"interfaces.pad.friction_damping: not with analyses.transient"):
        validate(bad)


def test_preload_with_a_speed_law_is_reproduced_by_the_linearised_operator():
    """The preload's friction residual and the linearised K_f take μ(V) at the same points:
    (K + K_c(a) + K_f(a)) u_s = f to the Newton tolerance; the friction force is ∫ μ(V) p dA."""
    md, spec, ops, pre, lin, _ = preloaded(FALLING)
    r = lin.K_total().createVecLeft()
    lin.K_total().mult(pre.u, r)
    r.axpy(-1.0, ops.f)
    assert r.norm() <= 1e-9 * ops.f.norm()        # the Newton tolerance (1e-9 by default)
    (it, op), = ops.contacts
    mu = it.friction_coefficient(op.x)
    assert np.all((mu > 0.3) & (mu < 0.5))           # on the falling branch between μ_d and μ_s
    ratio = pre.friction_force["pad"] / pre.normal_force["pad"]
    assert 0.3 < ratio < 0.5 and abs(ratio - 0.3) > 1e-3


# ------------------------------------------------------------------ reduced model against the full CEA
@pytest.mark.slow
def test_reduced_model_carries_the_friction_damping():
    """C_d goes into the reduced model as Cd0 = Φᵀ C_d Φ (apart from C₀: it scales with μ and 1/Ω), and
    the basis holds the static corrections (K + σM)⁻¹ C_d Φ (as it holds those of K_f): the reduced
    damped eigenvalues match the full PEP.  Measured at a 2.5 kHz cut (127 modes): 2.6e-5 with the
    corrections (382 vectors), 1.4e-2 without (255): the basis, not the projection, limits it."""
    from fem_squeal.fe.eigen import solve_complex_modes
    from fem_squeal.fe.projection import ParametricOperators, build_basis, project, reduce

    md, spec, ops, pre, lin, Cd = preloaded(FALLING)
    full = solve_complex_modes(lin.K_total(), ops.M, Cd, 8, 1.0, method="pep").eigenvalues
    full = full[full.imag > 0]
    errors = {}
    for with_cd in (True, False):
        lind = lin._replace(C=Cd, Cd=Cd if with_cd else None)
        par = ParametricOperators(lind, spec, spec.interfaces[0].mu)
        basis = build_basis(lind, par, 2500.0, extra=pre.u.array_r.copy()[:, None], n_start=10)
        rm = reduce(lind, par, basis, pre)
        C = rm.Cd0 if with_cd else rm.C0    # C_d apart (it scales with μ and 1/Ω), or in C₀
        assert np.max(np.abs(C - project(Cd, basis.Phi))) <= 1e-12 * np.max(np.abs(C))
        (K,), (C,) = rm.matrices()[0], rm.matrices()[1]
        n = rm.size
        lr = np.linalg.eigvals(np.block([[np.zeros((n, n)), np.eye(n)], [-K, -C]]))
        errors[with_cd] = max(np.min(np.abs(lr - lam)) / abs(lam) for lam in full)
    assert errors[True] < 1e-4 < errors[False]      # 4× and 1/140× margins on the measured values
    assert np.any(full.real > 1.0)   # a friction-damping instability (falling μ) is among the matched


# ------------------------------------------------------------------ 1 rank against 2 ranks
def signature() -> dict:
    """Partition-independent numbers: the blocks with a falling μ(V) and friction damping (preload,
    xᵀC_d x of a fixed smooth field, the damped eigenvalues) and a ring on a damped plate (xᵀC_d x)."""
    from fem_squeal.fe.eigen import solve_complex_modes
    from fem_squeal.fe.preload import friction_damping, static_displacement

    md, spec, ops, pre, lin, Cd = preloaded(FALLING)
    x = vec(ops.V, smooth)
    y = Cd.createVecLeft()
    Cd.mult(x, y)
    lam = solve_complex_modes(lin.K_total(), ops.M, Cd, 6, 1.0, method="pep").eigenvalues
    # mesh_size 0.003: gmsh 4.8 meshes this ring reproducibly (0.004 is not; see test_contact_kt)
    mdr = ring_mesh(mesh_size=0.003)
    plates = (RigidPlate("bottom", 1e10, 0.3, 1, friction_damping=True, speed=20.0),)
    sr = ModelSpec({"disc": Material(3e9, 0.4, 1400.0)}, plates, fixed=(FixedFace("inner", ("x", "y")),),
                   pressures=(Pressure("top", 1e5),))
    opr = assemble_operators(mdr, sr)
    Cr = friction_damping(opr, mdr, sr, static_displacement(opr), None)
    xr = vec(opr.V, smooth)
    yr = Cr.createVecLeft()
    Cr.mult(xr, yr)
    return {"normal_force": pre.normal_force["pad"], "friction_force": pre.friction_force["pad"],
            "xCx": x.dot(y), "ring_xCx": xr.dot(yr), "re": lam.real.tolist(), "im": lam.imag.tolist()}


@pytest.mark.slow     # 26 s (a serial and a 2-rank run of the blocks and the ring)
@pytest.mark.mpi
def test_two_ranks_give_the_same_numbers(mpirun, tmp_path):
    from support.ranks import assert_same_spectrum, two_rank_signature

    if COMM.size > 1:
        pytest.skip("compares a serial run with an mpirun -n 2 child")
    par, ser = two_rank_signature(mpirun, "test_friction_damping", tmp_path / "sig.json"), signature()
    for key in ("normal_force", "friction_force", "xCx", "ring_xCx"):
        assert par[key] == pytest.approx(ser[key], rel=1e-8), key
    assert_same_spectrum(ser, par, "", 1e-8)     # every eigenvalue has its twin within 1e-8 |λ|


# ------------------------------------------------------------------ through the scene and the pipeline
def test_scene_run_adds_the_friction_damping_to_the_cea(tmp_path):
    """A ring pressed on a sliding plate: with friction_damping the CEA solves the damped PEP and the
    in-plane pairs gain damping (the plate's C_d ⪰ 0 for a constant μ); without it they stay undamped."""
    from fem_squeal.app.run import run_scene
    from fem_squeal.app.scene import validate

    quiet = dict(log=lambda *a, **k: None, write_fields=False, report=False)
    res = {}
    for fd in (True, False):
        raw = ring_scene(geometry__mesh_size=0.005, interfaces__bottom_plate__friction_damping=fd,
                           operating__speed=20.0 if fd else 0.0)
        # the in-plane modes of the ring held on its inner face start near 6.7 kHz (flutter pairs ±σ)
        raw["analyses"] = {"cea": {"n_modes": 6, "band_hz": [1.0, 9000.0], "target_hz": 1.0, "method": "pep"}}
        res[fd] = run_scene(validate(raw), tmp_path / str(fd), MPI.COMM_SELF, cache=tmp_path / "cache", **quiet)
    assert res[True]["friction_damping"]["norm"] > 0 and "friction_damping" not in res[False]
    damped = np.array([m["real_part"] for m in res[True]["complex_modes"]])
    free = np.array([m["real_part"] for m in res[False]["complex_modes"]])
    # measured: each mode moves left by 0.007 .. 0.1 /s; the undamped pairs ±σ sum to round-off (1e-5)
    assert len(damped) == len(free) > 0 and np.sum(damped) < np.sum(free) - 0.05
