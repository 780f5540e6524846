"""Stability map of the brake corner over friction and disc stiffness (seed 001 §4, Figs. 17-19).

A sweep of sign(v)μ over [−1, 1] tracks every branch, and a full-factorial design of 101 values
of sign(v)μ (forward and backward sliding) × 21 values of the disc's Young's modulus (nominal ±
20 %) is evaluated on the reduced model, the points shared among the MPI ranks. The basis holds
the frictionless modes at the nominal disc and at both ends of the E range, plus the static
corrections of the friction forces; it is grown until the unstable eigenvalues at the corners of
the design move by < 1e-3, and the full CEA is run at those corners to confirm it. The number of
unstable modes is counted per frequency band (six equal bands of 0-10 kHz, as the seed's ranges
A-F) and in total.

Checks (the cheap ones the verification already has; the full CEA at each of the design's seven
check points, ``analyses.reduced.verify = true`` in the scene, took 203 s of a 7-minute cold demo
on 2 ranks, and ``--set analyses.reduced.verify=true`` adds it back): the reduced model equals the
full CEA at the nominal point within its tol, unstable count included (the full CEA there is the
scene's own CEA stage); the lifted backward error of every unstable reduced pair at every check
point is at most 1e-4; the map's count at the nominal point equals the full CEA of the scene; every
unstable mode of the CEA names its coupling pair, the real modes up to 1.25 × the band top holding all but
at most 5 % of its kinetic energy (measured on the coarse brake: 0.15 % at most); every instability of
the map (a region where one mode is unstable) names the basis's real modes coupling in it.  Outputs under
out/mu_E_stability_map/: stability_map.png/.npz, stability_map_coupling.png, root_locus.png,
results.json, report.html.
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
from fem_squeal.fe.projection import relative_change

# The lifted backward error η of a reduced pair (Tisseur's, in the full model) bounds its
# eigenvalue error by κ·η (κ: the eigenvalue's condition number).  Measured over the 14 design
# points of the coarse and the demo mesh: η ≤ 7.7e-6, full-CEA error / η ≤ 354.  1e-4 is 13× the
# largest η measured: a pair above it has left the subspace the basis was grown for.
BACKWARD_TOL = 1e-4
# The share of an unstable mode's kinetic energy outside the real modes of its coupling basis: measured
# at most 1.5e-3 on the coarse brake; above 5 % the pair named would not be the mode's mechanism.
OUTSIDE_TOL = 0.05

root, outdir, overrides = demo_arguments(__file__)
comm = MPI.COMM_WORLD
scene = load_scene(root / "scenes" / "brake_mu_E_map.toml", ["analyses.reduced.verify=false", *overrides])
res = run_scene(scene, outdir, comm, write_fields=False, cache=default_cache_dir())

red, smap = res["reduced"], res["map"]
failures = verification_failures(red)       # the full CEAs at the check points, where asked for
bands = [scene["analyses"][a]["band_hz"] for a in ("reduced", "cea")]
lo, hi = max(b[0] for b in bands), min(b[1] for b in bands)         # where both looked
full = np.array([m["real_part"] + 2j * np.pi * m["freq_hz"] for m in res["complex_modes"]
                 if m["unstable"] and lo <= m["freq_hz"] <= hi])
nominal = next(r for r in red["lifted_residuals"] if r["point"] == {"mu": red["mu0"]})
f_red = np.asarray(nominal["freq_hz"])
reduced = (np.asarray(nominal["real_part"]) + 2j * np.pi * f_red)[(f_red >= lo) & (f_red <= hi)]
nominal_error = relative_change(full, reduced)
if nominal_error > red["tol"] or len(full) != len(reduced):
    failures.append(f"reduced vs full CEA at the nominal point: {len(reduced)} vs {len(full)} unstable, "
                    f"error {nominal_error:.1e} (tol {red['tol']})")
worst_eta = max((max(r["backward_error"], default=0.0) for r in red["lifted_residuals"]), default=0.0)
if worst_eta > BACKWARD_TOL:
    failures.append(f"lifted backward error {worst_eta:.1e} > {BACKWARD_TOL:g}")
for m in (m for m in res["complex_modes"] if m["unstable"]):
    c = m.get("coupling")
    if c is None or len(c["pair"]) < 1 or c["outside"] > OUTSIDE_TOL:
        failures.append(f"coupling of the unstable mode at {m['freq_hz']:.0f} Hz: "
                        + ("missing" if c is None else f"{c['label']}, outside {c['outside']:.1e}"))
for k, x in enumerate(smap["instabilities"]):
    if "coupling" not in x:
        failures.append(f"instability {k + 1} of the map ({x['freq_hz'][0]:.0f} Hz): no coupling")
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
    for m in (m for m in res["complex_modes"] if m["unstable"] and "coupling" in m):
        print(f"unstable {m['freq_hz']:.0f} Hz ({m['real_part']:.3g}/s): {m['coupling']['label']}")
    for k, x in enumerate(smap["instabilities"][:5]):
        print(f"map instability {k + 1}: {x['freq_hz'][0]:.0f}-{x['freq_hz'][1]:.0f} Hz on "
              f"{100 * x['share']:.1f} % of the map, up to {x['max_growth_rate']:.3g}/s: "
              f"{x.get('coupling', {}).get('label', 'no coupling')}")
    print(f"reduced vs full CEA at the nominal point: {len(reduced)} unstable, error {nominal_error:.1e}; "
          f"lifted backward errors at {len(red['lifted_residuals'])} design points ≤ {worst_eta:.1e}")
    print("CHECK FAILED:\n  " + "\n  ".join(failures) if failures else
          "check passed: reduced = full CEA at the nominal point, backward errors small at every design "
          "point; map matches the CEA at the nominal point; every unstable mode and every instability of the "
          "map names its coupling pair")
sys.exit(1 if failures else 0)
