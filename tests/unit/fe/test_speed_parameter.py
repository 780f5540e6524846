"""The disc speed as a parameter of the reduced model (issue 20 item 6): C(Ω) = C₀ + Ω G + (|μ|/|μ⁰|)(Ω₀/Ω) C_d,
K(Ω) = K₀ + K_σ0 + Ω² (K_σc − S), checked against fresh assemblies at other speeds, the projection of the
full operators, full CEAs and finite differences, on the ring pressed on one rigid plate."""
from __future__ import annotations

import functools

import numpy as np
import pytest
from support.ring import ring_mesh

from fem_squeal.fe.model import FixedFace, Material, ModelSpec, Pressure, RigidPlate

W0, MU = 20.0, 0.3          # nominal speed [rad/s] and friction coefficient
BAND = (5000.0, 15000.0)   # the held ring on its plate: modes from 6.7 kHz


def spec_at(speed: float = W0, mu: float = MU) -> ModelSpec:
    plate = RigidPlate("bottom", 1e10, mu, 1, friction_damping=True, speed=speed, name="bottom")
    return ModelSpec({"disc": Material(3e9, 0.4, 1400.0)}, (plate,), fixed=(FixedFace("inner", ("x", "y")),),
                     pressures=(Pressure("top", 1e5),))


@functools.cache
def model():
    """Ring on a damped plate at Ω₀, turning (transport form) with stress stiffening; the parametric
    operators and a reduced model on modes up to 2× the band with the static corrections."""
    from fem_squeal.fe.assembly import assemble_operators, operating_terms
    from fem_squeal.fe.preload import friction_damping, static_displacement
    from fem_squeal.fe.projection import ParametricOperators, build_basis, reduce

    md = ring_mesh(mesh_size=0.004)
    ops = assemble_operators(md, spec_at(), parts=True)
    u = static_displacement(ops)
    Cd = friction_damping(ops, md, spec_at(), u, None)
    lin = ops._replace(C=Cd, Cd=Cd)
    terms = operating_terms(lin, md, spec_at(), gyroscopic=True, rotating_parts=["disc"], stress_stiffening=True,
                            u_static=u)
    par = ParametricOperators(lin, spec_at(), MU, ["disc"], operating=terms, speed0=W0)
    basis = build_basis(lin, par, 2 * BAND[1], n_start=30)
    return md, ops, u, par, basis, reduce(lin, par, basis)


def rel(A, B) -> float:
    D = A.copy()
    D.axpy(-1.0, B, structure=A.Structure.DIFFERENT_NONZERO_PATTERN)
    return D.norm() / B.norm()


@pytest.mark.parametrize("speed", [0.5 * W0, W0, 3 * W0])
def test_parametric_speed_gives_the_operators_assembled_at_that_speed(speed):
    """K(Ω), C(Ω) of the parametric operators equal the CEA's operators assembled afresh for a scene at Ω
    (friction damping re-assembled with V = Ω r, rotation and prestress by operating_operators): the
    1/Ω law of C_d and the Ω, Ω² laws hold to round-off (1e-12)."""
    from fem_squeal.fe.assembly import operating_operators
    from fem_squeal.fe.preload import friction_damping

    md, ops, u, par, _, _ = model()
    K, C = par.matrices({"speed": speed})
    Cd = friction_damping(ops, md, spec_at(speed), u, None)
    Kr, Cr, info = operating_operators(ops._replace(C=Cd, Cd=Cd), md, spec_at(speed), speed=speed,
                                       gyroscopic=True, rotating_parts=["disc"], stress_stiffening=True,
                                       u_static=u)
    assert info["gyroscopic_norm"] > 0 and info["geometric_stiffness_norm"] > 0
    assert rel(K, Kr) < 1e-12 and rel(C, Cr) < 1e-12


@pytest.mark.parametrize("mu", [0.45, -0.45])
def test_friction_damping_scales_with_mu(mu):
    """C(μ, Ω) − Ω G = C_d of a plate with |μ| at that speed (about the nominal preload), to 1e-12: the
    signed μ (backward sliding) turns the friction force, not the damping p|μ|/V of a transverse velocity."""
    from fem_squeal.fe.preload import friction_damping

    md, ops, u, par, _, _ = model()
    _, C = par.matrices({"mu": mu, "speed": 2 * W0})
    C.axpy(-2 * W0, par.operating.G, structure=C.Structure.DIFFERENT_NONZERO_PATTERN)
    assert rel(C, friction_damping(ops, md, spec_at(2 * W0, abs(mu)), u, None)) < 1e-12


def test_reduced_speed_terms_are_the_projection_of_the_full_ones():
    """Φᵀ K(p) Φ and Φᵀ C(p) Φ at (μ, Ω) points equal the reduced model's (round-off: 1e-10 of the largest
    entry); 'speed' is a parameter with its nominal value."""
    from support.operators import projection_mismatch

    _, _, _, par, basis, rm = model()
    assert "speed" in rm.parameters and rm.nominal()["speed"] == W0
    for point in ({"speed": 0.5 * W0}, {"speed": 3 * W0, "mu": 0.2}, {"mu": -0.3}):
        errors = projection_mismatch(par, basis.Phi, rm, point)
        assert len(errors) == 2 and max(errors) <= 1e-10      # K and C


def test_reduced_eigenvalues_follow_the_full_cea_over_the_speed():
    """Reduced eigenvalues in the band against full PEPs at Ω₀/2 and 3Ω₀: the basis (modes at rest, the
    static corrections of K_f Φ, C_d Φ, G Φ) follows the speed terms: measured ≤ 1.1e-7 at Ω₀/2, Ω₀, 3Ω₀
    and 10Ω₀ (198 vectors with the prestress corrections too); 1e-5 leaves a wide margin."""
    from fem_squeal.fe.projection import full_modes, relative_change
    from fem_squeal.reduced.sweep import solve_points

    _, _, _, par, _, rm = model()
    for speed in (0.5 * W0, 3 * W0):
        red = solve_points(rm, {"speed": np.array([speed])})[0]
        f = red.imag / (2 * np.pi)
        red = red[(f >= BAND[0]) & (f <= BAND[1])]
        full = full_modes(par, {"speed": speed}, len(red) + 2, 10000.0, band_hz=BAND)
        assert full.size >= 6
        assert relative_change(full, red) < 1e-5


def test_speed_derivatives_full_reduced_and_finite_differences():
    """dλ/dΩ from the left and right eigenvectors of the full model against central differences of full
    CEAs (step 1e-3 Ω₀: truncation ~1e-6 relative; measured ≤ 3e-10), and the reduced model's dλ/dΩ against
    the full one (the basis error; measured ≤ 2e-10, 1e-3 allowed).  Independently of both, the transport
    form shifts a k-nodal-diameter wave of the axisymmetric ring by ±ikΩ: Im dλ/dΩ is an integer k up to
    the small Coriolis/prestress part (measured 3e-4·k; 2e-3·max(k, 1) allowed)."""
    from fem_squeal.fe.projection import full_modes, full_sensitivities
    from fem_squeal.reduced.sensitivity import sensitivities
    from fem_squeal.reduced.sweep import solve_points

    _, _, _, par, _, rm = model()
    lam = solve_points(rm, {})[0]
    f = lam.imag / (2 * np.pi)
    pick = np.flatnonzero((f >= BAND[0]) & (f <= BAND[1]))[:4]
    full = full_sensitivities(par, lam[pick], ["speed"], BAND)
    red = sensitivities(rm, None, ["speed"], pick)
    h = 1e-3 * W0
    fd = [full_modes(par, {"speed": W0 + d}, 12, 10000.0, band_hz=BAND) for d in (h, -h)]
    for s, r in zip(full, red):
        lp = fd[0][np.argmin(np.abs(fd[0] - s.eigenvalue))]
        lm = fd[1][np.argmin(np.abs(fd[1] - s.eigenvalue))]
        scale = abs(s.eigenvalue) / W0
        assert abs(s.d_lambda["speed"] - (lp - lm) / (2 * h)) < 1e-6 * scale
        assert abs(r.d_lambda["speed"] - s.d_lambda["speed"]) < 1e-3 * scale
        k = abs(s.d_lambda["speed"].imag)
        assert abs(k - round(k)) < 2e-3 * max(round(k), 1)
    assert max(round(abs(s.d_lambda["speed"].imag)) for s in full) >= 1   # a travelling wave among them


# ------------------------------------------------------------------ scene keys
def ring_scene(**over) -> dict:
    """The damped-plate ring scene of test_friction_damping, turning, with a reduced model and a speed sweep."""
    from test_friction_damping import ring_scene as damped_ring

    base = {"geometry__mesh_size": 0.004, "operating": {"speed": W0, "gyroscopic": True},
            "analyses": {"reduced": {"band_hz": list(BAND)},
                         "sweep": {"parameter": "speed", "range": [5.0, 80.0], "n": 16}}}
    return damped_ring(**{**base, **over})


def test_scene_speed_sweep_and_map_are_valid():
    from fem_squeal.app.analyses.reduced import basis_design
    from fem_squeal.app.scene import model_spec, validate

    s = validate(ring_scene())
    _, checks, samples, _ = basis_design(s, model_spec(s))
    assert {"mu": MU, "speed": 5.0} in checks and {"mu": MU, "speed": 80.0} in checks and not samples
    s = validate(ring_scene(analyses={"reduced": {}, "map": {"second": "speed"}}))
    _, checks, _, parts = basis_design(s, model_spec(s))
    assert {"mu": -1.0, "speed": 0.5 * W0} in checks and {"mu": 1.0, "speed": 2 * W0} in checks and not parts
    rob = {"n_samples": 100, "parameters": {"speed": {"distribution": "uniform", "lower": 10.0, "upper": 40.0}}}
    s = validate(ring_scene(analyses={"reduced": {}, "robustness": rob}))
    _, checks, samples, _ = basis_design(s, model_spec(s))
    assert {"mu": MU, "speed": 10.0} in checks and {"mu": MU, "speed": 40.0} in checks and not samples


@pytest.mark.parametrize("over, message", [
    ({"interfaces__bottom_plate__friction": "stribeck", "interfaces__bottom_plate__mu_s": 0.4,
      "interfaces__bottom_plate__mu_d": 0.3},
     r"analyses\.sweep\.parameter: 'speed' is not a parameter of this model: interfaces\.bottom_plate\.friction = "
     r"'stribeck': μ\(V\)"),
    ({"analyses__sweep__range": [0.0, 10.0]},
     r"analyses\.sweep\.range: the speed must be > 0 with friction damping"),
    ({"analyses": {"reduced": {}, "map": {"second": "speed", "speed_range": [30.0, 10.0]}}},
     r"analyses\.map\.speed_range: "),
    ({"analyses": {"reduced": {}, "sensitivity": {"parameters": ["speed"]}}, "operating": {"speed": 0.0},
      "interfaces__bottom_plate__friction_damping": False},
     r"analyses\.sensitivity\.parameters\[0\]: 'speed' is not a parameter of this model: operating\.speed = 0"),
    ({"analyses": {"reduced": {}, "transient": {}}, "interfaces__bottom_plate__friction_damping": False},
     r"operating\.gyroscopic: the nonlinear study analyses\.transient"),
])
def test_scene_speed_errors(over, message):
    from fem_squeal.app.scene import validate
    from fem_squeal.util.errors import SceneError

    with pytest.raises(SceneError, match=message):
        validate(ring_scene(**over))


SPEED_TOML = """
title = "ring on a damped plate, turning: speed sweep and (mu, speed) map"
[geometry]
builder = "annular_disc"
mean_radius = 0.05
width = 0.005
thickness = 0.004
mesh_size = 0.0025
[materials.disc]
E = 3e9
nu = 0.4
rho = 1400
[interfaces.bottom_plate]
type = "rigid_plate"
face = "bottom"
kn = 1e10
mu = 0.3
friction_damping = true
[loads.pressure.top]
face = "top"
p = 1e5
[boundary.fixed.inner]
face = "inner"
components = ["x", "y"]
[operating]
speed = 20.0
gyroscopic = true
[preload]
geometric_stiffness = true
[analyses.reduced]
band_hz = [5000.0, 15000.0]
verify = true
[analyses.sweep]
parameter = "speed"
range = [2.0, 200.0]
n = 11
[analyses.map]
second = "speed"
mu_max = 0.6
n_mu = 5
n_speed = 3
speed_range = [2.0, 200.0]
"""


@pytest.mark.slow
@pytest.mark.mpi
def test_speed_sweep_and_map_scene_one_and_two_ranks(tmp_path, mpirun):
    """The scene path end to end (~40 s): the reduced model verified against full CEAs at the (μ, Ω) corners
    of the map and the sweep (measured ≤ 4e-7), the same sweep and map on 1 and 2 ranks."""
    import json
    import subprocess
    import sys

    from mpi4py import MPI
    from support.processes import clean_env

    from fem_squeal.app.run import run_scene
    from fem_squeal.app.scene import load_scene

    scene = tmp_path / "speed.toml"
    scene.write_text(SPEED_TOML)
    one = run_scene(load_scene(scene), tmp_path / "one", MPI.COMM_SELF, log=lambda *a: None, write_fields=False)
    rows = one["reduced"]["verification"]
    assert {"speed": 200.0, "mu": 0.6} in [r["point"] for r in rows]
    assert max(r["max_rel_error"] for r in rows) < 1e-5
    assert all(r["n_unstable_full"] == r["n_unstable_reduced"] for r in rows)
    cmd = mpirun + [sys.executable, "-m", "fem_squeal.cli", "run", str(scene), "-o", str(tmp_path / "two"),
                    "--no-fields"]
    p = subprocess.run(cmd, capture_output=True, text=True, timeout=900, env=clean_env())
    assert p.returncode == 0, p.stderr
    two = json.loads((tmp_path / "two" / "results.json").read_text())
    assert one["map"]["parameter"] == "speed" and one["map"]["total"] == two["map"]["total"]
    a = np.array(one["sweep"]["values"])
    assert np.array_equal(a, np.array(two["sweep"]["values"]))
