"""Segmented pad of a high-speed train brake (seed 004): stick-slip, creep and sliding.

``scenes/segmented_pad.toml`` through the pipeline (no mesh: a lumped model of 9 friction
elements, 28 DOFs; the runs are dealt over the MPI ranks).  Each run starts from steady sliding
with a small radial kick and lasts 0.3 s; the regime of each element is read from its sliding
speed s = |w| over the second half: stick (s < v_s), creep (v_s ≤ s < v_d, the falling branch of
the Stribeck law) and slip (s ≥ v_d).

Checks (the seed's phenomena, §4):
- at the lowest disc speed every element sticks and slips;
- above a transition speed no element sticks (the kick dies out into steady sliding);
- below it every stick-slip cycle has creep segments (≥ 5 % of the time on the falling branch
  between stick and slip), above it none;
- at 20 mm/s, with v_d below the disc speed the pad slides, with v_d above it sticks and slips,
  and the creep share grows with v_d (the gentler the slope, the longer the creep segments of
  the phase trajectory, seed Fig. 5).
Outputs in out/segmented_pad/: segmented_pad_speeds.png, segmented_pad_velocities.png,
segmented_pad.json, report.html.  Run: ``mpirun -n 2 .venv/bin/python demos/segmented_pad.py``.
"""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
from mpi4py import MPI

from fem_squeal.pipeline import default_cache_dir
from fem_squeal.run import run_scene
from fem_squeal.scene import load_scene

root = Path(__file__).resolve().parents[1]
args = [a for a in sys.argv[1:] if not a.startswith("--")]
outdir = Path(args[0]) if args else root / "out" / "segmented_pad"
overrides = [a.split("=", 1)[1] for a in sys.argv[1:] if a.startswith("--set=")]
comm = MPI.COMM_WORLD
scene = load_scene(root / "scenes" / "segmented_pad.toml", overrides)
res = run_scene(scene, outdir, comm, cache=default_cache_dir(root))
runs = res["segmented_pad"]["runs"]
by_speed = [r for r in runs if r["kind"] == "speed"]
pairs = [r for r in runs if r["kind"] == "velocities"]
stick = lambda r: np.array(r["fractions"])[:, 0]  # noqa: E731  (per element)
creep = lambda r: float(np.mean(np.array(r["fractions"])[:, 1]))  # noqa: E731

failures = []
if not all(g == "stick-slip" for g in by_speed[0]["regimes"]):
    failures.append(f"{by_speed[0]['speed']} m/s: not every element sticks and slips ({by_speed[0]['regimes']})")
sliding = [r for r in by_speed if not np.any(stick(r) > 0)]
if not sliding:
    failures.append("no disc speed without sticking: no transition in the range")
else:
    v_t = sliding[0]["speed"]
    below = [r for r in by_speed if r["speed"] < v_t]
    if any(np.any(stick(r) > 0) for r in by_speed if r["speed"] > v_t):
        failures.append("stick-slip above the transition speed")
    c = np.array([creep(r) for r in below])
    if not np.all(c >= 0.05):
        failures.append(f"stick-slip without creep segments (creep share {np.round(c, 3)})")
    if any(creep(r) > 0 for r in by_speed if r["speed"] >= v_t):
        failures.append("creep above the transition speed")
for r in pairs:
    sticks = bool(np.any(stick(r) > 0))
    if sticks != (r["v_d"] > r["speed"]):
        failures.append(f"v_d {r['v_d']} at {r['speed']} m/s: stick {sticks}")
c_pairs = [creep(r) for r in sorted(pairs, key=lambda r: r["v_d"]) if r["v_d"] > r["speed"]]
if len(c_pairs) >= 2 and not np.all(np.diff(c_pairs) > 0):
    failures.append(f"creep share does not grow with v_d: {np.round(c_pairs, 3)}")
if comm.rank == 0:
    for r in runs:
        f = np.array(r["fractions"]).mean(axis=0)
        print(f"V {r['speed'] * 1e3:6.1f} mm/s, v_s {r['v_s'] * 1e3:4.1f}, v_d {r['v_d'] * 1e3:5.1f} mm/s: "
              f"{r['regime']:<12} stick {f[0]:.2f}, creep {f[1]:.2f}, slip {f[2]:.2f}")
    if sliding:
        print(f"transition: stick-slip up to {below[-1]['speed'] * 1e3:g} mm/s, sliding from {v_t * 1e3:g} mm/s")
    print(f"report: {outdir / 'report.html'}")
    print("CHECK FAILED:\n  " + "\n  ".join(failures) if failures else
          "check passed: stick-slip with creep at low speed, sliding above the transition; "
          "v_d decides stick-slip at a given speed")
sys.exit(1 if failures else 0)
