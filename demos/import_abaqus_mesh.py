"""Bring your own mesh: the complex eigenvalue analysis of a brake read from an Abaqus deck.

``meshes/brake_corner_mm.inp`` stands in for a customer's file: a flat Abaqus input deck in
millimetres with C3D10 elements, one ``*ELSET`` per part and element-based ``*SURFACE``s for the
contact, clamp and load faces.  The scene ``scenes/brake_import_abaqus.toml`` maps those sets to
the parts and faces of the brake-corner physics (materials, contact, loads and the CEA come from
``brake_corner_cea.toml`` unchanged) and scales mm to m.  The mesh is read by meshio on rank 0,
checked (inverted, degenerate and badly shaped elements), and distributed by dolfinx exactly like
a gmsh-built mesh.  The mode shapes are written as XDMF and, through meshio, as VTU.

Run:  mpirun -n 2 python3 demos/import_abaqus_mesh.py [OUTDIR] [--set=key=value ...]

It checks itself:
- each part's volume against the exact volume of the brake geometry (P2 circles: 5e-4);
- the CEA on the deck against the native gmsh brake the deck was written from (``fem-squeal mesh
  scenes/brake_corner_cea.toml meshes/brake_corner_mm.inp --set geometry.mesh_size=0.016 --scale
  1000``): the same mesh up to the deck's 17 printed digits, so the same eigenvalues to the solver
  tolerance (1e-8 relative; measured 1e-10).  If gmsh ever meshes differently the check says so:
  regenerate the deck with that command.
"""
from __future__ import annotations

import warnings

import numpy as np
import ufl
from dolfinx import fem
from mpi4py import MPI

from fem_squeal.app.analyses.mesh import build_mesh
from fem_squeal.app.cli import demo_arguments
from fem_squeal.app.run import run_scene
from fem_squeal.app.scene import load_scene
from geometry.brake_corner import BrakeCornerParams
from geometry.mesh_file import prepare

args = demo_arguments(__file__)
comm = MPI.COMM_WORLD
say = print if comm.rank == 0 else (lambda *a, **k: None)
scene = load_scene(args.root / "scenes" / "brake_import_abaqus.toml", args.overrides)
geo = scene["geometry"]

# --- what a forgotten unit factor looks like ----------------------------------------------------
if comm.rank == 0:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        _, info = prepare(geo["file"], parts=geo["parts"], faces=geo["faces"], scale=1.0)
    say("without geometry.scale the import warns:\n  " + "\n  ".join(info["warnings"]))

# --- the CEA on the imported deck ---------------------------------------------------------------
res = run_scene(scene, args.outdir / "imported", comm)
imp = res["mesh"]["import"]
say(f"\n{imp['file']}: {imp['elements']} {imp['element']} elements, worst aspect ratio "
    f"{imp['quality']['worst_aspect_ratio']:.2f}, min Jacobian ratio {imp['quality']['min_jacobian_ratio']:.2f}")
say("parts (elements): " + ", ".join(f"{k} {v}" for k, v in imp["parts"].items()))
modes = res["complex_modes"]
say(f"\n{'f [Hz]':>9} {'Re λ [1/s]':>11}")
for m in modes:
    say(f"{m['freq_hz']:9.1f} {m['real_part']:11.3f}" + ("  UNSTABLE" if m["unstable"] else ""))

# --- checks -------------------------------------------------------------------------------------
failures = []
md = build_mesh(comm, scene)
exact = BrakeCornerParams().analytic_volumes()
dx = ufl.Measure("dx", domain=md.mesh, subdomain_data=md.cell_tags)
one = fem.Constant(md.mesh, 1.0)
for part, v in exact.items():
    vol = comm.allreduce(fem.assemble_scalar(fem.form(one * dx(md.volumes[part]))), op=MPI.SUM)
    if abs(vol / v - 1) > 5e-4:
        failures.append(f"{part}: volume {vol:.6e} m³ against the exact {v:.6e} m³")

physics = [s for s in args.overrides if not s.startswith("geometry.")]
native_scene = load_scene(args.root / "scenes" / "brake_corner_cea.toml", ["geometry.mesh_size=0.016", *physics])
native = run_scene(native_scene, args.outdir / "native", comm, write_fields=False, report=False)
lam = np.array([complex(m["real_part"], 2 * np.pi * m["freq_hz"]) for m in modes])
ref = np.array([complex(m["real_part"], 2 * np.pi * m["freq_hz"]) for m in native["complex_modes"]])
if native["model"]["cells"] != res["model"]["cells"] or len(lam) != len(ref):
    failures.append(f"the native brake at mesh_size 0.016 has {native['model']['cells']} cells and "
                    f"{len(ref)} modes, the deck {res['model']['cells']} and {len(lam)}: gmsh meshed differently, "
                    "regenerate meshes/brake_corner_mm.inp (see meshes/README.md)")
else:
    err = float(np.max(np.abs(lam - ref) / np.abs(ref)))
    say(f"\nimported against native: {len(lam)} eigenvalues, max relative difference {err:.1e}")
    if err > 1e-8:
        failures.append(f"eigenvalues differ from the native mesh's by {err:.1e} > 1e-8")
if "complex_modes.vtu" not in res["files"]:
    failures.append("no complex_modes.vtu written")

if failures:
    raise SystemExit("CHECK FAILED:\n  " + "\n  ".join(failures))
say(f"checks passed; results in {args.outdir}")
