"""Complex eigenvalue analysis of a brake corner, about its braking preload.

The brake pressure pushes the piston and, through the floating caliper, the fingers: both pads
are clamped on the disc.  The static step finds which points of each lining touch the disc
(active-set penalty contact with sliding friction); the CEA then linearises about that state
(seed 000 eqs. 4-6): contact springs k_n and the asymmetric friction stiffness μ k_n at the
closed points only (seed 001 eq. 4).  Friction couples pairs of modes into flutter: a mode
with Re λ > 0 is a squeal candidate.  For each mode the script prints the frequency, growth rate,
the disc's nodal diameters and which components carry the strain energy.

Run:  mpirun -n 2 python3 demos/brake_corner_cea.py [OUTDIR] [--set key=value ...]
It checks itself: force balance of the preload, residuals, and the ±σ symmetry of flutter.
"""
from __future__ import annotations

import math
import sys

import numpy as np
from mpi4py import MPI

from fem_squeal.app.cli import demo_arguments
from fem_squeal.app.run import run_scene
from fem_squeal.app.scene import load_scene

root, outdir, sets = demo_arguments(__file__)
scene = load_scene(root / "scenes" / "brake_corner_cea.toml", sets)
comm = MPI.COMM_WORLD
res = run_scene(scene, outdir, comm)
say = print if comm.rank == 0 else (lambda *a, **k: None)

# --- the preload: where the clamp force goes ---------------------------------------------------
p = scene["loads"]["pressure"]["piston"]["p"]
r_piston = scene["geometry"]["piston_radius"]
piston_force = p * math.pi * r_piston ** 2
pre = res["preload"]["interfaces"]
say(f"\npiston force p·A = {piston_force:.0f} N")
for name, v in pre.items():
    say(f"  {name}: normal {v['normal_force']:.0f} N, friction {v['friction_force']:.0f} N, "
        f"closed {100 * v['closed_share']:.0f} % of the lining, peak pressure {v['peak_pressure'] / 1e6:.2f} MPa")

# --- the complex modes -------------------------------------------------------------------------
modes = res["complex_modes"]
say(f"\n{'f [Hz]':>9} {'Re λ [1/s]':>11} {'ζ':>8} {'ND':>3}  "
    "strain energy: disc/linings/backplates/caliper/piston")
for m in modes:
    e = m["energy_shares"]
    flag = "  UNSTABLE" if m["unstable"] else ""
    say(f"{m['freq_hz']:9.1f} {m['real_part']:11.3f} {m['damping_ratio']:8.4f} {m['nodal_diameter']:3d}  "
        f"{e['disc']:.2f} {e['linings']:.2f} {e['backplates']:.2f} {e['caliper']:.2f} {e['piston']:.2f}{flag}")

# --- checks ------------------------------------------------------------------------------------
failures = []
# Force balance: the seal, guide pins and abutments are soft axially (k_axial 1e8 N/m³, seal
# k_t 1e9 N/m³ over a few cm²), so each pad carries the piston force less a few per cent.
for name, v in pre.items():
    if not 0.9 * piston_force < v["normal_force"] <= piston_force * (1 + 1e-9):
        failures.append(f"{name}: normal force {v['normal_force']:.1f} N vs piston force {piston_force:.1f} N")
    mu = scene["interfaces"][name]["mu"]
    if abs(v["friction_force"] - mu * v["normal_force"]) > 1e-9 * v["normal_force"]:
        failures.append(f"{name}: friction force is not μ N")
max_res = scene["analyses"]["cea"]["max_residual"]
if any(m["residual"] > max_res for m in modes):
    failures.append("a complex mode exceeds the residual bound")
for m in modes:
    if abs(sum(m["energy_shares"].values()) - 1) > 1e-9:
        failures.append(f"{m['freq_hz']:.1f} Hz: strain-energy shares do not add up to 1")
# Undamped flutter comes in quadruples ±σ ± iω: each unstable mode has a mirror at the same ω.
lam = np.array([m["real_part"] + 2j * math.pi * m["freq_hz"] for m in modes])
undamped = all(v.get("rayleigh_alpha", 0) == 0 and v.get("rayleigh_beta", 0) == 0
               for v in scene["materials"].values())
unstable = lam[lam.real > 0]
if undamped:
    for u in unstable:
        if np.min(np.abs(lam - np.conj(-u))) > 1e-6 * abs(u):
            failures.append(f"{u.imag / 2 / math.pi:.1f} Hz: unstable mode without its stable mirror")
if comm.rank == 0:
    print(f"\n{len(unstable)} unstable of {len(modes)} modes in {scene['analyses']['cea']['band_hz']} Hz; "
          f"results in {outdir / 'results.json'}, pressure map {outdir / 'contact_pressure.png'}")
    print("CHECK FAILED:\n  " + "\n  ".join(failures) if failures else
          "check passed: preload balances the piston force, residuals bounded, flutter pairs mirror")
sys.exit(1 if failures else 0)
