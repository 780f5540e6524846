"""The scene keys of analyses.operating_matrix: the conditions and friction laws it makes, bad values named
by their key before any computation (a condition outside a friction table, a pressure other than the
scene's where the operators depend on it beyond the stress stiffening), the pressure as a parameter of the
reduced model with the stress stiffening, and its report section."""
from __future__ import annotations

import numpy as np
import pytest
from support.paths import ROOT

from fem_squeal.app.analyses import operating_matrix as om
from fem_squeal.app.scene import load_scene
from fem_squeal.reduced.laws.friction import TableFriction
from fem_squeal.reduced.model import ReducedModel
from fem_squeal.reduced.operating_matrix import (
    InterfaceLaw,
    MatrixResult,
    evaluate,
    noise_matrix,
    parameter_points,
)
from fem_squeal.util.errors import SceneError

SCENE = ROOT / "scenes" / "brake_operating_matrix.toml"


def test_bundled_scene_conditions_and_laws():
    scene = load_scene(SCENE)
    cond = om.conditions(scene)
    assert cond.size == 24 and len(cond.corners()) == 8
    mus = om.friction_values(scene, cond)
    assert list(mus) == ["default"] and mus["default"][0] == pytest.approx(  # 50 °C, 10 rad/s
        0.45 + 0.25 * (0.40 - 0.45) + (10 / 150) * (0.42 - 0.45) + 0.25 * (10 / 150) * (0.38 - 0.40 - 0.42 + 0.45))
    ranged = load_scene(SCENE, ["analyses.operating_matrix.temperature={start = 50.0, stop = 350.0, n = 7}"])
    c = om.conditions(ranged)
    assert c.size == 42 and np.unique(c.temperature).tolist() == [50.0, 100.0, 150.0, 200.0, 250.0, 300.0, 350.0]


@pytest.mark.parametrize("override, message", [
    ("analyses.operating_matrix.pressure=[1.0, 2.0]\npreload.mode='all_closed'",
     r"^analyses\.operating_matrix\.pressure: other pressures than the scene's \(1\) need a reduced model whose "
     r"operators do not depend on the pressure, but preload\.mode is 'all_closed' .*\(got \[2\.0\]\)"),

    ("analyses.operating_matrix.pressure=[-1.0]",
     r"^analyses\.operating_matrix\.conditions\.pressure: must be > 0"),
    ("analyses.operating_matrix.temperature=[50.0, 450.0]",
     r"^analyses\.operating_matrix\.friction\.default: temperature 450 is outside the table's range \[0, 400\]"),
    ("analyses.operating_matrix.speed=[10.0, 200.0]",
     r"^analyses\.operating_matrix\.friction\.default: speed 200 is outside the table's range \[0, 150\]"),
    ("analyses.operating_matrix.friction.default={law = 'table', temperature = [0.0, 400.0], speed = [0.0], "
     "pressure = [0.5, 0.8], mu = [[[0.4], [0.3]], [[0.4], [0.3]]]}",
     r"^analyses\.operating_matrix\.friction\.default: pressure 1 is outside the table's range \[0\.5, 0\.8\]"),
    ("analyses.operating_matrix.friction.default={law = 'table', temperature = [0.0, 400.0], speed = [0.0], "
     "pressure = [0.5, 2.0], mu = [[0.4], [0.3]]}",
     r"^analyses\.operating_matrix\.friction\.default\.mu: with a pressure axis, one \(temperature × speed\) "
     r"table per pressure, shape \(2, 2, 1\)"),
    ("analyses.operating_matrix.direction=['backward']",
     r"^analyses\.operating_matrix\.direction: must be a list of \['forward', 'reverse'\]"),
    ("analyses.operating_matrix.temperature={start = 1.0, n = 3}",
     r"^analyses\.operating_matrix\.temperature: a range is \{start, stop, n\}"),
    ("analyses.operating_matrix.friction.default.law='polynomial'",
     r"^analyses\.operating_matrix\.friction\.default\.law: must be one of \['constant', 'stribeck', 'table'\]"),
    ("analyses.operating_matrix.friction.default.law=[]",      # found by the fuzzed scenes: a TypeError
     r"^analyses\.operating_matrix\.friction\.default\.law: must be one of \['constant', 'stribeck', 'table'\] "
     r"\(got \[\]\)"),
    ("analyses.operating_matrix.friction.default.mu=[[0.4, 0.4]]",
     r"^analyses\.operating_matrix\.friction\.default\.mu: must have one row per temperature"),
    ("analyses.operating_matrix.friction.piston_seal={law = 'constant', mu = 0.3}",
     r"^analyses\.operating_matrix\.friction\.piston_seal: not a sliding interface with friction; those: "
     r"\['pad_inner', 'pad_outer'\]"),
    ("analyses.operating_matrix.friction.pad_inner="
     "{law = 'stribeck', mu_s = 0.5, mu_d = 0.4, v_s = 0.1, v_d = 1.0}",
     r"^analyses\.operating_matrix\.friction\.pad_inner\.radius: required for law = 'stribeck'"),
])
def test_bad_values_name_the_key(override, message):
    with pytest.raises(SceneError, match=message):
        load_scene(SCENE, override.split("\n"))


def test_other_pressures_are_continued_by_the_preload():
    from fem_squeal.app.analyses import pressure_continuation

    scene = load_scene(SCENE, ["analyses.operating_matrix.pressure=[0.5, 1.0, 2.0]"])
    assert pressure_continuation.scales(scene) == [0.5, 2.0]
    assert pressure_continuation.key_inputs(scene)["pressure_scales"] == [0.5, 2.0]
    plain = load_scene(SCENE)
    assert pressure_continuation.scales(plain) == [] and pressure_continuation.key_inputs(plain) is plain.preload


def test_stress_stiffening_makes_the_pressure_a_parameter():
    """With preload.geometric_stiffness (or a contact's friction damping) the other pressures are accepted:
    the reduced stage checks its basis at the extreme pressures, the conditions give the model's ``pressure``
    parameter, the results say how; a rigid plate's friction damping is still refused by name."""
    from types import SimpleNamespace

    from fem_squeal.app.analyses import pressure_continuation
    from fem_squeal.app.analyses.reduced import basis_design

    scene = load_scene(SCENE, ["analyses.operating_matrix.pressure=[0.5, 1.0, 2.0]",
                               "preload.geometric_stiffness=true"])
    assert pressure_continuation.pressure_parameter(scene)
    assert not pressure_continuation.pressure_parameter(load_scene(SCENE, ["preload.geometric_stiffness=true"]))
    damped = load_scene(SCENE, ["analyses.operating_matrix.pressure=[0.5, 1.0]",
                                "interfaces.pad_inner.friction_damping=true"])
    assert pressure_continuation.pressure_parameter(damped)
    assert pressure_continuation.friction_damped_contacts(damped) == ["pad_inner"]
    plate = SimpleNamespace(preload={"mode": "nonlinear"},
                            interfaces={"pad": {"type": "contact", "friction_damping": True},
                                        "floor": {"type": "rigid_plate", "friction_damping": True}})
    why = om.pressure_dependent_terms(plate)
    assert why.startswith("interfaces.floor.friction_damping = true on a rigid_plate")
    mu0, checks, _, _ = basis_design(scene, scene.spec)
    assert {"mu": mu0, "pressure": 0.5} in checks and {"mu": mu0, "pressure": 2.0} in checks
    plain = load_scene(SCENE)
    assert not any("pressure" in c for c in basis_design(plain, plain.spec)[1])
    cond = om.conditions(scene)
    K0 = np.diag([(2 * np.pi * 1000.0) ** 2, (2 * np.pi * 1100.0) ** 2])
    model = ReducedModel(K0=K0, Kf1=np.array([[0.0, 1e6], [-1e6, 0.0]]), mu0=0.3, Ksp=1e-2 * K0)
    pts = parameter_points(model, cond, {}, InterfaceLaw(TableFriction([0.0, 400.0], [0.0, 150.0],
                                                                       [[0.4, 0.4], [0.4, 0.4]])))
    assert np.array_equal(pts["pressure"], cond.pressure) and set(cond.pressure.tolist()) == {0.5, 1.0, 2.0}
    assert "K_σ(u(1)) + (p − 1) K_σ(du/ds)" in om.pressure_model(model) and "C_d" not in om.pressure_model(model)
    both = ReducedModel(K0=K0, Kf1=model.Kf1, mu0=0.3, Ksp=model.Ksp, Cd0=np.eye(2), Cdp=np.eye(2))
    assert "C_d(1) + (p − 1) C_d(dp/ds)" in om.pressure_model(both) and "and them" not in om.pressure_model(both)
    assert "no stress stiffening" in om.pressure_model(ReducedModel(K0=K0))
    row = {"condition": 1, **cond.row(0), "max_rel_error": 2e-3, "n_unstable_full": 1, "n_unstable_reduced": 1}
    assert om.verification_failures({"verification": [row]}, 1e-3) == [
        "operating matrix: reduced vs full at condition 1 (0.5 × loads.pressure, 50 °C, 10 rad/s, forward): "
        "2.0e-03 > tol 0.001"]


def test_report_section_from_results():
    a = 2 * np.pi ** 2 * (1100.0 ** 2 - 1000.0 ** 2) * 2
    model = ReducedModel(K0=np.diag([(2 * np.pi * 1000.0) ** 2, (2 * np.pi * 1100.0) ** 2]),
                         Kf1=np.array([[0.0, a], [-a, 0.0]]), mu0=0.3)
    law = InterfaceLaw(TableFriction([0.0, 300.0], [0.0], [[0.7], [0.3]]))
    cond = om.factorial([1.0], [0.0, 300.0], [0.0], ["forward", "reverse"])
    res: MatrixResult = evaluate(model, cond, parameter_points(model, cond, {}, law))
    noise = noise_matrix(res, (0.0, 10000.0), 1e-6)
    html = om.report({"operating_matrix": {"conditions": [cond.row(k) for k in range(cond.size)],
                                           "band_hz": [0.0, 10000.0], "seconds": res.seconds,
                                           "squeal_index": "not available", **noise,
                                           "verification": [{"condition": 0, **cond.row(0), "max_rel_error": 1e-5,
                                                             "n_unstable_full": 1, "n_unstable_reduced": 1}]}})
    assert "<h2>Operating matrix</h2>" in html and "2 (50 %) with an unstable mode" in html
    assert "Reduced vs full model at the corners" in html and "<td>full CEA</td>" in html
    assert html.count("<tr>") > 13 + 4 + 4
    assert om.verification_failures({"verification": [{"condition": 3, **cond.row(3), "max_rel_error": 2e-3,
                                                       "n_unstable_full": 1, "n_unstable_reduced": 0}]}, 1e-3) == [
        "operating matrix: reduced vs full at condition 3 (300 °C, 0 rad/s, reverse): 2.0e-03 > tol 0.001",
        "operating matrix: 0 unstable reduced vs 1 full at condition 3 (300 °C, 0 rad/s, reverse)"]


def test_a_scene_speed_law_needs_its_law_at_the_conditions():
    stribeck = ["interfaces.pad_inner.friction='stribeck'", "interfaces.pad_outer.friction='stribeck'",
                "operating.gyroscopic=false", "analyses.operating_matrix.friction={}"]
    with pytest.raises(SceneError, match=r"^analyses\.operating_matrix\.friction: interfaces\.pad_inner has a "
                                         r"μ\(V\) law \('stribeck'\) that the reduced model holds at "
                                         r"operating\.speed only; .*"
                                         r"\(analyses\.operating_matrix\.friction\.pad_inner"):
        load_scene(SCENE, stribeck)
    load_scene(SCENE, stribeck + ["analyses.operating_matrix.speed=[60.0]"])   # the scene's speed: fine


def test_a_pressure_that_changes_the_contact_set():
    """The continuation's summary (from the preload stage): a pressure whose contact set is not the scene's
    is evaluated with its own contact state (the reduced model's contact_states)."""
    from fem_squeal.app.analyses import pressure_continuation

    scene = load_scene(SCENE, ["analyses.operating_matrix.pressure=[1.0, 2.0, 3.0]"])
    cond = om.conditions(scene)

    class Ctx:
        products = {"pressure_continuation": {"pressures": [
            {"scale": 2.0, "same_contact_set": True, "changed_points": 0},
            {"scale": 3.0, "same_contact_set": False, "changed_points": 7}]},
            "pressure_states": {2.0: "state at 2", 3.0: "state at 3"}}

    assert [r["scale"] for r in om.pressure_states(Ctx(), cond)["pressures"]] == [2.0, 3.0]
    assert pressure_continuation.changed_states(Ctx()) == {3.0: "state at 3"}
    Ctx.products["pressure_continuation"]["pressures"].pop()
    assert pressure_continuation.changed_states(Ctx()) == {}

    class Alone:          # only the scene's pressure: no continuation ran, none to read (the corner checks)
        products: dict = {}

        def entry(self, name):
            raise AssertionError(f"read the {name} stage's files")

    assert pressure_continuation.changed_states(Alone()) == {}


def test_checks_at_the_corners_and_between_them():
    """The verification's conditions: the corners, and where the contact set changes at a pressure inside
    the matrix, the one that changed most, at the first corner's other variables; none inside when only
    the extreme pressures change it."""
    scene = load_scene(SCENE, ["analyses.operating_matrix.pressure=[0.5, 1.0, 1.5, 2.0]"])
    cond = om.conditions(scene)
    corners = [(k, False) for k in cond.corners()]
    first = cond.row(cond.corners()[0])
    checks = om.checked_conditions(cond, {0.5: 40, 1.5: 12, 2.0: 30})
    assert checks[:-1] == corners and checks[-1][1]
    k = checks[-1][0]
    assert cond.row(k) == {**first, "pressure": 1.5}
    assert om.checked_conditions(cond, {0.5: 40, 1.5: 0, 2.0: 30}) == corners
    assert om.checked_conditions(cond, {}) == corners
    k = om.checked_conditions(cond, {1.5: 3, 1.0: 0})[-1][0]     # the pressure that changed, not the scene's
    assert cond.pressure[k] == 1.5


@pytest.mark.parametrize("value,message", [
    ("{slope = 1.0}", r"interfaces\.pad_inner\.initial_gap: unknown key 'slope'; allowed: offset, gradient, at"),
    ("{gradient = [1.0, 2.0]}", r"interfaces\.pad_inner\.initial_gap: gradient: must be 3 numbers"),
    ("{offset = true}", r"interfaces\.pad_inner\.initial_gap: offset: must be a number \[m\] \(got True\)"),
    ("{at = [0.1, 'a', 0.0]}", r"interfaces\.pad_inner\.initial_gap: at: must be 3 numbers")])
def test_initial_gap_is_checked(value, message):
    with pytest.raises(SceneError, match=message):
        load_scene(SCENE, [f"interfaces.pad_inner.initial_gap={value}"])
    with pytest.raises(SceneError, match=r"interfaces\.piston_pad\.initial_gap: unknown key"):   # bonded: none
        load_scene(SCENE, ["interfaces.piston_pad.initial_gap={offset = 1e-6}"])


def test_initial_gap_reaches_the_model_spec():
    from fem_squeal.app.scene.validation import model_spec
    from fem_squeal.fe.model import GapProfile

    scene = load_scene(SCENE, ["interfaces.pad_inner.initial_gap={offset = -1e-6, gradient = [0.0, 1e-4, 0.0]}"])
    spec = model_spec(scene)
    gaps = {it.name: it.initial_gap for it in spec.interfaces}
    assert gaps["pad_inner"] == GapProfile(-1e-6, (0.0, 1e-4, 0.0), None) and gaps["pad_outer"] is None
    x = np.array([[0.1, 0.02, 0.0], [0.1, -0.02, 0.0]])
    assert np.allclose(gaps["pad_inner"].values(x, np.array([0.1, 0.0, 0.0])), [-1e-6 + 2e-6, -1e-6 - 2e-6])
