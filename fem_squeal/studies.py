"""Parametric studies of a scene on its reduced model: the ``reduced``, ``sweep`` and ``map`` analyses.

reduced   the basis grown to ``tol`` (:func:`fem_squeal.reduction.adaptive_reduce`), checked at the
          nominal point and at the corners of the requested parameter ranges; optionally the full
          CEA at those points, compared with the reduced one (``verify``).
sweep     one parameter (sign(v)μ or a part's E) over a range, every branch tracked by MAC
          continuation (:func:`fem_squeal.reduced.tracking.track`), critical values refined.
map       the (sign(v)μ, E) full-factorial design of seed 001 §4 on the ranks of the run, with
          the number of unstable modes per frequency band.
masa      seed 000 on the reduced model: for each μ, the static equilibrium with the cubic contact
          law (eq. 4), the CEA about it (eq. 6) and the amplitude sweep of every instability in
          the band (:mod:`fem_squeal.reduced.masa`), dealt over the ranks.

Files: reduced_model.npz, sweep.json, root_locus.png, complex_plane.png, stability_map.npz,
stability_map.png, masa.json, masa/mu<μ>_<f>Hz.png and masa/mu<μ>_<f>Hz_contact.png.
"""
from __future__ import annotations

import time
from pathlib import Path
from typing import Any

import numpy as np

from fem_squeal.reduced.eigensolve import TWO_PI, unstable
from fem_squeal.reduced.model import MU, e_param
from fem_squeal.reduced.stability_map import equal_bands, stability_map
from fem_squeal.reduced.sweep import Grid, evaluate, path_solver, signed_mu_axis, solve_points
from fem_squeal.reduced.tracking import track


def map_E_range(scene: dict, spec) -> tuple[float, float]:
    m = scene["analyses"]["map"]
    E0 = spec.materials[m["part"]].E
    return tuple(m["E_range"]) if m["E_range"] else (0.8 * E0, 1.2 * E0)


def design_points(scene: dict, spec, mu0: float) -> tuple[list[dict], list[dict], list[str]]:
    """(check points, E samples for the basis, parts whose E varies) implied by sweep and map."""
    ana = scene["analyses"]
    checks: list[dict] = [{MU: mu0}]
    samples: list[dict] = []
    parts: list[str] = []
    if "sweep" in ana:
        s = ana["sweep"]
        lo, hi = s["range"]
        if s["parameter"] == MU:
            checks += [{MU: lo}, {MU: hi}]
        else:
            parts.append(s["parameter"][2:])
            samples += [{s["parameter"]: lo}, {s["parameter"]: hi}]
            checks += [{MU: mu0, s["parameter"]: lo}, {MU: mu0, s["parameter"]: hi}]
    if "map" in ana:
        m = ana["map"]
        name = e_param(m["part"])
        parts.append(m["part"])
        e_lo, e_hi = map_E_range(scene, spec)
        samples += [{name: e_lo}, {name: e_hi}]
        checks += [{MU: s * m["mu_max"], name: e} for s in (-1, 1) for e in (e_lo, e_hi)]
    if "masa" in ana:
        checks += [{MU: float(v)} for v in ana["masa"]["mu"]]
    uniq = lambda pts: [dict(t) for t in dict.fromkeys(tuple(sorted(p.items())) for p in pts)]  # noqa: E731
    return uniq(checks), uniq(samples), sorted(set(parts))


def basis_design(scene: dict, spec) -> tuple[float, list[dict], list[dict], list[str]]:
    """(μ₀, check points, E samples, parts whose stiffness the basis carries): :func:`design_points`,
    with every part when a transient asks for component strain-energy shares along its cycle."""
    from fem_squeal.model import common_mu

    mu0 = common_mu(spec)
    checks, samples, parts = design_points(scene, spec, mu0)
    if "transient" in scene["analyses"]:
        parts = sorted(spec.materials)
    return mu0, checks, samples, parts


def full_cea(par, point: dict, band, nev: int, options) -> tuple[np.ndarray, float]:
    """Eigenvalues (Im λ > 0, in ``band``) of the full CEA at ``point`` and its wall time [s]."""
    from fem_squeal.eigen import solve_complex_modes

    K, C = par.matrices(point)
    t = time.perf_counter()
    target = np.sqrt(0.5 * (band[0] ** 2 + band[1] ** 2))
    cm = solve_complex_modes(K, par.ops.M, C, nev, target, band_hz=tuple(band), options=options,
                             prefix="verify_", progress=True)
    seconds = time.perf_counter() - t
    for A in (K, C, *cm.vectors_re, *cm.vectors_im):
        if A is not None:
            A.destroy()
    return cm.eigenvalues, seconds


def _verify(par, model, point: dict, band, growth_tol: float, options) -> dict:
    """Full CEA at ``point`` against the reduced eigenvalues: worst relative error of the unstable
    full eigenvalues (of all in the band when none is unstable)."""
    from fem_squeal.reduction import relative_change

    lam_r = solve_points(model, {k: np.array([v]) for k, v in point.items()})[0]
    f = lam_r.imag / TWO_PI
    lam_r = lam_r[(f >= band[0]) & (f <= band[1])]
    full, seconds = full_cea(par, point, band, len(lam_r) + 2, options)
    bad = unstable(full, growth_tol)
    watched = full[bad] if bad.any() else full
    return {"point": point, "n_full": int(full.size), "n_unstable_full": int(bad.sum()),
            "n_unstable_reduced": int(unstable(lam_r, growth_tol).sum()),
            "max_rel_error": relative_change(watched, lam_r), "full_cea_s": seconds,
            "unstable_full": [complex(x) for x in full[bad]]}


def band_and_growth_tol(scene: dict) -> tuple[tuple[float, float], float]:
    """analyses.reduced's band [Hz] and growth tolerance (unstable: Re λ > growth_tol |λ|)."""
    a = scene["analyses"]["reduced"]
    return tuple(a["band_hz"]), a["growth_tol"]


def stage_reduced(ctx, work: Path, timings: dict) -> dict[str, Any]:
    """analyses.reduced: the basis grown to ``tol`` about the preload; ``reduced_model.npz``."""
    from fem_squeal.output import write_basis_field
    from fem_squeal.pipeline import extra_vector_settings, field_basis_needed
    from fem_squeal.reduction import ParametricOperators, adaptive_reduce

    scene, spec, comm, say = ctx.scene, ctx.spec, ctx.comm, ctx.say
    ops, preload = ctx.products["linear"], ctx.products["preload"]
    a = scene["analyses"]["reduced"]
    band = tuple(a["band_hz"])
    opts = scene["solver"]["petsc_options"]
    mu0, checks, samples, parts = basis_design(scene, spec)
    par = ParametricOperators(ops, spec, mu0, parts)
    t = time.perf_counter()
    attach = extra_vector_settings(scene)
    extra = masa_vectors(ops, preload, attach, band, opts) if attach is not None else None
    model, basis, report = adaptive_reduce(
        ops, par, band, checks, tol=a["tol"], cut_factors=tuple(a["cut_factors"]), samples=samples,
        static=a["static_correction"], sigma_hz=a["sigma_hz"] or None, growth_tol=a["growth_tol"],
        enrich_rtol=a["enrich_rtol"], preload=preload, options=opts, log=say, extra=extra)
    timings["reduced_basis"] = time.perf_counter() - t
    if comm.rank == 0:
        model.save(work / "reduced_model.npz")
    if field_basis_needed(scene):
        write_basis_field(comm, work / "basis_field.npz", ops.V, basis.Phi)
    out: dict[str, Any] = {"size": model.size, "parameters": model.parameters, "mu0": mu0, **report.as_dict()}
    say(f"[fem_squeal] reduced model: {model.size} vectors {basis.counts}, estimated error "
        f"{report.estimate:.1e}, {timings['reduced_basis']:.1f} s")
    if a["verify"]:
        t = time.perf_counter()
        rows = [_verify(par, model, p, band, a["growth_tol"], opts) for p in checks]
        timings["reduced_verify"] = time.perf_counter() - t
        out["verification"] = rows
        say("[fem_squeal] reduced vs full CEA: " + ", ".join(
            f"{r['point']}: {r['max_rel_error']:.1e}" for r in rows))
    par.destroy()
    ctx.products["reduced"] = model
    return {"reduced": out}


def stage_sweep(ctx, work: Path, timings: dict) -> dict[str, Any]:
    """analyses.sweep on the reduced model: sweep.json, root_locus.png, complex_plane.png."""
    from fem_squeal import plots
    from fem_squeal.output import write_json_atomic

    scene, model = ctx.scene, ctx.reduced_model()
    s = scene["analyses"]["sweep"]
    band, gt = band_and_growth_tol(scene)
    t = time.perf_counter()
    values = np.linspace(*s["range"], s["n"])
    fixed = {} if s["parameter"] == MU else {MU: model.mu0}
    tr = track(path_solver(model, s["parameter"], fixed), values, growth_tol=gt,
               start=0.0 if s["parameter"] == MU and values[0] <= 0 <= values[-1] else None,
               progress=ctx.comm.rank == 0)
    timings["sweep"] = time.perf_counter() - t
    f = tr.freqs_hz
    inside = np.flatnonzero(np.any((f >= band[0]) & (f <= band[1]), axis=0))
    events = [e for e in tr.events if band[0] <= e.freq_hz <= band[1]]
    out = {"parameter": s["parameter"], "values": values, "branches": [
        {"label": tr.labels[j], "parent_hz": tr.parents_hz[j], "freq_hz": f[:, j],
         "real_part": tr.eigenvalues[:, j].real} for j in inside],
        "critical": [e.as_dict() for e in events], "solves": tr.solves,
        "ambiguous_steps": tr.ambiguous_steps, "seconds": timings["sweep"]}
    ctx.say(f"[fem_squeal] sweep of {s['parameter']}: {s['n']} values, {tr.solves} reduced solves, "
            f"{len(events)} stability changes in the band, {timings['sweep']:.2f} s")
    if ctx.comm.rank == 0:
        write_json_atomic(work / "sweep.json", out)
        xlabel = "sign(v) μ" if s["parameter"] == MU else f"{s['parameter']} [Pa]"
        plots.root_locus(work / "root_locus.png", values, tr.eigenvalues, unstable(tr.eigenvalues, gt),
                         xlabel, band, tr.labels, scene["title"])
        plots.complex_plane(work / "complex_plane.png", tr.eigenvalues, band, gt, scene["title"])
    out.pop("branches")  # kept in sweep.json; results.json holds the summary
    return {"sweep": out}


def stage_map(ctx, work: Path, timings: dict) -> dict[str, Any]:
    """analyses.map: unstable modes per band over the (sign(v)μ, E) design; stability_map.npz/png."""
    from fem_squeal import plots
    from fem_squeal.output import write_npz_atomic

    scene, model = ctx.scene, ctx.reduced_model()
    m = scene["analyses"]["map"]
    band, gt = band_and_growth_tol(scene)
    name = e_param(m["part"])
    E = np.linspace(*map_E_range(scene, ctx.spec), m["n_E"])
    grid = Grid({name: E, MU: signed_mu_axis(m["mu_max"], m["n_mu"])})
    res = evaluate(model, grid, ctx.comm, progress=True)
    timings["map"] = res.seconds
    bands = equal_bands(band, m["n_bands"])
    smap = stability_map(res, bands, gt)
    out = {"parameter": name, "points": grid.size, "seconds": res.seconds,
           "seconds_per_point": res.seconds_per_point, **smap.as_dict()}
    ctx.say(f"[fem_squeal] stability map: {grid.size} points in {res.seconds:.2f} s "
            f"({1e3 * res.seconds_per_point:.2f} ms per point per rank), "
            f"at most {int(smap.total.max())} unstable modes")
    if ctx.comm.rank == 0:
        write_npz_atomic(work / "stability_map.npz", {"mu": grid.axes[MU], "E": E, "counts": smap.counts,
                                                       "total": smap.total, "eigenvalues": res.eigenvalues,
                                                       "bands_hz": np.array(bands)})
        plots.stability_maps(work / "stability_map.png", grid.axes[MU], E / 1e9, smap.counts, smap.total,
                             bands, f"E of {m['part']} [GPa]", scene["title"])
    return {"map": out}


def stage_masa(ctx, work: Path, timings: dict) -> dict[str, Any]:
    return {"masa": run_masa_analysis(ctx.comm, ctx.scene, ctx.reduced_model(), work, ctx.say, timings)}


def masa_vectors(ops, preload, attachments: list, band, options) -> np.ndarray:
    """Basis vectors MASA and the transient need beyond the modes: the preload displacement (so
    that the reduced static equilibrium reproduces the full one) and the contact-patch
    attachments ([n_radial, n_angular]; [] = none)."""
    from fem_squeal.reduction import contact_attachments

    cols = [preload.u.array_r.copy()[:, None]]
    if attachments:
        cols.append(contact_attachments(ops, tuple(attachments), 0.1 * band[1], options))
    return np.hstack(cols)


def masa_amplitudes(prob, targets, m: dict) -> np.ndarray:
    """(n_targets, n) amplitude grids: 0 … amplitude_max in the chosen unit."""
    steps = np.linspace(0.0, m["amplitude_max"], m["n_amplitudes"])
    if m["amplitude_unit"] == "modal":
        return np.tile(steps, (len(targets), 1))
    scale = [prob.loss_amplitude(t) for t in targets]
    return np.array([steps * (s if np.isfinite(s) else 1.0) for s in scale])


def run_masa_analysis(comm, scene: dict, model, outdir: Path, say, timings: dict) -> dict[str, Any]:
    """analyses.masa on the reduced model (module docstring)."""
    from fem_squeal import plots
    from fem_squeal.output import write_json_atomic
    from fem_squeal.reduced.masa import MasaProblem, from_reduced, run_masa, static_equilibrium

    m = scene["analyses"]["masa"]
    band, gt = band_and_growth_tol(scene)
    mus = [float(v) for v in m["mu"]] or [model.mu0]
    cd = m["contact_damping"] or [0.0, np.inf]
    out: dict[str, Any] = {"settings": m, "cases": []}
    t0 = time.perf_counter()
    for mu in mus:
        t = time.perf_counter()
        mm = from_reduced(model, {MU: mu}, cubic_share=m["cubic_share"], c_max=cd[0], depth=cd[1],
                          patches=tuple(m["patches"]) if m["patches"] else None)
        eq = static_equilibrium(mm, model.q_static)
        prob = MasaProblem(mm, eq, band, n_samples=m["n_samples"], growth_tol=gt)
        targets = prob.instabilities()
        amps = masa_amplitudes(prob, targets, m)
        results = run_masa(prob, targets, amps, sweep_break=m["sweep_break"], update_shape=m["update_shape"],
                           refine=m["refine"], comm=comm, progress=True)
        seconds = time.perf_counter() - t
        unit = "× first contact loss" if m["amplitude_unit"] == "loss" else "modal amplitude p"
        case = {"mu": mu, "equilibrium": eq.as_dict(), "elements": prob.n_elements, "basis": mm.size,
                "instabilities": [], "seconds": seconds}
        for res, a in zip(results, amps):
            scale = a[-1] / m["amplitude_max"]  # p of one unit
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
    from dataclasses import replace

    return replace(res, amplitudes=res.amplitudes * factor, stationary=[s * factor for s in res.stationary])


def verification_failures(reduced: dict, what: str = "") -> list[str]:
    """The check points where the reduced model misses the full CEA: relative error above the
    requested ``tol``, or a different number of unstable modes (``results["reduced"]``)."""
    out = []
    for v in reduced.get("verification", []):
        if v["max_rel_error"] > reduced["tol"]:
            out.append(f"{what}reduced vs full at {v['point']}: {v['max_rel_error']:.1e} > tol {reduced['tol']}")
        if v["n_unstable_full"] != v["n_unstable_reduced"]:
            out.append(f"{what}{v['n_unstable_reduced']} unstable reduced vs {v['n_unstable_full']} full "
                       f"at {v['point']}")
    return out
