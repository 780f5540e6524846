"""The ``mesh`` stage: the scene's geometry built by its gmsh builder or read from a mesh file."""
from __future__ import annotations

import dataclasses
import hashlib
import time
from pathlib import Path

from mpi4py import MPI

from fem_squeal.app.convert import mesh_errors
from fem_squeal.app.stage import Context, Stage
from fem_squeal.util.errors import PipelineError
from geometry import BUILDERS

#: interface types that run on native hexahedra (quadrilateral facets): all of them since the
#: interface operator takes quadrilaterals (fe/interface.py, RefCell)
NATIVE_INTERFACES = ("rigid_plate", "contact", "spring", "bonded")


def hexahedra_options(scene: dict) -> dict:
    """``hexahedra`` (discretisation.hexahedra) and ``blockers`` (the scene's features that need the
    split: interface types not in :data:`NATIVE_INTERFACES`, none today) for a mesh file
    (:func:`geometry.hexahedra.choose_path`)."""
    disc = scene.get("discretisation", {})
    blockers = [f"interfaces.{name} ({t['type']})" for name, t in scene.get("interfaces", {}).items()
                if t["type"] not in NATIVE_INTERFACES]
    return {"hexahedra": disc.get("hexahedra", "auto"), "blockers": blockers}


def build_mesh(comm: MPI.Comm, scene: dict):
    """Mesh stage: call the geometry builder named in the scene."""
    g = dict(scene.geometry)
    builder = BUILDERS[g.pop("builder")]
    if builder is BUILDERS["mesh_file"]:
        g.update(hexahedra_options(scene))
    with mesh_errors():
        return builder(comm, **g)


def spec_for_hexahedra(spec, hexahedra: dict):
    """The model description with the cell rule of a native hexahedral deck: a C3D20 deck (full
    integration, ``geometry.hexahedra.integration_rule``) at degree 2 gets the 3 × 3 × 3 Gauss rule
    unless ``discretisation.quadrature_degree`` is set; anything else is unchanged (the 2 × 2 × 2 rule of
    C3D20R and C3D8, :mod:`fem_squeal.fe.hexahedra`).  A C3D8R deck (integration "one-point") at degree 1
    without a set rule runs CalculiX's C3D8R (:mod:`fem_squeal.fe.c3d8r`)."""
    if (spec is not None and hexahedra.get("path") == "native" and hexahedra.get("integration") == "one-point"
            and spec.degree == 1 and spec.quadrature_degree is None):
        return dataclasses.replace(spec, c3d8r=True)
    if (spec is None or hexahedra.get("path") != "native" or hexahedra.get("integration") != "full"
            or hexahedra.get("element") != "hexahedron20" or spec.degree != 2
            or spec.quadrature_degree is not None):
        return spec
    from fem_squeal.fe.hexahedra import GAUSS_3X3X3  # heavy: FE stack

    return dataclasses.replace(spec, quadrature_degree=GAUSS_3X3X3)


def run(ctx: Context, work: Path, timings: dict) -> dict:
    """Build the mesh (gmsh builder or mesh file); summary and import report for results.json."""
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
        if "hexahedra" in md.info:
            hx = md.info["hexahedra"]
            ctx.say(f"[fem_squeal] hexahedra: {hx['path']} path ({hx['reason']})")
            if "integration" in hx:
                ctx.say(f"[fem_squeal] hexahedra: {hx['integration']} integration ({hx['integration_reason']})")
            ctx.spec = spec_for_hexahedra(ctx.spec, hx)
        for w in md.info["warnings"]:
            ctx.say(f"[fem_squeal] warning: {w}")
    return {"mesh": out}


def inputs(scene: dict, spec) -> dict:
    """The geometry section; a mesh file counts by its content (SHA-256), not by its path."""
    geo = dict(scene.geometry)
    if geo["builder"] == "mesh_file":
        h = hashlib.sha256()
        try:
            with open(geo["file"], "rb") as f:
                for chunk in iter(lambda: f.read(1 << 20), b""):
                    h.update(chunk)
        except OSError as e:
            raise PipelineError(f"geometry.file: cannot read {geo['file']} ({e.strerror})") from None
        geo["file"] = h.hexdigest()
        geo.update(hexahedra_options(scene))
    return geo


STAGE = Stage("mesh", (), run, "geometry (gmsh builder or mesh file) and tagged mesh", inputs=inputs, memory=True)
