"""Nothing lost, nothing silently wrong (issue 35): faults injected into the cache and the output folder.

A coarse ring scene with a CEA, a reduced model and a μ sweep writes every kind of cached file
(``.h5``, ``.xdmf``, ``.vtu``, ``.npz``, ``.json``, ``.png``).  Each fault below is applied to a copy of
its cache; the next run must recompute exactly the damaged stage (the others stay cached: keys are
content hashes) and give the clean run's numbers.  A recomputed stage runs the same code on the same
input in the same process, so its numbers are compared to 1e-12 relative (round-off of a
re-factorisation at most), not exactly.  The ring is meshed at 0.003 m, where gmsh's default Delaunay
mesh passes the quality check: at 0.004 m only HXT does, and HXT's mesh differs from run to run.
"""
from __future__ import annotations

import errno
import json
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import pytest
from mpi4py import MPI

from fem_squeal.app import outputs as outputs_module
from fem_squeal.app import run as run_module
from fem_squeal.app.cache import Cache
from fem_squeal.app.pipeline import make_plan
from fem_squeal.app.run import run_scene
from fem_squeal.app.scene import load_scene
from fem_squeal.util.errors import StorageError
from fem_squeal.util.storage import digest

ROOT = Path(__file__).resolve().parents[2]
RING = ROOT / "scenes" / "ryzhik_ring.toml"
SETS = ["geometry.mesh_size=0.003", "analyses.sweep.n=5", "analyses.reduced.band_hz=[100.0, 5000.0]"]
QUIET = dict(log=lambda *a, **k: None)


def ring(*extra: str):
    return load_scene(RING, SETS + list(extra))


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    """One clean run with fields: (cache folder, output folder, results)."""
    base = tmp_path_factory.mktemp("reference")
    res = run_scene(ring(), base / "out", MPI.COMM_SELF, cache=base / "cache", **QUIET)
    return base / "cache", base / "out", res


def copy_cache(reference, tmp_path) -> Path:
    cache = tmp_path / "cache"
    shutil.copytree(reference[0], cache)
    return cache


def entry_of(cache: Path, stage: str) -> Path:
    (e,) = [p for p in Cache(cache).entries() if p.name.startswith(f"{stage}-")]
    return e


def numbers(res: dict) -> dict:
    """The computed numbers of the ring run that a recomputation must reproduce."""
    return {"cea": [(m["freq_hz"], m["real_part"]) for m in res["complex_modes"]],
            "reduced": res["reduced"]["size"],
            "sweep": [(c["value"], c["freq_hz"]) for c in res["sweep"]["critical"]]}


def assert_same_numbers(a: dict, b: dict) -> None:
    na, nb = numbers(a), numbers(b)
    assert na["reduced"] == nb["reduced"]
    for key in ("cea", "sweep"):
        assert len(na[key]) == len(nb[key])
        for x, y in zip(na[key], nb[key]):
            assert x == pytest.approx(y, rel=1e-12, abs=1e-9), key


def damage(path: Path, how: str) -> None:
    data = path.read_bytes()
    if how == "truncate":
        path.write_bytes(data[: min(1000, len(data) // 2)])
    elif how == "bitflip":                          # one bit in the middle: the size stays
        i = len(data) // 2
        path.write_bytes(data[:i] + bytes([data[i] ^ 0x10]) + data[i + 1:])
    elif how == "delete":
        path.unlink()
    elif how == "edit":                             # still valid JSON, one number changed
        e = json.loads(data)
        e["seconds"] = e["seconds"] + 1.0
        path.write_text(json.dumps(e))
    else:
        raise ValueError(how)


# every fault on each kind the issue names (.h5, .npz, .json, .vtu), and on the XDMF, a plot and the index
FAULTS = [(stage, name, how) for stage, name in (("cea", "complex_modes.h5"), ("reduced", "reduced_model.npz"),
                                                 ("sweep", "sweep.json"), ("cea", "complex_modes.vtu"))
          for how in ("truncate", "bitflip", "delete")]
FAULTS += [("cea", "complex_modes.xdmf", "delete"), ("sweep", "root_locus.png", "delete"),
           ("cea", "entry.json", "truncate"), ("sweep", "entry.json", "edit"), ("reduced", "entry.json", "delete")]


@pytest.mark.parametrize("stage,name,how", FAULTS, ids=[f"{s}-{n}-{h}" for s, n, h in FAULTS])
def test_a_damaged_entry_is_recomputed_never_published(reference, tmp_path, stage, name, how):
    cache = copy_cache(reference, tmp_path)
    damage(entry_of(cache, stage) / name, how)
    plan = {p.stage: p for p in make_plan(ring(), Cache(cache))}
    assert plan[stage].status == "run" and plan[stage].note.startswith(f"cache entry {stage}-")
    assert all(p.status in ("cached", "memory") for s, p in plan.items() if s != stage)
    said = []
    res = run_scene(ring(), tmp_path / "out", MPI.COMM_SELF, cache=cache, log=said.append)
    status = {s["stage"]: s["status"] for s in res["stages"]}
    assert status[stage] == "run" and {status[s] for s in ("cea", "reduced", "sweep") if s != stage} == {"cached"}
    assert any("warning: cache entry" in m and stage in m for m in said), said
    assert_same_numbers(res, reference[2])
    # what was published is the new entry, byte for byte, and the entry verifies again
    entry = entry_of(cache, stage)
    assert Cache(cache).verify_folder(entry).state == "ok"
    files = json.loads((entry / "entry.json").read_text())["files"]
    for rel, rec in files.items():
        assert digest(tmp_path / "out" / rel) == (rec["size"], rec["sha256"])
    assert not [p for p in cache.iterdir() if p.name.startswith(".")]


def test_outputs_are_copies_and_an_edited_output_is_republished(reference, tmp_path, monkeypatch):
    cache = copy_cache(reference, tmp_path)
    out = tmp_path / "out"
    run_scene(ring(), out, MPI.COMM_SELF, cache=cache, **QUIET)
    cea = entry_of(cache, "cea")
    h5 = out / "complex_modes.h5"
    assert os.stat(h5).st_ino != os.stat(cea / "complex_modes.h5").st_ino
    with open(h5, "r+b") as f:                      # a tool that rewrites the output in place
        f.seek(4096)
        f.write(b"\0" * 64)
    assert Cache(cache).verify_folder(cea).state == "ok"
    table = run_module._stage_functions()
    monkeypatch.setattr(run_module, "_stage_functions",
                        lambda: {n: (lambda *a: pytest.fail("recomputed")) for n in table})
    run_scene(ring(), out, MPI.COMM_SELF, cache=cache, **QUIET)
    rec = json.loads((cea / "entry.json").read_text())["files"]["complex_modes.h5"]
    assert digest(h5) == (rec["size"], rec["sha256"])


def snapshot(folder: Path) -> dict[str, tuple[int, str]]:
    return {str(p.relative_to(folder)): digest(p) for p in sorted(folder.rglob("*")) if p.is_file()}


def test_no_space_for_the_outputs_changes_nothing(reference, tmp_path, monkeypatch):
    """An injected ENOSPC while the outputs are copied: a StorageError naming the folder and what was
    being written; the folder holds exactly the earlier run's files, and no temporary."""
    out = tmp_path / "out"
    shutil.copytree(reference[1], out)
    before = snapshot(out)
    cache = copy_cache(reference, tmp_path)

    def full(src, dst):
        Path(dst).write_bytes(b"x" * 10)             # a partial write, then the disk is full
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), str(dst))

    monkeypatch.setattr(outputs_module, "clone_file", full)
    with pytest.raises(StorageError, match=r"No space left on device while copying sweep-\w+/"):
        run_scene(ring("analyses.sweep.n=6"), out, MPI.COMM_SELF, cache=cache, **QUIET)
    assert snapshot(out) == before


def test_no_space_for_results_json_changes_nothing(reference, tmp_path, monkeypatch):
    """ENOSPC while results.json is written (after the stage files were staged): StorageError (exit 4),
    the folder as it was."""
    out = tmp_path / "out"
    shutil.copytree(reference[1], out)
    before = snapshot(out)

    def full(path, data):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), str(path))

    monkeypatch.setattr(run_module, "write_json_atomic", full)
    with pytest.raises(StorageError, match=r"results.json: No space left on device while writing the outputs"):
        run_scene(ring("analyses.sweep.n=6"), out, MPI.COMM_SELF, cache=copy_cache(reference, tmp_path), **QUIET)
    assert snapshot(out) == before
    assert StorageError("x").exit_code == 4


def test_a_report_failure_changes_nothing(reference, tmp_path, monkeypatch):
    out = tmp_path / "out"
    shutil.copytree(reference[1], out)
    before = snapshot(out)

    def broken(*a, **k):
        raise RuntimeError("report section failed")

    monkeypatch.setattr(run_module, "write_report", broken)
    with pytest.raises(RuntimeError, match="report section failed"):
        run_scene(ring("analyses.sweep.n=6"), out, MPI.COMM_SELF, cache=copy_cache(reference, tmp_path), **QUIET)
    assert snapshot(out) == before


@pytest.fixture
def small_fs(tmp_path):
    """A 1 MB tmpfs (root only; skipped elsewhere), unmounted afterwards."""
    mnt = tmp_path / "small"
    mnt.mkdir()
    p = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=1m", "tmpfs", str(mnt)], capture_output=True)
    if p.returncode != 0:
        pytest.skip(f"cannot mount a small tmpfs here ({p.stderr.decode().strip()})")
    yield mnt
    subprocess.run(["umount", "-l", str(mnt)], check=False)


def test_a_full_output_file_system(reference, tmp_path, small_fs):
    """The outputs (about 5 MB) do not fit a 1 MB file system: refused before anything is written,
    naming the bytes needed."""
    out = small_fs / "out"
    with pytest.raises(StorageError, match=r"no space left for the outputs of .* MB needed"):
        run_scene(ring(), out, MPI.COMM_SELF, cache=copy_cache(reference, tmp_path), **QUIET)
    assert [p.name for p in out.iterdir()] == []


def test_a_full_cache_file_system(tmp_path, small_fs, child_env):
    """The cache on a 1 MB file system: the CEA's 2 MB HDF5 file (written by PETSc) cannot be, the run
    exits 4 naming the stage, no temporary folder is left, the entries that fitted verify."""
    cache = small_fs / "cache"
    cmd = [sys.executable, "-m", "fem_squeal.cli", "--cache-dir", str(cache), "run", str(RING),
           "-o", str(tmp_path / "out")] + [a for s in SETS for a in ("--set", s)]
    p = subprocess.run(cmd, capture_output=True, text=True, timeout=600, env=child_env)
    assert p.returncode == 4, p.stdout + p.stderr
    last = p.stderr.strip().splitlines()[-1]
    assert last.startswith("fem-squeal: error: ") and "cache entry of stage cea" in last, p.stderr
    assert "No space left on device" in last or "no space left on device" in last
    assert not [x for x in cache.iterdir() if x.name.startswith(".")]
    assert all(v.state == "ok" for _, v in Cache(cache).check_all())
    assert not (tmp_path / "out" / "results.json").exists()


def test_no_fields_is_not_an_input(reference, tmp_path, monkeypatch):
    """A --no-fields run caches the same entries (the fields inside); the same scene with fields then
    computes nothing and publishes them."""
    cache = tmp_path / "cache"
    run_scene(ring(), tmp_path / "a", MPI.COMM_SELF, cache=cache, write_fields=False, **QUIET)
    assert not list((tmp_path / "a").glob("*.vtu")) and not list((tmp_path / "a").glob("*.h5"))
    assert [p.status for p in make_plan(ring(), Cache(cache))] == ["cached"] * 6
    assert sorted(p.name for p in Cache(cache).entries()) == sorted(p.name for p in Cache(reference[0]).entries())
    table = run_module._stage_functions()
    monkeypatch.setattr(run_module, "_stage_functions",
                        lambda: {n: (lambda *a: pytest.fail("recomputed")) for n in table})
    res = run_scene(ring(), tmp_path / "b", MPI.COMM_SELF, cache=cache, **QUIET)
    assert {"complex_modes.vtu", "complex_modes.h5", "complex_modes.xdmf"} <= set(res["files"])
    assert (tmp_path / "b" / "complex_modes.vtu").stat().st_size > 0
    # and back: a --no-fields run into the same folder removes the fields it does not publish
    run_scene(ring(), tmp_path / "b", MPI.COMM_SELF, cache=cache, write_fields=False, **QUIET)
    assert not (tmp_path / "b" / "complex_modes.vtu").exists()


def test_cache_verify_removes_only_bad_entries(reference, tmp_path, child_env):
    cache = copy_cache(reference, tmp_path)
    bad = entry_of(cache, "reduced")
    damage(bad / "reduced_model.npz", "bitflip")
    stale = cache / ".sweep-0123.killed"
    stale.mkdir()
    os.utime(stale, (time.time() - 7200,) * 2)
    cli = [sys.executable, "-m", "fem_squeal.cli", "--cache-dir", str(cache), "cache"]
    listing = subprocess.run(cli, capture_output=True, text=True, timeout=120, env=child_env)
    assert listing.returncode == 0 and "6 entries" in listing.stdout and bad.exists()
    p = subprocess.run(cli + ["--verify"], capture_output=True, text=True, timeout=120, env=child_env)
    assert p.returncode == 0, p.stderr
    line = next(x for x in p.stdout.splitlines() if bad.name in x)
    assert "BAD, removed: reduced_model.npz does not match its recorded SHA-256" in line
    assert not bad.exists() and not stale.exists()
    assert len(Cache(cache).entries()) == 5 and "1 bad entries removed" in p.stdout


def _pad_toml(path: Path) -> Path:
    path.write_text('[analyses.segmented_pad]\nspeeds = [0.005, 0.3]\nt_end = 0.02\ndt = 4e-5\n')
    return path


@pytest.mark.mpi
@pytest.mark.parametrize("ranks", [1, 2])
def test_two_runs_at_once_on_one_cache(tmp_path, ranks, mpirun, child_env):
    """Two runs of one scene started together on one cache (each on ``ranks`` ranks): both finish,
    with identical results, and the cache holds one verified entry."""
    scene = _pad_toml(tmp_path / "pad.toml")
    cache = tmp_path / "cache"
    env = child_env
    prefix = [] if ranks == 1 else mpirun
    procs = [subprocess.Popen(prefix + [sys.executable, "-m", "fem_squeal.cli", "--cache-dir", str(cache), "run",
                                        str(scene), "-o", str(tmp_path / f"out{i}")],
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
             for i in range(2)]
    for p in procs:
        _, err = p.communicate(timeout=600)
        assert p.returncode == 0, err
    a, b = (json.loads((tmp_path / f"out{i}" / "results.json").read_text())["segmented_pad"] for i in range(2))
    a.pop("seconds"), b.pop("seconds")
    assert a == b
    found = Cache(cache).check_all()
    assert len(found) == 1 and found[0][1].state == "ok"
