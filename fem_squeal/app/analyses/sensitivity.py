"""The ``sensitivity`` analysis: dλ/dp of the unstable modes (or of every mode in the band) with
respect to the parameters of the reduced model (sign(v)μ, E and η of the parts its basis carries,
μ, k_n and k_t of each contact interface: :mod:`fem_squeal.reduced.model`), from
the left and right eigenvectors at the nominal point (:mod:`fem_squeal.reduced.sensitivity`).
A mode near a coalescence (κ_loc > ``kappa_max``) is flagged and gets no derivative.
``full = true``: also the full model's dλ/dp of the same modes (each record's ``full`` block), from the
right eigenvectors of the full CEA at the nominal point and the left ones of the transposed problem
(:func:`fem_squeal.fe.projection.full_sensitivities`), the check of the reduced derivatives.
Files: sensitivity.json, tornado_mode<index>.png (one per unstable mode)."""
from __future__ import annotations

import time
from pathlib import Path
from typing import Any

import numpy as np

from fem_squeal.app import plots
from fem_squeal.app.analyses import matrix_studies
from fem_squeal.app.analyses.reduced import (
    band_and_growth_tol,
    parametric_operators,
    robustness_E_ranges,
    speed_not_a_parameter,
)
from fem_squeal.app.fields import REAL, Field, one_of
from fem_squeal.app.html import table as _table
from fem_squeal.app.stage import Context, Stage
from fem_squeal.reduced.eigensolve import TWO_PI
from fem_squeal.reduced.model import INTERFACE_PREFIXES, MU, PART_PREFIXES, SPEED, e_param, split_param
from fem_squeal.reduced.sensitivity import (
    KAPPA_COALESCENCE,
    band_records,
    parameter_values,
)
from fem_squeal.reduced.sweep import solve_points
from fem_squeal.util.atomic import write_json_atomic
from fem_squeal.util.errors import SceneError

SECTION = {
    "modes": Field(str, "unstable", one_of("unstable", "band"),
                   "'unstable': the unstable modes in analyses.reduced.band_hz; 'band': every mode in it"),
    "parameters": Field(list, [], None,
                        "parameters ('mu', 'E.<part>', 'eta.<part>', 'mu.<interface>', 'kn.<interface>', "
                        "'kt.<interface>'); [] = every parameter of the reduced model"),
    "kappa_max": Field(REAL, KAPPA_COALESCENCE, lambda v: None if v > 1 else f"must be > 1 (got {v})",
                       "near a coalescence when the local condition number exceeds this (≈ 0.5 % from it)"),
    "full": Field(bool, False, None, "also dλ/dp of the full model (CEA right vectors, SLEPc left vectors of "
                  "the transposed problem) in each mode's 'full' block"),
    "max_plots": Field(int, 12, lambda v: None if v >= 0 else f"must be >= 0 (got {v})",
                       "tornado plots for at most this many unstable modes (the most unstable)"),
}


def basis_parts(scene: dict, volumes) -> list[str]:
    """Parts whose Young's modulus the reduced basis carries (as
    :func:`fem_squeal.app.analyses.reduced.basis_design`: the swept part, the map's part, every
    part when a transient runs, every part with a loss factor ``materials.<part>.eta`` > 0, every part
    whose E the robustness study scatters)."""
    ana = scene.analyses
    parts = {p for p, m in scene.get("materials", {}).items() if m.get("eta", 0.0) > 0}
    if "sweep" in ana and ana["sweep"]["parameter"].startswith("E."):
        parts.add(ana["sweep"]["parameter"][2:])
    if "map" in ana and ana["map"]["second"] == "E":
        parts.add(ana["map"]["part"])
    if "transient" in ana:
        parts.update(volumes)
    if "robustness" in ana:
        parts.update(n[2:] for n in robustness_E_ranges(ana["robustness"]))
    return sorted(parts)


PARAMETER_NAMES = ("'mu', 'E.<part>' and 'eta.<part>' with a part of {parts}, 'mu.<interface>', 'kn.<interface>' "
                   "and 'kt.<interface>' with a contact or rigid_plate interface of {contacts}")


def check_parameter(scene: dict, volumes, name: str, key: str) -> None:
    """``name`` is a parameter of the reduced model of this scene (:attr:`~fem_squeal.reduced.model.
    ReducedModel.parameters`): 'mu'; 'E.<part>' or 'eta.<part>' with a part the reduced basis carries;
    'mu.<c>' (c sliding), 'kn.<c>', 'kt.<c>' with a contact or rigid_plate interface c (a plate with
    k_n > 0); else SceneError at ``key``."""
    if name == MU:
        return
    if name == SPEED:
        why = speed_not_a_parameter(scene)
        if why:
            raise SceneError(f"{key}: 'speed' is not a parameter of this model: {why}")
        return
    prefix, target = split_param(name)
    interfaces = scene.get("interfaces", {})
    contacts = sorted(n for n, t in interfaces.items() if t.get("type") == "contact" or
                      (t.get("type") == "rigid_plate" and t.get("kn", 0) > 0))
    known = PARAMETER_NAMES.format(parts=sorted(volumes), contacts=contacts)
    if prefix in INTERFACE_PREFIXES and target is not None:
        if target in interfaces and target not in contacts:
            t = interfaces[target]
            what = t.get("type") + (f" with kn = {t.get('kn')}" if t.get("type") == "rigid_plate" else "")
            raise SceneError(f"{key}: {name!r}: interface {target!r} is a {what}; per-interface parameters "
                             f"exist for contact and rigid_plate interfaces with kn > 0 ({contacts or 'none'})")
        if target not in contacts:
            raise SceneError(f"{key}: unknown parameter {name!r}; parameters are {known}")
        if prefix == "mu" and not interfaces[target].get("sliding", 1):
            raise SceneError(f"{key}: {name!r}: interface {target!r} does not slide (sliding = 0): it has no "
                             "friction stiffness")
        return
    if prefix not in PART_PREFIXES or target not in volumes:
        raise SceneError(f"{key}: unknown parameter {name!r}; parameters are {known}")
    carried = basis_parts(scene, volumes)
    if target not in carried:
        raise SceneError(f"{key}: the reduced basis does not carry {name!r} (it carries "
                         f"{[e_param(p) for p in carried] or 'only mu'}); add it with analyses.sweep.parameter "
                         f"= {e_param(target)!r}, analyses.map.part = {target!r}, materials.{target}.eta > 0 or a "
                         f"robustness distribution of {e_param(target)!r}")


def run(ctx: Context, work: Path, timings: dict) -> dict[str, Any]:
    """analyses.sensitivity: dλ/dp at the nominal point; sensitivity.json and the tornado plots."""
    scene, model = ctx.scene, ctx.reduced_model()
    s = scene.analyses["sensitivity"]
    band, gt = band_and_growth_tol(scene)
    t = time.perf_counter()
    lam = solve_points(model, {})[0]
    params = s["parameters"] or model.parameters
    sens, records = band_records(model, lam, band, gt, s["modes"], params, s["kappa_max"])
    values = parameter_values(model)
    timings["sensitivity"] = time.perf_counter() - t
    if s["full"] and records:
        t = time.perf_counter()
        _full_block(ctx, model, records, [x.eigenvalue for x in sens], params, values, band)
        timings["sensitivity_full"] = time.perf_counter() - t
    near = [r for r in records if r["near_coalescence"]]
    ctx.say(f"[fem_squeal] sensitivity: {len(records)} modes × {len(params)} parameters in "
            f"{timings['sensitivity']:.2f} s"
            + (f"; {len(near)} near a coalescence (no derivative)" if near else ""))
    if ctx.comm.rank == 0:
        write_json_atomic(work / "sensitivity.json", {"parameters": params, "values": values,
                                                      "kappa_max": s["kappa_max"], "modes": records})
        shown = sorted((r for r in records if r["unstable"]), key=lambda r: -r["real_part"])[:s["max_plots"]]
        for r in shown:
            plots.tornado(work / f"tornado_mode{r['index']}.png", r, scene.title)
    return {"sensitivity": records}


def _full_block(ctx: Context, model, records: list[dict], eigenvalues, params, values, band) -> None:
    """Each record gets ``full``: the full model's eigenvalue and dλ/dp (None near a coalescence),
    relative forms, and the match of the left eigenvalue."""
    from fem_squeal.fe.projection import full_sensitivities  # heavy: FE stack

    par = parametric_operators(ctx, model.mu0, sorted(model.K_parts))
    try:
        full = full_sensitivities(par, np.array(eigenvalues), list(params), band,
                                  options=ctx.scene.solver.petsc_options)
    finally:
        par.destroy()
    for r, x in zip(records, full):
        near = r["near_coalescence"]
        d_re = {p: None if near else float(d.real) for p, d in x.d_lambda.items()}
        d_f = {p: None if near else float(d.imag / TWO_PI) for p, d in x.d_lambda.items()}
        r["full"] = {"freq_hz": float(x.eigenvalue.imag / TWO_PI), "real_part": float(x.eigenvalue.real),
                     "d_real_part": d_re, "d_freq_hz": d_f,
                     "rel_d_real_part": {p: None if v is None else v * values[p] for p, v in d_re.items()},
                     "left_mismatch": x.left_mismatch, "residual": x.residual}
    ctx.say("[fem_squeal] sensitivity, full model: " + ", ".join(
        f"{r['full']['freq_hz']:.0f} Hz" for r in records))


def check(scene: dict, volumes) -> None:
    """Every listed parameter is one of the reduced model's (:func:`check_parameter`); ``full`` needs a
    real stiffness (no loss factor at the nominal point)."""
    if "matrices" in scene:                 # a model given as matrices: :mod:`.matrix_studies`
        return matrix_studies.check_sensitivity(scene, volumes)
    if scene.analyses["sensitivity"].full:
        lossy = sorted(p for p, m in scene.get("materials", {}).items() if m.get("eta", 0.0) > 0)
        if lossy:
            raise SceneError(f"analyses.sensitivity.full: the full CEA has real arithmetic and no loss factor, "
                             f"but materials.{lossy[0]}.eta > 0; use the reduced sensitivities (full = false)")
    for i, name in enumerate(scene.analyses["sensitivity"].parameters):
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
    txt += _table(["mode", "f [Hz]", "Re λ [1/s]", "κ_loc", "drivers p·∂Re λ/∂p"], rows, cls)
    full = [r for r in recs if "full" in r]
    if full:
        txt += ("<p>The same derivatives on the full model (CEA right eigenvectors, left eigenvectors of the "
                "transposed problem), p·∂Re λ/∂p:</p>")
        txt += _table(["mode", "f full [Hz]", "Re λ full [1/s]", "drivers (full)"],
                      [[r["index"], r["full"]["freq_hz"], r["full"]["real_part"],
                        _fmt_rank({**r, "rel_d_real_part": r["full"]["rel_d_real_part"]})] for r in full])
    return txt


# "preload": the full-model derivatives (``full``) need the linearised operators (rebuilt in memory if cached)
STAGE = Stage("sensitivity", ("reduced", "preload"), run, "eigenvalue sensitivities dλ/dp", section=SECTION,
              check=check, report=report,
              on_matrices=matrix_studies.run_sensitivity, section_on_matrices=matrix_studies.SENSITIVITY)
