"""Stability map, sensitivities and robustness on a model given as matrices (the 48-DOF stand-in of
scenes/matrices_brake.toml with a second parameter s scaling KR), each against the full problem: a map
point against a direct dense solve, the reduced dλ/dp against central differences of full sparse CEAs
(the tolerance derived from the step), the Monte Carlo's growth rates at a few samples against the dense
solve, bad names as named errors; the same scene on 2 ranks (the modal basis built distributed, PETSc/
SLEPc) equal to 1 rank (1e-8); and the distributed basis on one rank equal to the serial SciPy one."""
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
from fem_squeal.util.errors import SceneError

sys.path.insert(0, str(ROOT / "scenes" / "matrices"))
from make_matrices import matrices  # noqa: E402  (the generator of the scene's files)

BAND = (100.0, 1000.0)
STUDIES = f"""
[matrices.parameters.s]
value = 1.0
range = [0.8, 1.2]

[analyses.map]
parameters = ["s", "W"]
n = 7
check_points = 2
n_bands = 2
basis_modes = 16
band_hz = [{BAND[0]}, {BAND[1]}]

[analyses.sensitivity]
modes = "band"
full = true
max_plots = 0
basis_modes = 16
band_hz = [{BAND[0]}, {BAND[1]}]

[analyses.robustness]
n_samples = 64
spot_checks = 2
n_histograms = 1
basis_modes = 16
band_hz = [{BAND[0]}, {BAND[1]}]
parameters.W = {{ distribution = "uniform", lower = 0.9, upper = 1.4 }}
parameters.s = {{ distribution = "normal", mean = 1.0, std = 0.05 }}
"""
#: the relative accuracy of a full sparse CEA's eigenvalue (SLEPc, 48 DOFs: 1e-11 measured against QZ)
EPS_CEA = 1e-11


def scene_text() -> str:
    """scenes/matrices_brake.toml with absolute file paths, K = K1 + s KR + (W² − 1) KGEO, its CEA and the
    three studies (its real modes and sweep: tests/integration/test_matrices.py)."""
    text = (ROOT / "scenes" / "matrices_brake.toml").read_text()
    text = text.replace('"matrices/', f'"{ROOT}/scenes/matrices/')
    text = text.replace('K = "K1 + KR + (W**2 - 1)*KGEO"', 'K = "K1 + s*KR + (W**2 - 1)*KGEO"')
    text = text[:text.index("[analyses.real_modes]")] + text[text.index("[analyses.cea]"):]
    return text[:text.index("[analyses.sweep]")] + STUDIES


def dense(W: float, s: float) -> np.ndarray:
    """λ (Im λ > 0) of the assembled problem by SciPy's dense QZ."""
    m = {k: v.toarray() for k, v in matrices().items()}
    M = m["M"]
    C = m["D1"] + W * m["DG"] + (1 / W - 1) * m["DR"] + m["D4"] / (2 * np.pi * 1600)
    K = m["K1"] + s * m["KR"] + (W ** 2 - 1) * m["KGEO"]
    n = len(M)
    eye, Z = np.eye(n), np.zeros((n, n))
    lam = sl.eig(np.block([[Z, eye], [-K, -C]]), np.block([[eye, Z], [Z, M]]), right=False)
    return lam[lam.imag > 0]


def in_band(lam: np.ndarray) -> np.ndarray:
    f = lam.imag / (2 * np.pi)
    return lam[(f >= BAND[0]) & (f <= BAND[1])]


@pytest.fixture(scope="module")
def serial(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("studies")
    (tmp / "scene.toml").write_text(scene_text())
    res = run_scene(load_scene(tmp / "scene.toml"), tmp / "out", write_fields=False, log=lambda *a, **k: None,
                    cache=tmp / "cache", report=False)
    return tmp, res


def test_map_points_equal_the_full_problem(serial):
    """The unstable count of every band at a grid corner and the checked points equal a dense solve, and the
    checked points' reduced eigenvalues equal the full sparse CEA (1e-6)."""
    tmp, res = serial
    red = res["map_reduction"]
    assert red["passed"] and len(red["verification"]) == 2 and red["max_rel_error"] <= 1e-6
    data = np.load(tmp / "out" / "stability_map.npz")
    s_axis, W_axis = data["axis/s"], data["axis/W"]
    assert data["total"].shape == (7, 7) and data["total"].max() > data["total"].min()
    for i, j in [(0, 0), (6, 6), (3, 5)]:
        lam = in_band(dense(W_axis[j], s_axis[i]))
        assert data["total"][i, j] == np.sum(lam.real > 1e-6 * np.abs(lam))
    for c in red["verification"]:
        lam = in_band(dense(c["point"]["W"], c["point"]["s"]))
        assert c["n_unstable_full"] == c["n_unstable_reduced"] == np.sum(lam.real > 1e-6 * np.abs(lam))
    # the map's instabilities (fem_squeal.reduced.stability_map.instabilities): every unstable point lies in
    # at least one and in at most as many as it has unstable modes; masks in the npz, table and picture written
    inst = data["instabilities"]
    assert inst.shape[1:] == (7, 7) and len(inst) == len(res["map"]["instabilities"]) >= 1
    cover = inst.sum(axis=0)
    assert np.array_equal(cover > 0, data["total"] > 0) and np.all(cover <= data["total"])
    files = ("stability_map_instabilities.csv", "stability_map_coupling.png", "stability_map_coupling.csv")
    assert all((tmp / "out" / f).is_file() for f in files)


def test_sensitivities_equal_central_differences_of_full_ceas(serial):
    """Reduced dλ/dp against (λ(p + h) − λ(p − h))/2h of full sparse CEAs: the difference's own error is
    ε|λ|/(h|dλ/dp|) (ε the CEA's accuracy) plus h²|λ'''|/6|λ'| (≈ (h/range)²/6 ≈ 2e-7); that bound, over
    every mode and parameter, is below 3e-6, and the reduced derivatives are within it plus 1e-6 (the basis)."""
    _, res = serial
    recs = res["sensitivity"]
    assert len(recs) >= 8 and not any(r["near_coalescence"] for r in recs)
    resolved = 0
    for r in recs:
        lam = r["real_part"] + 2j * np.pi * r["freq_hz"]
        for p in ("W", "s"):
            d = complex(r["full"]["d_real_part"][p], 2 * np.pi * r["full"]["d_freq_hz"][p])
            h = r["full"]["steps"][p]
            bound = EPS_CEA * abs(lam) / (h * abs(d)) + 2e-7
            assert r["full"]["rel_difference"][p] <= bound + 1e-6, (r["freq_hz"], p)
            resolved += bound < 3e-6        # the difference resolves the derivative to 3e-6
    assert resolved >= len(recs)
    assert res["sensitivity"][0]["full"]["steps"] == {"W": pytest.approx(2.5e-3), "s": pytest.approx(4e-4)}


def test_robustness_growth_rates_equal_the_full_problem(serial):
    """The Monte Carlo's largest growth rate in the band at 4 samples equals the dense solve's (1e-6 |λ|),
    and the spot checks against the full sparse CEA pass."""
    tmp, res = serial
    rob, red = res["robustness"], res["robustness_reduction"]
    assert red["passed"] and len(rob["spot_checks"]) == 2 and rob["n_samples"] == 64
    data = np.load(tmp / "out" / "robustness.npz")
    for k in (0, 17, 40, 63):
        lam = in_band(dense(data["sample/W"][k], data["sample/s"][k]))
        assert abs(data["max_growth"][k] - lam.real.max()) <= 1e-6 * np.abs(lam).max()
    assert set(rob["drivers"]) == {"W", "s"}


@pytest.mark.parametrize("key, value, message", [
    ("analyses.map.parameters", '["W", "X"]', "analyses.map.parameters: 'X' is not a parameter of matrices"),
    ("analyses.map.parameters", '["W", "W"]', "analyses.map.parameters: one or two distinct names"),
    ("analyses.map.ranges", "{ W = [0.0, 1.0] }",
     "analyses.map.ranges: matrices.C: the coefficient 1.0 / W - 1.0"),
    ("analyses.sensitivity.parameters", '["mu"]', "analyses.sensitivity.parameters: 'mu' is not a parameter"),
    ("analyses.robustness.parameters", '{ X = { distribution = "uniform", lower = 0.9, upper = 1.1 } }',
     "analyses.robustness.parameters.X: 'X' is not a parameter"),
])
def test_bad_names_are_named_errors(tmp_path, key, value, message):
    (tmp_path / "scene.toml").write_text(scene_text())
    with pytest.raises(SceneError, match=message.replace("[", r"\[").replace("(", r"\(")):
        load_scene(tmp_path / "scene.toml", [f"{key}={value}"])


def test_distributed_basis_on_one_rank_equals_the_serial_one():
    """fem_squeal.fe.matrix_basis (PETSc/SLEPc, on COMM_SELF) against the SciPy basis: the same real modes
    (1e-10) and the same reduced eigenvalues at three values of W (1e-8)."""
    from mpi4py import MPI

    from fem_squeal.fe.matrix_basis import reduce_rows
    from fem_squeal.reduced.matrix_model import matrix_model
    from fem_squeal.reduced.matrix_reduction import reduce_matrix_model
    from fem_squeal.reduced.sweep import solve_points

    mats = matrices()
    model = matrix_model({"M": "M", "C": "D1 + W*DG + (1/W - 1)*DR + D4/(2*pi*1600)",
                          "K": "K1 + KR + (W**2 - 1)*KGEO"}, list(mats), {"W": 1.0}, {"W": (0.5, 3.0)})
    a, b = reduce_matrix_model(model, mats, modes=8), reduce_rows(model, mats, MPI.COMM_SELF, 8)
    assert a.size == b.size == 26       # of 48 DOFs: 8 modes and 18 corrections (16 modes fill the space)
    fa, fb = np.array(a.info["modes_hz"]), np.array(b.info["modes_hz"])
    assert np.max(np.abs(fa - fb) / fa) <= 1e-10
    for W in (0.6, 1.0, 2.9):
        la, lb = (np.sort_complex(solve_points(r, {"W": np.array([W])})[0]) for r in (a, b))
        assert np.max(np.abs(la - lb) / np.abs(la)) <= 1e-8


@pytest.mark.slow           # a 2-rank run (~10 s); the distributed basis on 2 ranks in the default suite: the
@pytest.mark.mpi            # sweep of tests/integration/test_matrices.py::test_two_ranks_equal_one
def test_two_ranks_equal_one(serial, mpirun, tmp_path):
    """The scene on 2 ranks (the modal basis built distributed): the map's, the derivatives' and the
    samples' eigenvalues equal one rank's (1e-8) (the sweep's: tests/integration/test_matrices.py)."""
    one_dir, one = serial
    (tmp_path / "scene.toml").write_text(scene_text())
    p = subprocess.run(mpirun + [sys.executable, "-m", "fem_squeal.cli", "--cache-dir", str(tmp_path / "cache"),
                                 "--log-level", "warning", "run", str(tmp_path / "scene.toml"), "-o",
                                 str(tmp_path / "out"), "--no-report"], capture_output=True, text=True,
                       env=clean_env(), cwd=ROOT, timeout=300)
    assert p.returncode == 0, p.stdout[-3000:] + p.stderr[-3000:]
    two = json.loads((tmp_path / "out" / "results.json").read_text())
    assert two["run"]["ranks"] == 2 and "2 rank" in two["map_reduction"]["built_on"]
    ma, mb = (np.load(d / "out" / "stability_map.npz") for d in (one_dir, tmp_path))
    la, lb = np.sort_complex(ma["eigenvalues"]), np.sort_complex(mb["eigenvalues"])
    assert np.max(np.abs(la - lb) / np.abs(la)) <= 1e-8 and np.array_equal(ma["total"], mb["total"])
    assert np.array_equal(ma["instabilities"], mb["instabilities"])
    for ra, rb in zip(one["sensitivity"], two["sensitivity"], strict=True):
        for p_ in ("W", "s"):
            da = complex(ra["d_real_part"][p_], ra["d_freq_hz"][p_])
            db = complex(rb["d_real_part"][p_], rb["d_freq_hz"][p_])
            assert abs(da - db) <= 1e-8 * abs(da)
    ga, gb = (np.load(d / "out" / "robustness.npz")["max_growth"] for d in (one_dir, tmp_path))
    assert np.max(np.abs(ga - gb)) <= 1e-8 * 2 * np.pi * BAND[1]
    assert two["robustness"]["probability"] == one["robustness"]["probability"]
