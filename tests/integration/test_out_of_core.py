"""Out-of-core factors chosen by the memory model (issue 36, fem_squeal.app.resources): a run whose
in-core factors would not fit keeps every MUMPS factor in files of a folder of its own, says so in
results.json, removes the folder afterwards, and gives the in-core run's eigenvalues."""
from __future__ import annotations

import os
import socket
import subprocess
import sys
import threading
from pathlib import Path

import numpy as np
import pytest
from mpi4py import MPI
from support.memory import between_the_fits

from fem_squeal.app import resources
from fem_squeal.app.run import run_scene
from fem_squeal.app.scene import load_scene
from fem_squeal.fe.eigen.block_krylov import OUT_OF_CORE_BLOCK, block_size

RING = Path(__file__).resolve().parents[2] / "scenes" / "ryzhik_ring.toml"


def _eigenvalues(res: dict) -> np.ndarray:
    return np.array([m["real_part"] + 1j * m["freq_hz"] * 2 * np.pi for m in res["complex_modes"]])


def test_a_run_that_does_not_fit_in_core_goes_out_of_core(tmp_path, monkeypatch):
    """The ring on a machine faked to hold its out-of-core but not its in-core factors.  Files appear in
    the run's folder under $MUMPS_OOC_TMPDIR while it runs (polled), and none is left; the folder a killed
    run on this machine left goes too.  The factors are
    the in-core ones stored elsewhere and the eigensolves converge to 1e-10 on the shifted operator, so
    the two runs' eigenvalues differ by rounding of their solves only: 1e-9 relative allows both runs'
    tolerance twice over; the same unstable set."""
    scene = load_scene(RING, ["geometry.mesh_size=0.003"])
    _, _, machine = between_the_fits(scene)
    folder = tmp_path / "ooc"
    folder.mkdir()
    monkeypatch.setenv("MUMPS_OOC_TMPDIR", str(folder))
    # a killed run's folder (its process is gone) is removed; a live run's and another machine's are kept
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    host = socket.gethostname()
    stale, live, other = (folder / f"fem_squeal_factors.{h}.{pid}.x" for h, pid in
                          ((host, dead.pid), (host, os.getpid()), ("elsewhere", dead.pid)))
    for d in (stale, live, other):
        d.mkdir()
        (d / "mumps_0_x").write_bytes(b"0" * 1000)
    with monkeypatch.context() as m:
        m.setattr(resources, "machine_memory", lambda: machine)
        seen, done = set(), threading.Event()

        def poll():
            while not done.wait(0.002):
                try:    # a folder may go while it is listed (the killed run's, removed by this one)
                    seen.update(p.name for p in folder.glob("fem_squeal_factors.*/mumps_*"))
                except FileNotFoundError:
                    pass
        watcher = threading.Thread(target=poll)
        watcher.start()
        lines: list[str] = []
        try:
            out = run_scene(scene, tmp_path / "out", MPI.COMM_SELF, write_fields=False, report=False,
                            log=lambda *a, **k: lines.append(" ".join(map(str, a))))
        finally:
            done.set()
            watcher.join()
    assert out["solver"]["factors"] == out["estimate"]["factors"] == "out of core (memory model)"
    assert any("the factors go out of core" in line and "MUMPS_OOC_TMPDIR" in line for line in lines)
    assert seen and sorted(folder.iterdir()) == sorted([live, other])
    assert any("removed 1e-06 GB of factor files that killed runs left" in line for line in lines)
    ref_lines: list[str] = []
    ref = run_scene(scene, tmp_path / "ref", MPI.COMM_SELF, write_fields=False, report=False,
                    log=lambda *a, **k: ref_lines.append(" ".join(map(str, a))))
    assert ref["solver"]["factors"] == "in core"
    # the CEA's blocks: wider where each solve reads the factor back from its files
    wide, default = OUT_OF_CORE_BLOCK, block_size(scene.analyses["cea"]["n_modes"])
    assert default < wide and any(f"block Arnoldi, {wide} columns" in line for line in lines)
    assert any(f"block Arnoldi, {default} columns" in line for line in ref_lines)
    assert out["solver"]["paths"]["cea"]["block_arnoldi"] == {f"{wide} columns": 1}      # results.json says so
    assert ref["solver"]["paths"]["cea"]["block_arnoldi"] == {f"{default} columns": 1}
    # every computed stage says the peak memory so far (getrusage's high-water mark: it never falls)
    peaks = [st["peak_rss_gib"]["largest_rank"] for st in ref["stages"]]
    assert len(peaks) == len(ref["stages"]) and 0 < peaks[0] and peaks == sorted(peaks)
    assert all(st["peak_rss_gib"]["sum_of_ranks"] == st["peak_rss_gib"]["largest_rank"] for st in ref["stages"])
    a, b = _eigenvalues(out), _eigenvalues(ref)
    assert len(a) == len(b) > 0 and out["n_unstable"] == ref["n_unstable"]
    assert np.abs(a - b).max() <= 1e-9 * np.abs(b).max()
    assert [m["unstable"] for m in out["complex_modes"]] == [m["unstable"] for m in ref["complex_modes"]]


def test_out_of_core_refused_where_its_files_do_not_fit(tmp_path, monkeypatch):
    """The files' disk is checked before meshing: too small, or no folder, is refused naming it."""
    from fem_squeal.util.errors import ResourceError

    scene = load_scene(RING, ["geometry.mesh_size=0.003"])
    _, ooc, machine = between_the_fits(scene)
    monkeypatch.setattr(resources, "machine_memory", lambda: machine)
    monkeypatch.setenv("MUMPS_OOC_TMPDIR", str(tmp_path))
    est, notes = resources.check_resources(scene, MPI.COMM_SELF)
    assert est.factors == "out of core (memory model)" and est.memory_gib == pytest.approx(ooc / resources.GIB)
    monkeypatch.setattr(resources, "factor_file_bytes", lambda n: 1e18)
    with pytest.raises(ResourceError, match=rf"factor files need about 1e\+09 GB under {tmp_path}, which has"):
        resources.check_resources(scene, MPI.COMM_SELF)
    monkeypatch.setenv("MUMPS_OOC_TMPDIR", str(tmp_path / "missing"))
    with pytest.raises(ResourceError, match=r"MUMPS_OOC_TMPDIR=.*missing: not a folder"):
        resources.check_resources(scene, MPI.COMM_SELF)


def test_out_of_core_the_preload_preconditions_with_the_frictionless_cholesky(tmp_path, monkeypatch):
    """The brake corner (coarse) on a machine faked to hold its out-of-core but not its in-core factors:
    preload.jacobian "auto" takes "symmetric" there (its in-core Cholesky fits: fem_squeal.app.resources.
    preload_jacobian), so the preload factorises no LU (CHOLMOD of the frictionless Jacobian, GMRES on the
    Jacobian), and results.json says so.  The state is the default path's within 1e-10 (tests/integration/
    test_brake.py), so the CEA on the out-of-core LU gives the in-core run's pairs to the eigensolves'
    tolerance (1e-9 relative, as above) and the same unstable set."""
    sets = ["geometry.mesh_size=0.016", "analyses.cea.band_hz=[0.0, 6000.0]", "analyses.cea.n_modes=20",
            "analyses.cea.coupling=false"]
    scene = load_scene(RING.parent / "brake_corner_cea.toml", sets)
    exact, ooc, machine = between_the_fits(scene)
    assert resources.solve_memory(resources.estimate(scene).dofs, kind="symmetric") < 0.5 * (exact + ooc)
    monkeypatch.setenv("MUMPS_OOC_TMPDIR", str(tmp_path))
    ref = run_scene(scene, tmp_path / "ref", MPI.COMM_SELF, write_fields=False, report=False,
                    log=lambda *a, **k: None)
    monkeypatch.setattr(resources, "machine_memory", lambda: machine)
    out = run_scene(scene, tmp_path / "out", MPI.COMM_SELF, write_fields=False, report=False,
                    log=lambda *a, **k: None)
    assert ref["solver"]["factors"] == "in core" and ref["preload"]["jacobian"] == "update"
    assert out["solver"]["factors"] == "out of core (memory model)" and out["preload"]["jacobian"] == "symmetric"
    steps = out["solver"]["paths"]["preload"]["newton_step"]
    assert "symmetric factorisation (cholmod), GMRES" in steps and "factorisation" not in steps, steps
    a, b = _eigenvalues(out), _eigenvalues(ref)
    assert len(a) == len(b) > 0 and out["n_unstable"] == ref["n_unstable"]
    assert np.abs(a - b).max() <= 1e-9 * np.abs(b).max()
