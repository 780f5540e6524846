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

import numpy as np

from fem_squeal.app import plots
from fem_squeal.app.analyses.reduced import band_and_growth_tol, mismatches, parametric_operators, verify_point
from fem_squeal.app.analyses.sensitivity import check_parameter
from fem_squeal.app.fields import Field, at_least, non_negative, positive
from fem_squeal.app.html import escape as _e
from fem_squeal.app.html import num as _num
from fem_squeal.app.html import table as _table
from fem_squeal.app.stage import Context, Stage
from fem_squeal.reduced.eigensolve import TWO_PI
from fem_squeal.reduced.model import INTERFACE_PREFIXES, PART_PREFIXES, format_point, split_param
from fem_squeal.reduced.robustness import KINDS, Distribution, run_robustness
from fem_squeal.reduced.stability_map import equal_bands
from fem_squeal.util.atomic import write_json_atomic, write_npz_atomic
from fem_squeal.util.errors import ModelError, SceneError
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

_KEYS = {"uniform": ("lower", "upper"), "normal": ("mean", "std"), "lognormal": ("mean", "std")}


def _tables(params: dict) -> dict[str, Any]:
    """name → table, the nested forms ``E = {disc = {...}}``, ``kn = {pad = {...}}`` (any of E, eta,
    mu, kn, kt) flattened to ``E.disc``, ``kn.pad``; a table-valued entry of ``mu`` is ``mu.<interface>``
    also next to ``mu``'s own distribution keys (``[...parameters.mu]`` and ``[...parameters.mu.pad]``)."""
    out = {}
    for name, t in params.items():
        if name in (*PART_PREFIXES, *INTERFACE_PREFIXES) and isinstance(t, dict) and \
                ("distribution" not in t or any(isinstance(v, dict) for v in t.values())):
            own = {k: v for k, v in t.items() if not isinstance(v, dict)}
            if own:
                out[name] = own
            out.update({f"{name}.{target}": v for target, v in t.items() if isinstance(v, dict)})
        else:
            out[name] = t
    return out


def distributions(section: dict) -> dict[str, Distribution]:
    """The section's distributions (checked: SceneError naming ``analyses.robustness.parameters.<name>.<key>``)."""
    out = {}
    for name, t in _tables(section["parameters"]).items():
        key = f"analyses.robustness.parameters.{name}"
        if not isinstance(t, dict):
            raise SceneError(f"{key}: must be a table with distribution and its bounds or moments (got {t!r})")
        kind = t.get("distribution")
        if kind not in KINDS:
            raise SceneError(f"{key}.distribution: must be one of {list(KINDS)} (got {kind!r})")
        want = _KEYS[kind]
        unknown = sorted(set(t) - {"distribution", *want})
        if unknown:
            raise SceneError(f"{key}.{unknown[0]}: unknown key for a {kind} distribution; allowed: {list(want)}")
        for k in want:
            v = t.get(k)
            if v is None:
                raise SceneError(f"{key}.{k}: required for a {kind} distribution")
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not np.isfinite(v):
                raise SceneError(f"{key}.{k}: must be a finite number (got {v!r})")
        try:
            d = Distribution(kind, float(t[want[0]]), float(t[want[1]]))
        except ModelError as err:
            raise SceneError(f"{key}.{err}") from None
        prefix = split_param(name)[0]
        if name.startswith("E.") and not d.stays_positive():
            raise SceneError(f"{key}: a Young's modulus must stay > 0 (a normal needs mean > 8 std; "
                             f"or use a lognormal) (got {d.as_dict()})")
        if prefix == "kn" and "." in name and not d.stays_positive():
            raise SceneError(f"{key}: a contact stiffness must stay > 0 (a normal needs mean > 8 std; "
                             f"or use a lognormal) (got {d.as_dict()})")
        if prefix in ("kt", "eta") and not d.stays_non_negative():
            raise SceneError(f"{key}: {'a tangential stiffness' if prefix == 'kt' else 'a loss factor'} must stay "
                             f">= 0 (uniform: lower >= 0; a normal needs mean > 8 std; or use a lognormal) "
                             f"(got {d.as_dict()})")
        out[name] = d
    return out


def _spot_points(res, n: int) -> list[int]:
    """Sample indices for the full CEA: largest and smallest growth rate, then the extremes of
    each parameter (deterministic: the same on every rank)."""
    cand = [int(np.argmax(res.max_growth)), int(np.argmin(res.max_growth))]
    for v in res.samples.values():
        cand += [int(np.argmax(v)), int(np.argmin(v))]
    return list(dict.fromkeys(cand))[:n]


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
    prob = res.probability()
    fam_p = res.family_probabilities()
    labels = [f"{f:.0f} Hz" for f in res.nominal.imag / TWO_PI]
    families = []
    for j, (lab, p) in enumerate(zip(labels, fam_p)):
        g = res.family_lambda[:, j].real
        q = np.quantile(g, [0.05, 0.5, 0.95])
        fam = {"label": lab, "freq_hz": float(res.nominal[j].imag / TWO_PI),
               "nominal_real_part": float(res.nominal[j].real), **p.as_dict(),
               "growth": {"mean": float(g.mean()), "std": float(g.std()), "min": float(g.min()),
                          "q05": float(q[0]), "median": float(q[1]), "q95": float(q[2]), "max": float(g.max())}}
        if p.p > 0:
            fam["drivers"] = res.drivers(g)
        families.append(fam)
    out = {"n_samples": n, "seed": r["seed"], "ranks": res.ranks, "seconds": res.seconds,
           "seconds_per_sample": res.seconds * res.ranks / n,
           "parameters": {k: d.as_dict() for k, d in dists.items()},
           "probability": prob.as_dict(),
           "bands": [{"band_hz": list(b), **p.as_dict()} for b, p in zip(bands, res.band_probabilities())],
           "families": families, "drivers": res.drivers(), "sobol": res.sobol(),
           "family_assignment": "nearest nominal eigenvalue (Hungarian, |λ − λ⁰|/|λ⁰|)"}
    ctx.say(f"[fem_squeal] robustness: {n} samples in {res.seconds:.1f} s on {res.ranks} rank(s); "
            f"P(unstable) = {prob.p:.4f} ± {prob.stderr:.4f}")
    if r["spot_checks"]:
        t = time.perf_counter()
        out["spot_checks"] = _spot_checks(ctx, model, res, band, gt, r["spot_checks"])
        timings["robustness_spot_checks"] = time.perf_counter() - t
        ctx.say("[fem_squeal] robustness spot checks (reduced vs full CEA): " + ", ".join(
            f"{format_point(s['point'])}: {s['max_rel_error']:.1e}" for s in out["spot_checks"]))
    if comm.rank == 0:
        write_npz_atomic(work / "robustness.npz", {**{f"sample/{k}": v for k, v in res.samples.items()},
                                                   "max_growth": res.max_growth, "band_hits": res.band_hits,
                                                   "nominal": res.nominal, "family_lambda": res.family_lambda,
                                                   "bands_hz": np.array(bands)})
        write_json_atomic(work / "robustness.json", out)
        top = sorted(range(len(families)), key=lambda j: -fam_p[j].p)[:r["n_histograms"]]
        top = [j for j in top if fam_p[j].p > 0] or top[:1]
        plots.robustness(work / "robustness.png", bands, [b["p"] for b in out["bands"]],
                         [b["stderr"] for b in out["bands"]], out["drivers"],
                         [{"label": labels[j], "growth": res.family_lambda[:, j].real} for j in top],
                         scene.title)
    return {"robustness": out}


def spot_check_failures(rob: dict, tol: float, what: str = "") -> list[str]:
    """Spot samples where the reduced model misses the full CEA (:func:`~fem_squeal.app.analyses.reduced.
    mismatches`: relative error above ``tol``, or a different number of unstable modes)."""
    return mismatches(rob.get("spot_checks", []), tol, what,
                      lambda s: f"sample {s['sample']} ({format_point(s['point'])})")


def check(scene: dict, volumes) -> None:
    """At least one parameter; each a valid distribution of μ or of the E of a part the basis carries."""
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
              section=SECTION, check=check, report=report)
