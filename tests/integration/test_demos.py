"""The demos not covered by another test file run here and check themselves (each ends with
"check passed" and exit 0), the brake ones behind the slow marker.  The others: ryzhik_ring
(test_regression_mpi), brake_corner_cea (test_brake), mu_sweep (test_reduction), masa_brake
(test_masa_brake), segmented_pad (test_limit_cycle_pad), transient_brake (test_transient_brake),
import_abaqus_mesh (test_mesh_import)."""
from __future__ import annotations

import subprocess
import sys

import pytest
from support.paths import ROOT
from support.processes import clean_env


def _demo(name: str, out, *args, prefix=(), timeout=900) -> str:
    env = {**clean_env(), "FEM_SQUEAL_CACHE": str(out) + ".cache"}     # never the user's cache
    p = subprocess.run([*prefix, sys.executable, str(ROOT / "demos" / name), str(out), *args], capture_output=True,
                       text=True, timeout=timeout, env=env)
    assert p.returncode == 0 and "check passed" in p.stdout, p.stdout[-3000:] + p.stderr[-3000:]
    return p.stdout


def test_masa_two_dof_demo_checks_itself(tmp_path):
    _demo("masa_two_dof.py", tmp_path)
    assert (tmp_path / "masa.json").is_file() and (tmp_path / "masa.png").is_file()


@pytest.mark.slow
@pytest.mark.mpi
def test_main_demo_checks_itself_on_a_coarse_brake(tmp_path, mpirun):
    """The main demo (scripts/demo.sh) on the coarse brake, 2 ranks: reduced = full CEA at the design
    corners, the map's count at the nominal point = the CEA's.  Slow: a reduced basis with its
    verification CEAs."""
    coarse = ["--set=geometry.mesh_size=0.016", "--set=analyses.reduced.band_hz=[0.0, 6000.0]",
              "--set=analyses.cea.band_hz=[0.0, 6000.0]", "--set=analyses.map.n_mu=21", "--set=analyses.map.n_E=5"]
    env_cache = ["--set=analyses.sweep.n=41"]
    _demo("mu_E_stability_map.py", tmp_path, *coarse, *env_cache, prefix=mpirun, timeout=3000)


@pytest.mark.slow
@pytest.mark.mpi
def test_robustness_demo_checks_itself_on_a_coarse_brake(tmp_path, mpirun):
    """Sensitivities against finite differences of the reduced model, 10⁴ robustness samples and the
    full-CEA spot checks on the coarse brake, 2 ranks (≈ 5 min: a reduced basis)."""
    coarse = ["--set=geometry.mesh_size=0.016", "--set=analyses.reduced.band_hz=[0.0, 6000.0]",
              "--set=analyses.cea.band_hz=[0.0, 6000.0]"]
    _demo("brake_robustness.py", tmp_path, *coarse, prefix=mpirun, timeout=3000)

