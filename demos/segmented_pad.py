"""Segmented pad of a high-speed train brake (seed 004): stick-slip, creep and sliding.

``scenes/segmented_pad.toml`` through the pipeline (no mesh: a lumped model of 9 friction
elements, 28 DOFs; the runs are dealt over the MPI ranks).  Each run starts from steady sliding
with a small radial kick and lasts 0.3 s; the regime of each element is read from its sliding
speed s = |w| over the second half: stick (s < v_s), creep (v_s ≤ s < v_d, the falling branch of
the Stribeck law) and slip (s ≥ v_d).

Checks (the seed's phenomena, §4; regimes as in :func:`fem_squeal.reduced.segmented_pad.classify`):
- every element sticks and slips below V_t = v_d R/r_min (37.5 mm/s: steady sliding is unstable
  while the inner row's local speed lies on the falling branch) and slides steadily above it;
- at 5 mm/s, (v_s, v_d) = (1, 33) mm/s sticks and slips, while a shallow branch (v_d = 100 mm/s)
  gives creep cycles that never catch up with the disc, their level min |w| set by v_s
  (seed Fig. 5: v_s = 3 mm/s creeps at a level over twice that of v_s = 1 mm/s).
Outputs in out/segmented_pad/: segmented_pad_speeds.png, segmented_pad_velocities.png,
segmented_pad.json, report.html.  Run: ``mpirun -n 2 .venv/bin/python demos/segmented_pad.py``.
"""
from __future__ import annotations

import sys

import numpy as np
from mpi4py import MPI

from fem_squeal.app.analyses.segmented_pad import pad_parameters
from fem_squeal.app.cli import demo_arguments
from fem_squeal.app.pipeline import default_cache_dir
from fem_squeal.app.run import run_scene
from fem_squeal.app.scene import load_scene

root, outdir, overrides = demo_arguments(__file__)
comm = MPI.COMM_WORLD
scene = load_scene(root / "scenes" / "segmented_pad.toml", overrides)
res = run_scene(scene, outdir, comm, cache=default_cache_dir())
runs = res["segmented_pad"]["runs"]
by_speed = [r for r in runs if r["kind"] == "speed"]
pairs = [r for r in runs if r["kind"] == "velocities"]
pad = pad_parameters(scene["analyses"]["segmented_pad"])
# steady sliding is linearly unstable while an element's local speed V r/R lies on the falling
# branch (v_s, v_d) (no in-plane damping); the inner row (r_min) leaves it last
r_min = pad.radius - (pad.n_side - 1) / 2 * pad.pitch
v_t = pad.v_d * pad.radius / r_min

failures = []
for r in by_speed:
    want = {"stick-slip"} if r["speed"] < v_t else {"steady", "periodic"}
    if not set(r["regimes"]) <= want:
        failures.append(f"{r['speed'] * 1e3:g} mm/s: regimes {sorted(set(r['regimes']))}, expected {sorted(want)} "
                        f"({'below' if r['speed'] < v_t else 'above'} v_d R/r_min = {v_t * 1e3:.1f} mm/s)")
# (v_s, v_d, V) -> regime, from a map of the model over V (0.5 mm/s - 1 m/s) and nine (v_s, v_d):
# (1, 33) mm/s creeps only for V in 1.2-1.7 mm/s and sticks above; a shallow branch v_d = 100 mm/s
# creeps for V in 2-10 mm/s (v_s = 1) and 5-10 mm/s (v_s = 3)
EXPECTED = {(0.001, 0.033, 0.005): "stick-slip", (0.001, 0.1, 0.005): "creep", (0.003, 0.1, 0.005): "creep"}
level = {}
for r in pairs:
    want = EXPECTED.get((r["v_s"], r["v_d"], r["speed"]))
    if want == "creep":
        level[r["v_s"]] = float(np.mean(r["s_min"]))
    if want is not None and r["regime"] != want:
        failures.append(f"v_s {r['v_s']}, v_d {r['v_d']} at {r['speed']} m/s: {r['regime']}, expected {want}")
if len(level) >= 2:                       # seed Fig. 5: the creep level moves with v_s
    lo, hi = sorted(level)
    if not level[hi] > 2 * level[lo]:
        failures.append(f"creep levels {level} do not follow v_s")
if comm.rank == 0:
    for r in runs:
        f = np.array(r["fractions"]).mean(axis=0)
        print(f"V {r['speed'] * 1e3:6.1f} mm/s, v_s {r['v_s'] * 1e3:4.1f}, v_d {r['v_d'] * 1e3:5.1f} mm/s: "
              f"{r['regime']:<12} time at s < v_s {f[0]:.2f}, on the falling branch {f[1]:.2f}, "
              f"s >= v_d {f[2]:.2f}; min s {np.mean(r['s_min']) * 1e3:.3f} mm/s")
    print(f"transition expected at v_d R/r_min = {v_t * 1e3:.1f} mm/s; creep level min|w| per v_s: "
          + ", ".join(f"v_s {k * 1e3:g} mm/s: {v * 1e3:.2f} mm/s" for k, v in sorted(level.items())))
    print(f"report: {outdir / 'report.html'}")
    print("CHECK FAILED:\n  " + "\n  ".join(failures) if failures else
          "check passed: stick-slip below v_d R/r_min, sliding above; creep cycles on a shallow branch, "
          "their level set by v_s")
sys.exit(1 if failures else 0)
