"""The ``robustness`` analysis: Monte Carlo over scattered parameters on the reduced model
(:mod:`fem_squeal.reduced.robustness`): the probability of at least one unstable mode, in the
whole band, per frequency band and per mode family, with standard errors; each family's
growth-rate distribution; the drivers (Spearman ρ with Fisher-z intervals, first-order Sobol'
indices with bootstrap intervals); and spot checks of
the full CEA at a few samples, the extreme ones included (the samples with the largest and the
smallest growth rate, then those with the extreme value of each parameter).

The spot checks need the finite-element operators, so the stage needs ``preload`` besides
``reduced``: when the stage runs, the model stages are rebuilt in memory if they are cached.

Scene: ``[analyses.robustness.parameters.mu]`` (or ``."E.disc"``, or the nested
``[analyses.robustness.parameters.E.disc]``) with ``distribution = "uniform"`` and ``lower``,
``upper``, or ``"normal"`` / ``"lognormal"`` and ``mean``, ``std``.
Files: robustness.npz, robustness.json, robustness.png."""
from __future__ import annotations

import time
from pathlib import Path
from typing import Any

from fem_squeal.app.analyses import matrix_studies
from fem_squeal.app.analyses.reduced import band_and_growth_tol, mismatches, parametric_operators, verify_point
from fem_squeal.app.analyses.robustness_summary import (  # noqa: F401  (defined there, used here and re-exported)
    _KEYS,
    _spot_points,
    _tables,
    distributions,
    summary,
    write_files,
)
from fem_squeal.app.analyses.sensitivity import check_parameter
from fem_squeal.app.fields import Field, at_least, non_negative, positive
from fem_squeal.app.html import escape as _e
from fem_squeal.app.html import num as _num
from fem_squeal.app.html import table as _table
from fem_squeal.app.stage import Context, Stage
from fem_squeal.reduced.model import format_point
from fem_squeal.reduced.robustness import run_robustness
from fem_squeal.reduced.stability_map import equal_bands
from fem_squeal.util.errors import SceneError
from fem_squeal.util.progress import ProgressBar

SECTION = {
    "n_samples": Field(int, 1000, at_least(2), "Monte Carlo samples"),
    "seed": Field(int, 0, non_negative, "seed of numpy.random.default_rng (the same samples on any rank count)"),
    "n_bands": Field(int, 6, positive, "equal frequency ranges of analyses.reduced.band_hz"),
    "parameters": Field(dict, {}, None, "<name> = {distribution = 'uniform', lower, upper} or "
                        "{distribution = 'normal' | 'lognormal', mean, std}; names 'mu', 'E.<part>', "
                        "'eta.<part>', 'mu.<interface>', 'kn.<interface>', 'kt.<interface>' (contact or "
                        "rigid_plate)"),
    "spot_checks": Field(int, 3, non_negative, "full CEA at this many samples (the extreme ones first)"),
    "n_histograms": Field(int, 4, non_negative, "growth-rate histograms of the families most often unstable"),
}

def _spot_checks(ctx: Context, model, res, band, gt: float, n: int) -> list[dict]:
    """Full CEA at the spot samples against the reduced eigenvalues (as analyses.reduced.verify)."""
    # every part the model carries: a part's nominal loss factor enters the full problem too
    par = parametric_operators(ctx, model.mu0, sorted(model.K_parts))
    opts = ctx.scene.solver.petsc_options
    rows = []
    try:
        for k in _spot_points(res, n):
            point = {name: float(v[k]) for name, v in res.samples.items()}
            rows.append({"sample": k, "max_growth_reduced": float(res.max_growth[k]),
                         **verify_point(par, model, point, band, gt, opts)})
    finally:
        par.destroy()
    return rows


def run(ctx: Context, work: Path, timings: dict) -> dict[str, Any]:
    """analyses.robustness: Monte Carlo on the reduced model; robustness.npz/json/png."""
    scene, model = ctx.scene, ctx.reduced_model()
    r = scene.analyses["robustness"]
    band, gt = band_and_growth_tol(scene)
    dists = distributions(r)
    bands = equal_bands(band, r["n_bands"])
    n, comm = r["n_samples"], ctx.comm
    share = len(range(comm.rank, n, comm.size))
    with ProgressBar(share, "robustness", enabled=comm.rank == 0, unit=" samples") as bar:
        res = run_robustness(model, dists, n, r["seed"], band, bands, gt, comm=comm if comm.size > 1 else None,
                             bar=bar)
    timings["robustness"] = res.seconds
    out = summary(res, r, dists, bands)
    prob = res.probability()
    ctx.say(f"[fem_squeal] robustness: {n} samples in {res.seconds:.1f} s on {res.ranks} rank(s); "
            f"P(unstable) = {prob.p:.4f} ± {prob.stderr:.4f}")
    if r["spot_checks"]:
        t = time.perf_counter()
        out["spot_checks"] = _spot_checks(ctx, model, res, band, gt, r["spot_checks"])
        timings["robustness_spot_checks"] = time.perf_counter() - t
        ctx.say("[fem_squeal] robustness spot checks (reduced vs full CEA): " + ", ".join(
            f"{format_point(s['point'])}: {s['max_rel_error']:.1e}" for s in out["spot_checks"]))
    if comm.rank == 0:
        write_files(work, res, out, bands, r["n_histograms"], scene.title)
    return {"robustness": out}


def spot_check_failures(rob: dict, tol: float, what: str = "") -> list[str]:
    """Spot samples where the reduced model misses the full CEA (:func:`~fem_squeal.app.analyses.reduced.
    mismatches`: relative error above ``tol``, or a different number of unstable modes)."""
    return mismatches(rob.get("spot_checks", []), tol, what,
                      lambda s: f"sample {s['sample']} ({format_point(s['point'])})")


def check(scene: dict, volumes) -> None:
    """At least one parameter; each a valid distribution of μ or of the E of a part the basis carries."""
    if "matrices" in scene:                 # a model given as matrices: :mod:`.matrix_studies`
        return matrix_studies.check_robustness(scene, volumes)
    r = scene.analyses["robustness"]
    if not r["parameters"]:
        raise SceneError("analyses.robustness.parameters: at least one parameter is required, e.g. "
                         "[analyses.robustness.parameters.mu] distribution = \"uniform\", lower = 0.3, "
                         "upper = 0.5")
    for name in _tables(r["parameters"]):
        check_parameter(scene, volumes, name, f"analyses.robustness.parameters.{name}")
    distributions(r)


def report(res: dict) -> str:
    """The report section (HTML) of this stage from results.json ``res``."""
    if "robustness" not in res:
        return ""
    r = res["robustness"]
    p = r["probability"]
    txt = (f"<h2>Robustness</h2><p>{r['n_samples']} samples (seed {r['seed']}) of "
           f"{_e(', '.join(r['parameters']))} in {_num(r['seconds'])} s on {r['ranks']} rank(s): "
           f"P(at least one unstable mode) = {_num(p['p'])} ± {_num(p['stderr'])} "
           f"(95 % {_num(p['ci95'][0])}–{_num(p['ci95'][1])}).</p>")
    txt += _table(["band [Hz]", "P(unstable)", "std. error"],
                  [[f"{b['band_hz'][0]:.0f}–{b['band_hz'][1]:.0f}", b["p"], b["stderr"]] for b in r["bands"]])
    fams = [f for f in r["families"] if f["p"] > 0]
    if fams:
        txt += "<p>Mode families (nominal mode nearest in eigenvalue) that are unstable in some sample:</p>"
        txt += _table(["family", "P(unstable)", "std. error", "Re λ median [1/s]", "Re λ 5–95 %"],
                      [[f["label"], f["p"], f["stderr"], f["growth"]["median"],
                        f"{f['growth']['q05']:.3g} – {f['growth']['q95']:.3g}"] for f in fams])
    sob = r.get("sobol", {})
    txt += ("<p>Drivers of the largest growth rate (Spearman ρ and the first-order Sobol' index S₁, "
            "95 % intervals):</p>") + _table(
        ["parameter", "ρ", "95 % interval", "S₁", "S₁ 95 % interval"],
        [[k, d["rho"], f"{d['ci95'][0]:.3f} – {d['ci95'][1]:.3f}", sob[k]["S1"] if k in sob else "",
          f"{sob[k]['ci95'][0]:.3f} – {sob[k]['ci95'][1]:.3f}" if k in sob else ""]
         for k, d in sorted(r["drivers"].items(), key=lambda kv: -abs(kv[1]["rho"]))])
    if r.get("spot_checks"):
        txt += "<p>Spot checks, full CEA against the reduced model:</p>" + _table(
            ["sample", "point", "max rel. error", "unstable full", "unstable reduced"],
            [[s["sample"], format_point(s["point"]), s["max_rel_error"], s["n_unstable_full"],
              s["n_unstable_reduced"]] for s in r["spot_checks"]])
    return txt


STAGE = Stage("robustness", ("reduced", "preload"), run, "Monte Carlo robustness of the stability",
              section=SECTION, check=check, report=report,
              on_matrices=matrix_studies.run_robustness_on_matrices, section_on_matrices=matrix_studies.ROBUSTNESS)
