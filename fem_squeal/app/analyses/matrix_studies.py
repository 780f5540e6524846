"""analyses.map, analyses.sensitivity and analyses.robustness on a model given as matrices (a
``[matrices]`` scene), over the scene's named parameters (matrices.parameters), on the reduced model
of the matrices (:func:`fem_squeal.app.analyses.matrix_reduced.reduced_model`) with the reduced layer's
machinery of the finite-element model's studies, and each checked against the full sparse problem:

- **map**: the number of unstable modes per frequency band over the grid of one or two parameters
  (:func:`fem_squeal.reduced.sweep.evaluate`, :func:`fem_squeal.reduced.stability_map.stability_map`),
  the points dealt over the ranks; ``check_points`` grid points (the one with the most unstable modes,
  the one with the fewest, the centre) against the full sparse CEA.  Files: stability_map.npz,
  stability_map.png (two parameters).
- **sensitivity**: dλ/dp of the unstable modes (or every mode in the band) from the left and right
  eigenvectors of the reduced model (:func:`fem_squeal.reduced.sensitivity.sensitivities`; the
  coefficients of the expressions differentiated exactly).  ``full = true``: also dλ/dp of the full
  problem by central differences of full sparse CEAs, (λ(p + h) − λ(p − h))/2h, h = ``step`` × the
  parameter's range (its value where it has none, 1 where that is 0).  The error of that difference
  relative to |dλ/dp| is ε|λ|/(h|dλ/dp|) + h²|d³λ/dp³|/(6|dλ/dp|), ε ≈ 1e-11 the relative accuracy of
  the sparse CEA; for λ(p) varying on the scale of the range (|dⁿλ/dpⁿ| ~ |λ|/rangeⁿ, |λ|/|dλ/dp| ~ 100
  range) the default step 1e-3 gives ≈ 1e-6 + 2e-7.  Files: sensitivity.json, tornado_mode<index>.png.
- **robustness**: Monte Carlo over distributions of the parameters
  (:func:`fem_squeal.reduced.robustness.run_robustness`: the same samples on any number of ranks),
  with ``spot_checks`` samples (the extreme ones first) against the full sparse CEA.  Files:
  robustness.npz, robustness.json, robustness.png.

results.json: ``map``, ``sensitivity``, ``robustness`` as for a finite-element model, and
``map_reduction``, ``sensitivity_reduction``, ``robustness_reduction``: the basis (its checks against
the full CEA in the study's own section)."""
from __future__ import annotations

import time
from pathlib import Path
from typing import Any

import numpy as np

from fem_squeal.app import plots
from fem_squeal.app.analyses import matrix_reduced
from fem_squeal.app.analyses import robustness_summary as robustness
from fem_squeal.app.analyses.map_instabilities import map_instabilities, masks
from fem_squeal.app.analyses.matrix_reduced import BASIS_MODES, STUDY, check_parameter, parameter_range
from fem_squeal.app.fields import REAL, Field, at_least, non_negative, one_of, positive
from fem_squeal.app.stage import Context
from fem_squeal.reduced.eigensolve import TWO_PI
from fem_squeal.reduced.robustness import KINDS, draw, run_robustness
from fem_squeal.reduced.sensitivity import (
    KAPPA_COALESCENCE,
    band_records,
    parameter_values,
)
from fem_squeal.reduced.stability_map import equal_bands, stability_map
from fem_squeal.reduced.sweep import Grid, evaluate, solve_points
from fem_squeal.util.atomic import write_json_atomic, write_npz_atomic
from fem_squeal.util.errors import SceneError
from fem_squeal.util.progress import ProgressBar

MAP = {
    "parameters": Field(list, None, None, "the axes: one or two names of matrices.parameters"),
    "ranges": Field(dict, {}, None, "<name> = [low, high] of an axis; not given: "
                    "matrices.parameters.<name>.range"),
    "n": Field(int, 21, at_least(2), "values per axis"),
    "n_bands": Field(int, 6, positive, "equal frequency ranges of band_hz"),
    "check_points": Field(int, 1, at_least(0), "grid points checked against the full sparse CEA (the one with "
                          "the most unstable modes, the fewest, the centre)"),
    **STUDY, **BASIS_MODES,
}
SENSITIVITY = {
    "modes": Field(str, "unstable", one_of("unstable", "band"),
                   "'unstable': the unstable modes in band_hz; 'band': every mode in it"),
    "parameters": Field(list, [], None, "names of matrices.parameters; [] = every parameter"),
    "kappa_max": Field(REAL, KAPPA_COALESCENCE, lambda v: None if v > 1 else f"must be > 1 (got {v})",
                       "near a coalescence when the local condition number exceeds this (≈ 0.5 % from it)"),
    "full": Field(bool, False, None, "also dλ/dp of the full problem by central differences of full sparse "
                  "CEAs (each record's 'full' block)"),
    "step": Field(REAL, 1e-3, positive, "full: the difference step, a fraction of the parameter's range (of its "
                  "value where it has none)"),
    "max_plots": Field(int, 12, lambda v: None if v >= 0 else f"must be >= 0 (got {v})",
                       "tornado plots for at most this many unstable modes (the most unstable)"),
    **STUDY, **BASIS_MODES,
}
ROBUSTNESS = {
    "n_samples": Field(int, 1000, at_least(2), "Monte Carlo samples"),
    "seed": Field(int, 0, non_negative, "seed of numpy.random.default_rng (the same samples on any rank count)"),
    "n_bands": Field(int, 6, positive, "equal frequency ranges of band_hz"),
    "parameters": Field(dict, {}, None, "<name> = {distribution = 'uniform', lower, upper} or "
                        "{distribution = 'normal' | 'lognormal', mean, std}; names of matrices.parameters"),
    "spot_checks": Field(int, 3, non_negative, "full sparse CEA at this many samples (the extreme ones first)"),
    "n_histograms": Field(int, 4, non_negative, "growth-rate histograms of the families most often unstable"),
    **STUDY, **BASIS_MODES,
}


# -- map ------------------------------------------------------------------------------------------

def map_axes(scene) -> dict[str, np.ndarray]:
    """The values of each axis of analyses.map (``n`` over its range)."""
    m = scene.analyses["map"]
    return {p: np.linspace(*parameter_range(scene, p, m["ranges"].get(p), f"analyses.map.ranges.{p}"), m["n"])
            for p in m["parameters"]}


def check_map(scene, volumes) -> None:
    """One or two distinct parameters of matrices.parameters, each with a range; the coefficients finite
    over the grid."""
    m, key = scene.analyses["map"], "analyses.map"
    names = m["parameters"]
    if not names or len(names) > 2 or len(set(names)) != len(names):
        raise SceneError(f"{key}.parameters: one or two distinct names of matrices.parameters on a model given as "
                         f"matrices (got {names!r}); parameters: {sorted(scene.matrices.parameters)}")
    for p in names:
        check_parameter(scene, p, f"{key}.parameters")
    for p in m["ranges"]:
        if p not in names:
            raise SceneError(f"{key}.ranges.{p}: not an axis of the map (analyses.map.parameters = {names})")
    axes = map_axes(scene)
    grid = Grid(axes)
    matrix_reduced.check_finite(scene, grid.points(), f"{key}.ranges")


def run_map(ctx: Context, work: Path, timings: dict) -> dict[str, Any]:
    """analyses.map on a model given as matrices (module docstring)."""
    scene, m = ctx.scene, ctx.scene.analyses["map"]
    axes = map_axes(scene)
    t = time.perf_counter()
    red = matrix_reduced.reduced_model(ctx, m, matrix_reduced.diagonal_points(
        {p: (float(v[0]), float(v[-1])) for p, v in axes.items()}, m["snapshots"]))
    timings["map_reduction"] = time.perf_counter() - t
    band, gt = matrix_reduced.study_band(ctx, m, red), m["growth_tol"]
    grid = Grid(axes)
    res = evaluate(red, grid, ctx.comm, progress=True)
    timings["map"] = res.seconds
    bands = equal_bands(band, m["n_bands"])
    smap = stability_map(res, bands, gt)
    t = time.perf_counter()
    flat = smap.total.ravel()
    order = list(dict.fromkeys([int(np.argmax(flat)), int(np.argmin(flat)), grid.size // 2]))[:m["check_points"]]
    pts = grid.points()
    checks = [matrix_reduced.check_point(ctx, red, {p: float(v[k]) for p, v in pts.items()}, band, gt,
                                         "map_check_") for k in order]
    timings["map_check"] = time.perf_counter() - t
    worst = max((c["max_rel_error"] for c in checks), default=None)
    names = list(axes)
    t = time.perf_counter()
    # no coupling: a model given as matrices has no frictionless real modes to name (its parameters are its own)
    found = map_instabilities(ctx, work, red, res, band, gt, (names[-1], names[0]), couple=False)
    timings["map_instabilities"] = time.perf_counter() - t
    out = {"parameter": " × ".join(names), "parameters": names, "points": grid.size, "band_hz": list(band),
           "seconds": res.seconds, "seconds_per_point": res.seconds_per_point, **smap.as_dict(),
           "instabilities": [x.as_dict() for x in found]}
    reduction = {**red.info, "verification": checks, "max_rel_error": worst, "tol": m["tol"],
                 "passed": worst is None or (worst <= m["tol"] and all(
                     c["n_unstable_full"] == c["n_unstable_reduced"] for c in checks))}
    ctx.say(f"[fem_squeal] stability map of {' × '.join(names)} on the matrices' reduced model (size {red.size}): "
            f"{grid.size} points in {res.seconds:.2f} s, at most {int(smap.total.max())} unstable modes; reduced "
            f"vs full CEA at {len(checks)} points: worst "
            + (f"{worst:.1e}" if worst is not None else "not checked"))
    if not reduction["passed"]:
        ctx.say(f"[fem_squeal] warning: the reduced model misses the full CEA on the map (worst {worst:.1e}, tol "
                f"{m['tol']:g}, or another count of unstable modes): raise analyses.map.basis_modes")
    if ctx.comm.rank == 0:
        write_npz_atomic(work / "stability_map.npz", {**{f"axis/{p}": v for p, v in axes.items()},
                                                       "counts": smap.counts, "total": smap.total,
                                                       "eigenvalues": res.eigenvalues,
                                                       "bands_hz": np.array(bands),
                                                       "instabilities": masks(found, grid.shape)})
        if len(names) == 2:
            plots.stability_maps(work / "stability_map.png", axes[names[1]], axes[names[0]], smap.counts,
                                 smap.total, bands, names[0], scene.title, x_label=names[1])
    return {"map": out, "map_reduction": reduction}


# -- sensitivity ----------------------------------------------------------------------------------

def check_sensitivity(scene, volumes) -> None:
    """Every listed parameter is one of matrices.parameters."""
    for p in scene.analyses["sensitivity"]["parameters"]:
        check_parameter(scene, p, "analyses.sensitivity.parameters")


def _step(scene, name: str, fraction: float) -> float:
    p = scene.matrices.parameters[name]
    if p["range"] is not None:
        return fraction * (p["range"][1] - p["range"][0])
    return fraction * (abs(p["value"]) or 1.0)


def _full_differences(ctx: Context, s, records: list[dict], eigenvalues, params, values, band) -> None:
    """Each record gets ``full``: dλ/dp of the full problem by central differences of full sparse CEAs
    (module docstring) of the full eigenvalue nearest the reduced one (``match``: their relative distance;
    where it is not small against the spacing of the eigenvalues the pair may not be the same mode), and
    the relative difference of the reduced derivative to it."""
    lam0 = np.array(eigenvalues)
    f0 = lam0.imag / TWO_PI
    lo, hi = min(band[0], f0.min()), max(band[1], f0.max())
    lo, hi = max(0.0, lo - 0.05 * (hi - lo)), hi + 0.05 * (hi - lo)
    n = int(np.sum((f0 >= lo) & (f0 <= hi))) + 4
    full0 = matrix_reduced.full_cea(ctx, {}, (lo, hi), n, "sensitivity_full_")
    at = [full0[np.argmin(np.abs(full0 - x))] for x in lam0]       # the full eigenvalues of the modes
    steps, diffs = {}, {}
    for p in params:
        h = _step(ctx.scene, p, s["step"])
        plus, minus = (matrix_reduced.full_cea(ctx, {p: values[p] + sign * h}, (lo, hi), n, "sensitivity_full_")
                       for sign in (1, -1))
        steps[p] = h
        diffs[p] = [(plus[np.argmin(np.abs(plus - x))] - minus[np.argmin(np.abs(minus - x))]) / (2 * h)
                    for x in at]
    for i, (r, xf) in enumerate(zip(records, at)):
        near = r["near_coalescence"]
        d = {p: complex(diffs[p][i]) for p in params}
        d_re = {p: None if near else float(v.real) for p, v in d.items()}
        d_f = {p: None if near else float(v.imag / TWO_PI) for p, v in d.items()}
        red = {p: complex(r["d_real_part"][p], TWO_PI * r["d_freq_hz"][p]) if not near else None for p in params}
        r["full"] = {"freq_hz": float(xf.imag / TWO_PI), "real_part": float(xf.real),
                     "match": float(abs(xf - lam0[i]) / abs(lam0[i])), "d_real_part": d_re,
                     "d_freq_hz": d_f, "steps": steps,
                     "rel_d_real_part": {p: None if v is None else v * values[p] for p, v in d_re.items()},
                     "rel_difference": {p: None if near or d[p] == 0 else float(abs(red[p] - d[p]) / abs(d[p]))
                                        for p in params}}


def run_sensitivity(ctx: Context, work: Path, timings: dict) -> dict[str, Any]:
    """analyses.sensitivity on a model given as matrices (module docstring)."""
    scene, s = ctx.scene, ctx.scene.analyses["sensitivity"]
    params = s["parameters"] or list(scene.matrices.parameters)
    ranges = {p: tuple(scene.matrices.parameters[p]["range"]) for p in params
              if scene.matrices.parameters[p]["range"] is not None}
    t = time.perf_counter()
    red = matrix_reduced.reduced_model(ctx, s, matrix_reduced.diagonal_points(ranges, s["snapshots"])
                                       if ranges else [{}])
    timings["sensitivity_reduction"] = time.perf_counter() - t
    band, gt = matrix_reduced.study_band(ctx, s, red), s["growth_tol"]
    t = time.perf_counter()
    lam = solve_points(red, {})[0]
    sens, records = band_records(red, lam, band, gt, s["modes"], params, s["kappa_max"])
    values = parameter_values(red)
    timings["sensitivity"] = time.perf_counter() - t
    if s["full"] and records:
        t = time.perf_counter()
        _full_differences(ctx, s, records, [x.eigenvalue for x in sens], params, values, band)
        timings["sensitivity_full"] = time.perf_counter() - t
        worst = max((v for r in records for v in r["full"]["rel_difference"].values() if v is not None),
                    default=None)
        ctx.say("[fem_squeal] sensitivity, reduced against central differences of the full CEA: worst relative "
                "difference " + (f"{worst:.1e}" if worst is not None else "-"))
    near = [r for r in records if r["near_coalescence"]]
    ctx.say(f"[fem_squeal] sensitivity on the matrices' reduced model (size {red.size}): {len(records)} modes × "
            f"{len(params)} parameters in {timings['sensitivity']:.2f} s"
            + (f"; {len(near)} near a coalescence (no derivative)" if near else ""))
    if ctx.comm.rank == 0:
        write_json_atomic(work / "sensitivity.json", {"parameters": params, "values": values,
                                                      "band_hz": list(band), "kappa_max": s["kappa_max"],
                                                      "modes": records, "reduction": red.info})
        shown = sorted((r for r in records if r["unstable"]), key=lambda r: -r["real_part"])[:s["max_plots"]]
        for r in shown:
            plots.tornado(work / f"tornado_mode{r['index']}.png", r, scene.title)
    return {"sensitivity": records, "sensitivity_reduction": red.info}


# -- robustness -----------------------------------------------------------------------------------

def check_robustness(scene, volumes) -> None:
    """At least one parameter, each of matrices.parameters with a valid distribution, and the coefficients
    finite at every sample (drawn here: the same samples as the run)."""
    r, key = scene.analyses["robustness"], "analyses.robustness.parameters"
    if not r["parameters"]:
        raise SceneError(f"{key}: at least one parameter is required, e.g. [{key}.W] distribution = \"uniform\", "
                         "lower = 0.9, upper = 1.1")
    for name in robustness._tables(r["parameters"]):
        check_parameter(scene, name, f"{key}.{name}")
    dists = robustness.distributions(r)
    matrix_reduced.check_finite(scene, draw(dists, r["n_samples"], r["seed"]), key)


def _support(d) -> tuple[float, float]:
    """Where the snapshots of a distribution go: [lower, upper], mean ± 2 std."""
    return (d.a, d.b) if d.kind == KINDS[0] else (d.a - 2 * d.b, d.a + 2 * d.b)


def run_robustness_on_matrices(ctx: Context, work: Path, timings: dict) -> dict[str, Any]:
    """analyses.robustness on a model given as matrices (module docstring)."""
    scene, r = ctx.scene, ctx.scene.analyses["robustness"]
    dists = robustness.distributions(r)
    t = time.perf_counter()
    red = matrix_reduced.reduced_model(ctx, r, matrix_reduced.diagonal_points(
        {p: _support(d) for p, d in dists.items()}, r["snapshots"]))
    timings["robustness_reduction"] = time.perf_counter() - t
    band, gt = matrix_reduced.study_band(ctx, r, red), r["growth_tol"]
    bands = equal_bands(band, r["n_bands"])
    n, comm = r["n_samples"], ctx.comm
    with ProgressBar(len(range(comm.rank, n, comm.size)), "robustness", enabled=comm.rank == 0,
                     unit=" samples") as bar:
        res = run_robustness(red, dists, n, r["seed"], band, bands, gt, comm=comm if comm.size > 1 else None,
                             bar=bar)
    timings["robustness"] = res.seconds
    out = robustness.summary(res, r, dists, bands)
    prob = res.probability()
    ctx.say(f"[fem_squeal] robustness on the matrices' reduced model (size {red.size}): {n} samples in "
            f"{res.seconds:.1f} s on {res.ranks} rank(s); P(unstable) = {prob.p:.4f} ± {prob.stderr:.4f}")
    worst = None
    if r["spot_checks"]:
        t = time.perf_counter()
        out["spot_checks"] = [
            {"sample": k, "max_growth_reduced": float(res.max_growth[k]),
             **matrix_reduced.check_point(ctx, red, {p: float(v[k]) for p, v in res.samples.items()}, band, gt,
                                          "robustness_check_")}
            for k in robustness._spot_points(res, r["spot_checks"])]
        timings["robustness_spot_checks"] = time.perf_counter() - t
        worst = max(s["max_rel_error"] for s in out["spot_checks"])
        ctx.say(f"[fem_squeal] robustness spot checks (reduced vs full CEA): worst {worst:.1e}")
    reduction = {**red.info, "max_rel_error": worst, "tol": r["tol"],
                 "passed": worst is None or (worst <= r["tol"] and all(
                     s["n_unstable_full"] == s["n_unstable_reduced"] for s in out["spot_checks"]))}
    if comm.rank == 0:
        robustness.write_files(work, res, out, bands, r["n_histograms"], scene.title)
    return {"robustness": out, "robustness_reduction": reduction}
