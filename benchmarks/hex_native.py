"""Native hexahedra against CalculiX 2.20 on the same deck: the clamped-free annular plate of issue #37.

The plate b = 0.05 m <= r <= a = 0.1 m, h = 2 mm, steel (E 210 GPa, ν 0.3, ρ 7800 kg/m³), clamped on
the inner cylinder (every node at r = b), free elsewhere; 6 x 96 x 2 elements.  The same file
(:func:`geometry.hex_decks.annular_plate_hex20` / :func:`~geometry.hex_decks.annular_plate_hex8`,
written with ``*MATERIAL``, ``*SOLID SECTION``, ``*BOUNDARY`` and ``*FREQUENCY``) runs in ``ccx`` as
C3D20R, C3D20, C3D8 and C3D8R, and in fem_squeal through ``geometry.mesh_file`` on the native hexahedral
path (each displacement element and rule) and on the split into curved P2 tetrahedra.  The table:
each variant's DOFs, wall time and max |f − f_ccx| / f_ccx over the ten lowest frequencies.

    .venv/bin/python benchmarks/hex_native.py [--quick] [--workdir DIR]
"""
from __future__ import annotations

import argparse
import json
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from casework import ccx_nodes  # noqa: E402

B, A, H = 0.05, 0.1, 0.002
MAT = dict(E=210e9, nu=0.3, rho=7800.0)
GRID = (6, 96, 2)
N_MODES = 10


def write_plate(path: Path, element: str, grid=GRID, ccx: bool = True, thickness: float = H,
                jitter: float = 0.0) -> None:
    """The plate deck with ``element`` C3D20R, C3D20, C3D8 or C3D8R (``ccx``: with the material, the clamp and a
    *FREQUENCY step of N_MODES + 2 modes for CalculiX; the mesh reader ignores them).  ``jitter``: every node
    off the clamp moves by up to that fraction of the smallest element edge along each axis (seeded)."""
    from geometry.hex_decks import annular_plate_hex8, annular_plate_hex20, write_inp

    make = annular_plate_hex8 if element.startswith("C3D8") else annular_plate_hex20
    pts, blocks, inner, outer = make(B, A, thickness, *grid)
    r = np.hypot(pts[:, 0], pts[:, 1])
    clamp = np.flatnonzero(np.abs(r - B) < 1e-9 * A)
    if jitter:
        h = min((A - B) / grid[0], 2 * np.pi * B / grid[1], thickness / grid[2])
        free = np.setdiff1d(np.arange(len(pts)), clamp)
        pts[free] += jitter * h * np.random.default_rng(0).uniform(-1, 1, (len(free), 3))
    write_inp(path, pts, blocks, elsets={"PLATE": np.arange(len(blocks[0][1]))}, nsets={"CLAMP": clamp},
              surfaces={"INNER": [(e, "S6") for e in inner]}, types={blocks[0][0]: element})
    if ccx:
        ccx_nodes(path)
        with open(path, "a") as f:
            f.write("\n".join(["*MATERIAL, NAME=STEEL", "*ELASTIC", f"{MAT['E']:.6e}, {MAT['nu']}", "*DENSITY",
                               f"{MAT['rho']}", "*SOLID SECTION, ELSET=PLATE, MATERIAL=STEEL", "*BOUNDARY",
                               "CLAMP, 1, 3", "*STEP", "*FREQUENCY", f"{N_MODES + 2}", "*END STEP"]) + "\n")


def run_ccx(folder: Path, job: str) -> tuple[np.ndarray, float]:
    """The eigenfrequencies [Hz] ccx writes in ``job.dat``, and its wall time."""
    t = time.perf_counter()
    with open(folder / f"{job}.log", "w") as out:
        p = subprocess.run(["ccx", "-i", job], cwd=folder, stdout=out, stderr=subprocess.STDOUT,
                           env={"OMP_NUM_THREADS": "1", "CCX_NPROC_EQUATION_SOLVER": "1", "PATH": "/usr/bin:/bin"})
    if p.returncode != 0:
        tail = (folder / f"{job}.log").read_text()[-2000:]
        raise RuntimeError(f"ccx -i {job} failed (exit {p.returncode}): {tail}")
    text = (folder / f"{job}.dat").read_text()
    i = text.find("E I G E N V A L U E   O U T P U T")
    j = text.find("P A R T I C I P A T I O N", i)
    rows = [r.split() for r in text[i:j if j > 0 else None].splitlines()]
    f = [float(r[3]) for r in rows if len(r) == 5 and re.fullmatch(r"\d+", r[0])]
    return np.sort(np.array(f)), time.perf_counter() - t


SCENE = """title = "hex_native plate"
[geometry]
builder = "mesh_file"
file = "{deck}"
parts = {{ plate = ["PLATE"] }}
faces = {{ inner = ["INNER"] }}
[materials.plate]
E = {E}
nu = {nu}
rho = {rho}
[boundary]
clamped = ["inner"]
[analyses.real_modes]
n_modes = {n}
target_hz = 0.0
"""

#: fem_squeal variants: (label, deck, CalculiX reference, scene overrides, element family on hexahedra).
#: The family "Q" (27-node Lagrange) is a measured candidate only: the code's choice is
#: fem_squeal.fe.hexahedra.ELEMENTS, swapped here for that row.
VARIANTS = [
    ("native S2, 2x2x2 (default)", "C3D20R", "C3D20R", [], None),
    ("native S2, 3x3x3", "C3D20R", "C3D20", ["discretisation.quadrature_degree=5"], None),
    ("native S2 on the C3D20 deck (its 3x3x3 rule)", "C3D20", "C3D20", [], None),
    ("native Q2, 2x2x2", "C3D20R", "C3D20R", ["discretisation.quadrature_degree=3"], "Q"),
    ("native Q2, 3x3x3", "C3D20R", "C3D20R", ["discretisation.quadrature_degree=5"], "Q"),
    ("split: curved P2 tetrahedra", "C3D20R", "C3D20R", ["discretisation.hexahedra=split"], None),
    ("native Q1, 2x2x2 (degree 1)", "C3D8", "C3D8", ["discretisation.degree=1"], None),
    ("native S2, 2x2x2 on the C3D8 deck", "C3D8", "C3D20R", [], None),
    ("native Q1, one point + hourglass (degree 1)", "C3D8R", "C3D8R", ["discretisation.degree=1"], None),
    ("native Q1, one point + hourglass (degree 1)", "C3D8R_thick_distorted", "C3D8R_thick_distorted",
     ["discretisation.degree=1"], None),
]
#: the decks: name -> (element type, write_plate options).  The second C3D8R deck (h = 10 mm, three elements
#: through the thickness, nodes moved by up to 20 % of the smallest edge) checks the element on
#: non-affine cells (mean strain, hourglass vectors and volume all differ from the centre's there).
DECKS = {"C3D20R": ("C3D20R", {}), "C3D20": ("C3D20", {}), "C3D8": ("C3D8", {}), "C3D8R": ("C3D8R", {}),
         "C3D8R_thick_distorted": ("C3D8R", {"thickness": 0.01, "jitter": 0.2, "n_z": 3})}


def run_fem_squeal(folder: Path, deck: Path, overrides: list[str],
                   family: str | None) -> tuple[np.ndarray, int, float]:
    """The lowest N_MODES frequencies [Hz], the DOFs and the wall time of ``fem-squeal run`` on ``deck``."""
    from mpi4py import MPI

    from fem_squeal.app.run import run_scene
    from fem_squeal.app.scene import load_scene
    from fem_squeal.fe import hexahedra

    scene = folder / f"{deck.stem}.toml"
    scene.write_text(SCENE.format(deck=deck, n=N_MODES, **MAT))
    saved = dict(hexahedra.ELEMENTS)
    if family:
        hexahedra.ELEMENTS[2] = (family, f"Q2 Lagrange (27 nodes), family {family}")
    try:
        out = folder / ("out_" + "_".join([deck.stem, family or "", *overrides]).replace("=", "_"))
        t = time.perf_counter()
        run_scene(load_scene(scene, overrides), out, MPI.COMM_WORLD, write_fields=False, report=False,
                  log=lambda *a: None)
        elapsed = time.perf_counter() - t
    finally:
        hexahedra.ELEMENTS.update(saved)
    res = json.loads((out / "results.json").read_text())
    return np.array([m["freq_hz"] for m in res["real_modes"]]), int(res["model"]["dofs"]), elapsed


def main(quick: bool, workdir: Path) -> dict:
    grid = (3, 48, 2) if quick else GRID
    workdir.mkdir(parents=True, exist_ok=True)
    ccx, rows = {}, []
    for deck, (element, opts) in DECKS.items():
        opts = dict(opts)
        g = (*grid[:2], opts.pop("n_z", grid[2]))
        write_plate(workdir / f"plate_{deck}.inp", element, g, **opts)
        f, t = run_ccx(workdir, f"plate_{deck}")
        nodes = sum(1 for line in _node_lines(workdir / f"plate_{deck}.inp"))
        ccx[deck] = f[:N_MODES]
        rows.append({"variant": f"CalculiX {element}", "deck": deck, "reference": deck, "dofs": 3 * nodes,
                     "seconds": t, "max_rel": 0.0, "f_hz": f[:N_MODES].tolist()})
    for label, deck, ref, overrides, family in VARIANTS:
        f, dofs, t = run_fem_squeal(workdir, workdir / f"plate_{deck}.inp", overrides, family)
        err = float(np.max(np.abs(f[:N_MODES] / ccx[ref] - 1)))
        rows.append({"variant": label, "deck": deck, "reference": ref, "dofs": dofs, "seconds": t, "max_rel": err,
                     "f_hz": f[:N_MODES].tolist()})
    lines = [f"Annular plate b = {B} m, a = {A} m, h = {H * 1e3:g} mm, {grid[0]} x {grid[1]} x {grid[2]} "
             f"elements, clamped at r = b; ten lowest frequencies against CalculiX 2.20 on the same deck "
             f"(deck C3D8R_thick_distorted: h = 10 mm, {grid[0]} x {grid[1]} x 3 elements, nodes moved)",
             "", "| element / path | deck | DOFs | seconds | max abs(f - f_ccx)/f_ccx | against |",
             "|---|---|---:|---:|---:|---|"]
    for r in rows:
        err = "(reference)" if r["variant"].startswith("CalculiX") else f"{r['max_rel']:.2e}"
        lines.append(f"| {r['variant']} | {r['deck']} | {r['dofs']} | {r['seconds']:.1f} | {err} | "
                     f"ccx {r['reference']} |")
    lines += [""] + [f"- {r['variant']}: f = " + ", ".join(f"{v:.2f}" for v in r["f_hz"]) + " Hz" for r in rows]
    text = "\n".join(lines)
    print(text)
    from casework import out_path
    out_path("hex_native", 1, quick, "md").write_text(text + "\n")
    out_path("hex_native", 1, quick, "json").write_text(json.dumps(rows, indent=1))
    return {"rows": rows}


def _node_lines(path: Path):
    inside = False
    for line in path.read_text().splitlines():
        if line.startswith("*"):
            inside = line.upper().replace(" ", "").startswith("*NODE")
        elif inside and line.strip():
            yield line


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="3 x 48 x 2 elements")
    ap.add_argument("--workdir", type=Path, help="keep the decks and ccx files here (default: a temporary folder)")
    a = ap.parse_args()
    if a.workdir:
        main(a.quick, a.workdir)
    else:
        with tempfile.TemporaryDirectory() as d:
            main(a.quick, Path(d))
