"""The ``real_modes`` analysis: modes of the symmetric (frictionless) operator K − ω²M (SLEPc EPS)."""
from __future__ import annotations

import time
from pathlib import Path

from fem_squeal.app.analyses.matrices import operators
from fem_squeal.app.fields import REAL, Field, non_negative, positive
from fem_squeal.app.html import link
from fem_squeal.app.html import table as _table
from fem_squeal.app.stage import Context, Stage

SECTION = {
    "n_modes": Field(int, 20, positive), "target_hz": Field(REAL, 1000.0, non_negative),
    "tol": Field(REAL, 1e-10, positive), "max_residual": Field(REAL, 1e-8, positive),
}


def run(ctx: Context, work: Path, timings: dict) -> dict:
    """Real modes of the linearised, frictionless (symmetric) operator."""
    from fem_squeal.fe.eigen import solve_real_modes  # heavy: FE stack
    from fem_squeal.fe.output import write_modes_xdmf, write_vtu  # heavy: FE stack

    ops, basis = ctx.products["linear"], ctx.products["basis"]
    a = ctx.scene.analyses["real_modes"]
    t = time.perf_counter()
    rm = solve_real_modes(ops.K, ops.M, a["n_modes"], a["target_hz"], tol=a["tol"], max_residual=a["max_residual"],
                          options=ctx.scene.solver.petsc_options, prefix="real_", progress=True)
    timings["real_modes"] = time.perf_counter() - t
    t = time.perf_counter()
    rows = []
    for f, r, d in zip(rm.freqs_hz, rm.residuals, basis.describe_all([(x, None) for x in rm.vectors])):
        rows.append({"freq_hz": f, "residual": r, "in_plane_share": d.in_plane_share,
                     "nodal_diameter": d.nodal_diameter, "nodal_share": d.nodal_share})
    timings["real_modes_descriptors"] = time.perf_counter() - t
    ctx.say(f"[fem_squeal] real modes: {len(rows)} in {timings['real_modes']:.2f} s")
    t = time.perf_counter()
    write_modes_xdmf(ctx.comm, work / "real_modes.xdmf", ops.V, [(x, None) for x in rm.vectors])
    write_vtu(ctx.comm, work / "real_modes.vtu", ops.V, {f"mode_{j}": x for j, x in enumerate(rm.vectors)},
              {"freq_hz": rm.freqs_hz})
    timings["real_modes_fields"] = time.perf_counter() - t
    return {"real_modes": rows}


def run_on_matrices(ctx: Context, work: Path, timings: dict) -> dict:
    """Real modes of a model given as matrices: of the symmetric parts (K + Kᵀ)/2, (M + Mᵀ)/2 of its
    operators at the nominal point (K, M themselves where symmetric: results.json ``matrices.asymmetry``)."""
    from fem_squeal.fe.eigen import solve_real_modes  # heavy: FE stack
    from fem_squeal.fe.matrix_operators import symmetric_part  # heavy: FE stack

    ops = operators(ctx)
    a = ctx.scene.analyses["real_modes"]
    t = time.perf_counter()
    (K, _), (M, _) = symmetric_part(ops["K"]), symmetric_part(ops["M"])
    rm = solve_real_modes(K, M, a["n_modes"], a["target_hz"], tol=a["tol"], max_residual=a["max_residual"],
                          options=ctx.scene.solver.petsc_options, prefix="real_", progress=True)
    timings["real_modes"] = time.perf_counter() - t
    for x in rm.vectors:
        x.destroy()
    for S, A in ((K, ops["K"]), (M, ops["M"])):
        if S is not A:
            S.destroy()
    ctx.say(f"[fem_squeal] real modes: {len(rm.freqs_hz)} in {timings['real_modes']:.2f} s")
    return {"real_modes": [{"freq_hz": f, "residual": r} for f, r in zip(rm.freqs_hz, rm.residuals)]}


def report(res: dict) -> str:
    """The report section (HTML) of this stage from results.json ``res``."""
    if "real_modes" not in res:
        return ""
    shape = (lambda j: link("real_modes.vtu", f"mode_{j}")) if "real_modes.vtu" in res.get("files", []) else \
        (lambda j: "")
    rows = [[i, r["freq_hz"], r.get("nodal_diameter", ""), r.get("in_plane_share", ""), r["residual"], shape(i)]
            for i, r in enumerate(res["real_modes"])]
    return ("<h2>Real modes</h2>" + _table(["#", "f [Hz]", "nodal diameter", "in-plane share",
                                              "residual", "shape"], rows))


STAGE = Stage("real_modes", ("preload",), run, "real modes (SLEPc EPS)", section=SECTION, report=report,
              fields=True, on_matrices=run_on_matrices)
