"""The ``cea`` analysis: complex eigenvalue analysis of the linearised model (seed 000 eq. 6, seed 001 eq. 5)."""
from __future__ import annotations

import math
import time
from pathlib import Path

from fem_squeal.app import nvh
from fem_squeal.app.analyses.matrices import operators
from fem_squeal.app.analyses.preload import operating
from fem_squeal.app.fields import REAL, Field, band, one_of, positive
from fem_squeal.app.html import escape as _e
from fem_squeal.app.html import link
from fem_squeal.app.html import table as _table
from fem_squeal.app.mode_shapes import write_mode_shapes
from fem_squeal.app.stage import Context, Stage
from fem_squeal.reduced.eigensolve import unstable
from fem_squeal.util.errors import SceneError
from geometry.tags import COMPONENT_GROUPS

#: ``method = "auto"``: the projection for models of at least this many DOFs ...  None: never (today).
#: Measured so far (benchmarks/industrial_scale.py, brake corner 78k DOFs, 0–16 kHz, one rank): the
#: projection 86.6 s against the full CEA's 24 s; where it overtakes the full CEA is not measured yet,
#: so "auto" keeps the full CEA until a benchmark at scale shows it (then set the size here).
AUTO_DOFS: int | None = None
#: ... with at least this many real modes below the band top (an inertia count); else the full CEA
AUTO_MODES = 40
#: projection: the default tolerance of η, the pairs' residual relative to λ²M
#: (:func:`fem_squeal.fe.projection.projected_cea.full_residuals`).  Measured on the ring (band 0.1–5 kHz,
#: modes ≤ 10 kHz, the full CEA at 1e-10): the worst |Δλ|/|λ| against the full CEA's is 3.6e-7 at η ≤ 8.2e-4
#: (no enrichment), 1.5e-9 at η ≤ 8.7e-5 (one round), 1.0e-11 at η ≤ 9.8e-7 (two): about η²/2
PROJECTION_TOL = 1e-5
#: projection: the real modes up to this factor × the band top (Abaqus's practice: 1.5–2).  Measured on the
#: brake corner (78k DOFs, 0–16 kHz, 88 pairs, one rank, the two runs side by side on a loaded machine):
#: 1.5: 157 modes, basis 521 after 4 enrichment rounds, CEA 139 s; 2.0: 270 modes, 660 after 3, 199 s
#: (the modes to 32 kHz 53 s against 28 s to 24 kHz); both within 1e-9 of the full CEA's frequencies
CUT_FACTOR = 1.5

def above_one(v):
    return None if v > 1 else f"must be > 1 (got {v})"


SECTION = {
    "n_modes": Field(int, 20, positive, "complex modes (Im λ > 0) to compute near target_hz; the linear "
                     "method (block Arnoldi or Krylov–Schur) stops sooner once every pair of band_hz and 2 "
                     "beyond have converged"),
    "target_hz": Field(REAL, None, positive, "shift; not set: centre of band_hz", unset=0),
    "band_hz": Field(list, [0.0, 10000.0], band, "frequency band kept in the results"),
    "method": Field(str, "auto", one_of("auto", "linear", "pep", "projection"),
                    "'linear' (undamped: EPS of K x = ω²M x) and 'pep' (TOAR on the quadratic): the full CEA, "
                    "n_modes pairs near target_hz; 'projection': every pair in band_hz on the real modes up to "
                    "cut_factor × the band top plus static corrections, each pair checked in the full model and "
                    "the basis enriched until it meets max_residual and projection_tol (as Abaqus, ANSYS "
                    "QRDAMP); 'auto': 'linear' without damping and 'pep' with it"
                    + ("" if AUTO_DOFS is None else
                       f", the projection for models of at least {AUTO_DOFS} DOFs with at least {AUTO_MODES} "
                       "real modes below the band top (an inertia count, made only above that size; "
                       "results.json: cea_choice)")),
    "tol": Field(REAL, 1e-10, positive), "max_residual": Field(REAL, 1e-8, positive),
    "cut_factor": Field(REAL, CUT_FACTOR, above_one, "projection: real modes up to cut_factor × the band top"),
    "projection_tol": Field(REAL, PROJECTION_TOL, positive, "projection: every pair's residual relative to λ²M, "
                            "‖(λ²M + λC + K)x‖_(diag M)⁻¹ / (|λ|² ‖x‖_M), at most this (about twice the "
                            "relative error of λ², squared)"),
    "growth_tol": Field(REAL, 1e-6, positive, "unstable: Re λ > growth_tol |λ| (the reduced layer's "
                        "definition, fem_squeal.reduced.eigensolve.unstable: round-off of a neutral mode, "
                        "a gyroscopic disc's ~1e-9 |λ|, is not an instability)"),
    "describe_part": Field(str, "", None, "part for nodal diameters; '' = disc if present"),
    "coupling": Field(bool, True, None, "each complex mode on the real modes of the frictionless K (those of "
                      "the reduced basis: one number per mode in every table): their participation and the "
                      "coupling pair.  method 'projection': read off its basis (no solve); else one more "
                      "real-mode solve up to coupling_f_max_hz (main demo: 16.1 s beside the CEA's 20.5 s, "
                      "docs/validation.md; false saves it)"),
    "coupling_f_max_hz": Field(REAL, None, positive, "the real modes of the coupling reach this frequency "
                               "(not with 'projection': its basis's cut); not set: 1.25 × the upper end of "
                               "band_hz", unset=0),
    "radiation": Field(dict, {}, nvh.check_radiation, "the ERP of the modes and the squeal index: a table of "
                       + ", ".join(f"{k} ({f.doc}; default {f.default!r})" for k, f in nvh.RADIATION.items())),
}


def cea_target_hz(cea: dict) -> float:
    """Shift of the CEA: ``target_hz`` or, when not set, the band centre in ω² (the linear EPS works in θ = ω²)."""
    lo, hi = cea["band_hz"]
    return cea["target_hz"] or math.sqrt(0.5 * (lo * lo + hi * hi))


def run(ctx: Context, work: Path, timings: dict) -> dict:
    """Complex eigenvalues λ²M + λC + (K + K_f) in analyses.cea.band_hz, with their descriptors."""
    from fem_squeal.fe.assembly import operating_operators, part_stiffnesses  # heavy: FE stack
    from fem_squeal.fe.descriptors import strain_energy_shares_all  # heavy: FE stack
    from fem_squeal.fe.eigen import solve_complex_modes  # heavy: FE stack
    from fem_squeal.fe.output import write_modes_xdmf, write_vtu  # heavy: FE stack
    from fem_squeal.fe.projection import auto_method, projected_complex_modes  # heavy: FE stack

    ops, basis, scene = ctx.products["linear"], ctx.products["basis"], ctx.scene
    a = scene.analyses["cea"]
    t = time.perf_counter()
    # the disc's rotation and the stress stiffening (fe.assembly.operating_operators; None: neither)
    K, C, rotation = operating_operators(ops, ctx.products["mesh"], ctx.spec, speed=scene.operating.speed,
                                         terms=operating(ctx))
    method, choice, projection = a["method"], None, None
    if method == "auto" and AUTO_DOFS is not None:
        chosen, choice = auto_method(ops, tuple(a["band_hz"]), AUTO_DOFS, AUTO_MODES, scene.solver.petsc_options)
        method = "projection" if chosen == "projection" else "auto"
    if method == "projection":
        cm, projection = projected_complex_modes(
            ops, K, C, tuple(a["band_hz"]), operating=operating(ctx), cut_factor=a["cut_factor"],
            max_residual=a["max_residual"], tol=a["projection_tol"], options=scene.solver.petsc_options,
            log=ctx.say)
    else:
        cm = solve_complex_modes(K, ops.M, C, a["n_modes"], cea_target_hz(a), method=method,
                                 tol=a["tol"], max_residual=a["max_residual"], band_hz=tuple(a["band_hz"]),
                                 options=scene.solver.petsc_options, prefix="cea_", progress=True)
    timings["cea"] = time.perf_counter() - t
    lo, hi = a["band_hz"]
    growing = [bool(unstable(lam, a["growth_tol"])) for lam in cm.eigenvalues]
    n_unstable = sum(growing)
    ctx.say(f"[fem_squeal] CEA ({cm.method}, {cm.algorithm}): {len(cm.eigenvalues)} modes in {lo:g}-{hi:g} Hz, "
            f"{n_unstable} unstable, {timings['cea']:.2f} s (factorisation {cm.seconds['factor']:.2f} s, "
            f"iterations {cm.seconds['solve']:.2f} s)")
    t = time.perf_counter()
    fields = list(zip(cm.vectors_re, cm.vectors_im))
    described = basis.describe_all(fields)
    groups = COMPONENT_GROUPS.get(scene.geometry.builder)
    if ops.K_parts:
        shares = strain_energy_shares_all(ops.K_parts, fields, groups)
    elif len(ctx.spec.materials) > 1:   # one part at a time (analyses.operators.keeps_part_stiffnesses)
        shares = strain_energy_shares_all(part_stiffnesses(ops.V, ctx.products["mesh"], ctx.spec), fields, groups,
                                          release=True)
    else:
        shares = [None] * len(fields)
    rows = []
    for g, f, re, zeta, r, d, e in zip(growing, cm.freqs_hz, cm.real_parts, cm.damping_ratios,
                                       cm.residuals, described, shares):
        rows.append({"index": len(rows), "freq_hz": f, "real_part": re, "damping_ratio": zeta,
                     "residual": r, "unstable": g, **d._asdict()})
        if e is not None:
            rows[-1]["energy_shares"] = e
    timings["cea_descriptors"] = time.perf_counter() - t
    ctx.say(f"[fem_squeal] CEA descriptors (nodal diameters, energy shares): {timings['cea_descriptors']:.2f} s")
    t = time.perf_counter()
    more = nvh.compute(ctx, ops, fields, rows, cm.eigenvalues, a,
                       coupling=projection.coupling if projection is not None else None)
    timings["cea_nvh"] = time.perf_counter() - t
    t = time.perf_counter()
    write_modes_xdmf(ctx.comm, work / "complex_modes.xdmf", ops.V, fields)
    gathered = write_vtu(ctx.comm, work / "complex_modes.vtu", ops.V,
                         {f"mode_{j}_{part}": x for j, pair in enumerate(fields)
                          for part, x in zip(("re", "im"), pair)},
                         {"freq_hz": [r["freq_hz"] for r in rows], "real_part": [r["real_part"] for r in rows]})
    timings["cea_fields"] = time.perf_counter() - t
    ctx.say(f"[fem_squeal] CEA mode fields written: {timings['cea_fields']:.2f} s")
    out = {"complex_modes": rows, "n_unstable": n_unstable, "cea_method": cm.method, **more}
    if choice is not None:
        out["cea_choice"] = choice
    if projection is not None:
        out["cea_projection"] = {**projection.as_dict(), "seconds": cm.seconds}
    if ctx.comm.rank == 0:
        nvh.write_files(work, rows, out, scene.title)
    t = time.perf_counter()
    # the report's pictures (rank 0, from the gathered fields; fem_squeal.app.mode_shapes)
    pictures = write_mode_shapes(work, gathered, rows, scene.title) if gathered and ctx.keep_files else None
    out["mode_shapes"] = ctx.comm.bcast(pictures, root=0)
    timings["cea_pictures"] = time.perf_counter() - t
    if pictures:
        ctx.say(f"[fem_squeal] CEA mode pictures drawn: {timings['cea_pictures']:.2f} s")
    if rotation:
        out["cea_rotation"] = {"speed": scene.operating.speed, **rotation}
    return out


def run_on_matrices(ctx: Context, work: Path, timings: dict) -> dict:
    """Complex eigenvalues λ²M + λC + K of a model given as matrices, at the nominal point, in
    analyses.cea.band_hz (no descriptors: the matrices carry no mesh)."""
    from fem_squeal.fe.eigen import solve_complex_modes  # heavy: FE stack

    ops, scene = operators(ctx), ctx.scene
    a = scene.analyses["cea"]
    t = time.perf_counter()
    cm = solve_complex_modes(ops["K"], ops["M"], ops.get("C"), a["n_modes"], cea_target_hz(a), method=a["method"],
                             tol=a["tol"], max_residual=a["max_residual"], band_hz=tuple(a["band_hz"]),
                             options=scene.solver.petsc_options, prefix="cea_", progress=True)
    timings["cea"] = time.perf_counter() - t
    for x in (*cm.vectors_re, *cm.vectors_im):
        x.destroy()
    rows = [{"index": j, "freq_hz": f, "real_part": re, "damping_ratio": zeta, "residual": r,
             "unstable": bool(unstable(lam, a["growth_tol"]))}
            for j, (lam, f, re, zeta, r) in enumerate(zip(cm.eigenvalues, cm.freqs_hz, cm.real_parts,
                                                          cm.damping_ratios, cm.residuals))]
    n_unstable = sum(r["unstable"] for r in rows)
    lo, hi = a["band_hz"]
    ctx.say(f"[fem_squeal] CEA ({cm.method}, {cm.algorithm}): {len(rows)} modes in {lo:g}-{hi:g} Hz, "
            f"{n_unstable} unstable, {timings['cea']:.2f} s")
    return {"complex_modes": rows, "n_unstable": n_unstable, "cea_method": cm.method}


def check(scene: dict, volumes) -> None:
    """analyses.cea.describe_part and the parts of analyses.cea.radiation.efficiency must be parts of the model."""
    part = scene.analyses["cea"].describe_part
    if part and part not in volumes:
        raise SceneError(f"analyses.cea.describe_part: unknown part {part!r}; parts: {sorted(volumes)}")
    nvh.check_parts(scene.analyses["cea"], volumes)


def report(res: dict) -> str:
    """The report section (HTML) of this stage from results.json ``res``."""
    if "complex_modes" not in res:
        return ""
    cm = res["complex_modes"]
    files = set(res.get("files", []))
    shape = (lambda j: link("complex_modes.vtu", f"mode_{j}_re/_im")) if "complex_modes.vtu" in files else \
        (lambda j: "")
    rows = [[c["index"], c["freq_hz"], c["real_part"], c["damping_ratio"], c.get("nodal_diameter", ""),
             c.get("travelling_direction", ""), c["residual"], shape(c["index"])] for c in cm]
    note = " Shapes: the fields named in the last column of complex_modes.vtu (complex_modes.xdmf: time = #)." \
        if "complex_modes.vtu" in files else ""
    how = ""
    if "cea_projection" in res:
        p = res["cea_projection"]
        how += (f" Projection onto {p['basis']['modes']} real modes up to {p['cut_hz']:.0f} Hz, "
                f"{p['basis']['static']} static corrections and {p['basis']['enrichment']} enrichment vectors "
                f"({p['enrichment_rounds']} rounds): basis {p['basis_size']}, worst residual "
                f"{p['worst_residual']:.1e} (relative to λ²M {p['worst_relative_residual']:.1e}).")
    if "cea_choice" in res:
        how += f" Method 'auto': {_e(res['cea_choice'])}."
    return (f"<h2>Complex eigenvalue analysis</h2><p><b>{res['n_unstable']}</b> unstable of {len(cm)} "
            f"modes ({_e(res.get('cea_method', ''))}); unstable rows are shaded.{how}{note}</p>" + _table(
                ["#", "f [Hz]", "Re λ [1/s]", "ζ", "nodal diameter", "travelling", "residual", "shape"], rows,
                ["unstable" if c["unstable"] else "" for c in cm]) + nvh.report_html(res))


STAGE = Stage("cea", ("preload",), run, "complex eigenvalue analysis", section=SECTION, check=check, report=report,
              fields=True, on_matrices=run_on_matrices)
