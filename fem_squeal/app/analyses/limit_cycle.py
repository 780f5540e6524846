"""The ``limit_cycle`` analysis: post-processing of the transient's history (seed 002 §3–4).

Envelope saturation, frequency and amplitude; space–time SVD of the last cycles in the
strain-energy norm and its MAC with the tangent CEA modes at steady sliding; the dynamic stability
diagram (tangent CEA along the last cycle); component strain-energy shares along it; and the
complex-mode cycles Re(αψe^(iωt)) of the most unstable mode for each α (eq. 6), with braking torque
and friction work per cycle.  Files: limit_cycle.json, limit_cycle.png (with the energy-share and
mode-cycle panels), dynamic_stability.png."""
from __future__ import annotations

import time
from pathlib import Path
from typing import Any

import numpy as np

from fem_squeal.app import plots
from fem_squeal.app.analyses.transient import brake_start, probe, static_closure
from fem_squeal.app.fields import REAL, Field, at_least, positive
from fem_squeal.app.html import escape as _e
from fem_squeal.app.html import num as _num
from fem_squeal.app.html import table as _table
from fem_squeal.app.stage import Context, Stage
from fem_squeal.reduced.eigensolve import TWO_PI
from fem_squeal.reduced.limit_cycle import (
    detect_limit_cycle,
    dynamic_stability,
    follow_mode,
    mac,
    mode_cycle,
    plane_mac,
    space_time_svd,
    strain_energy_shares,
)
from fem_squeal.reduced.transient import load_history
from fem_squeal.util.atomic import write_json_atomic
from fem_squeal.util.blas import single_threaded
from fem_squeal.util.errors import SceneError
from fem_squeal.util.parallel import on_root

SECTION = {
    "cycles": Field(REAL, 2.0, positive, "periods analysed at the end of the run (SVD window)"),
    "svd_shapes": Field(int, 4, positive, "SVD shapes reported and compared with the CEA modes"),
    "stability_samples": Field(int, 48, at_least(4), "tangent CEAs along the last cycle"),
    "mode_cycle_amplitudes": Field(list, [0.01, 0.1, 0.5, 1.0, 2.0], None,
                                   "α of the complex-mode cycles [× static closure]"),
    "mode_cycle_samples": Field(int, 64, at_least(8), "pseudo-time samples per mode cycle"),
}


def run(ctx: Context, work: Path, timings: dict) -> dict[str, Any]:
    """Post-processing of the transient's history, on rank 0 with one BLAS thread."""
    with single_threaded():
        return _stage_limit_cycle(ctx, work, timings)


def _stage_limit_cycle(ctx, work: Path, timings: dict) -> dict[str, Any]:

    a = ctx.scene.analyses["limit_cycle"]
    ta = ctx.scene.analyses["transient"]
    band = tuple(ctx.scene.analyses["reduced"].band_hz)
    comm = ctx.comm

    def compute() -> dict[str, Any]:
        t0 = time.perf_counter()
        rm = ctx.reduced_model()
        dm, integ, qs, lam, Y, unstable, i, y = brake_start(rm, ta, band)
        h = load_history(ctx.entry("transient") / "run")
        t, Q, V = h["t"], h["q"], h["v"]
        k, j = probe(dm, y)
        x = Q @ dm.contacts[k].D[j]
        lc = detect_limit_cycle(t, x)
        period = 1.0 / lc.frequency_hz
        last = t >= t[-1] - a.cycles * period
        Kt, _ = integ.tangent_matrices(qs, np.zeros_like(qs))
        W = 0.5 * (Kt + Kt.T)
        svd = space_time_svd(Q[last] - Q[last].mean(axis=0), weight=W)
        n_sh = min(a.svd_shapes, svd.shapes.shape[1])
        near = (lam.imag > 0) & (lam.imag / TWO_PI >= band[0]) & (lam.imag / TWO_PI <= band[1])
        cand = np.flatnonzero(near)
        macs = mac(svd.shapes[:, :n_sh], Y[:, cand])
        planes = plane_mac(svd.shapes[:, :n_sh], Y[:, cand])
        best = [{"shape": r + 1, "freq_hz": float(lam[cand[c]].imag / TWO_PI),
                 "real_part": float(lam[cand[c]].real), "mac": float(macs[r, c]),
                 "plane_share": float(planes[r, c])} for r, c in enumerate(np.argmax(planes, axis=1))]
        samples = np.flatnonzero(t >= t[-1] - period)
        samples = samples[:: max(samples.size // a.stability_samples, 1)]
        ds = dynamic_stability(integ, t[samples], Q[samples], V[samples])
        trail = follow_mode(ds, lam[i]) if i >= 0 else None
        K_parts = rm.K_parts
        shares_t = None
        if K_parts:
            dq = Q[samples] - Q[last].mean(axis=0)
            e = np.array([[0.5 * d @ (K @ d) for K in K_parts.values()] for d in dq])
            shares_t = e / np.maximum(e.sum(axis=1, keepdims=True), 1e-300)
        cycles = []
        if i >= 0:
            omega = float(lam[i].imag)
            yn = y / np.abs(dm.contacts[k].D[j] @ y)        # unit closure amplitude at the probe
            for alpha in a.mode_cycle_amplitudes:
                mc = mode_cycle(integ, qs, yn, omega, alpha * static_closure(dm, qs), n=a.mode_cycle_samples)
                dsm = dynamic_stability(integ, mc.t, mc.q, mc.v)
                re = dsm.eigenvalues.real[np.arange(len(mc.t)), follow_mode(dsm, lam[i])]
                cycles.append({"alpha": alpha, "friction_work": mc.friction_work,
                               "torque_mean": float(np.mean(mc.torque)), "torque_range": float(np.ptp(mc.torque)),
                               "normal_force_range": float(np.ptp(mc.normal_force)),
                               "pseudo_real_part_min": float(re.min()), "pseudo_real_part_max": float(re.max())})
        out = {"limit_cycle": lc.as_dict(), "window_s": float(t[last][-1] - t[last][0]),
               "svd_energy": svd.energy_fraction()[:n_sh], "svd_best_mac": best,
               "dynamic_stability": {"samples": int(samples.size), "followed_real_part": (
                   [float(ds.eigenvalues[s, c].real) for s, c in enumerate(trail)] if trail is not None else []),
                   "unstable_share": float(np.mean(ds.eigenvalues[np.arange(samples.size), trail].real > 0))
                   if trail is not None else None},
               "energy_shares": ({p: float(v) for p, v in zip(K_parts, shares_t.mean(axis=0))}
                                 if shares_t is not None else {}),
               "mode_energy_shares": strain_energy_shares(y, K_parts) if K_parts else {},
               "mode_cycles": cycles}
        write_json_atomic(work / "limit_cycle.json", out)
        plots.dynamic_stability(work / "dynamic_stability.png", ds.t, ds.eigenvalues, band,
                                title="tangent CEA over the last cycle (seed 002 Fig. 10)")
        plots.limit_cycle(work / "limit_cycle.png", t, x, lc, svd.energy_fraction()[:n_sh], best,
                          t[samples], shares_t, list(K_parts), cycles, ctx.scene.title)
        timings["limit_cycle"] = time.perf_counter() - t0
        ctx.say(f"[fem_squeal] limit cycle: saturated {lc.saturated}, {lc.frequency_hz:.0f} Hz, amplitude "
                f"{lc.amplitude * 1e6:.3g} µm; SVD shape 1 lies {100 * best[0]['plane_share']:.0f} % in the plane "
                f"of the {best[0]['freq_hz']:.0f} Hz mode (MAC {best[0]['mac']:.2f})")
        return out

    return {"limit_cycle": on_root(comm, compute)}


def check(scene: dict, volumes) -> None:
    """The amplitudes of the complex-mode cycles are numbers > 0."""
    amps = scene.analyses["limit_cycle"].mode_cycle_amplitudes
    if not all(isinstance(v, (int, float)) and not isinstance(v, bool) and v > 0 for v in amps):
        raise SceneError(f"analyses.limit_cycle.mode_cycle_amplitudes: must be numbers > 0 (got {amps})")


def report(res: dict) -> str:
    """The report section (HTML) of this stage from results.json ``res``."""
    if "limit_cycle" not in res:
        return ""
    lc = res["limit_cycle"]
    c = lc["limit_cycle"]
    txt = (f"<h2>Limit cycle</h2><p>saturated: <b>{_e(c['saturated'])}</b>, {_num(c['frequency_hz'])} Hz, "
           f"amplitude {_num(c['amplitude'] * 1e6)} µm.</p>")
    txt += _table(["SVD shape", "energy share", "best CEA mode [Hz]", "share in its plane", "MAC"],
                  [[b["shape"], lc["svd_energy"][b["shape"] - 1], b["freq_hz"], b["plane_share"], b["mac"]]
                   for b in lc["svd_best_mac"]])
    if lc["energy_shares"]:
        txt += _table(["component", "strain-energy share"], [[k, v] for k, v in lc["energy_shares"].items()])
    if lc["mode_cycles"]:
        txt += _table(["α", "friction work [J]", "mean torque [N m]", "pseudo Re λ min", "max"],
                      [[m["alpha"], m["friction_work"], m["torque_mean"], m["pseudo_real_part_min"],
                        m["pseudo_real_part_max"]] for m in lc["mode_cycles"]])
    return (txt)


STAGE = Stage("limit_cycle", ("transient",), run,
              "limit cycle, space-time SVD, MAC, dynamic stability, mode cycles", section=SECTION, check=check,
              report=report)
