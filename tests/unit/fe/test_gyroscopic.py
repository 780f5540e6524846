"""The disc's rotation (issue 20 item 4): transport-form gyroscopic and convective matrices, the
rotating-frame Coriolis and spin-softening matrices, the centrifugal load, and the scene keys.

Model: steel annular disc r 0.05–0.15 m, h 0.01 m, P2 curved tetrahedra (mesh size 0.04 m), free or
clamped on its inner cylinder.  Reference integrals: J_z = ∫ρ r² dV = ρ h π (r_o⁴ − r_i⁴)/2.
"""
from __future__ import annotations

import functools

import numpy as np
import pytest
from mpi4py import MPI
from petsc4py import PETSc
from support.operators import bilinear, nodal_vector

from fem_squeal.app.scene import validate
from fem_squeal.util.errors import SceneError

R_I, R_O, H, RHO = 0.05, 0.15, 0.01, 7850.0
J_Z = RHO * H * np.pi * (R_O ** 4 - R_I ** 4) / 2
VOLUME = np.pi * H * (R_O ** 2 - R_I ** 2)


@functools.cache
def disc(clamped: bool):
    from fem_squeal.fe.assembly import assemble_operators, rotation_matrices
    from fem_squeal.fe.model import Material, ModelSpec
    from geometry import annular_disc_mesh

    md = annular_disc_mesh(MPI.COMM_WORLD, mean_radius=0.5 * (R_I + R_O), width=R_O - R_I, thickness=H,
                           mesh_size=0.04, order=2)
    spec = ModelSpec({"disc": Material(2.1e11, 0.3, RHO)}, clamped=("inner",) if clamped else ())
    ops = assemble_operators(md, spec)
    return md, spec, ops, rotation_matrices(ops, md, spec, ["disc"], "fixed"), \
        rotation_matrices(ops, md, spec, ["disc"], "rotating")




def _geometric_tolerance(md) -> float:
    """Relative error of the curved mesh's volume: the tolerance of exact integrals over the disc."""
    import ufl
    from dolfinx import fem

    vol = md.mesh.comm.allreduce(fem.assemble_scalar(fem.form(1.0 * ufl.dx(domain=md.mesh))), op=MPI.SUM)
    return abs(vol / VOLUME - 1)


@pytest.mark.parametrize("clamped", [False, True])
def test_gyroscopic_matrices_are_skew_with_zero_energy(clamped):
    _, _, ops, fixed, rotating = disc(clamped)
    rng = np.random.default_rng(1)
    for G in (fixed.G, rotating.G):
        T = G.copy()
        T.axpy(1.0, G.transpose(PETSc.Mat()), structure=PETSc.Mat.Structure.DIFFERENT_NONZERO_PATTERN)
        # G₁ = ∫ρ[(Lu)·v − u·(Lv)] and 2∫ρ(e_z×u)·v are skew term by term: round-off only
        assert T.norm(PETSc.NormType.INFINITY) <= 1e-14 * G.norm(PETSc.NormType.INFINITY)
        x = ops.K.createVecRight()
        x.array[:] = rng.standard_normal(x.getLocalSize())
        # xᵀGx = 0: the gyroscopic force does no work (round-off of a sum of ~1e4 terms of size ‖G‖‖x‖²/n)
        assert abs(bilinear(G, x, x)) <= 1e-13 * G.norm(PETSc.NormType.INFINITY) * x.norm() ** 2


def test_convective_stiffness_is_symmetric_positive_semidefinite():
    """K_L = ∫ρ (Lu)·(Lv) ≥ 0, so −Ω² K_L (and −Ω² M_r) is symmetric negative semi-definite."""
    from scipy.sparse import csr_matrix

    if MPI.COMM_WORLD.size > 1:
        pytest.skip("dense check on one rank")
    for S in (disc(True)[3].S,):   # K_L (M_r is the mass of the in-plane components: a Gram matrix too)
        ia, ja, a = S.getValuesCSR()
        A = csr_matrix((a, ja, ia), shape=S.getSize()).toarray()
        scale = np.abs(A).max()
        assert np.abs(A - A.T).max() <= 1e-15 * scale       # assembled from a symmetric form: exact
        # Gram matrix: every eigenvalue ≥ −δ, δ = 1e-12‖A‖ (round-off), iff A + δI has a Cholesky factor
        np.linalg.cholesky(A + 1e-12 * scale * np.eye(len(A)))
    # and only semi-definite: a uniform axial field w = e_z has L w = 0, so K_L w = 0 (free disc: no clamped
    # columns removed; round-off)
    _, _, ops, fixed, _ = disc(False)
    ez = nodal_vector(ops, lambda x, y, z: (0 * x, 0 * y, 1 + 0 * z))
    r = fixed.S.createVecLeft()
    fixed.S.mult(ez, r)
    assert r.norm(PETSc.NormType.INFINITY) <= 1e-13 * fixed.S.norm(PETSc.NormType.INFINITY)


def test_rotation_forms_against_closed_forms():
    """Free disc, fields of degree 1 (interpolated exactly): with r = (x, y, 0) and w = e_z × x,
    L r = w and L w = −r, so G₁(r, w) = 2 J_z = G_c(r, w), K_L(w, w) = M_r(w, w) = J_z, f_c(r) = J_z."""
    md, _, ops, fixed, rotating = disc(False)
    r = nodal_vector(ops, lambda x, y, z: (x, y, 0 * z))
    w = nodal_vector(ops, lambda x, y, z: (-y, x, 0 * z))
    tol = 3 * _geometric_tolerance(md) + 1e-12   # exact integrands, curved-mesh volume error only
    assert abs(bilinear(fixed.G, r, w) / (2 * J_Z) - 1) < tol
    assert abs(bilinear(rotating.G, r, w) / (2 * J_Z) - 1) < tol
    assert abs(bilinear(fixed.S, w, w) / J_Z - 1) < tol
    assert abs(bilinear(rotating.S, w, w) / J_Z - 1) < tol
    assert abs(fixed.f.dot(r) / J_Z - 1) < tol
    # an axial field is not softened: M_r(e_z, e_z) = 0 exactly; K_L of a uniform field is 0
    ez = nodal_vector(ops, lambda x, y, z: (0 * x, 0 * y, 1 + 0 * z))
    assert abs(bilinear(rotating.S, ez, ez)) < 1e-12 * J_Z
    assert abs(bilinear(fixed.S, ez, ez)) < 1e-12 * J_Z


def test_zero_speed_reproduces_the_modes_at_rest():
    from fem_squeal.fe.assembly import operating_operators
    from fem_squeal.fe.eigen import solve_complex_modes

    md, spec, ops, _, _ = disc(True)
    K, C, _ = operating_operators(ops, md, spec, speed=0.0, gyroscopic=True, rotating_parts=["disc"])
    D = K.copy()
    D.axpy(-1.0, ops.K, structure=PETSc.Mat.Structure.DIFFERENT_NONZERO_PATTERN)
    assert D.norm(PETSc.NormType.INFINITY) == 0.0 and C.norm(PETSc.NormType.INFINITY) == 0.0   # exactly
    rest = solve_complex_modes(ops.K, ops.M, None, 8, 1000.0).eigenvalues
    spun = solve_complex_modes(K, ops.M, C, 8, 1000.0, method="pep").eigenvalues
    inside = rest[(rest.imag >= spun.imag.min()) & (rest.imag <= spun.imag.max())]
    assert len(inside) >= 6
    # the same matrices: only the two solvers' tolerance (1e-10 residual) separates them
    assert max(np.min(np.abs(spun - lam)) / abs(lam) for lam in inside) < 1e-8


def test_fixed_frame_is_the_rotating_frame_shifted_by_k_omega():
    """λ_fixed = λ_rot ∓ ikΩ for the forward/backward waves of a k-diameter doublet.  The mesh is not
    axisymmetric: each doublet is split by δ₀ at rest, so per eigenvalue the relation holds to δ₀/2;
    the doublet-pair model ω = c ± ½√(δ₀² + s²) removes δ₀ and leaves the centre c and the gyroscopic
    split s, which obey it to the discretisation error of ∂/∂θ (benchmarks/coriolis_calculix.py).
    k = 1 is left out on this coarse mesh: its shifted waves pass within 5 Hz of the k = 0 mode (847 Hz),
    which the non-axisymmetric mesh couples to them (0.8 Hz; 2e-3 Hz at mesh size 0.025)."""
    from fem_squeal.fe.descriptors import CircumferentialBasis
    from fem_squeal.fe.eigen import solve_complex_modes

    _, _, ops, fixed, rotating = disc(True)
    basis = CircumferentialBasis(ops.V, ops.M, ops.M_axial)
    omega = 50.0
    modes = {}
    for name, rot, om in (("rest", fixed, 0.0), ("rotating", rotating, omega), ("fixed", fixed, omega)):
        K = ops.K.copy()
        K.axpy(-om ** 2, rot.S, structure=PETSc.Mat.Structure.DIFFERENT_NONZERO_PATTERN)
        C = rot.G.copy()
        C.scale(om)
        cm = solve_complex_modes(K, ops.M, C, 9, 1200.0, method="pep")
        modes[name] = [(lam.imag / (2 * np.pi), d.nodal_diameter, d.travelling_index)
                       for lam, d in zip(cm.eigenvalues, (basis.describe(a, b) for a, b in
                                                          zip(cm.vectors_re, cm.vectors_im)))]
    checked = 0
    for k in (2, 3):
        pick = {n: sorted((f, tau) for f, kk, tau in m if kk == k) for n, m in modes.items()}
        if any(len(p) != 2 for p in pick.values()):
            continue
        kf = k * omega / (2 * np.pi)
        d0 = pick["rest"][1][0] - pick["rest"][0][0]
        (r1, t1), (r2, t2) = pick["rotating"]
        (f1, s1), (f2, s2) = pick["fixed"]
        assert s1 < -0.9 and s2 > 0.9    # fixed frame: the lower is a pure backward wave, the upper forward
        r_fw, r_bw = (r1, r2) if t1 > t2 else (r2, r1)
        assert abs(f2 - (r_fw + kf)) <= 0.5 * d0 + 1e-3 * kf     # δ₀/2: the mesh's non-axisymmetry
        assert abs(f1 - (r_bw - kf)) <= 0.5 * d0 + 1e-3 * kf
        g_rot = np.sign(r_fw - r_bw) * np.sqrt(max((r2 - r1) ** 2 - d0 ** 2, 0.0)) / 2
        g_fix = np.sqrt(max((f2 - f1) ** 2 - d0 ** 2, 0.0)) / 2
        # discretisation error of ∂/∂θ on a k-diameter mode (measured ≤ 5e-5 kΩ on this mesh)
        assert abs(g_fix - (kf + g_rot)) < 1e-3 * kf
        assert abs(0.5 * (f1 + f2) - 0.5 * (r1 + r2)) < 1e-3 * kf
        checked += 1
    assert checked == 2


SCENE = {
    "geometry": {"builder": "annular_disc", "mean_radius": 0.1, "width": 0.1, "thickness": 0.01,
                 "mesh_size": 0.04},
    "materials": {"disc": {"E": 2.1e11, "nu": 0.3, "rho": 7850.0}},
    "boundary": {"clamped": ["inner"]},
    "analyses": {"cea": {"n_modes": 4}},
}


def _scene(**operating):
    return {**SCENE, "operating": operating}


def test_scene_keys_default_off_and_named_errors():
    s = validate(dict(SCENE))
    assert s["operating"]["gyroscopic"] is False and s["operating"]["rotating_parts"] == ["disc"]
    assert s["preload"]["geometric_stiffness"] is False
    validate(_scene(speed=100.0, gyroscopic=True))
    with pytest.raises(SceneError, match=r"operating\.rotating_parts\[0\]: unknown part 'rotor'"):
        validate(_scene(speed=100.0, gyroscopic=True, rotating_parts=["rotor"]))
    with pytest.raises(SceneError, match=r"operating\.rotating_parts: must name at least one part"):
        validate(_scene(speed=100.0, gyroscopic=True, rotating_parts=[]))
    with pytest.raises(SceneError, match=r"operating\.speed: must be > 0 when operating\.gyroscopic"):
        validate(_scene(gyroscopic=True))
    with pytest.raises(SceneError, match=r"operating\.rotating_parts: must be list"):
        validate(_scene(speed=100.0, gyroscopic=True, rotating_parts="disc"))
    with pytest.raises(SceneError, match=r"operating\.rotating_parts: must be a list of part names"):
        validate(_scene(speed=100.0, gyroscopic=True, rotating_parts=[1]))
    # the CEA and the reduced model have the rotation and the stress stiffening; a nonlinear study is refused
    with pytest.raises(SceneError, match=r"operating\.gyroscopic: the nonlinear study analyses\.transient"):
        validate({**_scene(speed=100.0, gyroscopic=True), "analyses": {"cea": {}, "transient": {}}})
    with pytest.raises(SceneError, match=r"preload\.geometric_stiffness: the nonlinear study analyses\.masa"):
        validate({**SCENE, "preload": {"geometric_stiffness": True}, "analyses": {"masa": {}}})


SPIN_TOML = """
title = "spinning disc, 1 against 2 ranks"
[geometry]
builder = "annular_disc"
mean_radius = 0.1
width = 0.1
thickness = 0.01
mesh_size = 0.04
[materials.disc]
E = 2.1e11
nu = 0.3
rho = 7850.0
[boundary]
clamped = ["inner"]
[operating]
speed = 300.0
gyroscopic = true
[preload]
geometric_stiffness = true
[analyses.cea]
n_modes = 8
band_hz = [100.0, 3000.0]
"""


@pytest.mark.slow
@pytest.mark.mpi
def test_spinning_disc_one_and_two_ranks_agree(tmp_path, mpirun):
    """The CEA of a spinning, centrifugally prestressed disc (transport form) on 1 and 2 ranks (~20 s)."""
    import json
    import subprocess
    import sys

    from support.processes import clean_env

    from fem_squeal.app.run import run_scene
    from fem_squeal.app.scene import load_scene

    scene = tmp_path / "spin.toml"
    scene.write_text(SPIN_TOML)
    serial = run_scene(load_scene(scene), tmp_path / "one", MPI.COMM_SELF, log=lambda *a: None)
    cmd = mpirun + [sys.executable, "-m", "fem_squeal.cli", "run", str(scene), "-o", str(tmp_path / "two")]
    p = subprocess.run(cmd, capture_output=True, text=True, timeout=600, env=clean_env())
    assert p.returncode == 0, p.stderr
    par = json.loads((tmp_path / "two" / "results.json").read_text())
    assert par["model"]["ranks"] == 2 and "cea_rotation" in serial

    def lam(res):
        return np.array([complex(m["real_part"], 2 * np.pi * m["freq_hz"]) for m in res["complex_modes"]])

    a, b = lam(serial), lam(par)
    assert len(a) == len(b) == 8
    # the same mesh and operators; the eigensolver's tolerance (1e-10) bounds the difference
    assert np.max(np.abs(a - b) / np.abs(a)) < 1e-8
    # travelling waves at ±kΩ: forward and backward k = 1 waves 2Ω/2π apart within the mesh's δ₀ (< 2 Hz)
    k1 = sorted(m["freq_hz"] for m in serial["complex_modes"] if m["nodal_diameter"] == 1)
    assert abs(k1[-1] - k1[0] - 2 * 300.0 / (2 * np.pi)) < 2.0


def test_rotating_frame_matches_calculix_coriolis(tmp_path):
    """benchmarks/coriolis_calculix.py on a coarse mesh: fem_squeal's Coriolis matrix projected on the
    same real modes as ccx's *COMPLEX FREQUENCY, CORIOLIS gives ccx's eigenvalues to the 7 digits of
    its .dat file (6 s: ccx, real modes and the full PEP on 1.5k DOFs)."""
    import shutil
    import sys

    if shutil.which("ccx") is None:
        pytest.skip("ccx not installed")
    from support.paths import ROOT

    sys.path.insert(0, str(ROOT / "benchmarks"))
    import coriolis_calculix as bench

    mesh = bench.make_mesh(tmp_path, 0.04)
    res = bench.calculix_table(tmp_path, mesh, 1000.0, 12)
    assert len(res["rows"]) >= 5
    for r in res["rows"]:
        assert abs(r["d_proj"]) < 1e-6      # .dat rounding (7 digits) and ccx's Newton stop (its 1e-3 step)
