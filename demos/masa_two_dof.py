"""MASA on a minimal friction oscillator (seed 000 §3 on a two-DOF mode-coupling model).

A unit mass on two inclined springs is pressed onto a sliding belt through one contact element
with the cubic unilateral law of seed 000 eq. 3 (k_l, k_nl tuned so that the tangent stiffness
at the preload is 1e7 N/m, 30 % of it from the cubic term).  The script

1. solves the static equilibrium (eq. 4, Newton with line search) and the CEA about it (eq. 6):
   the two modes have coalesced into a flutter pair near 1 kHz;
2. sweeps the modal amplitude p of the unstable mode (eqs. 21–25) with the AFT first-harmonic
   linearisation (eq. 18): the cubic term first stiffens the contact, then contact loss
   (impacts, once p passes p_loss) softens it and the real part returns to zero: the
   stationary amplitude estimates the limit cycle;
3. repeats the sweep with the mode shape updated from the state matrix at each step (the
   seed's proposed extension) and compares.

It checks itself: p = 0 reproduces the CEA, the cubic regime matches the describing function
¾ k_nl A², a stationary amplitude exists beyond the first impact, and the sweep break stops
there.  Outputs in out/masa_two_dof/: masa.png, contact_status.png, masa.json.
"""
from __future__ import annotations

import sys

import numpy as np
from mpi4py import MPI

from fem_squeal.app import plots
from fem_squeal.app.cli import demo_arguments
from fem_squeal.reduced.eigensolve import quadratic_eigs
from fem_squeal.reduced.masa import MasaProblem, run_masa, static_equilibrium
from fem_squeal.reduced.two_dof import two_dof_model
from fem_squeal.util.atomic import write_json_atomic

root, outdir, _ = demo_arguments(__file__)
comm = MPI.COMM_WORLD
say = print if comm.rank == 0 else (lambda *a, **k: None)
failures: list[str] = []

# --- 1. equilibrium and CEA -------------------------------------------------------------------
model = two_dof_model(mu=0.4, k_contact=1e7, preload=100.0, cubic_share=0.3)
eq = static_equilibrium(model)
prob = MasaProblem(model, eq, band_hz=(0.0, 5000.0))
(inst,) = prob.instabilities()
p_loss = prob.loss_amplitude(inst)
say(f"equilibrium: {eq.iterations} Newton iterations, ‖R‖/‖f‖ = {eq.residual:.1e}, "
    f"closure {eq.closure[0][0] * 1e6:.2f} µm")
say(f"CEA: unstable pair at {inst.freq_hz:.1f} Hz, Re λ = {inst.lam.real:.2f} 1/s; "
    f"first contact loss at p = {p_loss:.4g}")

# --- 2. fixed-shape MASA (the seed's method) ----------------------------------------------------
p = np.linspace(0.0, 6.0 * p_loss, 121)
full = run_masa(prob, [inst], p, sweep_break=False, comm=comm)[0]
brk = run_masa(prob, [inst], p, sweep_break=True, comm=comm)[0]
stat = ", ".join(f"{s:.4g} ({s / p_loss:.2f} p_loss)" for s in full.stationary)
say(f"MASA: stationary amplitude(s) p = {stat}; "
    f"with the sweep break: {brk.steps} state matrices instead of {full.steps}")

# --- 3. shape updated along the sweep -------------------------------------------------------------
upd = run_masa(prob, [inst], p, sweep_break=False, update_shape=True, comm=comm)[0]
stat = ", ".join(f"{s / p_loss:.2f} p_loss" for s in upd.stationary) or "none"
dev = np.max(np.abs(upd.tracked.real - full.tracked.real))
say(f"shape-updated MASA: stationary p = {stat} in the range; max |Δ Re λ| against fixed shape {dev:.1f} 1/s")

# --- checks -------------------------------------------------------------------------------------
lam0 = quadratic_eigs(prob.K)
if not np.array_equal(full.eigenvalues[0], lam0[lam0.imag > 0]):
    failures.append("p = 0 does not reproduce the CEA")
i = int(np.searchsorted(p, 0.5 * p_loss))
a = full.interface_amplitude[i]
cs = model.contacts[0]
ref = quadratic_eigs(prob.K + 0.75 * cs.law.k_nl[0] * a * a * np.outer(cs.B[0], cs.D[0]))
if np.max(np.abs(full.eigenvalues[i] - ref[ref.imag > 0]) / np.abs(ref[ref.imag > 0])) > 1e-12:
    failures.append("cubic regime differs from the describing function ¾ k_nl A²")
if len(full.stationary) != 1 or not p_loss < full.stationary[0] < p[-1]:
    failures.append(f"expected one stationary amplitude beyond p_loss, got {full.stationary}")
elif brk.broke_at is None or not full.stationary[0] <= brk.broke_at < full.stationary[0] + 2 * (p[1] - p[0]):
    failures.append(f"sweep break at {brk.broke_at}, stationary amplitude {full.stationary}")

if comm.rank == 0:
    outdir.mkdir(parents=True, exist_ok=True)
    label = "modal amplitude p"
    plots.masa(outdir / "masa.png", full, "two-DOF oscillator: MASA (fixed shape)", label)
    plots.contact_status(outdir / "contact_status.png", full, "two-DOF oscillator: contact status", label)
    write_json_atomic(outdir / "masa.json", {
        "equilibrium": eq.as_dict(), "p_loss": p_loss, "fixed_shape": full.as_dict(),
        "with_break": brk.as_dict(), "updated_shape": upd.as_dict(), "ranks": comm.size})
    print("CHECK FAILED:\n  " + "\n  ".join(failures) if failures else
          "check passed: CEA continuity, describing function, stationary amplitude and sweep break")
sys.exit(1 if failures else 0)
