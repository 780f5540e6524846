"""Modal amplitude stability analysis of the brake corner (seed 000 on the bundled brake).

The chain of seed 000 Fig. 3 on the reduced brake model, under ``mpirun -n 2``:

1. nonlinear static preload of the full model (active-set Newton), then the reduced basis:
   frictionless modes, static corrections of the friction forces, the preload displacement and
   the static responses to unit pressure on 4 × 8 patches of each pad (attachments), grown until
   the unstable eigenvalues move by < 1e-3;
2. on that basis, every lining quadrature point gets the cubic unilateral law (eq. 3; k_l, k_nl
   tuned per pad so that the tangent is the penalty k_n at the mean preload pressure, 30 % of it
   cubic); the static equilibrium is solved again with it (eq. 4, Newton with line search) and
   the CEA is taken about it (eq. 6);
3. every instability in 0–10 kHz is swept in modal amplitude up to 5× the amplitude of its
   first contact loss, with the AFT first-harmonic linearisation at every lining quadrature
   point (2808 contact elements, eq. 18) and the sweep break; instabilities are dealt over the
   ranks.

Checks: with the linear law the reduced equilibrium is the full-order preload (to round-off) and
MASA's CEA is the full CEA (within the reduction's tol); at p = 0 every sweep starts from the CEA;
each stationary amplitude is a zero of the tracked real part.  Outputs in out/masa_brake/:
masa.json, masa/*.png (the seed's Figs. 4–10), reduced_model.npz, results.json.
``--set=key=value`` overrides scene entries (e.g. ``--set=geometry.mesh_size=0.016``).
"""
from __future__ import annotations

import json
import sys

import numpy as np
from mpi4py import MPI

from fem_squeal.app.cli import demo_arguments
from fem_squeal.app.run import run_scene
from fem_squeal.app.scene import load_scene
from fem_squeal.reduced.masa import MasaProblem, from_reduced, static_equilibrium
from fem_squeal.reduced.model import ReducedModel

root, outdir, overrides = demo_arguments(__file__)
comm = MPI.COMM_WORLD
say = print if comm.rank == 0 else (lambda *a, **k: None)
scene = load_scene(root / "scenes" / "brake_corner_cea.toml",
                   ["analyses.masa.amplitude_max=5.0", "analyses.masa.n_amplitudes=100",
                    "analyses.masa.sweep_break=true", *overrides])
res = run_scene(scene, outdir, comm, write_fields=False)
failures: list[str] = []
band = tuple(scene["analyses"]["reduced"]["band_hz"])
tol = scene["analyses"]["reduced"]["tol"]

# --- the linear law reproduces the full-order preload and CEA -----------------------------------
rm = ReducedModel.load(outdir / "reduced_model.npz")
lin = from_reduced(rm, cubic_share=0.0)
eq = static_equilibrium(lin, rm.q_static)
if eq.iterations != 0 or eq.residual > 1e-9:
    failures.append(f"linear law: reduced equilibrium is not the full preload ({eq.iterations} Newton steps, "
                    f"residual {eq.residual:.1e})")
red = np.array([i.lam for i in MasaProblem(lin, eq, band).instabilities()], complex)
full = [complex(r["real_part"], 2 * np.pi * r["freq_hz"]) for r in res["complex_modes"]
        if r["unstable"] and band[0] <= r["freq_hz"] <= band[1]]
if len(red) != len(full) or any(min(abs(red - f)) > 10 * tol * abs(f) for f in full):
    failures.append(f"linear law: MASA CEA {np.round(red.imag / 2 / np.pi)} Hz against full CEA "
                    f"{[round(f.imag / 2 / np.pi) for f in full]} Hz")
say(f"linear law: reduced equilibrium = full preload (residual {eq.residual:.1e}); "
    f"{len(red)} instabilities as the full CEA")

# --- the sweeps -----------------------------------------------------------------------------
with open(outdir / "masa.json") as fh:
    masa = json.load(fh)
for case in masa["cases"]:
    say(f"μ = {case['mu']:+.2f}: {case['elements']} contact elements, basis {case['basis']}, "
        f"{case['seconds']:.2f} s on {comm.size} rank(s)")
    for r in case["instabilities"]:
        lam0 = r["eigenvalues"][0]
        if not any(abs(re - r["real_part"]) <= 1e-9 * abs(r["real_part"]) for re in lam0["real"]):
            failures.append(f"{r['freq_hz']:.0f} Hz: p = 0 does not start from the CEA")
        st = r["stationary_in_unit"]
        tr = np.asarray(r["tracked_real"])
        say(f"  {r['freq_hz']:7.1f} Hz  Re λ {r['real_part']:7.1f} 1/s -> max {tr.max():7.1f}; "
            f"stationary at {', '.join(f'{s:.2f}' for s in st) or 'none'} × first contact loss; "
            f"{r['steps']} steps"
            + (f", break at {r['broke_at'] / r['amplitude_unit_value']:.2f}" if r["broke_at"] else ""))
        if r["broke_at"] is not None and not st:
            failures.append(f"{r['freq_hz']:.0f} Hz: sweep broke without a stationary amplitude")

if comm.rank == 0:
    print("CHECK FAILED:\n  " + "\n  ".join(failures) if failures else
          "check passed: linear law = full preload and CEA; sweeps start from the CEA; "
          "every sweep break has its stationary amplitude")
sys.exit(1 if failures else 0)
