"""Run a validated scene: mesh → operators → real modes and/or CEA → descriptors → outputs.

Each stage is a function of the scene and the upstream results, and only the stages that the
requested analyses need are run (a scene without ``analyses.real_modes`` solves no real modes).
Outputs go to ``outdir``: ``results.json`` (schema below, written atomically by rank 0) and XDMF
files of the mode shapes.

results.json (schema_version 1)
-------------------------------
scene            the validated scene (all defaults filled in)
model            dofs, cells, ranks, degree
timings_s        wall time per stage
real_modes       [{freq_hz, residual, in_plane_share, nodal_diameter, nodal_share}]
complex_modes    [{index, freq_hz, real_part [1/s], damping_ratio, residual, unstable,
                   in_plane_share, nodal_diameter, nodal_share, travelling_index,
                   travelling_direction}]   (Im λ > 0, inside analyses.cea.band_hz)
n_unstable       number of complex modes with Re λ > 0
"""
from __future__ import annotations

import math
import time
from pathlib import Path
from typing import Any

from mpi4py import MPI

from fem_squeal.scene import model_spec

SCHEMA_VERSION = 1


def build_mesh(comm: MPI.Comm, scene: dict):
    """Mesh stage: call the geometry builder named in the scene."""
    from geometry import BUILDERS

    g = dict(scene["geometry"])
    builder = BUILDERS[g.pop("builder")]
    return builder(comm, **g)


def cea_target_hz(cea: dict) -> float:
    """Shift of the CEA: ``target_hz`` or, when 0, the band centre in ω² (the linear EPS works in θ = ω²)."""
    lo, hi = cea["band_hz"]
    return cea["target_hz"] or math.sqrt(0.5 * (lo * lo + hi * hi))


def run_scene(scene: dict, outdir: str | Path, comm: MPI.Comm = MPI.COMM_WORLD,
              write_fields: bool = True, log=print) -> dict[str, Any]:
    """Run every analysis of ``scene`` and write the outputs; returns the results dictionary."""
    from fem_squeal.assembly import assemble_operators
    from fem_squeal.descriptors import CircumferentialBasis
    from fem_squeal.eigen import solve_complex_modes, solve_real_modes
    from fem_squeal.output import write_json_atomic, write_modes_xdmf

    outdir = Path(outdir)
    rank0 = comm.rank == 0
    say = log if rank0 else (lambda *a, **k: None)
    spec = model_spec(scene)
    petsc_options = scene["solver"]["petsc_options"]
    timings: dict[str, float] = {}

    t = time.perf_counter()
    md = build_mesh(comm, scene)
    timings["mesh"] = time.perf_counter() - t
    t = time.perf_counter()
    ops = assemble_operators(md, spec)
    timings["assembly"] = time.perf_counter() - t
    ndofs = ops.V.dofmap.index_map.size_global * ops.V.dofmap.index_map_bs
    ncells = md.mesh.topology.index_map(3).size_global
    say(f"[fem_squeal] {ncells} cells, {ndofs} DOFs (P{spec.degree}) on {comm.size} rank(s); "
        f"mesh {timings['mesh']:.2f} s, assembly {timings['assembly']:.2f} s")
    basis = CircumferentialBasis(ops.V, ops.M, ops.M_axial)
    results: dict[str, Any] = {
        "schema_version": SCHEMA_VERSION, "scene": scene,
        "model": {"dofs": ndofs, "cells": ncells, "ranks": comm.size, "degree": spec.degree},
        "timings_s": timings,
    }
    ana = scene["analyses"]

    if "real_modes" in ana:
        a = ana["real_modes"]
        t = time.perf_counter()
        rm = solve_real_modes(ops.K, ops.M, a["n_modes"], a["target_hz"], tol=a["tol"],
                              max_residual=a["max_residual"], options=petsc_options, prefix="real_")
        timings["real_modes"] = time.perf_counter() - t
        rows = []
        for f, r, x in zip(rm.freqs_hz, rm.residuals, rm.vectors):
            d = basis.describe(x)
            rows.append({"freq_hz": f, "residual": r, "in_plane_share": d.in_plane_share,
                         "nodal_diameter": d.nodal_diameter, "nodal_share": d.nodal_share})
        results["real_modes"] = rows
        say(f"[fem_squeal] real modes: {len(rows)} in {timings['real_modes']:.2f} s")
        if write_fields:
            write_modes_xdmf(comm, outdir / "real_modes.xdmf", ops.V, [(x, None) for x in rm.vectors])

    if "cea" in ana:
        a = ana["cea"]
        t = time.perf_counter()
        cm = solve_complex_modes(ops.K_total(), ops.M, ops.C, a["n_modes"], cea_target_hz(a),
                                 method=a["method"], tol=a["tol"], max_residual=a["max_residual"],
                                 band_hz=tuple(a["band_hz"]), options=petsc_options, prefix="cea_")
        timings["cea"] = time.perf_counter() - t
        lo, hi = a["band_hz"]
        rows, fields = [], []
        for f, re, zeta, r, xr, xi in zip(cm.freqs_hz, cm.real_parts, cm.damping_ratios, cm.residuals,
                                          cm.vectors_re, cm.vectors_im):
            d = basis.describe(xr, xi)
            rows.append({"index": len(rows), "freq_hz": f, "real_part": re, "damping_ratio": zeta,
                         "residual": r, "unstable": bool(re > 0), **d._asdict()})
            fields.append((xr, xi))
        results["complex_modes"] = rows
        results["n_unstable"] = sum(r["unstable"] for r in rows)
        results["cea_method"] = cm.method
        say(f"[fem_squeal] CEA ({cm.method}): {len(rows)} modes in {lo:g}-{hi:g} Hz, "
            f"{results['n_unstable']} unstable, {timings['cea']:.2f} s")
        if write_fields:
            write_modes_xdmf(comm, outdir / "complex_modes.xdmf", ops.V, fields)

    if rank0:
        write_json_atomic(outdir / "results.json", results)
    comm.barrier()
    return results
