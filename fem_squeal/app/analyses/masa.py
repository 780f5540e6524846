"""The ``masa`` analysis (seed 000) on the reduced model: for each μ, the static equilibrium with the
cubic contact law (eq. 4), the CEA about it (eq. 6) and the amplitude sweep of every instability
in the band (:mod:`fem_squeal.reduced.masa`), dealt over the ranks.
Files: masa.json, masa/mu<μ>_<f>Hz.png and masa/mu<μ>_<f>Hz_contact.png."""
from __future__ import annotations

import time
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from fem_squeal.app import plots
from fem_squeal.app.analyses.reduced import band_and_growth_tol, check_contact_study
from fem_squeal.app.fields import REAL, Field, at_least, non_negative, one_of, positive
from fem_squeal.app.html import table as _table
from fem_squeal.app.stage import Context, Stage
from fem_squeal.reduced.masa import MasaProblem, from_reduced, run_masa, static_equilibrium
from fem_squeal.reduced.model import MU
from fem_squeal.util.atomic import write_json_atomic
from fem_squeal.util.errors import SceneError

SECTION = {
    "mu": Field(list, [], None, "sign(v)μ values, one equilibrium + CEA + MASA each; [] = the scene's"),
    "amplitude_max": Field(REAL, 5.0, positive, "last amplitude of the sweep"),
    "n_amplitudes": Field(int, 100, at_least(2), "amplitude steps (from 0)"),
    "amplitude_unit": Field(str, "loss", one_of("loss", "modal"),
                            "'loss': multiples of the first contact loss; 'modal': p of eq. 25"),
    "cubic_share": Field(REAL, 0.3, non_negative, "share of the preload tangent from k_nl (0 = linear)"),
    "contact_damping": Field(list, [], None, "[c_max per area N s/m³, depth m] (seed 004 eq. 3)"),
    "patches": Field(list, [], None, "[n_radial, n_angular] AFT elements per interface; [] = every "
                     "contact point (default: patches change the stationary amplitudes, see "
                     "benchmarks/README.md)"),
    "attachments": Field(list, [4, 8], None, "[n_radial, n_angular] patch attachment vectors in the "
                         "basis; [] = none"),
    "n_samples": Field(int, 64, at_least(8), "AFT samples per period"),
    "sweep_break": Field(bool, True, None, "stop once the instability's real part is <= 0"),
    "update_shape": Field(bool, False, None, "update ψ, ω from the state matrix along the sweep"),
    "refine": Field(int, 10, non_negative, "bisections of each stationary amplitude"),
}


def run(ctx: Context, work: Path, timings: dict) -> dict[str, Any]:
    return {"masa": run_masa_analysis(ctx.comm, ctx.scene, ctx.reduced_model(), work, ctx.say, timings)}


def masa_amplitudes(prob, targets, m: dict) -> np.ndarray:
    """(n_targets, n) amplitude grids: 0 … amplitude_max in the chosen unit."""
    steps = np.linspace(0.0, m.amplitude_max, m.n_amplitudes)
    if m.amplitude_unit == "modal":
        return np.tile(steps, (len(targets), 1))
    scale = [prob.loss_amplitude(t) for t in targets]
    return np.array([steps * (s if np.isfinite(s) else 1.0) for s in scale])


def run_masa_analysis(comm, scene: dict, model, outdir: Path, say, timings: dict) -> dict[str, Any]:
    """analyses.masa on the reduced model (module docstring)."""
    m = scene.analyses["masa"]
    band, gt = band_and_growth_tol(scene)
    mus = [float(v) for v in m.mu] or [model.mu0]
    cd = m.contact_damping or [0.0, np.inf]
    out: dict[str, Any] = {"settings": m, "cases": []}
    t0 = time.perf_counter()
    for mu in mus:
        t = time.perf_counter()
        mm = from_reduced(model, {MU: mu}, cubic_share=m.cubic_share, c_max=cd[0], depth=cd[1],
                          patches=tuple(m.patches) if m.patches else None)
        eq = static_equilibrium(mm, model.q_static)
        prob = MasaProblem(mm, eq, band, n_samples=m.n_samples, growth_tol=gt)
        targets = prob.instabilities()
        amps = masa_amplitudes(prob, targets, m)
        results = run_masa(prob, targets, amps, sweep_break=m.sweep_break, update_shape=m.update_shape,
                           refine=m.refine, comm=comm, progress=True)
        seconds = time.perf_counter() - t
        unit = "× first contact loss" if m.amplitude_unit == "loss" else "modal amplitude p"
        case = {"mu": mu, "equilibrium": eq.as_dict(), "elements": prob.n_elements, "basis": mm.size,
                "instabilities": [], "seconds": seconds}
        for res, a in zip(results, amps):
            scale = a[-1] / m.amplitude_max  # p of one unit
            rec = res.as_dict()
            rec["amplitude_unit_value"] = float(scale)
            rec["stationary_in_unit"] = [s / scale for s in res.stationary]
            case["instabilities"].append(rec)
            if comm.rank == 0:
                stem = f"mu{mu:+.3f}_{res.freq_hz:.0f}Hz"
                shown = replace_amplitudes(res, 1.0 / scale)
                label = f"amplitude [{unit}]"
                plots.masa(outdir / "masa" / f"{stem}.png", shown,
                           f"MASA, μ = {mu:+.3f}: instability at {res.freq_hz:.0f} Hz", label)
                plots.contact_status(outdir / "masa" / f"{stem}_contact.png", shown,
                                     f"contact status, μ = {mu:+.3f}, {res.freq_hz:.0f} Hz", label)
        out["cases"].append(case)
        say(f"[fem_squeal] MASA μ = {mu:+.3f}: equilibrium in {eq.iterations} Newton steps "
            f"(‖R‖/‖f‖ {eq.residual:.1e}), {len(targets)} instabilities × {m['n_amplitudes']} amplitudes on "
            f"{prob.n_elements} elements, {sum(r.steps for r in results)} state matrices, {seconds:.2f} s; "
            "stationary amplitudes: " + "; ".join(
                f"{r.freq_hz:.0f} Hz: {', '.join(f'{s:.3g}' for s in c['stationary_in_unit']) or '-'}"
                for r, c in zip(results, case["instabilities"])))
    timings["masa"] = time.perf_counter() - t0
    if comm.rank == 0:
        write_json_atomic(outdir / "masa.json", out)
    return {"cases": [{k: v for k, v in c.items() if k != "instabilities"} |
                      {"instabilities": [{k: r[k] for k in ("freq_hz", "real_part", "stationary_amplitudes",
                                                            "stationary_in_unit", "broke_at", "steps")}
                                         for r in c["instabilities"]]} for c in out["cases"]],
            "seconds": timings["masa"]}


def replace_amplitudes(res, factor: float):
    """A copy of a MASA result with its amplitudes (and stationary values) scaled by ``factor``."""
    return replace(res, amplitudes=res.amplitudes * factor, stationary=[s * factor for s in res.stationary])


def check(scene: dict, volumes) -> None:
    """A contact interface, the nonlinear preload, the shared law settings, and μ a list of numbers."""
    check_contact_study(scene, "masa")
    mus = scene.analyses["masa"].mu
    if not all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in mus):
        raise SceneError(f"analyses.masa.mu: must be a list of numbers (got {mus})")


def report(res: dict) -> str:
    """The report section (HTML) of this stage from results.json ``res``."""
    if "masa" not in res:
        return ""
    rows = [[c["mu"], i["freq_hz"], i["real_part"],
             ", ".join(f"{v:.3g}" for v in i["stationary_in_unit"]) or "–",
             i["broke_at"]] for c in res["masa"]["cases"] for i in c["instabilities"]]
    return ("<h2>MASA</h2>" + _table(["μ", "f [Hz]", "Re λ at 0 [1/s]", "stationary amplitudes",
                                        "sweep broke at"], rows))


STAGE = Stage("masa", ("reduced",), run, "modal amplitude stability analysis", section=SECTION, check=check,
              report=report,
              inputs=lambda scene, spec: {"masa": scene.analyses["masa"],
                                          "band": scene.analyses["reduced"].band_hz,
                                          "growth_tol": scene.analyses["reduced"].growth_tol})
