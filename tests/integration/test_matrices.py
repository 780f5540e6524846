"""A parametric QEP given only as matrices and expressions (scenes/matrices_brake.toml): the CEA and the
real modes of the scene run equal a direct dense solve of the assembled problem with SciPy (1e-10
relative), at two points of the parameter W, and 1 and 2 ranks give the same results."""
from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest
import scipy.linalg as sl
from support.paths import ROOT
from support.processes import clean_env

from fem_squeal.app.run import run_scene
from fem_squeal.app.scene import load_scene

SCENE = ROOT / "scenes" / "matrices_brake.toml"
sys.path.insert(0, str(ROOT / "scenes" / "matrices"))
from make_matrices import matrices  # noqa: E402  (the generator of the scene's files)


def dense_reference(W: float) -> tuple[np.ndarray, np.ndarray]:
    """(λ with Im λ > 0 of λ²M + λC + K, ω² of the symmetric parts), by SciPy's dense QZ and eigh."""
    m = {k: v.toarray() for k, v in matrices().items()}
    M = m["M"]
    C = m["D1"] + W * m["DG"] + (1 / W - 1) * m["DR"] + m["D4"] / (2 * np.pi * 1600)
    K = m["K1"] + m["KR"] + (W ** 2 - 1) * m["KGEO"]
    n = len(M)
    eye, Z = np.eye(n), np.zeros((n, n))
    lam = sl.eig(np.block([[Z, eye], [-K, -C]]), np.block([[eye, Z], [Z, M]]), right=False)
    return lam[lam.imag > 0], sl.eigh(0.5 * (K + K.T), M, eigvals_only=True)


def eigenvalues(res: dict) -> np.ndarray:
    return np.array([c["real_part"] + 2j * np.pi * c["freq_hz"] for c in res["complex_modes"]])


@pytest.fixture(scope="module")
def serial(tmp_path_factory):
    """The scene run at W = 1 and W = 2.5 (one rank, in this process)."""
    out = {}
    for W in (1.0, 2.5):
        tmp = tmp_path_factory.mktemp(f"w{W}")
        scene = load_scene(SCENE, [f"matrices.parameters.W.value={W}"])
        out[W] = run_scene(scene, tmp / "out", write_fields=False, log=lambda *a, **k: None, cache=tmp / "cache",
                           report=False)
    return out


@pytest.mark.parametrize("W", [1.0, 2.5])
def test_cea_and_real_modes_equal_a_dense_scipy_solve(serial, W):
    res = serial[W]
    lam_ref, w2_ref = dense_reference(W)
    lam = eigenvalues(res)
    assert len(lam) == 12
    for x in lam:
        assert np.min(np.abs(lam_ref - x)) <= 1e-10 * abs(x)
    inside = lam_ref[(lam_ref.imag / (2 * np.pi) >= 100) & (lam_ref.imag / (2 * np.pi) <= 2000)]
    growing = inside[inside.real > 0]            # every unstable root in the band is among those returned
    assert res["n_unstable"] == len(growing) and all(np.min(np.abs(lam - x)) <= 1e-10 * abs(x) for x in growing)
    f = np.array([r["freq_hz"] for r in res["real_modes"]])
    f_ref = np.sqrt(w2_ref[:len(f)]) / (2 * np.pi)
    assert np.max(np.abs(f - f_ref) / f_ref) <= 1e-10
    assert res["matrices"]["dofs"] == 48 and res["matrices"]["asymmetry"]["M"] == 0.0


def test_parameter_moves_the_unstable_pair(serial):
    assert serial[1.0]["n_unstable"] == 1 and serial[2.5]["n_unstable"] > 1


@pytest.mark.mpi
def test_two_ranks_equal_one(serial, mpirun, tmp_path):
    p = subprocess.run(mpirun + [sys.executable, "-m", "fem_squeal.cli", "--cache-dir", str(tmp_path / "cache"),
                                 "--log-level", "warning", "run", str(SCENE), "-o", str(tmp_path / "out"),
                                 "--no-report"], capture_output=True, text=True, env=clean_env(), cwd=ROOT,
                       timeout=300)
    assert p.returncode == 0, p.stdout[-3000:] + p.stderr[-3000:]
    two = json.loads((tmp_path / "out" / "results.json").read_text())
    one = serial[1.0]
    assert two["run"]["ranks"] == 2
    a, b = eigenvalues(one), eigenvalues(two)
    assert len(a) == len(b) and np.max(np.abs(a - b) / np.abs(a)) <= 1e-10
    fa, fb = (np.array([r["freq_hz"] for r in x["real_modes"]]) for x in (one, two))
    assert np.max(np.abs(fa - fb) / fa) <= 1e-10
    assert [c["unstable"] for c in one["complex_modes"]] == [c["unstable"] for c in two["complex_modes"]]
