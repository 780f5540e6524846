"""A parametric QEP given only as matrices and expressions (scenes/matrices_brake.toml): the CEA and the
real modes of the scene run equal a direct dense solve of the assembled problem with SciPy (1e-10
relative), at two points of the parameter W, and 1 and 2 ranks give the same results; the sweep of W on
the reduced model (real modes + static corrections, or snapshots) against the full problem (1e-6)."""
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
from fem_squeal.app.scene import apply_overrides, load_scene, read_scene, validate
from fem_squeal.reduced.matrix_model import matrix_model
from fem_squeal.reduced.matrix_reduction import reduce_matrix_model
from fem_squeal.reduced.sweep import solve_points
from fem_squeal.util.errors import SceneError

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


OUT = {}


def eigenvalues(res: dict) -> np.ndarray:
    return np.array([c["real_part"] + 2j * np.pi * c["freq_hz"] for c in res["complex_modes"]])


@pytest.fixture(scope="module")
def serial(tmp_path_factory):
    """The scene run at W = 1 and W = 2.5 (one rank, in this process; the output folders in OUT)."""
    out = {}
    for W in (1.0, 2.5):
        tmp = tmp_path_factory.mktemp(f"w{W}")
        OUT[W] = tmp / "out"
        raw = apply_overrides(read_scene(SCENE), [f"matrices.parameters.W.value={W}"])
        if W != 1.0:
            del raw["analyses"]["sweep"]        # the sweep: at W = 1 only
        scene = validate(raw)
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
                                 "--set", "analyses.sweep.n=11", "--set", "analyses.sweep.check_points=0",
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
    la, sa = _sweep_branches(OUT[1.0])         # the same sweep (the basis is built on rank 0): 11 of its
    lb, sb = _sweep_branches(tmp_path / "out")  # 51 values on 2 ranks, the same eigenvalues there
    assert np.allclose(sa["values"][::5], sb["values"], rtol=1e-14)
    la, lb = np.sort_complex(la[:, ::5].T), np.sort_complex(lb.T)
    assert la.shape == lb.shape and np.max(np.abs(la - lb) / np.abs(la)) <= 1e-8
    assert np.allclose([c["value"] for c in sa["critical"]], [c["value"] for c in sb["critical"]], rtol=1e-8)


def _sweep_branches(folder) -> tuple[np.ndarray, dict]:
    s = json.loads((folder / "sweep.json").read_text())
    lam = np.array([np.array(b["real_part"]) + 2j * np.pi * np.array(b["freq_hz"]) for b in s["branches"]])
    return lam, s


def test_sweep_on_the_reduced_model_equals_the_full_problem(serial):
    """The sweep's tracked eigenvalues (every 10th value) equal the dense solve of the full problem within
    1e-6, its check against the full sparse CEA passed, and at each critical value the full problem has a
    root on the imaginary axis (|Re λ| <= growth_tol |λ|) near the reported frequency (that of the grid value
    next to it on its unstable side)."""
    res = serial[1.0]
    red = res["sweep_reduction"]
    assert red["basis"] == "modes" and red["passed"] and len(red["verification"]) == 3
    assert red["max_rel_error"] <= 1e-6
    lam, s = _sweep_branches(OUT[1.0])
    for k in range(0, len(s["values"]), 10):
        ref, _ = dense_reference(s["values"][k])
        assert np.max(np.min(np.abs(lam[:, k, None] - ref[None, :]), axis=1) / np.abs(lam[:, k])) <= 1e-6
    crit = res["sweep"]["critical"]
    assert [round(c["value"], 3) for c in crit] == [0.578, 1.911]
    for c in crit:
        ref, _ = dense_reference(c["value"])
        near = ref[np.argmin(np.abs(ref.imag / (2 * np.pi) - c["freq_hz"]))]
        assert abs(near.real) <= 1e-6 * abs(near)
        assert abs(near.imag / (2 * np.pi) - c["freq_hz"]) < 1e-3 * c["freq_hz"]


def test_snapshot_basis_of_the_non_symmetric_problem():
    """Eigenvectors of the non-symmetric problem at 5 values of W (14 each, near 600 Hz) span a basis
    that gives the eigenvalues in 400-700 Hz over the range within 1e-6."""
    mats = matrices()
    model = matrix_model({"M": "M", "C": "D1 + W*DG + (1/W - 1)*DR + D4/(2*pi*1600)",
                          "K": "K1 + KR + (W**2 - 1)*KGEO"}, list(mats), {"W": 1.0}, {"W": (0.5, 3.0)})
    r = reduce_matrix_model(model, mats, basis="snapshots", snapshot_modes=14, target_hz=600.0,
                            snapshot_points=[{"W": w} for w in np.linspace(0.5, 3.0, 5)])
    assert r.info["basis"] == "snapshots" and r.size < 48
    for W in (0.7, 2.2):
        lam = solve_points(r, {"W": np.array([W])})[0]
        ref, _ = dense_reference(W)
        ref = ref[(ref.imag / (2 * np.pi) > 400) & (ref.imag / (2 * np.pi) < 700)]
        assert np.max(np.min(np.abs(ref[:, None] - lam[None, :]), axis=1) / np.abs(ref)) <= 1e-6


def resolved_difference(a, b, points) -> float:
    """The largest relative difference between the reduced eigenvalues of ``a`` the basis resolves (within
    1e-6 of the dense reference) and the nearest of ``b``'s, at the values ``points`` of W."""
    worst = 0.0
    for W in points:
        ref = np.concatenate(dense_reference(W)[:1])
        la, lb = (solve_points(r, {"W": np.array([W])})[0] for r in (a, b))
        la = la[la.imag > 0]
        good = la[np.min(np.abs(la[:, None] - ref[None, :]), axis=1) <= 1e-6 * np.abs(la)]
        assert len(good) >= 3
        worst = max(worst, float(np.max(np.min(np.abs(good[:, None] - lb[None, :]), axis=1) / np.abs(good))))
    return worst


def test_distributed_snapshot_basis_equals_the_serial_one():
    """fem_squeal.fe.matrix_snapshots (SLEPc's TOAR on the rows, here on COMM_SELF; the 2-rank run:
    tests/mpi/test_matrix_snapshots_mpi.py) against the SciPy snapshot basis: the same eigenpairs chosen
    (14 nearest ±600 Hz, 6 nearest 0), the same size, the eigenvalues it resolves equal to 1e-10."""
    from mpi4py import MPI

    from fem_squeal.fe.matrix_snapshots import reduce_snapshot_rows

    mats = matrices()
    model = matrix_model({"M": "M", "C": "D1 + W*DG + (1/W - 1)*DR + D4/(2*pi*1600)",
                          "K": "K1 + KR + (W**2 - 1)*KGEO"}, list(mats), {"W": 1.0}, {"W": (0.5, 3.0)})
    points = [{"W": w} for w in np.linspace(0.5, 3.0, 5)]
    for k, target in ((14, 600.0), (6, 0.0)):
        a = reduce_matrix_model(model, mats, basis="snapshots", snapshot_modes=k, target_hz=target,
                                snapshot_points=points)
        b = reduce_snapshot_rows(model, mats, MPI.COMM_SELF, points, k, target)
        assert b.info["basis"] == "snapshots" and a.size == b.size < 48
        assert resolved_difference(a, b, (0.7, 1.0, 2.2)) <= 1e-10


@pytest.mark.parametrize("sets, message", [
    (["analyses.sweep.parameter='X'"], "analyses.sweep.parameter: 'X' is not a parameter"),
    (["analyses.sweep.points=[0.5, 1.0]", "analyses.sweep.range=[0.5, 1.0]"],
     "analyses.sweep.points: give points or range, not both"),
    (["analyses.sweep.points=[0.0, 1.0]"],
     "analyses.sweep.points: matrices.C: the coefficient 1.0 / W - 1.0 of DR is not a finite"),
    (["analyses.sweep.basis='pod'"], "analyses.sweep.basis: must be one of"),
])
def test_sweep_bad_input_is_a_named_error(sets, message):
    with pytest.raises(SceneError, match=message.replace("[", r"\[")):
        load_scene(SCENE, sets)
