"""Stability map of the brake corner over friction and disc stiffness (seed 001 §4, Figs. 17-19).

A sweep of sign(v)μ over [−1, 1] tracks every branch, and a full-factorial design of 101 values
of sign(v)μ (forward and backward sliding) × 21 values of the disc's Young's modulus (nominal ±
20 %) is evaluated on the reduced model, the points shared among the MPI ranks. The basis holds
the frictionless modes at the nominal disc and at both ends of the E range, plus the static
corrections of the friction forces; it is grown until the unstable eigenvalues at the corners of
the design move by < 1e-3, and the full CEA is run at those corners to confirm it. The number of
unstable modes is counted per frequency band (six equal bands of 0-10 kHz, as the seed's ranges
A-F) and in total.

Checks: reduced = full CEA within tol at every check point (including the unstable count), and
the map's count at the nominal point equals the full CEA of the scene.  Outputs under
out/mu_E_stability_map/: stability_map.png/.npz, root_locus.png, results.json, report.html.
The scene is ``scenes/brake_mu_E_map.toml``; stages are cached in ``$XDG_CACHE_HOME/fem_squeal``
(or ``$FEM_SQUEAL_CACHE``), so a second run recomputes nothing.  Run with ``mpirun -n 2`` (``scripts/demo.sh``).
"""
from __future__ import annotations

import sys

import numpy as np
from mpi4py import MPI

from fem_squeal.app.analyses.reduced import verification_failures
from fem_squeal.app.cli import demo_arguments
from fem_squeal.app.pipeline import default_cache_dir
from fem_squeal.app.run import run_scene
from fem_squeal.app.scene import load_scene

root, outdir, overrides = demo_arguments(__file__)
comm = MPI.COMM_WORLD
scene = load_scene(root / "scenes" / "brake_mu_E_map.toml", overrides)
res = run_scene(scene, outdir, comm, write_fields=False, cache=default_cache_dir())

red, smap = res["reduced"], res["map"]
failures = verification_failures(red)
mu_axis, E_axis = np.asarray(smap["axes"]["mu"]), np.asarray(smap["axes"][smap["parameter"]])
E0 = scene["materials"][scene["analyses"]["map"]["part"]]["E"]
mu0 = red["mu0"]
i, j = np.argmin(np.abs(E_axis - E0)), np.argmin(np.abs(mu_axis - mu0))
if np.isclose(E_axis[i], E0) and np.isclose(mu_axis[j], mu0):
    if smap["total"][i][j] != res["n_unstable"]:
        failures.append(f"map at the nominal point: {smap['total'][i][j]} unstable, full CEA {res['n_unstable']}")
if comm.rank == 0:
    total = np.asarray(smap["total"])
    print(f"map: {smap['points']} points in {smap['seconds']:.2f} s on {comm.size} rank(s) "
          f"({1e3 * smap['seconds_per_point']:.2f} ms per point per rank); basis {red['size']} vectors, "
          f"estimated error {red['estimated_error']:.1e}")
    fwd = total[:, mu_axis > 0]
    print(f"unstable modes: min {total.min()}, max {total.max()}; stable share of the design "
          f"{np.mean(total == 0) * 100:.1f} % (forward sliding {np.mean(fwd == 0) * 100:.1f} %)")
    print(f"report: {outdir / 'report.html'}")
    print("CHECK FAILED:\n  " + "\n  ".join(failures) if failures else
          "check passed: reduced = full CEA at the design corners; map matches the CEA at the nominal point")
sys.exit(1 if failures else 0)
