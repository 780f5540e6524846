"""The stage graph, the content-hash cache and the report (issue 7).

- Requested analyses pull in only the stages they need (no mesh for the segmented pad, no CEA for
  a sweep, no reduced model for a ring CEA).
- Keys: a change re-keys exactly the stages that read it and those after them.
- Cache: an unchanged scene computes nothing (the stage functions are replaced by ones that
  fail); a failed or killed stage leaves no entry and the next run recomputes it.
- The same ring scene on 1 and 2 MPI ranks gives the same results.json numbers to 1e-8.
- report.html opens in headless Chromium and all its images decode.
"""
from __future__ import annotations

import base64
import io
import json
import os
import re
import shutil
import signal
import subprocess
import sys
import time

import numpy as np
import pytest
from mpi4py import MPI
from support.paths import ROOT
from support.processes import clean_env

from fem_squeal.app import run as run_module
from fem_squeal.app.mode_shapes import NPZ, ModeShapes
from fem_squeal.app.pipeline import Cache, PipelineError, make_plan, required, stage_keys
from fem_squeal.app.run import run_scene
from fem_squeal.app.scene import load_scene, validate

RING = ROOT / "scenes" / "ryzhik_ring.toml"
BRAKE_MAP = ROOT / "scenes" / "brake_mu_E_map.toml"
QUIET = dict(log=lambda *a, **k: None)


def pad_scene(**kw) -> dict:
    a = {"speeds": [0.005, 0.3], "t_end": 0.02, "dt": 4e-5, **kw}
    return validate({"title": "pad", "analyses": {"segmented_pad": a}})


def test_stages_are_pulled_in_by_the_analyses():
    assert required(pad_scene()) == ["segmented_pad"]
    assert required(load_scene(RING)) == ["mesh", "operators", "preload", "cea"]
    brake = load_scene(BRAKE_MAP)
    assert required(brake) == ["mesh", "operators", "preload", "cea", "reduced", "sweep", "map"]
    sweep_only = load_scene(RING, ["analyses.sweep.n=11"])
    sweep_only["analyses"].pop("cea")
    assert "cea" not in required(sweep_only)      # a μ sweep needs no full CEA


def test_keys_change_only_downstream_of_the_change():
    base = load_scene(BRAKE_MAP)
    stages = required(base)
    k0 = stage_keys(base, stages, version="v")

    def changed(*overrides):
        k = stage_keys(load_scene(BRAKE_MAP, list(overrides)), stages, version="v")
        return {s for s in stages if k[s] != k0[s]}

    assert changed("analyses.sweep.n=11") == {"sweep"}
    assert changed("analyses.map.n_mu=51") == {"map"}
    assert changed("analyses.cea.n_modes=30") == {"cea"}
    # the sweep range sets the basis' check points: the reduced model and everything on it
    assert changed("analyses.sweep.range=[-0.8, 0.8]") == {"reduced", "sweep", "map"}
    mu = {"operators", "preload", "cea", "reduced", "sweep", "map"}
    assert changed("interfaces.pad_inner.mu=0.5", "interfaces.pad_outer.mu=0.5") == mu
    assert changed("geometry.mesh_size=0.02") == set(stages)
    assert stage_keys(base, stages, version="w")["mesh"] != k0["mesh"]   # code version


def test_force_and_unknown_stage(tmp_path):
    cache = Cache(tmp_path)
    s = load_scene(RING)
    plan = make_plan(s, cache, force=["preload"])
    assert [p.status for p in plan] == ["run", "run", "forced", "forced"]
    with pytest.raises(PipelineError, match=r"^--force map: not a stage of this scene"):
        make_plan(s, cache, force=["map"])


def _forbid(monkeypatch, *names):
    table = run_module._stage_functions()

    def boom(ctx, work, timings):
        raise AssertionError("a cached stage was recomputed")

    monkeypatch.setattr(run_module, "_stage_functions", lambda: {**table, **{n: boom for n in names}})


def test_cache_reuse_and_recovery_on_the_pad(tmp_path, monkeypatch):
    cache, out = tmp_path / "cache", tmp_path / "out"
    first = run_scene(pad_scene(), out, MPI.COMM_SELF, cache=cache, **QUIET)
    assert [s["status"] for s in first["stages"]] == ["run"]
    again = run_scene(pad_scene(), out, MPI.COMM_SELF, cache=cache, **QUIET)
    assert [s["status"] for s in again["stages"]] == ["cached"]
    assert again["segmented_pad"] == first["segmented_pad"]

    # a stage that fails half-way: no entry, no temporary left, and the next run computes it
    table = run_module._stage_functions()

    def half(ctx, work, timings):
        (work / "segmented_pad.json").write_text("{partial")
        raise RuntimeError("killed")

    monkeypatch.setattr(run_module, "_stage_functions", lambda: {**table, "segmented_pad": half})
    with pytest.raises(RuntimeError, match="killed"):
        run_scene(pad_scene(mu_s=0.5), out, MPI.COMM_SELF, cache=cache, **QUIET)
    assert len(Cache(cache).entries()) == 1 and not [p for p in cache.iterdir() if p.name.startswith(".")]
    monkeypatch.undo()
    res = run_scene(pad_scene(mu_s=0.5), out, MPI.COMM_SELF, cache=cache, **QUIET)
    assert [s["status"] for s in res["stages"]] == ["run"]
    assert json.loads((out / "segmented_pad.json").read_text())["runs"][0]["speed"] == 0.005


def test_killed_run_recovers(tmp_path):
    """SIGKILL in the middle of a stage (no clean-up can run): the next run ignores the leftover
    temporary folder, computes the stage and commits a readable entry."""
    scene = tmp_path / "pad.toml"
    scene.write_text('[analyses.segmented_pad]\nspeeds = [0.005, 0.01, 0.02, 0.3]\nt_end = 0.3\n')
    cache = tmp_path / "cache"
    cmd = [sys.executable, "-m", "fem_squeal.cli", "--cache-dir", str(cache), "run", str(scene),
           "-o", str(tmp_path / "out")]
    p = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=clean_env())
    deadline = time.time() + 60
    while time.time() < deadline and not (cache.exists() and any(x.name.startswith(".") for x in cache.iterdir())):
        time.sleep(0.05)
    time.sleep(0.3)
    os.kill(p.pid, signal.SIGKILL)
    p.wait()
    assert not Cache(cache).entries()
    quick = [*cmd[:-2], "--set", "analyses.segmented_pad.t_end=0.02", "-o", str(tmp_path / "out")]
    scene.write_text('[analyses.segmented_pad]\nspeeds = [0.005, 0.01, 0.02, 0.3]\nt_end = 0.02\n')
    r = subprocess.run(quick, capture_output=True, text=True, env=clean_env(), timeout=300)
    assert r.returncode == 0, r.stderr
    (entry,) = Cache(cache).entries()
    assert json.loads((entry / "entry.json").read_text())["stage"] == "segmented_pad"
    plan = subprocess.run([sys.executable, "-m", "fem_squeal.cli", "--cache-dir", str(cache), "plan", str(scene)],
                          capture_output=True, text=True, env=clean_env())
    assert "0 of 1 stages to compute" in plan.stdout
    clean = subprocess.run([sys.executable, "-m", "fem_squeal.cli", "--cache-dir", str(cache), "clean"],
                           capture_output=True, text=True, env=clean_env())
    assert clean.returncode == 0 and not cache.exists()


@pytest.fixture(scope="module")
def ring_run(tmp_path_factory):
    """The ring's CEA on a coarse mesh with its fields and report (its cache, outputs and results)."""
    base = tmp_path_factory.mktemp("ring")
    s0 = load_scene(RING, ["geometry.mesh_size=0.003"])
    res = run_scene(s0, base / "out", MPI.COMM_SELF, cache=base / "cache", **QUIET)
    return s0, base / "cache", base / "out", res


def test_ring_cache_recomputes_only_what_changed(ring_run, tmp_path, monkeypatch):
    s0, cache, _, first = ring_run
    _forbid(monkeypatch, "mesh", "operators", "preload", "cea")
    again = run_scene(s0, tmp_path / "a", MPI.COMM_SELF, cache=cache, write_fields=False, **QUIET)
    assert {s["status"] for s in again["stages"]} == {"cached"}
    assert again["complex_modes"] == first["complex_modes"]
    # --no-fields: the mode pictures (drawn into the cache) are not published, and the report says so
    html = (tmp_path / "a" / "report.html").read_text()
    assert "<code>--no-fields</code>" in html and 'id="viewer"' not in html and "mode_shapes/" not in html
    assert not (tmp_path / "a" / "mode_shapes.npz").exists() and not (tmp_path / "a" / "mode_shapes").exists()
    monkeypatch.undo()
    # more modes: the CEA runs again on the mesh and operators rebuilt in memory
    s1 = load_scene(RING, ["geometry.mesh_size=0.003", "analyses.cea.n_modes=18"])
    res = run_scene(s1, tmp_path / "b", MPI.COMM_SELF, cache=cache, write_fields=False, **QUIET)
    assert [s["status"] for s in res["stages"]] == ["memory", "memory", "memory", "run"]
    assert len(Cache(cache).entries()) == 5
    lam = lambda r: np.array([m["freq_hz"] for m in r["complex_modes"]])  # noqa: E731
    n = len(lam(first))
    assert np.allclose(lam(res)[:n], lam(first), rtol=1e-9)


def _numbers(obj, path=""):
    """Leaves of a JSON tree as (path with list indices as *, index path, value)."""
    if isinstance(obj, dict):
        for k, v in obj.items():
            yield from _numbers(v, f"{path}.{k}")
    elif isinstance(obj, list):
        for i, v in enumerate(obj):
            for p, idx, x in _numbers(v, f"{path}[*]"):
                yield p, (i,) + idx, x
        return
    else:
        yield path, (), obj


# ".solver": which paths ran (the compiled kernels serve one rank; on two, PETSc's own), not a result
IGNORED = (".solver.", "timings_s", "seconds", "started", "residual", "backward_error", "ranks", "blas_threads",
           "lifted_residuals", "full_cea_s", "files", "estimated_error", "change", "stages",
           # diagnostics of the tracking walk: the SLEPc vectors of the ring's double eigenvalues are
           # any basis of their eigenspace (different per rank count), so the walk may take other
           # sub-steps; the eigenvalues and critical values it finds are compared below
           ".sweep.solves", ".sweep.vector_solves", ".sweep.ambiguous_steps")
# critical values are refined to a bracket of 1e-10 of the sweep range (fem_squeal.reduced.tracking.track):
# two runs may differ by twice that on top of round-off
ABSOLUTE = {".sweep.critical[*].value": 2 * 1e-10 * 2.0,
            # the share of an eigenvector outside the basis' modes: round-off (~1e-11) of a residual; the
            # CEA's on the real modes up to 1.25 × its band top: 3e-11–5e-10, equal to 6e-16 on 1 and 2 ranks
            ".sweep.critical[*].coupling.outside": 1e-9, ".complex_modes[*].coupling.outside": 1e-9,
            # the ring's three rigid-body modes (free in its plane): frequencies of round-off, ~1e-3 Hz
            ".cea_coupling.real_freqs_hz[*]": 1e-2, ".cea_coupling.real_modes[*].freq_hz": 1e-2}


@pytest.mark.mpi
def test_results_do_not_depend_on_the_rank_count(tmp_path, mpirun):
    """Ring: CEA, reduced model and μ sweep on 1 and 2 ranks.  Every number of results.json agrees
    to 1e-8 of the largest magnitude of its field (a field's values across modes share a scale:
    the real parts of neutral modes are round-off about 0 and compare against the largest one).
    Residuals, timings and the basis' error estimates are round-off or wall-clock and are skipped."""
    args = ["--set", "geometry.mesh_size=0.003", "--set", "analyses.sweep.n=21", "--set",
            "analyses.reduced.band_hz=[100.0, 5000.0]", "--no-fields", "--no-report"]
    outs = []
    for n, prefix in ((1, []), (2, mpirun)):
        out = tmp_path / f"r{n}"
        cli = [sys.executable, "-m", "fem_squeal.cli", "--cache-dir", str(tmp_path / f"c{n}")]
        p = subprocess.run(prefix + cli + ["run", str(RING), "-o", str(out), *args],
                           capture_output=True, text=True, timeout=900, env=clean_env())
        assert p.returncode == 0, p.stdout + p.stderr
        outs.append(json.loads((out / "results.json").read_text()))
    a, b = ({(p, i): x for p, i, x in _numbers(r) if not any(k in p for k in IGNORED)} for r in outs)
    assert a.keys() == b.keys()
    scale: dict[str, float] = {}
    for (p, _), x in a.items():
        if isinstance(x, (int, float)) and not isinstance(x, bool):
            scale[p] = max(scale.get(p, 0.0), abs(x))
    bad = []
    for k, x in a.items():
        y = b[k]
        if isinstance(x, (int, float)) and not isinstance(x, bool):
            if not abs(x - y) <= 1e-8 * scale[k[0]] + ABSOLUTE.get(k[0], 0.0):
                bad.append((k, x, y))
        elif x != y:
            bad.append((k, x, y))
    assert not bad, bad[:5]
    assert outs[0]["sweep"]["critical"] and outs[0]["n_unstable"] > 0
    assert all("coupling" in c for c in outs[0]["sweep"]["critical"])
    # a new sweep on the cached reduced model still names the real modes merging at each change of
    # stability (the model's basis counts are saved with it: info['modes'])
    cli = [sys.executable, "-m", "fem_squeal.cli", "--cache-dir", str(tmp_path / "c1")]
    p = subprocess.run(cli + ["run", str(RING), "-o", str(tmp_path / "r3"), *args, "--set", "analyses.sweep.n=25"],
                       capture_output=True, text=True, timeout=900, env=clean_env())
    assert p.returncode == 0, p.stdout + p.stderr
    again = json.loads((tmp_path / "r3" / "results.json").read_text())
    assert {s["stage"]: s["status"] for s in again["stages"]}["reduced"] == "cached"
    assert again["sweep"]["critical"] and all("coupling" in c for c in again["sweep"]["critical"])
    # the mode pictures' data (drawn by the CEA into its cache entry, with --no-fields too): the same
    # surface (its points to round-off), the same modes, the same normalised shapes (float32)
    one, two = (ModeShapes.load(next((tmp_path / f"c{n}").rglob(NPZ))) for n in (1, 2))
    for k in ("triangles", "modes"):
        assert np.array_equal(getattr(one, k), getattr(two, k)), k
    assert np.allclose(one.points, two.points, rtol=0, atol=1e-12)
    for k in ("u_re", "u_im", "un_re", "un_im"):
        assert np.allclose(getattr(one, k), getattr(two, k), atol=1e-5), k


def _chromium() -> str:
    exe = shutil.which("chromium") or shutil.which("chromium-browser")
    if exe is None:
        pytest.skip("chromium not installed (scripts/setup.sh --test installs it; scripts/test.sh passes --test)")
    return exe


def _dump_dom(page) -> str:
    """The DOM of ``page`` after its scripts ran, rendered by headless Chromium without network."""
    p = subprocess.run([_chromium(), "--headless", "--no-sandbox", "--disable-gpu", "--virtual-time-budget=5000",
                        "--dump-dom", page.as_uri()], capture_output=True, text=True, timeout=120)
    return p.stdout


#: appended to a copy of the report: click the summary table's frequency header, note the order
CLICK = """<script>window.addEventListener('load',function(){var th=[].filter.call(document.querySelectorAll('th'),
function(h){return h.textContent.trim()==='f [Hz]';})[0];th.click();var t=th.closest('table');
document.body.setAttribute('data-sorted',[].slice.call(t.rows,1).map(function(r){return r.cells[1].textContent;})
.join(','));
});</script>"""


def test_mode_pictures_and_3d_view_in_headless_chromium(ring_run, tmp_path):
    """The ring's report: a summary of the unstable modes with thumbnails, a section per drawn mode
    with its picture (non-blank), the 3-D view drawn (triangles, a canvas that is not uniform), no
    script error, nothing from the network, and a table sorted by a click on its header."""
    _, _, out, res = ring_run
    drawn = res["mode_shapes"]["modes"]
    assert drawn and all(res["complex_modes"][j]["unstable"] for j in drawn)
    html = (out / "report.html").read_text()
    assert not re.search(r"https?://", html)
    from PIL import Image

    pngs = re.findall(r'src="data:image/png;base64,([^"]+)"', html)
    plots = [f for f in res.get("files", []) if f.endswith(".png") and not f.startswith("mode_shapes/")]
    assert len(pngs) == 2 * len(drawn) + len(plots)  # pictures and thumbnails, and the plots section
    for b64 in pngs:
        img = np.asarray(Image.open(io.BytesIO(base64.b64decode(b64))).convert("L"), dtype=float)
        assert img.std() > 5                           # not blank
    for j in drawn:
        assert f'id="mode-{j}"' in html and f"mode_shapes/mode_{j}_points.csv" in html
        assert (out / "mode_shapes" / f"mode_{j}_triangles.csv").is_file()
    page = tmp_path / "report.html"
    page.write_text(html.replace("</body>", CLICK + "</body>"))
    dom = _dump_dom(page)
    body = dom[dom.find("<body"):].split(">", 1)[0]
    n = len(pngs)
    assert f'data-images-total="{n}"' in body and f'data-images-loaded="{n}"' in body, body
    assert 'data-script-errors="0"' in body, body
    view = dom[dom.find('<div id="viewer"'):].split(">", 1)[0]
    triangles = int(re.search(r'data-viewer-triangles="(\d+)"', view).group(1))
    assert 0 < triangles < res["mode_shapes"]["triangles"]     # the ones facing the viewer
    assert float(re.search(r'data-viewer-variance="([\d.]+)"', view).group(1)) > 50
    ranked = sorted((m for m in res["complex_modes"] if m["unstable"]), key=lambda m: m["freq_hz"])
    assert re.search(r'data-sorted="([\d,]+)"', body).group(1) == ",".join(str(m["index"]) for m in ranked)


def test_report_renders_in_headless_chromium(tmp_path):
    exe = _chromium()
    out = tmp_path / "out"
    run_scene(pad_scene(velocity_pairs=[[0.002, 0.05]], pair_speeds=[0.02]), out, MPI.COMM_SELF,
              cache=tmp_path / "c", **QUIET)
    html = (out / "report.html").read_text()
    assert html.count("<img") == 2 and "Segmented pad" in html
    p = subprocess.run([exe, "--headless", "--no-sandbox", "--disable-gpu", "--virtual-time-budget=5000",
                        "--dump-dom", (out / "report.html").as_uri()], capture_output=True, text=True, timeout=120)
    body = p.stdout[p.stdout.find("<body"):].split(">", 1)[0]
    assert 'data-images-total="2"' in body, p.stdout[:500] + p.stderr[-2000:]
    assert 'data-images-loaded="2"' in body


@pytest.mark.mpi
def test_a_rank0_failure_raises_on_every_rank(mpirun):
    """on_root: an exception in rank 0's section reaches the other ranks instead of leaving them
    in the next collective (which hung the transient stage when its snapshot writer failed)."""
    code = ("from mpi4py import MPI\nfrom fem_squeal.util.parallel import on_root\n"
            "comm = MPI.COMM_WORLD\nassert on_root(comm, lambda: comm.rank + 7) == 7\n"
            "def bad():\n    raise KeyError('analyses.x')\n"
            "try:\n    on_root(comm, bad)\n    msg = 'no exception'\nexcept KeyError as e:\n"
            "    msg = f'rank {comm.rank} raised {e}'\n"
            # gathered and printed by rank 0 alone: two ranks printing at once interleave their lines
            "msgs = comm.gather(msg)\nif comm.rank == 0:\n    print('\\n'.join(msgs))\n")
    p = subprocess.run(mpirun + [sys.executable, "-c", code], capture_output=True, text=True, timeout=120,
                       env=clean_env())
    assert p.returncode == 0, p.stdout + p.stderr
    assert p.stdout.split("\n")[-3:-1] == ["rank 0 raised 'analyses.x'", "rank 1 raised 'analyses.x'"], p.stdout
