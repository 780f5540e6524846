"""Squeal transient of the brake corner into the limit cycle (seed 002 §2–4).

1. ``scenes/brake_transient.toml`` through the pipeline: preload, CEA, the reduced model (modes,
   static corrections, preload displacement, pad attachments), then the transient: 8 × 16
   contact elements per pad (cubic law with contact damping), the disc at Ω, 100 ms at 1 µs
   from steady sliding plus a push along the most unstable tangent-CEA mode; then the limit
   cycle, space–time SVD and its MAC with the CEA modes, the dynamic stability diagram,
   component strain-energy shares and the complex-mode cycles.  Stages are cached
   (``$XDG_CACHE_HOME/fem_squeal``, or ``$FEM_SQUEAL_CACHE``): a second run only re-checks.
2. Independent check of the integrator on this model: at 1e-5 of the static closure no contact
   element switches, so the unstable mode must grow at the tangent CEA's Re λ (projection on its
   left eigenvector isolates it; 1 %).  The pipeline's discrete energy balance must close to 1e-6.

Outputs in out/transient_brake/ (report.html, transient.png, limit_cycle.png,
dynamic_stability.png, results.json).  ``--set=key=value`` overrides the scene.
Run: ``mpirun -n 2 .venv/bin/python demos/transient_brake.py``.
"""
from __future__ import annotations

import sys

import numpy as np
from mpi4py import MPI

from fem_squeal.app.analyses.transient import brake_start, integrator_options, static_closure
from fem_squeal.app.cli import demo_arguments
from fem_squeal.app.pipeline import default_cache_dir
from fem_squeal.app.run import run_scene
from fem_squeal.app.scene import load_scene
from fem_squeal.reduced.eigensolve import TWO_PI
from fem_squeal.reduced.model import ReducedModel
from fem_squeal.reduced.transient import run_transient

root, outdir, overrides = demo_arguments(__file__)
comm = MPI.COMM_WORLD
say = print if comm.rank == 0 else (lambda *a, **k: None)

# --- 1. the scene ------------------------------------------------------------------------------
scene = load_scene(root / "scenes" / "brake_transient.toml", overrides)
res = run_scene(scene, outdir, comm, write_fields=False, cache=default_cache_dir())
tr, lc = res["transient"], res["limit_cycle"]
failures = []
if comm.rank == 0:
    c = lc["limit_cycle"]
    say(f"transient: {tr['steps']} steps, {tr['ms_per_step']:.3f} ms/step; limit cycle: saturated "
        f"{c['saturated']}, {c['frequency_hz']:.0f} Hz, amplitude {c['amplitude'] * 1e6:.3g} µm")

    # --- 2. linear-regime growth against the tangent CEA ---------------------------------------
    a = scene["analyses"]["transient"]
    band = tuple(scene["analyses"]["reduced"]["band_hz"])
    rm = ReducedModel.load(outdir / "reduced_model.npz")
    dm, integ, qs, lam, Y, unstable, i, y = brake_start(rm, a, band)
    Kt, Ct = integ.tangent_matrices(qs, np.zeros_like(qs))
    m = dm.size
    A = np.block([[np.zeros((m, m)), np.eye(m)], [-Kt, -Ct]])
    mu_l, VL = np.linalg.eig(A.T)
    left = VL[:, np.argmin(np.abs(mu_l - lam[i]))]
    a_lin = 1e-5 * static_closure(dm, qs) / max(np.abs(cs.D @ y).max() for cs in dm.contacts)
    lin = run_transient(dm, qs + (a_lin * y).real, (a_lin * lam[i] * y).real, 3e-3, a["dt"], record_every=10,
                        **integrator_options(a))
    eta = np.abs(np.column_stack([lin.q - qs, lin.v]) @ left)
    late = lin.t > 5e-4
    rate = np.polyfit(lin.t[late], np.log(eta[late]), 1)[0]
    say(f"linear regime: the {lam[i].imag / TWO_PI:.0f} Hz mode grows at {rate:.2f}/s, tangent CEA Re λ "
        f"{lam[i].real:.2f}/s")
    if not abs(rate - lam[i].real) <= 0.01 * abs(lam[i].real):
        failures.append(f"linear growth rate {rate:.1f}/s is not the CEA's {lam[i].real:.1f}/s within 1 %")
    if not tr["energy_leak"] < 1e-6:
        failures.append(f"energy balance leaks {tr['energy_leak']:.1e} of the peak energy")
    say(f"report: {outdir / 'report.html'}")
    print("CHECK FAILED:\n  " + "\n  ".join(failures) if failures else
          "check passed: linear growth = tangent CEA Re λ (1 %); energy balance closes")
failures = comm.bcast(failures, root=0)
sys.exit(1 if failures else 0)
