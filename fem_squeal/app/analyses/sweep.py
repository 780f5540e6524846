"""The ``sweep`` analysis: one parameter (sign(v)μ or a part's E) over a range on the reduced model,
every branch tracked by MAC continuation (:func:`fem_squeal.reduced.tracking.track`) and the
critical values refined (by default only as far as the reduced model's estimated error warrants:
the parameter step over which the eigenvalue moves by that error; ``refine_tol`` asks for more).
Files: sweep.json, root_locus.png, complex_plane.png and sweep_coupling.png (the real modes of the basis
that merge at each change of stability: :func:`fem_squeal.reduced.mode_coupling.coupling_at`).  On a model
given as matrices: :mod:`fem_squeal.app.analyses.matrix_sweep`."""
from __future__ import annotations

import time
from pathlib import Path
from typing import Any

import numpy as np

from fem_squeal.app import plots
from fem_squeal.app.analyses import matrix_sweep
from fem_squeal.app.analyses.reduced import band_and_growth_tol, speed_not_a_parameter
from fem_squeal.app.fields import REAL, Field, at_least, increasing, positive
from fem_squeal.app.html import escape as _e
from fem_squeal.app.html import table as _table
from fem_squeal.app.stage import Context, Stage
from fem_squeal.reduced import mode_coupling
from fem_squeal.reduced.eigensolve import unstable
from fem_squeal.reduced.model import MU, SPEED
from fem_squeal.reduced.sweep import path_solver
from fem_squeal.reduced.tracking import track
from fem_squeal.util.atomic import write_json_atomic
from fem_squeal.util.errors import PipelineError, SceneError

SECTION = {
    "parameter": Field(str, "mu", None, "'mu' (sign(v)μ), 'E.<part>' (Young's modulus [Pa]) or 'speed' "
                       "(the disc speed Ω [rad/s]: gyroscopic ∝ Ω, convective and centrifugal ∝ Ω², friction "
                       "damping ∝ 1/Ω)"),
    "range": Field(list, [-1.0, 1.0], increasing(2), "[first, last] value"),
    "n": Field(int, 101, at_least(2), "number of values"),
    "refine_tol": Field(REAL, None, positive, "critical values refined to this fraction of the range; "
                        "not set: only as far as the reduced model's estimated error warrants", unset=0),
}


def basis_error(ctx: Context) -> float | None:
    """The reduced model's relative eigenvalue error: its estimate (the last round's change), or the
    worst reduced-vs-full error at the check points where it was verified, if larger (from the
    reduced stage's results, so that a cached reduced stage gives the same); None if unknown."""
    try:
        r = ctx.cache.load("reduced", ctx.keys["reduced"])["results"]["reduced"]
    except (PipelineError, KeyError, TypeError):  # no entry or no estimate: the default tolerance
        return None
    errs = [r.get("estimated_error")] + [v.get("max_rel_error") for v in r.get("verification", [])]
    errs = [float(e) for e in errs if isinstance(e, (int, float)) and np.isfinite(e)]
    return max(errs) if errs else None


def run(ctx: Context, work: Path, timings: dict) -> dict[str, Any]:
    """analyses.sweep on the reduced model: sweep.json, root_locus.png, complex_plane.png."""
    scene, model = ctx.scene, ctx.reduced_model()
    s = scene.analyses["sweep"]
    band, gt = band_and_growth_tol(scene)
    t = time.perf_counter()
    values = np.linspace(*s["range"], s["n"])
    fixed = {} if s["parameter"] == MU else {MU: model.mu0}
    error = basis_error(ctx) if s["refine_tol"] is None else None
    tr = track(path_solver(model, s["parameter"], fixed), values, growth_tol=gt,
               start=0.0 if s["parameter"] == MU and values[0] <= 0 <= values[-1] else None,
               progress=ctx.comm.rank == 0, values_solve=path_solver(model, s["parameter"], fixed, vectors=False),
               tol=s["refine_tol"] or 1e-10, error=error, band_hz=band)
    timings["sweep"] = time.perf_counter() - t
    f = tr.freqs_hz
    inside = np.flatnonzero(np.any((f >= band[0]) & (f <= band[1]), axis=0))
    events = [e for e in tr.events if band[0] <= e.freq_hz <= band[1]]
    # which real modes of the basis merge at each change of stability: the branch's eigenvector at the
    # grid value of its bracket where it grows faster (one reduced solve each; mode_coupling.coupling_at)
    n_modes = int(model.info.get("modes", 0))
    real = mode_coupling.basis_modes(model.K0, n_modes)
    solve = path_solver(model, s["parameter"], fixed)
    couplings = []
    for e in events:
        k = max((int(np.argmin(np.abs(values - b))) for b in e.bracket),
                key=lambda i, j=e.branch: tr.eigenvalues[i, j].real)
        couplings.append(mode_coupling.coupling_at(solve, values[k], tr.eigenvalues[k, e.branch], real)
                         if n_modes else None)
    out = {"parameter": s["parameter"], "values": values, "branches": [
        {"label": tr.labels[j], "parent_hz": tr.parents_hz[j], "freq_hz": f[:, j],
         "real_part": tr.eigenvalues[:, j].real} for j in inside],
        "critical": [{**e.as_dict(), **({"coupling": c} if c else {})} for e, c in zip(events, couplings)],
        "solves": tr.solves, "vector_solves": tr.vector_solves,
        "ambiguous_steps": tr.ambiguous_steps, "seconds": timings["sweep"],
        # the error the critical values were refined to (None: refine_tol, or 1e-10 of the range)
        "seconds_per_value": timings["sweep"] / s["n"], "refined_to_estimated_error": error}
    ctx.say(f"[fem_squeal] sweep of {s['parameter']}: {s['n']} values, {tr.solves} reduced solves, "
            f"{len(events)} stability changes in the band, {timings['sweep']:.2f} s")
    if ctx.comm.rank == 0:
        write_json_atomic(work / "sweep.json", out)
        xlabel = {MU: "sign(v) μ", SPEED: "speed Ω [rad/s]"}.get(s["parameter"], f"{s['parameter']} [Pa]")
        plots.root_locus(work / "root_locus.png", values, tr.eigenvalues, unstable(tr.eigenvalues, gt),
                         xlabel, band, tr.labels, scene.title)
        plots.complex_plane(work / "complex_plane.png", tr.eigenvalues, band, gt, scene.title)
        if any(couplings):
            plots.merging_pairs(work / "sweep_coupling.png", values, tr.eigenvalues, unstable(tr.eigenvalues, gt),
                                [(e.value, e.freq_hz, c) for e, c in zip(events, couplings) if c], xlabel, band,
                                scene.title)
    out.pop("branches")  # kept in sweep.json; results.json holds the summary
    return {"sweep": out}


def check(scene: dict, volumes) -> None:
    """The swept parameter is μ or the Young's modulus of a part of the model (> 0); on a model given as
    matrices: :func:`fem_squeal.app.analyses.matrix_sweep.check`."""
    if "matrices" in scene:
        return matrix_sweep.check(scene, volumes)
    s = scene.analyses["sweep"]
    par = s["parameter"]
    if par == SPEED:
        why = speed_not_a_parameter(scene)
        if why:
            raise SceneError(f"analyses.sweep.parameter: 'speed' is not a parameter of this model: {why}")
        if not s["range"][0] > 0 and any(t.get("friction_damping") for t in scene.interfaces.values()):
            raise SceneError(f"analyses.sweep.range: the speed must be > 0 with friction damping (∝ 1/Ω; "
                             f"got {s['range']})")
        if s["range"][0] < 0:
            raise SceneError(f"analyses.sweep.range: the speed must be >= 0 (got {s['range']})")
    elif par != "mu":
        if not par.startswith("E.") or par[2:] not in volumes:
            raise SceneError(f"analyses.sweep.parameter: must be 'mu', 'speed' or 'E.<part>' with a part of "
                             f"{sorted(volumes)} (got {par!r})")
        if s["range"][0] <= 0:
            raise SceneError(f"analyses.sweep.range: Young's modulus must be > 0 (got {s['range']})")


def report(res: dict) -> str:
    """The report section (HTML) of this stage from results.json ``res``."""
    if "sweep" not in res:
        return ""
    s = res["sweep"]
    r = res.get("sweep_reduction")          # a model given as matrices: its reduced model and its check
    how = "" if r is None else (
        f"<p>Reduced model of the matrices: {r['basis']} basis of size {r['size']}; against the full sparse CEA "
        f"at {len(r['verification'])} values the worst relative eigenvalue error is "
        + (f"{r['max_rel_error']:.1e} (tol {r['tol']:g})." if r["max_rel_error"] is not None else "not checked.")
        + "</p>")
    return (f"<h2>Sweep of {_e(s['parameter'])}</h2>{how}<p>{len(s['values'])} values, {s['solves']} reduced "
               "solves; real modes: the modes of the reduced basis (nominal, frictionless) in the unstable "
               "eigenvector at the grid value next to the critical value on its unstable side.</p>" + _table(
                   ["value", "f [Hz]", "kind", "branches", "real modes"],
                   [[c["value"], c["freq_hz"], c["kind"], c.get("labels", ""), c["coupling"]["label"]
                     if "coupling" in c else ""] for c in s["critical"]]))


STAGE = Stage("sweep", ("reduced",), run, "one-parameter sweep with mode tracking", section=SECTION, check=check,
              report=report, on_matrices=matrix_sweep.run, section_on_matrices=matrix_sweep.SECTION)
