"""Component-wise Dirichlet conditions (``[boundary.fixed.<name>]``, face and components).

A free ring whose bottom face (z = 0 plane, a full annulus) is held in some global components keeps
the rigid motions u = a + ω × x with those components zero on the face:
x only: a_x = ω_z = 0 → 4 rigid-body modes (a_y, a_z, ω_x, ω_y); x and y: a_z, ω_x, ω_y → 3;
z only: a_x, a_y, ω_z → 3; clamped (x, y, z): 0.
"""
from __future__ import annotations

import functools

import numpy as np
import pytest
from dolfinx import fem
from mpi4py import MPI
from petsc4py import PETSc

from fem_squeal.app.scene import SceneError, load_scene, model_spec
from fem_squeal.fe.assembly import assemble_operators
from fem_squeal.fe.eigen import solve_real_modes
from fem_squeal.fe.model import FixedFace, Material, ModelSpec
from fem_squeal.util.errors import ModelError

COMM = MPI.COMM_WORLD
MAT = {"disc": Material(3e9, 0.4, 1400.0)}


@functools.cache
def mesh():
    from support.ring import ring_mesh
    return ring_mesh(mesh_size=0.004)


@functools.cache
def ops_for(components: tuple[str, ...] | None, clamped: bool = False):
    fixed = () if components is None else (FixedFace("bottom", components),)
    return assemble_operators(mesh(), ModelSpec(MAT, clamped=("bottom",) if clamped else (), fixed=fixed))


def face_blocks(V) -> np.ndarray:
    md = mesh()
    facets = md.facet_tags.indices[md.facet_tags.values == md.faces["bottom"]]
    return fem.locate_dofs_topological(V, 2, facets)


@pytest.mark.parametrize("components", [("x",), ("y", "x"), ("z",), ("x", "y", "z")])
def test_fixed_components_are_exactly_the_named_ones(components):
    ops = ops_for(components)
    idx = sorted("xyz".index(c) for c in components)
    blocks = face_blocks(ops.V)
    expect = np.sort((blocks[:, None] * 3 + np.array(idx)[None, :]).ravel())
    assert np.array_equal(ops.bc_dofs, expect)
    # rows of M are zero exactly there (M is SPD elsewhere: a positive diagonal), K has 1 on the diagonal
    lo, hi = ops.M.getOwnershipRange()
    n_owned = hi - lo
    dM, dK = ops.M.getDiagonal().array, ops.K.getDiagonal().array
    held = np.zeros(n_owned, bool)
    held[ops.bc_dofs[ops.bc_dofs < n_owned]] = True
    assert np.all(dM[held] == 0.0) and np.all(dM[~held] > 0.0)
    assert np.all(dK[held] == 1.0)
    rows_zero = COMM.allreduce(int(np.sum(held)), op=MPI.SUM)
    assert rows_zero == COMM.allreduce(len(np.unique(blocks[blocks < n_owned // 3])), op=MPI.SUM) * len(idx)
    # the other components of the same nodes are free: their rows of M are not zero
    free = np.setdiff1d(np.arange(3), idx)
    if free.size:
        other = (blocks[:, None] * 3 + free[None, :]).ravel()
        assert np.all(dM[other[other < n_owned]] > 0.0)


def rigid_body_modes(ops) -> int:
    rm = solve_real_modes(ops.K, ops.M, 10, 20.0)
    return int(np.sum(rm.freqs_hz < 1.0))


@pytest.mark.parametrize("components, n_rigid", [(None, 6), (("x",), 4), (("x", "y"), 3), (("z",), 3),
                                                 (("x", "y", "z"), 0)])
def test_rigid_body_modes_left_by_the_fixed_components(components, n_rigid):
    assert rigid_body_modes(ops_for(components)) == n_rigid


def test_fixed_in_x_y_z_equals_clamped():
    a, b = ops_for(("x", "y", "z")), ops_for(None, clamped=True)
    assert np.array_equal(a.bc_dofs, b.bc_dofs)
    for A, B in ((a.K, b.K), (a.M, b.M)):
        D = A.copy()
        D.axpy(-1.0, B, structure=PETSc.Mat.Structure.DIFFERENT_NONZERO_PATTERN)
        assert D.norm() == 0.0


def test_model_spec_rejects_a_face_fixed_twice():
    with pytest.raises(ModelError, match="'bottom'"):
        ModelSpec(MAT, clamped=("bottom",), fixed=(FixedFace("bottom", ("x",)),))
    with pytest.raises(ModelError, match="'bottom'"):
        ModelSpec(MAT, fixed=(FixedFace("bottom", ("x", "y")), FixedFace("bottom", ("y", "z"))))
    ModelSpec(MAT, fixed=(FixedFace("bottom", ("x",)), FixedFace("bottom", ("z",))))   # disjoint: fine
    with pytest.raises(ModelError, match="components"):
        FixedFace("bottom", ("w",))


# ------------------------------------------------------------------ scene keys and their errors
from support.paths import ROOT  # noqa: E402

SCENE = ROOT / "scenes" / "ryzhik_ring.toml"


def test_scene_fixed_and_kt_reach_the_model_spec():
    s = load_scene(SCENE, ['boundary.fixed.backs={face = "inner", components = ["x", "y"]}',
                           "interfaces.top_plate.kt=1e9"])
    spec = model_spec(s)
    assert spec.fixed == (FixedFace("inner", ("x", "y")),)
    assert {p.face: p.kt for p in spec.plates} == {"top": 1e9, "bottom": 0.0}
    assert model_spec(load_scene(SCENE)).fixed == ()


@pytest.mark.parametrize("override, message", [
    ("interfaces.top_plate.kt=-1.0", r"^interfaces\.top_plate\.kt: must be >= 0 \(got -1\.0\)$"),
    ('boundary.fixed.backs={face = "inner", components = ["x", "w"]}', r"^boundary\.fixed\.backs\.components: "),
    ('boundary.fixed.backs={face = "inner", components = []}', r"^boundary\.fixed\.backs\.components: "),
    ('boundary.fixed.backs={face = "inner", components = ["x", "x"]}', r"^boundary\.fixed\.backs\.components: "),
    ('boundary.fixed.backs={face = "rim", components = ["x"]}',
     r"^boundary\.fixed\.backs\.face: unknown face 'rim'"),
    ('boundary.fixed.backs={face = "inner"}', r"^boundary\.fixed\.backs\.components: required"),
    ('boundary.fixed.backs={face = "inner", components = ["z"], k = 1}',
     r"^boundary\.fixed\.backs\.k: unknown key"),
    ("boundary.fixed.backs=3", r"^boundary\.fixed\.backs: must be a table"),
])
def test_bad_fixed_and_kt_values_name_the_key(override, message):
    with pytest.raises(SceneError, match=message):
        load_scene(SCENE, [override])


def test_a_face_fixed_twice_is_named():
    with pytest.raises(SceneError, match=r"^boundary\.fixed\.a: face 'inner' has \['x'\] fixed already in "
                                         r"boundary\.clamped"):
        load_scene(SCENE, ["boundary.clamped=['inner']", 'boundary.fixed.a={face = "inner", components = ["x"]}'])
    with pytest.raises(SceneError, match=r"^boundary\.fixed\.b: face 'inner' has \['y'\] fixed already in "
                                         r"boundary\.fixed\.a"):
        load_scene(SCENE, ['boundary.fixed.a={face = "inner", components = ["x", "y"]}',
                           'boundary.fixed.b={face = "inner", components = ["y", "z"]}'])
    with pytest.raises(SceneError, match=r"^boundary\.clamped: face 'inner' listed twice"):
        load_scene(SCENE, ["boundary.clamped=['inner', 'inner']"])
    s = load_scene(SCENE, ['boundary.fixed.a={face = "inner", components = ["x"]}',
                           'boundary.fixed.b={face = "inner", components = ["z"]}'])
    assert len(model_spec(s).fixed) == 2


def test_real_modes_far_from_the_target_meet_the_residual_bound():
    """Clamped on all three components, the block's modes lie near 46 kHz, far above a 20 Hz target:
    SLEPc's criterion (relative to the shift-inverted value 1/(λ − σ)) passes pairs whose residual
    ‖Kx − λMx‖/(‖K‖‖x‖) is ~1e-8 (the CI failure of 2026-11-23: 1.2e-8 against the 1e-8 bound).
    Asking for 1e-10 forces the continuation at the tighter tolerance on the same factorisation;
    its pairs must meet the bound and the frequencies agree with the first pass to the square of the
    first pass's residual (≤ 1e-12 relative, symmetric pencil)."""
    ops = ops_for(("x", "y", "z"))
    loose = solve_real_modes(ops.K, ops.M, 10, 20.0, max_residual=1e-7)
    tight = solve_real_modes(ops.K, ops.M, 10, 20.0, max_residual=1e-10)
    assert np.all(tight.residuals <= 1e-10)
    assert np.allclose(tight.freqs_hz, loose.freqs_hz, rtol=1e-10, atol=0.0)
