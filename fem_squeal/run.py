"""Run a validated scene: mesh → operators → preload → real modes and/or CEA → descriptors → outputs.

Each stage is a function of the scene and the upstream results, and only the stages that the
requested analyses need are run (a scene without ``analyses.real_modes`` solves no real modes).
Outputs go to ``outdir``: ``results.json`` (schema below, written atomically by rank 0) and XDMF
files of the mode shapes.

results.json (schema_version 2)
-------------------------------
scene            the validated scene (all defaults filled in)
model            dofs, cells, ranks, degree
timings_s        wall time per stage
preload          (models with contact interfaces) mode, iterations, history [[closed points,
                 ‖R‖/‖f‖]], and per interface: normal_force [N], friction_force [N],
                 contact_area [m²], area [m²], peak_pressure [Pa], closed_share
real_modes       [{freq_hz, residual, in_plane_share, nodal_diameter, nodal_share}]
complex_modes    [{index, freq_hz, real_part [1/s], damping_ratio, residual, unstable,
                   in_plane_share, nodal_diameter, nodal_share, travelling_index,
                   travelling_direction, energy_shares {component: share}}]
                 (Im λ > 0, inside analyses.cea.band_hz; descriptors of describe_part;
                 energy_shares only for models with several parts)
n_unstable       number of complex modes with Re λ > 0
reduced          size, parameters, mu0, rounds [{cut_hz, modes, sampled_modes, static, dropped,
                 size, change, seconds}], converged, tol, estimated_error, lifted_residuals
                 [{point, freq_hz, real_part, backward_error}], verification [{point,
                 max_rel_error, n_unstable_full, n_unstable_reduced, full_cea_s, ...}]
sweep            parameter, values, critical [{branch, partner, value, bracket, freq_hz, kind,
                 onset, labels}], solves, seconds (branches in sweep.json)
map              parameter, points, seconds, seconds_per_point, axes, bands_hz, counts, total

Files: real_modes.xdmf, complex_modes.xdmf (mode_re, mode_im), preload.xdmf
(preload_displacement, contact_pressure), contact_pressure.png; reduced_model.npz,
sweep.json, root_locus.png, complex_plane.png, stability_map.npz/png (fem_squeal.studies).
"""
from __future__ import annotations

import math
import time
from pathlib import Path
from typing import Any

import numpy as np
from mpi4py import MPI

from fem_squeal.scene import model_spec
from fem_squeal.tags import COMPONENT_GROUPS

SCHEMA_VERSION = 2


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


def describe_part(scene: dict, volumes: dict[str, int]) -> str | None:
    """The part whose nodal diameters are reported: analyses.cea.describe_part, else "disc"."""
    part = scene["analyses"].get("cea", {}).get("describe_part", "")
    if part:
        return part
    return "disc" if "disc" in volumes and len(volumes) > 1 else None


def _preload_outputs(comm, outdir: Path, ops, pre, write_fields: bool, title: str) -> dict[str, Any]:
    """Summary of the preload for results.json; pressure PNG and XDMF (pressure, displacement)."""
    from dolfinx import fem

    from fem_squeal import plots
    from fem_squeal.interface import project_to_nodes
    from fem_squeal.output import write_fields_xdmf

    summary: dict[str, Any] = {}
    plot_data = {}
    for it, op in ops.contacts:
        p = pre.pressure[it.name]
        area = op.area(comm)
        summary[it.name] = {
            "normal_force": pre.normal_force[it.name], "friction_force": pre.friction_force[it.name],
            "contact_area": pre.contact_area[it.name], "area": area,
            "closed_share": pre.contact_area[it.name] / area if area > 0 else 0.0,
            "peak_pressure": comm.allreduce(float(np.max(p, initial=0.0)), op=MPI.MAX),
        }
        xs, ps = comm.gather(op.x, root=0), comm.gather(p, root=0)
        if comm.rank == 0:
            plot_data[it.name] = (np.concatenate(xs), np.concatenate(ps))
    if comm.rank == 0:
        plots.contact_pressure(outdir / "contact_pressure.png", plot_data, title)
    if write_fields:
        V = ops.V
        S = fem.FunctionSpace(V.mesh, ("Lagrange", V.ufl_element().degree()))
        if S.dofmap.index_map.size_local != V.dofmap.index_map.size_local:
            raise RuntimeError("contact pressure output: scalar and vector spaces number their nodes differently")
        p_h = fem.Function(S, name="contact_pressure")
        for it, op in ops.contacts:
            dofs, vals = project_to_nodes(op, pre.pressure[it.name], comm)
            p_h.vector.setValues(dofs.astype(np.int32), vals)
        p_h.vector.assemble()
        p_h.x.scatter_forward()
        u = fem.Function(V, name="preload_displacement")
        u.x.array[: pre.u.getLocalSize()] = pre.u.array_r
        u.x.scatter_forward()
        write_fields_xdmf(comm, outdir / "preload.xdmf", {"preload_displacement": u, "contact_pressure": p_h})
    return summary


def run_scene(scene: dict, outdir: str | Path, comm: MPI.Comm = MPI.COMM_WORLD,
              write_fields: bool = True, log=print) -> dict[str, Any]:
    """Run every analysis of ``scene`` and write the outputs; returns the results dictionary."""
    from fem_squeal.assembly import assemble_operators, linearise
    from fem_squeal.blas import limit_threads_for
    from fem_squeal.descriptors import CircumferentialBasis, strain_energy_shares
    from fem_squeal.eigen import solve_complex_modes, solve_real_modes
    from fem_squeal.output import write_json_atomic, write_modes_xdmf

    outdir = Path(outdir)
    rank0 = comm.rank == 0
    limit_threads_for(comm)
    say = log if rank0 else (lambda *a, **k: None)
    spec = model_spec(scene)
    petsc_options = scene["solver"]["petsc_options"]
    timings: dict[str, float] = {}

    t = time.perf_counter()
    md = build_mesh(comm, scene)
    timings["mesh"] = time.perf_counter() - t
    t = time.perf_counter()
    ana = scene["analyses"]
    part = describe_part(scene, md.volumes)
    sub: dict[str, float] = {}
    studies = {"reduced", "sweep", "map", "masa"} & set(ana)
    ops = assemble_operators(md, spec, parts=bool(studies) or ("cea" in ana and len(spec.materials) > 1),
                             describe_part=part, timings=sub)
    timings["assembly"] = time.perf_counter() - t
    if spec.interfaces:
        timings["interface_operators"] = sub["interfaces"]
    ndofs = ops.V.dofmap.index_map.size_global * ops.V.dofmap.index_map_bs
    ncells = md.mesh.topology.index_map(3).size_global
    say(f"[fem_squeal] {ncells} cells, {ndofs} DOFs (P{spec.degree}) on {comm.size} rank(s); "
        f"mesh {timings['mesh']:.2f} s, assembly {timings['assembly']:.2f} s")
    Md, Mzd = ops.M_parts[part] if part else (ops.M, ops.M_axial)
    basis = CircumferentialBasis(ops.V, Md, Mzd)
    results: dict[str, Any] = {
        "schema_version": SCHEMA_VERSION, "scene": scene,
        "model": {"dofs": ndofs, "cells": ncells, "ranks": comm.size, "degree": spec.degree},
        "timings_s": timings,
    }

    pre = None
    if ops.contacts:
        pl = scene["preload"]
        t = time.perf_counter()
        if pl["mode"] == "nonlinear":
            from fem_squeal.preload import solve_preload

            pre = solve_preload(ops, friction=pl["friction"], tol=pl["tol"], max_iterations=pl["max_iterations"],
                                options=petsc_options)
            lin = linearise(ops, pre.active)
            timings["preload"] = time.perf_counter() - t
            results["preload"] = {"mode": "nonlinear", "iterations": pre.iterations, "history": pre.history,
                                  "interfaces": _preload_outputs(comm, outdir, ops, pre, write_fields,
                                                                 scene["title"])}
            say(f"[fem_squeal] preload: {pre.iterations} Newton iterations, "
                + ", ".join(f"{k} N = {v['normal_force']:.4g} N, closed {100 * v['closed_share']:.1f} %"
                            for k, v in results["preload"]["interfaces"].items())
                + f"; {timings['preload']:.2f} s")
        else:
            lin = linearise(ops, None)
            timings["preload"] = time.perf_counter() - t
            results["preload"] = {"mode": "all_closed"}
        ops.K.destroy()
        ops = lin

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
            if ops.K_parts:
                groups = COMPONENT_GROUPS.get(scene["geometry"]["builder"])
                rows[-1]["energy_shares"] = strain_energy_shares(ops.K_parts, xr, xi, groups)
            fields.append((xr, xi))
        results["complex_modes"] = rows
        results["n_unstable"] = sum(r["unstable"] for r in rows)
        results["cea_method"] = cm.method
        say(f"[fem_squeal] CEA ({cm.method}): {len(rows)} modes in {lo:g}-{hi:g} Hz, "
            f"{results['n_unstable']} unstable, {timings['cea']:.2f} s")
        if write_fields:
            write_modes_xdmf(comm, outdir / "complex_modes.xdmf", ops.V, fields)

    if studies:
        from fem_squeal.studies import run_studies

        results.update(run_studies(comm, scene, spec, ops, pre, outdir, say, timings))

    if rank0:
        write_json_atomic(outdir / "results.json", results)
    comm.barrier()
    return results
