"""The ``sensitivity`` analysis: dλ/dp of the unstable modes (or of every mode in the band) with
respect to the parameters of the reduced model (sign(v)μ, E of the parts its basis carries), from
the left and right eigenvectors at the nominal point (:mod:`fem_squeal.reduced.sensitivity`).
A mode near a coalescence (κ_loc > ``kappa_max``) is flagged and gets no derivative.
Files: sensitivity.json, tornado_mode<index>.png (one per unstable mode)."""
from __future__ import annotations

import time
from pathlib import Path
from typing import Any

import numpy as np

from fem_squeal.app import plots
from fem_squeal.app.analyses.reduced import band_and_growth_tol
from fem_squeal.app.fields import REAL, Field, one_of
from fem_squeal.app.html import table as _table
from fem_squeal.app.stage import Context, Stage
from fem_squeal.reduced.eigensolve import TWO_PI, unstable
from fem_squeal.reduced.model import MU, e_param
from fem_squeal.reduced.sensitivity import KAPPA_COALESCENCE, parameter_values, ranking, sensitivities
from fem_squeal.reduced.sweep import solve_points
from fem_squeal.util.atomic import write_json_atomic
from fem_squeal.util.errors import SceneError

SECTION = {
    "modes": Field(str, "unstable", one_of("unstable", "band"),
                   "'unstable': the unstable modes in analyses.reduced.band_hz; 'band': every mode in it"),
    "parameters": Field(list, [], None,
                        "parameters ('mu', 'E.<part>'); [] = every parameter of the reduced model"),
    "kappa_max": Field(REAL, KAPPA_COALESCENCE, lambda v: None if v > 1 else f"must be > 1 (got {v})",
                       "near a coalescence when the local condition number exceeds this (≈ 0.5 % from it)"),
    "max_plots": Field(int, 12, lambda v: None if v >= 0 else f"must be >= 0 (got {v})",
                       "tornado plots for at most this many unstable modes (the most unstable)"),
}


def basis_parts(scene: dict, volumes) -> list[str]:
    """Parts whose Young's modulus the reduced basis carries (as
    :func:`fem_squeal.app.analyses.reduced.basis_design`: the swept part, the map's part, every
    part when a transient runs)."""
    ana = scene["analyses"]
    parts = set()
    if "sweep" in ana and ana["sweep"]["parameter"].startswith("E."):
        parts.add(ana["sweep"]["parameter"][2:])
    if "map" in ana:
        parts.add(ana["map"]["part"])
    if "transient" in ana:
        parts.update(volumes)
    return sorted(parts)


def check_parameter(scene: dict, volumes, name: str, key: str) -> None:
    """``name`` is 'mu' or 'E.<part>' with a part the reduced basis carries; else SceneError at ``key``."""
    if name == MU:
        return
    if not name.startswith("E.") or name[2:] not in volumes:
        raise SceneError(f"{key}: unknown parameter {name!r}; parameters are 'mu' and 'E.<part>' with a part "
                         f"of {sorted(volumes)}")
    carried = basis_parts(scene, volumes)
    if name[2:] not in carried:
        raise SceneError(f"{key}: the reduced basis does not carry {name!r} (it carries "
                         f"{[e_param(p) for p in carried] or 'only mu'}); add it with analyses.sweep.parameter "
                         f"= {name!r} or analyses.map.part = {name[2:]!r}")


def run(ctx: Context, work: Path, timings: dict) -> dict[str, Any]:
    """analyses.sensitivity: dλ/dp at the nominal point; sensitivity.json and the tornado plots."""
    scene, model = ctx.scene, ctx.reduced_model()
    s = scene["analyses"]["sensitivity"]
    band, gt = band_and_growth_tol(scene)
    t = time.perf_counter()
    lam = solve_points(model, {})[0]
    f = lam.imag / TWO_PI
    inside = (f >= band[0]) & (f <= band[1])
    pick = inside & unstable(lam, gt) if s["modes"] == "unstable" else inside
    params = s["parameters"] or model.parameters
    sens = sensitivities(model, None, params, np.flatnonzero(pick), s["kappa_max"])
    values = parameter_values(model)
    records = []
    for x in sens:
        r = x.as_dict({p: values[p] for p in params})
        r["unstable"] = bool(unstable(np.array([x.eigenvalue]), gt)[0])
        r["ranking"] = [p for p, _ in ranking(r)]
        records.append(r)
    timings["sensitivity"] = time.perf_counter() - t
    near = [r for r in records if r["near_coalescence"]]
    ctx.say(f"[fem_squeal] sensitivity: {len(records)} modes × {len(params)} parameters in "
            f"{timings['sensitivity']:.2f} s"
            + (f"; {len(near)} near a coalescence (no derivative)" if near else ""))
    if ctx.comm.rank == 0:
        write_json_atomic(work / "sensitivity.json", {"parameters": params, "values": values,
                                                      "kappa_max": s["kappa_max"], "modes": records})
        shown = sorted((r for r in records if r["unstable"]), key=lambda r: -r["real_part"])[:s["max_plots"]]
        for r in shown:
            plots.tornado(work / f"tornado_mode{r['index']}.png", r, scene["title"])
    return {"sensitivity": records}


def check(scene: dict, volumes) -> None:
    """Every listed parameter is μ or the E of a part that the reduced basis carries."""
    for i, name in enumerate(scene["analyses"]["sensitivity"]["parameters"]):
        if not isinstance(name, str):
            raise SceneError(f"analyses.sensitivity.parameters[{i}]: must be a string (got {name!r})")
        check_parameter(scene, volumes, name, f"analyses.sensitivity.parameters[{i}]")


def _fmt_rank(r: dict, n: int = 4) -> str:
    if r["near_coalescence"]:
        return f"near a coalescence (κ = {r['kappa_local']:.3g}): derivative not defined"
    rel = r["rel_d_real_part"]
    return ", ".join(f"{p} {rel[p]:+.3g}" for p in r["ranking"][:n])


def report(res: dict) -> str:
    """The report section (HTML) of this stage from results.json ``res``."""
    if "sensitivity" not in res:
        return ""
    recs = res["sensitivity"]
    if not recs:
        return "<h2>Sensitivities</h2><p>No mode selected (no unstable mode in the band).</p>"
    txt = ("<h2>Sensitivities</h2><p>dλ/dp from the left and right eigenvectors of the reduced model at the "
           "nominal point. Ranking by p·∂Re λ/∂p [1/s per 100 % of p]; a mode whose local condition number "
           "exceeds the threshold is near a coalescence (the derivative is infinite there) and is not ranked.</p>")
    rows = [[r["index"], r["freq_hz"], r["real_part"], r["kappa_local"], _fmt_rank(r)] for r in recs]
    cls = ["unstable" if r.get("unstable") else "" for r in recs]
    return txt + _table(["mode", "f [Hz]", "Re λ [1/s]", "κ_loc", "drivers p·∂Re λ/∂p"], rows, cls)


STAGE = Stage("sensitivity", ("reduced",), run, "eigenvalue sensitivities dλ/dp", section=SECTION, check=check,
              report=report)
