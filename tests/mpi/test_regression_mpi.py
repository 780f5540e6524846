"""Regression against the stored reference of the ryzhik_ring scene, 1 against 2 MPI ranks,
and demo smoke tests (serial and mpirun -n 2).

The reference is never overwritten silently: with FEM_SQUEAL_UPDATE_REFERENCE=1 the test
writes a new file *and fails*, so that the change is reviewed with ``git diff`` and committed
on purpose.
"""
from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys

import numpy as np
import pytest
from mpi4py import MPI
from support.paths import ROOT
from support.processes import clean_env

from fem_squeal.app.run import run_scene
from fem_squeal.app.scene import load_scene
from fem_squeal.util.atomic import write_json_atomic

SCENE = ROOT / "scenes" / "ryzhik_ring.toml"
REFERENCE = ROOT / "tests" / "data" / "ryzhik_ring_reference.json"


def eigenvalues(results) -> np.ndarray:
    return np.array([complex(m["real_part"], 2 * np.pi * m["freq_hz"]) for m in results["complex_modes"]])


@pytest.fixture(scope="module")
def serial(tmp_path_factory):
    out = tmp_path_factory.mktemp("serial")
    return run_scene(load_scene(SCENE), out, MPI.COMM_SELF, log=lambda *a: None)


def test_regression_against_stored_reference(serial):
    lam = eigenvalues(serial)
    if os.environ.get("FEM_SQUEAL_UPDATE_REFERENCE") == "1":
        write_json_atomic(REFERENCE, {"scene": "scenes/ryzhik_ring.toml", "eigenvalues_re": lam.real,
                                      "eigenvalues_im": lam.imag})
        pytest.fail(f"reference rewritten: review 'git diff {REFERENCE.relative_to(ROOT)}' and commit it")
    ref = json.loads(REFERENCE.read_text())
    lam_ref = np.array(ref["eigenvalues_re"]) + 1j * np.array(ref["eigenvalues_im"])
    assert len(lam) == len(lam_ref)
    # Same deterministic gmsh mesh, same discrete operator; solver tolerance 1e-10 => 1e-8 relative.
    assert np.max(np.abs(lam - lam_ref) / np.abs(lam_ref)) < 1e-8


@pytest.mark.mpi
def test_two_ranks_give_the_same_eigenvalues(serial, mpirun, tmp_path):
    out = tmp_path / "mpi"
    # the eigenvalues and descriptors on 2 ranks: not the CEA's coupling (its 2-rank check is test_brake.py's)
    p = subprocess.run(mpirun + [sys.executable, "-m", "fem_squeal.cli", "run", str(SCENE), "-o", str(out),
                                 "--set", "analyses.cea.coupling=false"],
                       capture_output=True, text=True, timeout=600, env=clean_env())
    assert p.returncode == 0, p.stderr
    par = json.loads((out / "results.json").read_text())
    assert par["model"]["ranks"] == 2 and par["model"]["dofs"] == serial["model"]["dofs"]
    a, b = eigenvalues(serial), eigenvalues(par)
    assert len(a) == len(b)
    assert np.max(np.abs(a - b) / np.abs(a)) < 1e-8
    for ms, mp in zip(serial["complex_modes"], par["complex_modes"]):
        assert ms["nodal_diameter"] == mp["nodal_diameter"]
        assert ms["travelling_direction"] == mp["travelling_direction"]
        assert mp["in_plane_share"] == pytest.approx(ms["in_plane_share"], abs=1e-8)
    assert (out / "complex_modes.xdmf").exists() and (out / "complex_modes.h5").exists()


# serial behind the slow marker (13 s): the 2-rank run makes the same self-checks, and the scene's
# rank independence is test_two_ranks_give_the_same_eigenvalues
@pytest.mark.parametrize("ranks", [pytest.param(1, marks=pytest.mark.slow), 2])
def test_ryzhik_demo_runs_and_checks_itself(ranks, mpirun, tmp_path):
    cmd = [sys.executable, str(ROOT / "demos" / "ryzhik_ring.py"), str(tmp_path)]
    if ranks == 2:
        cmd = mpirun + cmd
    p = subprocess.run(cmd, capture_output=True, text=True, timeout=600, env=clean_env())
    assert p.returncode == 0, p.stdout + p.stderr
    assert "check passed" in p.stdout
    assert p.stdout.count("check passed") == 1  # printed on rank 0 only


def test_scene_with_real_modes_and_damping_writes_all_outputs(tmp_path):
    """A damped scene asking for both analyses: PEP is chosen, real modes are M-orthonormal
    with small residuals, and every output file is in place (and no temporary left behind)."""
    scene = load_scene(SCENE, ["geometry.mesh_size=0.003", "materials.disc.rayleigh_alpha=2.0",
                               "analyses.real_modes.n_modes=12", "analyses.real_modes.target_hz=2000"])
    res = run_scene(scene, tmp_path, MPI.COMM_SELF, log=lambda *a: None)
    assert res["cea_method"] == "pep"
    assert len(res["real_modes"]) == 12 and all(m["residual"] < 1e-8 for m in res["real_modes"])
    # mass damping α = 2 lowers every real part by α/2 = 1 (to O(α²/ω) ~ 1e-4) against the
    # undamped run on the same mesh
    undamped = run_scene(load_scene(SCENE, ["geometry.mesh_size=0.003"]), tmp_path / "u", MPI.COMM_SELF,
                         write_fields=False, log=lambda *a: None)
    shift = eigenvalues(res).real - eigenvalues(undamped).real
    assert np.allclose(shift, -1.0, atol=1e-3)
    # without fields: the report, the results and the CEA's coupling and radiation tables and plots
    # (fem_squeal.app.nvh; the coupling is on by default)
    nvh = ["cea_bands.csv", "cea_coupling.csv", "cea_coupling.png", "cea_erp.png", "cea_radiation.csv"]
    assert sorted(p.name for p in (tmp_path / "u").iterdir()) == [*nvh, "report.html", "results.json"]
    shutil.rmtree(tmp_path / "u")
    fields = ["complex_modes.h5", "complex_modes.vtu", "complex_modes.xdmf", "real_modes.h5", "real_modes.vtu",
              "real_modes.xdmf"]
    # the mode pictures, published with the fields (fem_squeal.app.mode_shapes)
    pictures = ["mode_shapes.npz", "mode_shapes/surface_points.csv", "mode_shapes/surface_triangles.csv"] + [
        f"mode_shapes/mode_{j}{end}" for j in res["mode_shapes"]["modes"]
        for end in (".png", "_thumb.png", "_points.csv", "_triangles.csv")]
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted([*fields, *nvh, "mode_shapes", "mode_shapes.npz",
                                                                 "report.html", "results.json"])
    assert sorted(res["files"]) == sorted(fields + pictures + nvh)
