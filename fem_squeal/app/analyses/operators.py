"""The ``operators`` stage: function space, assembled matrices and interface operators of the model."""
from __future__ import annotations

import time
import warnings
from pathlib import Path

from fem_squeal.app.stage import Context, Stage

#: the model sections besides geometry: what the assembly reads
MODEL_SECTIONS = ("materials", "interfaces", "boundary", "loads", "discretisation", "operating")


def describe_part(scene: dict, volumes: dict[str, int]) -> str | None:
    """The part whose nodal diameters are reported: analyses.cea.describe_part, else "disc"."""
    part = scene.analyses.get("cea", {}).get("describe_part", "")
    if part:
        return part
    return "disc" if "disc" in volumes and len(volumes) > 1 else None


def keeps_part_stiffnesses(analyses, materials: int) -> bool:
    """Whether the operators keep each part's stiffness beside K for the CEA's strain-energy shares: where
    another analysis runs too (it may read them).  A CEA alone takes them one at a time after its solve
    (:func:`fem_squeal.fe.assembly.part_stiffnesses`): at 1.32M DOFs they are 1.2 GiB, which the preload's
    peak then does not hold."""
    return "cea" in analyses and materials > 1 and set(analyses) != {"cea"}


def run(ctx: Context, work: Path, timings: dict) -> dict:
    """Function space, forms, K, M, C and the interface operators; penalty diagnostics."""
    from fem_squeal.fe.assembly import assemble_operators  # heavy: FE stack
    from fem_squeal.fe.descriptors import CircumferentialBasis  # heavy: FE stack
    from fem_squeal.fe.hexahedra import element_description, is_hexahedral  # heavy: FE stack
    from fem_squeal.fe.penalty import penalty_ratios, penalty_warnings  # heavy: FE stack

    scene, spec, md = ctx.scene, ctx.spec, ctx.products["mesh"]
    ana = scene.analyses
    t = time.perf_counter()
    part = describe_part(scene, md.volumes)
    sub: dict[str, float] = {}
    studies = {"reduced", "sweep", "map", "masa", "transient"} & set(ana)
    ops = assemble_operators(md, spec, parts=bool(studies) or keeps_part_stiffnesses(ana, len(spec.materials)),
                             describe_part=part, timings=sub)
    timings["assembly"] = time.perf_counter() - t
    if spec.interfaces:
        timings["interface_operators"] = sub["interfaces"]
    ndofs = ops.V.dofmap.index_map.size_global * ops.V.dofmap.index_map_bs
    ncells = md.mesh.topology.index_map(3).size_global
    element = f"P{spec.degree}"
    if is_hexahedral(md.mesh):
        element = element_description(ops.V, spec.quadrature_degree, spec.c3d8r)
    ctx.say(f"[fem_squeal] {ncells} cells, {ndofs} DOFs ({element}) on {ctx.comm.size} rank(s); "
            f"assembly {timings['assembly']:.2f} s")
    ratios = penalty_ratios(md, spec)
    for w in penalty_warnings(ratios):
        warnings.warn(w, stacklevel=2)
        ctx.say(f"[fem_squeal] warning: {w}")
    Md, Mzd = ops.M_parts[part] if part else (ops.M, ops.M_axial)
    ctx.products["operators"] = ops
    ctx.products["basis"] = CircumferentialBasis(ops.V, Md, Mzd)
    model = {"dofs": ndofs, "cells": ncells, "ranks": ctx.comm.size, "degree": spec.degree,
             "penalty": [r.as_dict() for r in ratios]}
    if is_hexahedral(md.mesh):
        model["element"] = element       # the native hexahedral path (tetrahedra: P<degree>, as always)
    return {"model": model}


def report(res: dict) -> str:
    """The report section (HTML) of this stage from results.json ``res``."""
    if "model" not in res:
        return ""
    m = res["model"]
    return (f"<h2>Model</h2><p>{m['cells']} cells, {m['dofs']} DOFs (P{m['degree']}), "
               f"{m['ranks']} rank(s)</p>")


STAGE = Stage("operators", ("mesh",), run, "function space, forms, K, M, C and interface operators",
              inputs=lambda scene, spec: {k: scene[k] for k in MODEL_SECTIONS}, report=report, memory=True)
