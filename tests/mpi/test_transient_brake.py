"""The brake_transient scene through the pipeline, on the coarse brake and 2 ranks: reduced model,
3 ms of transient from the most unstable tangent-CEA mode, and the limit-cycle post-processing.

3 ms at 2 µs keeps the response in the linear regime (the push is 1e-3 of the static closure and
grows ≈ e^(0.003 Re λ) ≈ 4×), so every result has an exact linear counterpart:

- the space–time SVD of a single unstable complex mode has two shapes spanning its plane;
- the tangent CEA along the cycle is the steady-sliding one (the cubic law's tangent moves by
  O(amplitude/closure) ≈ 1e-3 relative);
- the complex-mode cycle at α → 0 has the CEA real part, and its friction work grows as α²
  (the scene's exponential law adds O(α) corrections, bounded below);
- the discrete energy balance of the trapezoidal rule closes to round-off.

A second run that changes a limit_cycle option recomputes that stage only.
"""
from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest
from support.paths import ROOT
from support.processes import clean_env

SCENE = ROOT / "scenes" / "brake_transient.toml"
COARSE = ["geometry.mesh_size=0.016", "analyses.reduced.band_hz=[0.0, 6000.0]",
          "analyses.cea.band_hz=[0.0, 6000.0]",
          "analyses.transient.t_end=0.003", "analyses.transient.dt=2e-6", "analyses.transient.patches=[4, 8]",
          "analyses.transient.attachments=[2, 4]", "analyses.limit_cycle.stability_samples=4",
          "analyses.limit_cycle.mode_cycle_amplitudes=[0.001, 0.01]", "analyses.transient.amplitude=1e-3",
          "analyses.cea.coupling=false"]       # the CEA's coupling is not what this file tests


def _run(mpirun, cache, out, extra=()):
    sets = [a for s in [*COARSE, *extra] for a in ("--set", s)]
    cli = [sys.executable, "-m", "fem_squeal.cli", "--cache-dir", str(cache)]
    p = subprocess.run(mpirun + cli + ["run", str(SCENE), "-o", str(out), "--no-fields", *sets],
                       capture_output=True, text=True, timeout=900, env=clean_env())
    assert p.returncode == 0, p.stdout[-3000:] + p.stderr[-3000:]
    return json.loads((out / "results.json").read_text())


@pytest.fixture(scope="module")
def results(tmp_path_factory, mpirun):
    base = tmp_path_factory.mktemp("brake_transient")
    return base, mpirun, _run(mpirun, base / "cache", base / "out")


@pytest.mark.mpi
def test_transient_and_limit_cycle_in_the_linear_regime(results):
    _, _, r = results
    t, lc = r["transient"], r["limit_cycle"]
    pushed = t["pushed_mode"]
    assert t["steps"] == 1500 and t["energy_leak"] < 1e-9
    assert t["peak_closure_change"] < 0.05 * t["static_closure"]          # linear regime indeed
    assert lc["limit_cycle"]["saturated"] is False
    assert lc["limit_cycle"]["frequency_hz"] == pytest.approx(pushed["freq_hz"], rel=0.02)
    assert sum(lc["svd_energy"][:2]) > 0.999
    first = lc["svd_best_mac"][0]
    assert first["freq_hz"] == pytest.approx(pushed["freq_hz"], rel=1e-9) and first["plane_share"] > 0.99
    followed = np.array(lc["dynamic_stability"]["followed_real_part"])
    assert np.max(np.abs(followed - pushed["real_part"])) < 1e-3 * pushed["real_part"]
    cyc = {c["alpha"]: c for c in lc["mode_cycles"]}
    # exponential law: the contact tangent λF varies as 1 + λΔδ along a cycle of closure amplitude
    # α × closure (λ × closure ≈ 0.5-0.7), so the pseudo real part moves O(α) and the friction work
    # is α²(1 + O(α)): 1e-3 and 1e-2 bounds at α = 1e-3 and for the ratio of α = 1e-2 to 1e-3
    assert cyc[0.001]["pseudo_real_part_min"] == pytest.approx(pushed["real_part"], rel=1e-3)
    assert cyc[0.001]["friction_work"] > 0               # an unstable mode draws energy from friction
    assert cyc[0.01]["friction_work"] / cyc[0.001]["friction_work"] == pytest.approx(100.0, rel=1e-2)
    shares = lc["energy_shares"]
    assert set(shares) == set(r["scene"]["materials"]) and sum(shares.values()) == pytest.approx(1.0, abs=1e-9)
    out_files = set(r["files"])
    assert {"transient.png", "limit_cycle.png", "dynamic_stability.png", "limit_cycle.json"} <= out_files
    assert any(f.startswith("run/chunk_") for f in out_files)


# slow: 14 s; a changed option re-running its stage alone is the pipeline's rule, tested on the ring
# (test_pipeline.py::test_ring_cache_recomputes_only_what_changed)
@pytest.mark.slow
@pytest.mark.mpi
def test_changing_a_limit_cycle_option_reruns_that_stage_only(results):
    base, mpirun, first = results
    r = _run(mpirun, base / "cache", base / "out2", ["analyses.limit_cycle.svd_shapes=3"])
    status = {s["stage"]: s["status"] for s in r["stages"]}
    assert status == {"mesh": "cached", "operators": "cached", "preload": "cached", "cea": "cached",
                      "reduced": "cached", "transient": "cached", "limit_cycle": "run"}
    assert len(r["limit_cycle"]["svd_energy"]) == 3
    assert r["transient"] == first["transient"]


@pytest.mark.slow       # 49 s: the snapshot writer itself is checked in the default suite
@pytest.mark.mpi        # (test_mesh_import.py::test_vtu_fields_and_snapshots_are_the_functions_at_the_nodes)
def test_fields_add_the_transient_snapshots(results):
    """With fields on (a new key from the preload on, which writes fields too), the transient writes
    the scene's 20 snapshots over the last 0.4 ms from the reduced stage's Φ on the nodes, and its
    run is the same as without fields."""
    base, mpirun, first = results
    out = base / "out_fields"
    sets = [a for s in COARSE for a in ("--set", s)]
    cli = [sys.executable, "-m", "fem_squeal.cli", "--cache-dir", str(base / "cache")]
    p = subprocess.run(mpirun + cli + ["run", str(SCENE), "-o", str(out), "--no-report", *sets],
                       capture_output=True, text=True, timeout=900, env=clean_env())
    assert p.returncode == 0, p.stdout[-3000:] + p.stderr[-3000:]
    r = json.loads((out / "results.json").read_text())
    assert {s["stage"]: s["status"] for s in r["stages"]}["transient"] == "run"
    assert r["transient"]["peak_closure_change"] == pytest.approx(first["transient"]["peak_closure_change"],
                                                                  rel=1e-9)
    import meshio

    snap = meshio.read(out / "transient_snapshots.vtu")
    t = snap.field_data["time"]
    assert len(t) == 20 and t[-1] == pytest.approx(0.003) and t[0] == pytest.approx(0.0026, abs=3e-6)
    assert snap.cells[0].type == "tetra10" and snap.point_data["u_19"].shape == (len(snap.points), 3)
    assert (out / "transient_snapshots.xdmf").exists()


@pytest.mark.mpi
def test_exponential_law_carries_the_preload(results):
    """Seed 002's exponential law on the same patches (λ = k_n/p̄, p₀ = p̄/e): at steady sliding
    each pad's normal force balances the brake load as in the full-order preload.  The piston
    force is the same, and each pad's share follows the caliper's stiffness, which the law only
    redistributes within a pad: measured 0.4 and 0.9 % (inner, outer); bound 2 %."""
    from fem_squeal.reduced.laws.contact import ExponentialLaw
    from fem_squeal.reduced.model import ReducedModel
    from fem_squeal.reduced.transient import NewmarkHHT, from_reduced

    base, _, r = results
    rm = ReducedModel.load(base / "out" / "reduced_model.npz")
    dm = from_reduced(rm, 1.0, normal="exponential", patches=(4, 8))
    assert all(isinstance(cs.normal, ExponentialLaw) for cs in dm.contacts)
    integ = NewmarkHHT(dm, 1e-6)
    qs = integ.steady_sliding(rm.q_static)
    states = [cs.friction.initial_state(cs.size, cs.n_dir) for cs in dm.contacts]
    fr = integ.forces(qs, np.zeros_like(qs), None, 0.0, states)
    for cs, F in zip(dm.contacts, fr.F):
        full = r["preload"]["interfaces"][cs.name]["normal_force"]
        assert F.sum() == pytest.approx(full, rel=0.02)


# slow: 15 s; the resume itself is tested on the reduced model (tests/unit/reduced/test_transient.py::
# test_checkpoint_resume_and_failure) and a killed pipeline run's recovery on the pad (test_pipeline.py)
@pytest.mark.slow
@pytest.mark.mpi
def test_killed_transient_resumes_from_its_checkpoint(results):
    """SIGKILL during the transient stage (reduced model cached, 3000 steps, checkpoints every
    200): the next run resumes from the checkpoint in the cache's run folder, and its history
    is one continuous record (uniform t to t_end, no repeated or missing samples) whose energy
    balance closes across the restart (the work accumulators come back with the state)."""
    import os
    import signal
    import time

    from fem_squeal.reduced.transient import load_history

    base, mpirun, _ = results
    cache = base / "cache"
    extra = ["analyses.transient.dt=1e-6", "analyses.transient.checkpoint_every=200"]
    sets = [a for s in [*COARSE, *extra] for a in ("--set", s)]
    cmd = [sys.executable, "-m", "fem_squeal.cli", "--cache-dir", str(cache), "run", str(SCENE),
           "-o", str(base / "out3"), "--no-fields", "--no-report", *sets]
    p = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=clean_env())
    deadline = time.time() + 300
    checkpoint = None
    while time.time() < deadline and p.poll() is None:
        found = sorted(cache.glob(".run-transient-*/checkpoint.json"))
        if found:
            checkpoint = found[0]
            break
        time.sleep(0.01)
    assert checkpoint is not None, "the transient never wrote a checkpoint"
    os.kill(p.pid, signal.SIGKILL)
    p.wait()
    step_at_kill = json.loads(checkpoint.read_text())["step"]
    assert 0 < step_at_kill < 3000
    r = _run([], cache, base / "out3", extra)
    t = r["transient"]
    assert t["resumed"] is True and t["steps"] == 3000 and t["steps_computed"] < 3000
    h = load_history(base / "out3" / "run")
    dt_rec = np.diff(h["t"])
    assert h["t"][0] == 0.0 and h["t"][-1] == pytest.approx(0.003, rel=1e-12)
    assert np.allclose(dt_rec, 1e-5, rtol=1e-6)                   # every 10th step, once
    assert t["energy_leak"] < 1e-9


@pytest.mark.mpi
def test_transient_demo_checks_itself_on_the_cached_stages(results):
    """demos/transient_brake.py with the fixture's coarse settings and its cache (``FEM_SQUEAL_CACHE``):
    every stage comes from the cache (the 2-rank run computed them), so the demo's cost is its own
    check, the linear growth of a 1e-5 push against the tangent CEA's Re λ (1 %)."""
    base, _, _ = results
    out = base / "demo"
    p = subprocess.run([sys.executable, str(ROOT / "demos" / "transient_brake.py"), str(out),
                        *[f"--set={s}" for s in COARSE]], capture_output=True, text=True, timeout=900,
                       env={**clean_env(), "FEM_SQUEAL_CACHE": str(base / "cache")})
    assert p.returncode == 0 and "check passed" in p.stdout, p.stdout[-3000:] + p.stderr[-3000:]
    stages = json.loads((out / "results.json").read_text())["stages"]
    assert {s["status"] for s in stages} == {"cached"}, stages
