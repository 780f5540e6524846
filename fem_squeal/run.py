"""The stage functions of a scene run and :func:`run_scene`, which plans them
(:mod:`fem_squeal.pipeline`: only the stages the analyses need, cached by content hash) and
writes ``outdir``: ``results.json`` (schema below, written atomically by rank 0), the stages'
files (XDMF, PNG, npz, json) and ``report.html``.

results.json (schema_version 3)
-------------------------------
scene            the validated scene (all defaults filled in)
stages           [{stage, key, status ("run" | "cached" | "memory" | "forced"), seconds (of the
                 run that computed it)}]
files            output files of the stages (relative to outdir)
mesh             cells, volumes (part names)
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
masa             cases [{mu, equilibrium, elements, basis, instabilities [{freq_hz, real_part,
                 stationary_amplitudes, stationary_in_unit, broke_at, steps}], seconds}]
transient        basis, contact_elements, steps, steps_computed (fewer when resumed), dt, t_end,
                 wall_s, ms_per_step,
                 iterations_per_step, stats, resumed, static_closure, probe, steady_sliding_unstable
                 [{freq_hz, real_part}], pushed_mode, peak_closure_change, energy_leak, friction_work
limit_cycle      limit_cycle {saturated, frequency_hz, amplitude, t_saturation, growth_rate},
                 window_s, svd_energy, svd_best_mac [{shape, freq_hz, real_part, mac, plane_share}],
                 dynamic_stability {samples, followed_real_part, unstable_share}, energy_shares,
                 mode_energy_shares, mode_cycles [{alpha, friction_work, torque_mean, ...}]
segmented_pad    runs [{kind, speed, v_s, v_d, regimes, regime, fractions (time shares of s < v_s,
                 v_s ≤ s < v_d, s ≥ v_d per element), s_min (per element) [m/s], steps}], seconds

Files: real_modes.xdmf, complex_modes.xdmf (mode_re, mode_im), preload.xdmf, and the same fields
as VTU (meshio; real_modes.vtu mode_<j>, complex_modes.vtu mode_<j>_re/_im, preload.vtu; frequencies
in the field data) for tools other than ParaView
(preload_displacement, contact_pressure), contact_pressure.png; reduced_model.npz,
sweep.json, root_locus.png, complex_plane.png, stability_map.npz/png (fem_squeal.studies).
"""
from __future__ import annotations

import math
import time
import warnings
from pathlib import Path
from typing import Any

import numpy as np
from mpi4py import MPI

from fem_squeal.parallel import on_root
from fem_squeal.scene import model_spec
from fem_squeal.tags import COMPONENT_GROUPS

SCHEMA_VERSION = 3


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
    from fem_squeal.output import write_fields_xdmf, write_vtu

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
        write_vtu(comm, outdir / "preload.vtu", V, {"preload_displacement": u}, scalars={"contact_pressure": p_h})
    return summary


class Context:
    """What the stages of one run share: the scene, the communicator, the in-memory products of
    the stages run so far (``products``) and the cache entries of the stages before."""

    def __init__(self, scene: dict, comm: MPI.Comm, say, write_fields: bool, cache, keys: dict[str, str]):
        self.scene, self.comm, self.say, self.write_fields = scene, comm, say, write_fields
        self.cache, self.keys = cache, keys
        self.products: dict[str, Any] = {}
        self._spec = None

    @property
    def spec(self):
        if self._spec is None:
            self._spec = model_spec(self.scene)
        return self._spec

    def entry(self, stage: str) -> Path:
        """The committed cache folder of an upstream stage (its files)."""
        return self.cache.entry(stage, self.keys[stage])

    def reduced_model(self):
        """The reduced model: this run's, or the cached ``reduced_model.npz``."""
        from fem_squeal.reduced.model import ReducedModel

        if "reduced" not in self.products:
            self.products["reduced"] = ReducedModel.load(self.entry("reduced") / "reduced_model.npz")
        return self.products["reduced"]


def stage_mesh(ctx: Context, work: Path, timings: dict) -> dict:
    t = time.perf_counter()
    md = build_mesh(ctx.comm, ctx.scene)
    timings["mesh"] = time.perf_counter() - t
    ctx.products["mesh"] = md
    out = {"cells": md.mesh.topology.index_map(3).size_global, "volumes": sorted(md.volumes)}
    if md.info:
        out["import"] = md.info
        q = md.info["quality"]
        ctx.say(f"[fem_squeal] mesh file {Path(md.info['file']).name} ({md.info['format']}): "
                f"{md.info['elements']} "
                f"{md.info['element']}, worst aspect ratio {q['worst_aspect_ratio']:.3g}, min Jacobian ratio "
                f"{q['min_jacobian_ratio']:.3g}")
        for w in md.info["warnings"]:
            ctx.say(f"[fem_squeal] warning: {w}")
    return {"mesh": out}


def stage_operators(ctx: Context, work: Path, timings: dict) -> dict:
    from fem_squeal.assembly import assemble_operators
    from fem_squeal.descriptors import CircumferentialBasis
    from fem_squeal.penalty import penalty_ratios, penalty_warnings

    scene, spec, md = ctx.scene, ctx.spec, ctx.products["mesh"]
    ana = scene["analyses"]
    t = time.perf_counter()
    part = describe_part(scene, md.volumes)
    sub: dict[str, float] = {}
    studies = {"reduced", "sweep", "map", "masa", "transient"} & set(ana)
    ops = assemble_operators(md, spec, parts=bool(studies) or ("cea" in ana and len(spec.materials) > 1),
                             describe_part=part, timings=sub)
    timings["assembly"] = time.perf_counter() - t
    if spec.interfaces:
        timings["interface_operators"] = sub["interfaces"]
    ndofs = ops.V.dofmap.index_map.size_global * ops.V.dofmap.index_map_bs
    ncells = md.mesh.topology.index_map(3).size_global
    ctx.say(f"[fem_squeal] {ncells} cells, {ndofs} DOFs (P{spec.degree}) on {ctx.comm.size} rank(s); "
            f"assembly {timings['assembly']:.2f} s")
    ratios = penalty_ratios(md, spec)
    for w in penalty_warnings(ratios):
        warnings.warn(w, stacklevel=2)
        ctx.say(f"[fem_squeal] warning: {w}")
    Md, Mzd = ops.M_parts[part] if part else (ops.M, ops.M_axial)
    ctx.products["operators"] = ops
    ctx.products["basis"] = CircumferentialBasis(ops.V, Md, Mzd)
    return {"model": {"dofs": ndofs, "cells": ncells, "ranks": ctx.comm.size, "degree": spec.degree,
                      "penalty": [r.as_dict() for r in ratios]}}


def stage_preload(ctx: Context, work: Path, timings: dict) -> dict:
    from fem_squeal.assembly import linearise

    ops = ctx.products["operators"]
    out: dict[str, Any] = {}
    pre = None
    if ops.contacts:
        pl = ctx.scene["preload"]
        t = time.perf_counter()
        if pl["mode"] == "nonlinear":
            from fem_squeal.preload import solve_preload

            pre = solve_preload(ops, friction=pl["friction"], tol=pl["tol"], max_iterations=pl["max_iterations"],
                                options=ctx.scene["solver"]["petsc_options"])
            lin = linearise(ops, pre.active)
            timings["preload"] = time.perf_counter() - t
            out["preload"] = {"mode": "nonlinear", "iterations": pre.iterations, "history": pre.history,
                              "interfaces": _preload_outputs(ctx.comm, work, ops, pre, ctx.write_fields,
                                                             ctx.scene["title"])}
            ctx.say(f"[fem_squeal] preload: {pre.iterations} Newton iterations, "
                    + ", ".join(f"{k} N = {v['normal_force']:.4g} N, closed {100 * v['closed_share']:.1f} %"
                                for k, v in out["preload"]["interfaces"].items())
                    + f"; {timings['preload']:.2f} s")
        else:
            lin = linearise(ops, None)
            timings["preload"] = time.perf_counter() - t
            out["preload"] = {"mode": "all_closed"}
        ops.K.destroy()
        ops = lin
    ctx.products["preload"] = pre
    ctx.products["linear"] = ops
    return out


def stage_real_modes(ctx: Context, work: Path, timings: dict) -> dict:
    from fem_squeal.eigen import solve_real_modes
    from fem_squeal.output import write_modes_xdmf, write_vtu

    ops, basis = ctx.products["linear"], ctx.products["basis"]
    a = ctx.scene["analyses"]["real_modes"]
    t = time.perf_counter()
    rm = solve_real_modes(ops.K, ops.M, a["n_modes"], a["target_hz"], tol=a["tol"], max_residual=a["max_residual"],
                          options=ctx.scene["solver"]["petsc_options"], prefix="real_", progress=True)
    timings["real_modes"] = time.perf_counter() - t
    rows = []
    for f, r, x in zip(rm.freqs_hz, rm.residuals, rm.vectors):
        d = basis.describe(x)
        rows.append({"freq_hz": f, "residual": r, "in_plane_share": d.in_plane_share,
                     "nodal_diameter": d.nodal_diameter, "nodal_share": d.nodal_share})
    ctx.say(f"[fem_squeal] real modes: {len(rows)} in {timings['real_modes']:.2f} s")
    if ctx.write_fields:
        write_modes_xdmf(ctx.comm, work / "real_modes.xdmf", ops.V, [(x, None) for x in rm.vectors])
        write_vtu(ctx.comm, work / "real_modes.vtu", ops.V, {f"mode_{j}": x for j, x in enumerate(rm.vectors)},
                  {"freq_hz": rm.freqs_hz})
    return {"real_modes": rows}


def stage_cea(ctx: Context, work: Path, timings: dict) -> dict:
    from fem_squeal.descriptors import strain_energy_shares
    from fem_squeal.eigen import solve_complex_modes
    from fem_squeal.output import write_modes_xdmf, write_vtu

    ops, basis, scene = ctx.products["linear"], ctx.products["basis"], ctx.scene
    a = scene["analyses"]["cea"]
    t = time.perf_counter()
    cm = solve_complex_modes(ops.K_total(), ops.M, ops.C, a["n_modes"], cea_target_hz(a), method=a["method"],
                             tol=a["tol"], max_residual=a["max_residual"], band_hz=tuple(a["band_hz"]),
                             options=scene["solver"]["petsc_options"], prefix="cea_", progress=True)
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
    n_unstable = sum(r["unstable"] for r in rows)
    ctx.say(f"[fem_squeal] CEA ({cm.method}): {len(rows)} modes in {lo:g}-{hi:g} Hz, "
            f"{n_unstable} unstable, {timings['cea']:.2f} s")
    if ctx.write_fields:
        write_modes_xdmf(ctx.comm, work / "complex_modes.xdmf", ops.V, fields)
        write_vtu(ctx.comm, work / "complex_modes.vtu", ops.V,
                  {f"mode_{j}_{part}": x for j, pair in enumerate(fields) for part, x in zip(("re", "im"), pair)},
                  {"freq_hz": [r["freq_hz"] for r in rows], "real_part": [r["real_part"] for r in rows]})
    return {"complex_modes": rows, "n_unstable": n_unstable, "cea_method": cm.method}


def _stage_functions() -> dict:
    from fem_squeal import dynamics, studies

    return {"mesh": stage_mesh, "operators": stage_operators, "preload": stage_preload,
            "real_modes": stage_real_modes, "cea": stage_cea, "reduced": studies.stage_reduced,
            "sweep": studies.stage_sweep, "map": studies.stage_map, "masa": studies.stage_masa,
            "transient": dynamics.stage_transient, "limit_cycle": dynamics.stage_limit_cycle,
            "segmented_pad": dynamics.stage_segmented_pad}


def remove_stale_outputs(outdir: Path, files: list[str]) -> None:
    """Delete the files that an earlier run listed in ``outdir/results.json`` and this run did not
    write (a MASA plot of a μ no longer asked for), so the folder shows one run."""
    import json

    try:
        old = json.loads((outdir / "results.json").read_text()).get("files", [])
    except (OSError, ValueError):
        return
    for name in set(old) - set(files):
        p = (outdir / name).resolve()
        if outdir.resolve() in p.parents and p.is_file():
            p.unlink()


def run_scene(scene: dict, outdir: str | Path, comm: MPI.Comm = MPI.COMM_WORLD, write_fields: bool = True,
              log=print, cache: str | Path | None = None, force=(), report: bool = True) -> dict[str, Any]:
    """Run the stages that ``scene``'s analyses need (:mod:`fem_squeal.pipeline`), reusing the
    entries of ``cache`` (a folder; None = a temporary cache, removed afterwards), and write the
    outputs to ``outdir``.  Returns the results dictionary (the content of results.json)."""
    import shutil
    import tempfile

    from fem_squeal.blas import limit_threads_for
    from fem_squeal.output import jsonable, write_json_atomic
    from fem_squeal.pipeline import Cache, make_plan, publish, scratch

    outdir = Path(outdir)
    rank0 = comm.rank == 0
    limit_threads_for(comm)
    say = log if rank0 else (lambda *a, **k: None)
    temporary = cache is None
    if temporary:
        cache = comm.bcast(tempfile.mkdtemp(prefix="fem_squeal_cache.") if rank0 else None, root=0)
    store = Cache(cache)
    try:
        plan = make_plan(scene, store, force=force, write_fields=write_fields)
        ctx = Context(scene, comm, say, write_fields, store, {p.stage: p.key for p in plan})
        functions = _stage_functions()
        results: dict[str, Any] = {"schema_version": SCHEMA_VERSION, "scene": scene, "stages": []}
        timings: dict[str, float] = {}
        for i, item in enumerate(plan):
            t0 = time.perf_counter()
            if item.status == "cached":
                entry = store.load(item.stage, item.key)
            else:
                say(f"[fem_squeal] stage {i + 1}/{len(plan)}: {item.stage}"
                    + (" (in memory; outputs cached)" if item.status == "memory" else ""))
                stage_t: dict[str, float] = {}
                writer = scratch(comm) if item.status == "memory" else store.writing(comm, item.stage, item.key)
                with writer as work:
                    sections = jsonable(functions[item.stage](ctx, work, stage_t))
                    entry = {"stage": item.stage, "key": item.key, "results": sections, "timings": stage_t,
                             "seconds": time.perf_counter() - t0}
                    if rank0 and item.status != "memory":
                        write_json_atomic(work / "entry.json", entry)
                if item.status == "memory":
                    entry = store.load(item.stage, item.key)
                else:
                    timings.update(stage_t)
            results.update(entry["results"])
            results["stages"].append({"stage": item.stage, "key": item.key, "status": item.status,
                                      "seconds": entry["seconds"]})
        def publish_all() -> list[str]:
            outdir.mkdir(parents=True, exist_ok=True)
            files = []
            for item in plan:
                files += publish(store.entry(item.stage, item.key), outdir)
            remove_stale_outputs(outdir, files)
            return files

        results["files"] = on_root(comm, publish_all)
        results["timings_s"] = timings
        if "model" in results:
            results["model"]["ranks"] = comm.size
        if rank0:
            write_json_atomic(outdir / "results.json", results)
            if report:
                from fem_squeal.report import write_report

                write_report(outdir, results)
        comm.barrier()
        return results
    finally:
        if temporary:
            comm.barrier()
            if rank0:
                shutil.rmtree(cache, ignore_errors=True)
