"""Sensitivities and robustness of brake squeal on the reduced model (scenes/brake_robustness.toml).

The brake corner is reduced (basis grown to tol about the preload, E_disc sampled in by an E
sweep), then

* ``analyses.sensitivity``: dλ/dp of every unstable mode for sign(v)μ and E_disc from the left and
  right eigenvectors (a tornado plot per mode; modes near a coalescence are flagged, not ranked);
* ``analyses.robustness``: 10⁴ samples of μ ~ N(0.4, 0.04) and E_disc ~ U(112.5, 137.5) GPa: the
  probability of at least one unstable mode per band and per mode family, with standard errors,
  growth-rate histograms, the drivers (Spearman ρ), and the full CEA at the extreme samples.

Checks: (1) the spot checks: reduced = full CEA within analyses.reduced.tol with the same number of
unstable modes; (2) the sensitivity's unstable modes are the full CEA's count (same band); (3) every
derivative agrees with central finite differences of the reduced model (relative 1e-5 of |λ| per
100 % of p); (4) the robustness standard errors are √(p(1 − p)/N) and the probability is inside
[0, 1] with its band probabilities ≤ the total; (5) a degenerate distribution at the nominal point
gives the nominal (CEA) answer.  Coarse run:
``mpirun -n 2 .venv/bin/python demos/brake_robustness.py --set geometry.mesh_size=0.016
--set "analyses.reduced.band_hz=[0.0, 6000.0]" --set "analyses.cea.band_hz=[0.0, 6000.0]"``
"""
from __future__ import annotations

import sys

import numpy as np
from mpi4py import MPI

from fem_squeal.app.analyses.reduced import verification_failures
from fem_squeal.app.analyses.robustness import spot_check_failures
from fem_squeal.app.cli import demo_arguments
from fem_squeal.app.pipeline import default_cache_dir
from fem_squeal.app.run import run_scene
from fem_squeal.app.scene import load_scene
from fem_squeal.reduced.model import ReducedModel
from fem_squeal.reduced.robustness import Distribution, run_robustness
from fem_squeal.reduced.sensitivity import parameter_values
from fem_squeal.reduced.sweep import solve_points

root, outdir, overrides = demo_arguments(__file__)
comm = MPI.COMM_WORLD
scene = load_scene(root / "scenes" / "brake_robustness.toml", overrides)
res = run_scene(scene, outdir, comm, write_fields=False, cache=default_cache_dir())

red, sens, rob = res["reduced"], res["sensitivity"], res["robustness"]
failures = verification_failures(red) + spot_check_failures(rob, red["tol"])
if not rob.get("spot_checks"):
    failures.append("no spot check of the full CEA was made")

# (2) the unstable modes of the sensitivity = the full CEA's (when both look at the same band)
if scene["analyses"]["cea"]["band_hz"] == scene["analyses"]["reduced"]["band_hz"]:
    n_sens = sum(r["unstable"] for r in sens)
    if n_sens != res["n_unstable"]:
        failures.append(f"sensitivity: {n_sens} unstable modes on the reduced model, full CEA {res['n_unstable']}")

# (3) central finite differences of the reduced model
model = ReducedModel.load(outdir / "reduced_model.npz")
values = parameter_values(model)
lam0 = solve_points(model, {})[0]


def nearest(lam: np.ndarray, target: complex) -> complex:
    """The eigenvalue of ``lam`` nearest ``target`` (a doublet may reorder under a perturbation)."""
    return lam[np.argmin(np.abs(lam - target))]


worst_fd = 0.0
for p, v in values.items():
    if v == 0:   # k_t, η at 0: the check is relative to p (p ∂λ/∂p = 0), and η, k_t < 0 are not allowed
        continue
    h = 1e-6 * abs(v)
    lp = solve_points(model, {p: np.array([v + h])})[0]
    lm = solve_points(model, {p: np.array([v - h])})[0]
    for r in sens:
        if r["near_coalescence"]:
            continue
        i = r["index"]
        fd = (nearest(lp, lam0[i]) - nearest(lm, lam0[i])) / (2 * h)
        d = r["d_real_part"][p] + 1j * r["d_freq_hz"][p] * 2 * np.pi
        worst_fd = max(worst_fd, abs(d - fd) * abs(v) / abs(lam0[i]))
if worst_fd > 1e-5:
    failures.append(f"sensitivity vs central differences: {worst_fd:.1e} > 1e-5 (relative to |λ| per 100 % of p)")

# (4) the estimator's bookkeeping
n = rob["n_samples"]
for what, q in [("total", rob["probability"])] + [(f"band {b['band_hz']}", b) for b in rob["bands"]]:
    if abs(q["stderr"] - np.sqrt(q["p"] * (1 - q["p"]) / n)) > 1e-12 or not 0 <= q["p"] <= rob["probability"]["p"]:
        failures.append(f"robustness {what}: p {q['p']}, standard error {q['stderr']}")

# (5) a degenerate distribution at the nominal point gives the nominal answer
band = tuple(scene["analyses"]["reduced"]["band_hz"])
nominal = {k: Distribution("normal", v, 0.0) for k, v in values.items()}
deg = run_robustness(model, nominal, 8, 0, band, [band], scene["analyses"]["reduced"]["growth_tol"])
n_nominal = sum(r["unstable"] for r in sens) if scene["analyses"]["sensitivity"]["modes"] == "unstable" else None
if n_nominal is not None and deg.probability().p != float(n_nominal > 0):
    failures.append(f"degenerate distribution: P = {deg.probability().p}, nominal unstable modes {n_nominal}")

if comm.rank == 0:
    print(f"reduced model: {red['size']} vectors, estimated error {red['estimated_error']:.1e}; full CEA "
          f"{res['n_unstable']} unstable modes")
    for r in sens:
        drivers = (f"near a coalescence (κ_loc = {r['kappa_local']:.3g}): no derivative" if r["near_coalescence"]
                   else ", ".join(f"{p} {r['rel_d_real_part'][p]:+.3g} 1/s" for p in r["ranking"]))
        print(f"  mode {r['index']}: {r['freq_hz']:.0f} Hz, Re λ {r['real_part']:+.3g} 1/s, κ_loc "
              f"{r['kappa_local']:.3g}; p·∂Re λ/∂p: {drivers}")
    print(f"sensitivity vs central differences: worst {worst_fd:.1e} (relative to |λ| per 100 % of p)")
    p = rob["probability"]
    print(f"robustness: {n} samples in {rob['seconds']:.1f} s on {rob['ranks']} rank(s) "
          f"({1e3 * rob['seconds_per_sample']:.2f} ms per sample per rank); P(squeal) = {p['p']:.4f} ± "
          f"{p['stderr']:.4f}")
    for b in rob["bands"]:
        print(f"  {b['band_hz'][0]:.0f}–{b['band_hz'][1]:.0f} Hz: P = {b['p']:.4f} ± {b['stderr']:.4f}")
    for f in rob["families"]:
        if f["p"] > 0:
            g = f["growth"]
            print(f"  family {f['label']}: P = {f['p']:.4f} ± {f['stderr']:.4f}, Re λ median "
                  f"{g['median']:+.3g} (5–95 %: {g['q05']:+.3g} … {g['q95']:+.3g}) 1/s")
    print("  drivers: " + ", ".join(f"{k} ρ = {d['rho']:+.3f} [{d['ci95'][0]:+.3f}, {d['ci95'][1]:+.3f}]"
                                    for k, d in rob["drivers"].items()))
    for s in rob.get("spot_checks", []):
        print(f"  spot check sample {s['sample']}: rel. error {s['max_rel_error']:.1e}, unstable full "
              f"{s['n_unstable_full']} / reduced {s['n_unstable_reduced']}")
    print(f"report: {outdir / 'report.html'}")
    print("CHECK FAILED:\n  " + "\n  ".join(failures) if failures else
          "check passed: spot checks = full CEA, sensitivities = finite differences, estimator consistent")
sys.exit(1 if failures else 0)
