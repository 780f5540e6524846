"""The scene keys of the CEA's NVH view (analyses.cea.coupling, coupling_f_max_hz, radiation): defaults,
and bad values named by their key."""
from __future__ import annotations

import pytest
from support.paths import ROOT

from fem_squeal.app.nvh import radiation_settings
from fem_squeal.app.scene import load_scene
from fem_squeal.util.errors import SceneError

BRAKE = ROOT / "scenes" / "brake_corner_cea.toml"


def test_defaults():
    cea = load_scene(BRAKE).analyses["cea"]
    assert cea["coupling"] is True and cea["coupling_f_max_hz"] is None and cea["radiation"] == {}
    rad = radiation_settings(cea["radiation"])
    assert rad.enabled and rad.rho_c == pytest.approx(415.03) and rad.kinetic_energy == 1.0
    assert rad.default_efficiency == 1.0 and rad.efficiency == {} and rad.exclude_faces == []
    rad = radiation_settings(load_scene(BRAKE, ["analyses.cea.radiation.efficiency.caliper=0.1"])
                             .analyses["cea"]["radiation"])
    assert rad.efficiency == {"caliper": 0.1} and rad.rho_c == pytest.approx(415.03)


@pytest.mark.parametrize("override, message", [
    ("analyses.cea.radiation.rho=1.2", r"^analyses\.cea\.radiation\.rho: unknown key; allowed: \["),
    ("analyses.cea.radiation.rho_c=-1", r"^analyses\.cea\.radiation\.rho_c: must be > 0"),
    ("analyses.cea.radiation.kinetic_energy=0", r"^analyses\.cea\.radiation\.kinetic_energy: must be > 0"),
    ("analyses.cea.radiation.efficiency.caliper=-0.5",
     r"^analyses\.cea\.radiation\.efficiency: must map part names to numbers >= 0 \(got caliper = -0.5\)"),
    ("analyses.cea.radiation.efficiency.rotor=0.5",
     r"^analyses\.cea\.radiation\.efficiency\.rotor: unknown part; parts: \["),
    ("analyses.cea.radiation.exclude_faces=[1]",
     r"^analyses\.cea\.radiation\.exclude_faces: must be a list of face"),
    ("analyses.cea.coupling_f_max_hz=-5", r"^analyses\.cea\.coupling_f_max_hz: must be > 0"),
    ("analyses.cea.coupling=1", r"^analyses\.cea\.coupling: must be bool"),
])
def test_bad_values_name_the_key(override, message):
    with pytest.raises(SceneError, match=message):
        load_scene(BRAKE, [override])
