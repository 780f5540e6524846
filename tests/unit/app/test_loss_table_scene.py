"""materials.<part>.eta_table in a scene (issue 39, shims): named errors before any computation (bad
tables, both eta and eta_table, operating-matrix temperatures outside a table, corner checks with an η(f)
table), and a constant table that makes the part's material the constant-η one."""
from __future__ import annotations

import pytest
from support.paths import ROOT

from fem_squeal.app.scene import load_scene
from fem_squeal.util.errors import SceneError

RING = ROOT / "scenes" / "ryzhik_ring.toml"
OM = "analyses.operating_matrix={temperature=[0.0, 150.0]}"
RISING = "{frequency=[0.0, 10000.0], temperature=[0.0, 100.0], eta=[[0.01, 0.05], [0.002, 0.01]], " \
         "reference_frequency=1000.0, reference_temperature=20.0}"


@pytest.mark.parametrize("table, message", [
    ("{frequency=[100.0, 50.0], eta=[0.1, 0.1]}",
     r"^materials\.disc\.eta_table: frequency: must be strictly increasing \(got \[100\.0, 50\.0\]\)"),
    ("{frequency=[100.0, 5000.0], eta=[0.1, -0.1], reference_frequency=200.0}",
     r"^materials\.disc\.eta_table: eta: must be finite and >= 0 \(got -0\.1\)"),
    ("{frequency=[100.0, 5000.0], eta=[0.1, 0.2]}",
     r"^materials\.disc\.eta_table: reference_frequency: required, the table varies with the frequency"),
    ("{eta=[0.1], temp=[1.0]}", r"^materials\.disc\.eta_table: temp: unknown key"),
])
def test_bad_tables_are_named(table, message):
    with pytest.raises(SceneError, match=message):
        load_scene(RING, [f"materials.disc.eta_table={table}"])


def test_scene_tables_and_operating_conditions():
    with pytest.raises(SceneError, match=r"^materials\.disc\.eta_table: give eta or eta_table, not both"):
        load_scene(RING, ["materials.disc.eta_table={eta=[0.1]}", "materials.disc.eta=0.1"])
    flat = load_scene(RING, ["materials.disc.eta_table={frequency=[10.0, 10000.0], eta=[0.02, 0.02]}"])
    const = load_scene(RING, ["materials.disc.eta=0.02"])
    assert flat.spec.materials["disc"].eta == const.spec.materials["disc"].eta == 0.02
    with pytest.raises(SceneError, match=r"^materials\.disc\.eta_table: temperature 150 is outside the table's "
                                         r"range \[0, 100\] \(conditions of analyses\.operating_matrix"):
        load_scene(RING, [f"materials.disc.eta_table={RISING}", OM])
    # corner checks with a table in f: the full nonlinear eigenproblem per watched mode (no longer refused)
    scene = load_scene(RING, [f"materials.disc.eta_table={RISING}",
                              "analyses.operating_matrix={temperature=[0.0, 50.0], verify=true}"])
    assert scene.analyses["operating_matrix"]["verify"] is True
