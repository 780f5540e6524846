"""Friction-coefficient sweeps on the reduced model: root loci of the ring and of the brake.

Seed 001 §3 sweeps the friction coefficient on a modal projection of the brake (eq. 5) and
follows every eigenvalue in forward and backward sliding, sign(v)μ (Fig. 8).  This script does
the same on both bundled models (serial or ``mpirun -n 2``):

1. the Ryzhik ring (seed 003): each sin/cos pair of the axisymmetric ring is split only by the
   mesh, so friction makes it flutter almost at once (critical μ ≈ 0) and the growth rate is
   symmetric in sign(v)μ;
2. the brake corner: the basis is grown until the unstable eigenvalues move by < 1e-3, every
   branch is tracked over sign(v)μ ∈ [−1, 1], and the coalescences are reported with the
   frictionless parent modes and their critical μ.

It checks itself: the reduced eigenvalues agree with the full CEA at the check points, the ring
sweep is symmetric, and the brake's unstable count at the scene's μ equals the full CEA's.
Pass ``--ring-only`` for the quick half.  Outputs: out/mu_sweep/<model>/ (root_locus.png,
complex_plane.png, sweep.json, results.json).
"""
from __future__ import annotations

import sys

import numpy as np
from mpi4py import MPI

from fem_squeal.app.analyses.reduced import verification_failures
from fem_squeal.app.cli import demo_arguments
from fem_squeal.app.run import run_scene
from fem_squeal.app.scene import load_scene

root, outdir, _ = demo_arguments(__file__)
comm = MPI.COMM_WORLD
say = print if comm.rank == 0 else (lambda *a, **k: None)
failures: list[str] = []
SWEEP = ["analyses.sweep.parameter=\"mu\"", "analyses.sweep.range=[-1.0, 1.0]", "analyses.sweep.n=101",
         "analyses.reduced.verify=true"]

# --- 1. the ring -------------------------------------------------------------------------------
ring = load_scene(root / "scenes" / "ryzhik_ring.toml", SWEEP + ["analyses.reduced.band_hz=[100.0, 5000.0]"])
res = run_scene(ring, outdir / "ring", comm, write_fields=False)
red, sw = res["reduced"], res["sweep"]
failures += verification_failures(red, "ring: ")  # tol: the requested accuracy of the reduced model
onsets = [c for c in sw["critical"] if c["onset"] and c["kind"] == "coalescence"]
say(f"ring: {len(onsets)} coalescence onsets; critical |μ| of each pair: "
    + ", ".join(f"{'+'.join(c['labels'])} {c['value']:+.1e} ({c['freq_hz']:.0f} Hz)" for c in onsets))
# Every in-plane pair (k = 2..6) goes unstable next to μ = 0 in both directions: the pair is
# degenerate but for the mesh (split 1e-7 relative), so its critical μ is of that order.
fwd = sorted(c["freq_hz"] for c in onsets if c["value"] > 0)
bwd = sorted(c["freq_hz"] for c in onsets if c["value"] < 0)
if len(fwd) != 5 or not np.allclose(fwd, bwd, rtol=1e-6) or max(abs(c["value"]) for c in onsets) > 0.02:
    failures.append(f"ring: expected 5 pairs unstable at |μ| < 0.02 both ways, got forward {fwd}, backward {bwd}")

# --- 2. the brake corner -------------------------------------------------------------------------
if "--ring-only" not in sys.argv:
    brake = load_scene(root / "scenes" / "brake_corner_cea.toml", SWEEP)
    res = run_scene(brake, outdir / "brake", comm, write_fields=False)
    red, sw = res["reduced"], res["sweep"]
    failures += verification_failures(red, "brake: ")
    say(f"brake: {red['size']} basis vectors, estimated error {red['estimated_error']:.1e}; "
        f"full CEA at the scene's μ: {res['n_unstable']} unstable")
    for c in sorted(sw["critical"], key=lambda c: abs(c["value"])):
        if c["onset"]:
            say(f"  {'+'.join(c['labels']):>9}: unstable from sign(v)μ = {c['value']:+.4f} "
                f"at {c['freq_hz']:7.1f} Hz ({c['kind']})")

if comm.rank == 0:
    print("CHECK FAILED:\n  " + "\n  ".join(failures) if failures else
          "check passed: reduced = full CEA within tol at every check point; sweeps tracked")
sys.exit(1 if failures else 0)
