"""Squeal transient of the brake corner: 100 ms into the limit cycle (seed 002 §2–3).

1. The reduced brake model (modes, static corrections, the preload displacement and pad
   attachments, as for MASA) is built by the scene pipeline, or read with ``--model=FILE``.
2. Each pad's lining quadrature points are grouped into 8 × 16 polar patches (256 contact
   elements) with the cubic unilateral law with contact damping; the disc turns at Ω = 5 rad/s
   (constant-μ sliding, the law the CEA linearises); out-of-band vectors (> 18 kHz) get modal
   damping so that the basis' spurious high-frequency flutter does not swamp the squeal band.
3. From steady sliding plus a small push along the most unstable tangent-CEA mode, the
   trapezoidal Newmark rule runs 1e5 steps of 1 µs.
4. Post-processing: limit-cycle detection, space–time SVD (strain-energy norm) and its MAC with
   the CEA modes, the dynamic stability diagram (tangent CEA over the last cycle), time
   histories, spectrogram and phase portrait.

Checks: in the linear regime (1e-5 of the static closure) the unstable mode grows at the tangent
CEA's Re λ (1 %; the fit window is 5 periods of the slowest competing pair);
the discrete energy balance closes to 1e-6 of the peak energy.  Outputs in out/transient_brake/.
Options: ``--t_end=0.1 --dt=1e-6 --model=FILE --set=key=value``.
"""
from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np
from mpi4py import MPI

from fem_squeal import plots
from fem_squeal.output import write_json_atomic
from fem_squeal.reduced.eigensolve import TWO_PI
from fem_squeal.reduced.limit_cycle import detect_limit_cycle, dynamic_stability, mac, space_time_svd, tangent_eigs
from fem_squeal.reduced.model import ReducedModel
from fem_squeal.reduced.transient import NewmarkHHT, from_reduced, run_transient

root = Path(__file__).resolve().parents[1]
opts = dict(a[2:].split("=", 1) for a in sys.argv[1:]
            if a.startswith("--") and "=" in a and not a.startswith("--set="))
args = [a for a in sys.argv[1:] if not a.startswith("--")]
outdir = Path(args[0]) if args else root / "out" / "transient_brake"
comm = MPI.COMM_WORLD
say = print if comm.rank == 0 else (lambda *a, **k: None)
t_end, dt = float(opts.get("t_end", 0.1)), float(opts.get("dt", 1e-6))

# --- 1. the reduced model ---------------------------------------------------------------------
if "model" in opts:
    model_file = Path(opts["model"])
else:
    from fem_squeal.run import run_scene
    from fem_squeal.scene import load_scene

    overrides = [a.split("=", 1)[1] for a in sys.argv[1:] if a.startswith("--set=")]
    scene = load_scene(root / "scenes" / "brake_corner_cea.toml", ["analyses.masa.n_amplitudes=2", *overrides])
    run_scene(scene, outdir / "fe", comm, write_fields=False)
    model_file = outdir / "fe" / "reduced_model.npz"
if comm.rank != 0:          # the reduced transient is small: rank 0 runs it, the others wait
    comm.barrier()
    sys.exit(0)
rm = ReducedModel.load(model_file)

# --- 2. the dynamic model ---------------------------------------------------------------------
dm = from_reduced(rm, omega=5.0, cubic_share=0.3, c_max=2e5, depth=1e-6, patches=(8, 16), f_cut=18e3)
integ = NewmarkHHT(dm, dt)
qs = integ.steady_sliding(rm.q_static)
Kt, Ct = integ.tangent_matrices(qs, np.zeros_like(qs))
lam, Y = tangent_eigs(Kt, Ct, vectors=True)
band = (0.0, 16e3)
inb = (lam.imag / TWO_PI <= band[1]) & (lam.real > 1e-6 * np.abs(lam))
say(f"{dm.size} basis vectors, {sum(c.size for c in dm.contacts)} contact elements; "
    f"unstable in 0–16 kHz: " + ", ".join(f"{z.imag / TWO_PI:.0f} Hz ({z.real:.0f}/s)" for z in lam[inb]))
i = int(np.argmax(np.where(inb, lam.real, -np.inf)))
y = Y[:, i]
closure = np.median(np.concatenate([cs.d0 + cs.D @ qs for cs in dm.contacts]))
amp = float(opts.get("amplitude", 1e-3)) * closure / max(np.abs(cs.D @ y).max() for cs in dm.contacts)

# --- 3. the run ---------------------------------------------------------------------------------
# linear regime first: at 1e-5 of the static closure no contact element switches, so the unstable
# mode must grow at the tangent CEA's Re λ (projection on its left eigenvector isolates it)
m = dm.size
A = np.block([[np.zeros((m, m)), np.eye(m)], [-Kt, -Ct]])
mu_l, VL = np.linalg.eig(A.T)
left = VL[:, np.argmin(np.abs(mu_l - lam[i]))]
a_lin = 1e-5 * closure / max(np.abs(cs.D @ y).max() for cs in dm.contacts)
lin = run_transient(dm, qs + (a_lin * y).real, (a_lin * lam[i] * y).real, 3e-3, dt, record_every=10)
eta = np.abs(np.column_stack([lin.q - qs, lin.v]) @ left)
rate = np.polyfit(lin.t[lin.t > 5e-4], np.log(eta[lin.t > 5e-4]), 1)[0]
say(f"linear regime: the {lam[i].imag / TWO_PI:.0f} Hz mode grows at {rate:.2f}/s, "
    f"tangent CEA Re λ {lam[i].real:.2f}/s")

t0 = time.perf_counter()
res = run_transient(dm, qs + (amp * y).real, (amp * lam[i] * y).real, t_end, dt, record_every=10,
                    folder=outdir / "run", checkpoint_every=20000, progress=True,
                    rtol=float(opts.get("rtol", 1e-9)))
wall = time.perf_counter() - t0
st = res.stats
say(f"{st['steps']} steps in {wall:.1f} s ({1e3 * wall / st['steps']:.3f} ms/step, "
    f"{st['iterations'] / st['steps']:.2f} Newton iterations/step, {st['factorisations']} factorisations)")

# --- 4. post-processing --------------------------------------------------------------------------
probe = dm.contacts[0]
j = int(np.argmax(np.abs(probe.D @ y)))          # the patch that moves most in the unstable mode
x = res.q @ probe.D[j]
xv = res.v @ probe.D[j]
lc = detect_limit_cycle(res.t, x)
say(f"limit cycle: saturated {lc.saturated} at t = {lc.t_saturation * 1e3:.1f} ms, {lc.frequency_hz:.0f} Hz, "
    f"closure amplitude {lc.amplitude * 1e6:.3f} µm (static closure {closure * 1e6:.3f} µm)")
last = res.t >= res.t[-1] - 2.0 / lc.frequency_hz
svd = space_time_svd(res.q[last], weight=Kt)
macs = mac(svd.shapes[:, :2], Y[:, inb | (np.abs(lam.imag / TWO_PI - lc.frequency_hz) < 2000)])
cand = lam[inb | (np.abs(lam.imag / TWO_PI - lc.frequency_hz) < 2000)]
best = [(float(cand[k].imag / TWO_PI), float(macs[r, k])) for r, k in enumerate(np.argmax(macs, axis=1))]
say(f"cycle SVD: energy shares {np.round(svd.energy_fraction()[:3], 3)}; "
    "best MAC of shapes 1-2 with CEA modes "
    + ", ".join(f"{f:.0f} Hz ({v:.2f})" for f, v in best))
samples = np.flatnonzero(last)[:: max(int(last.sum()) // 48, 1)]
ds = dynamic_stability(integ, res.t[samples], res.q[samples], res.v[samples])
near = np.abs(ds.eigenvalues.imag / TWO_PI - lc.frequency_hz) < 1500
re_near = np.where(near, ds.eigenvalues.real, np.nan)
say(f"dynamic stability over the last cycle near {lc.frequency_hz:.0f} Hz: Re λ from {np.nanmin(re_near):.0f} "
    f"to {np.nanmax(re_near):.0f} 1/s")
E = res.total_energy()
leak = float(np.abs(res.energy_residual()).max() / E.max())
say(f"energy balance: max |E − E₀ − ΣW| / max E = {leak:.1e}; friction work {res.energy['W_friction'][-1]:.3e} J")

extra = {f"{cs.name} normal force [kN]": res.contact[f"{cs.name}.normal_force"] / 1e3 for cs in dm.contacts}
extra.update({f"{cs.name} torque [kN m]": res.contact[f"{cs.name}.torque"] / 1e3 for cs in dm.contacts})
plots.transient(outdir / "transient.png", res.t, x, xv, extra,
                title="brake transient: closure of the most active patch", label="closure [µm]")
plots.dynamic_stability(outdir / "dynamic_stability.png", ds.t, ds.eigenvalues, band,
                        title="tangent CEA over the last two cycles")
failures = []
if not abs(rate - lam[i].real) <= 0.01 * abs(lam[i].real):
    failures.append(f"linear growth rate {rate:.1f}/s is not the CEA's {lam[i].real:.1f}/s within 1 %")
if not leak < 1e-6:
    failures.append(f"energy balance leaks {leak:.1e} of the peak energy")
write_json_atomic(outdir / "results.json", {
    "basis": dm.size, "contact_elements": sum(c.size for c in dm.contacts), "dt": dt, "t_end": t_end,
    "wall_s": wall, "ms_per_step": 1e3 * wall / st["steps"], "stats": st, "limit_cycle": lc.as_dict(),
    "cea_unstable": [{"freq_hz": z.imag / TWO_PI, "real_part": z.real} for z in lam[inb]],
    "growth_rate": rate, "cea_real_part": lam[i].real, "energy_leak": leak,
    "svd_energy": svd.energy_fraction()[:5], "svd_best_mac": best, "failures": failures})
print("CHECK FAILED:\n  " + "\n  ".join(failures) if failures else
      "check passed: linear growth = tangent CEA Re λ (1 %); energy balance closes")
comm.barrier()
sys.exit(1 if failures else 0)
