"""Orthotropic and anisotropic decks, *ORIENTATION, *CLOAD and *MOTION against CalculiX 2.20 on the same deck
(issue #37, part 1).

The clamped-free annular plate of ``benchmarks/hex_native.py`` (b = 0.05 m <= r <= a = 0.1 m, h = 4 mm, C3D20R,
clamped at r = b) with a lining-like orthotropic material (engineering constants E1 = 150, E2 = 60, E3 = 20 GPa,
ν12 0.3, ν13 0.25, ν23 0.35, G12 30, G13 10, G23 8 GPa, ρ 2000 kg/m³), written as

- ``rect``: ``*ELASTIC, TYPE=ENGINEERING CONSTANTS`` in a tilted ``*ORIENTATION, SYSTEM=RECTANGULAR`` (all three
  local axes off the global ones);
- ``cyl``: the same constants in ``*ORIENTATION, SYSTEM=CYLINDRICAL`` about z (1 radial, 2 tangential, 3 axial:
  the frame varies from one Gauss point to the next);
- ``ortho``: ``TYPE=ORTHO`` (the nine D_ijkl of the same material) in the rectangular orientation;
- ``aniso``: ``TYPE=ANISO``, the 21 D_ijkl of the rectangular case already rotated to the global axes, no
  orientation (every coupling term nonzero: checks the order of the 21 constants);

each run by ``ccx`` and by ``fem-squeal run`` (the deck converted in memory; native S2 hexahedra with 2 × 2 × 2
Gauss points, CalculiX's C3D20R), ten lowest frequencies compared; and ``tet10 cyl`` (:func:`tet_case`): the
annulus as curved C3D10 tetrahedra in the cylindrical frame.  Then

- ``cload``: the ``rect`` plate in a ``*STATIC`` step with ``*CLOAD`` (a node on the outer rim, F = (20, −30,
  −100) N): the displacement of the loaded node and of the rim nodes against ccx's ``*NODE PRINT``;
- ``motion``: the frictional ring deck of ``benchmarks/cea_calculix.py`` with its prescribed rigid rotation
  replaced by ``*MOTION, ROTATION, TYPE=VELOCITY`` of the same sign gives the same scene (hence the same run).

Measured (6 × 96 × 2, 21 312 DOFs; CalculiX prints 7 significant digits, so 5e-7 is its rounding): ten lowest
frequencies within 2.4e-7 of ccx for rect, cyl, ortho and aniso; the C3D10 annulus in the cylindrical frame
(gmsh, 4 mm) within 2.0e-7 with quadrature degree 2 (C3D10's 4 points: ccx too evaluates the frame at its
integration points) and 8.8e-6 with the default degree 6 (the rule, not the frame); the *CLOAD deflection of
the 96 rim corner nodes within 3.5e-7 of max |u|; *MOTION gives the scene of the prescribed rotation for both
signs.  (``--quick``, 3 × 48 × 2 and 6 mm tetrahedra: 2.5e-7, 2.2e-7 / 3.4e-5, 2.1e-7.)

    .venv/bin/python benchmarks/deck_orthotropic.py [--quick] [--workdir DIR]
"""
from __future__ import annotations

import argparse
import json
import re
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from casework import ccx_nodes, out_path  # noqa: E402
from hex_native import N_MODES, A, B, run_ccx  # noqa: E402

H = 0.004
GRID = (6, 96, 2)
QUICK_GRID = (3, 48, 2)
ENG = (150e9, 60e9, 20e9, 0.3, 0.25, 0.35, 30e9, 10e9, 8e9)
RHO = 2000.0
#: a rectangular frame with every local axis off the global ones (a on local 1, b in the local 1-2 plane)
RECT = ((1.0, 0.5, 0.2), (-0.3, 1.0, 0.1))
LOAD = (20.0, -30.0, -100.0)


def _materials():
    from fem_squeal.fe.forms import rotated_voigt
    from fem_squeal.fe.model import ANISO_ORDER, ORTHO_ORDER, Material

    local = Material(None, None, RHO, **dict(zip(("E1", "E2", "E3", "nu12", "nu13", "nu23", "G12", "G13", "G23"),
                                                  ENG)),
                     orientation={"system": "rectangular", "a": RECT[0], "b": RECT[1]})
    C = local.local_stiffness()
    Cg = rotated_voigt(C, local.orientation.frame())
    return [C[i, j] for i, j in ORTHO_ORDER], [Cg[i, j] for i, j in ANISO_ORDER]


def _numbers(vals, per_line=8) -> list[str]:
    return [", ".join(f"{v:.17g}" for v in vals[i:i + per_line]) for i in range(0, len(vals), per_line)]


def write_deck(path: Path, case: str, grid) -> None:
    """The plate deck of ``case`` (module text), for ccx and fem_squeal alike."""
    from geometry.hex_decks import annular_plate_hex20, write_inp

    pts, blocks, inner, outer = annular_plate_hex20(B, A, H, *grid)
    r = np.hypot(pts[:, 0], pts[:, 1])
    clamp = np.flatnonzero(np.abs(r - B) < 1e-9 * A)
    rim = np.flatnonzero((np.abs(r - A) < 1e-9 * A) & (np.abs(pts[:, 2] - H / 2) < 1e-12))
    corner = set(np.asarray(blocks[0][1])[:, :8].ravel().tolist())
    load = min((i for i in rim.tolist() if i in corner), key=lambda i: abs(np.arctan2(pts[i, 1], pts[i, 0]) - 0.3))
    write_inp(path, pts, blocks, elsets={"PLATE": np.arange(len(blocks[0][1]))},
              nsets={"CLAMP": clamp, "RIM": rim, "LOADED": [load]},
              surfaces={"INNER": [(e, "S6") for e in inner]}, types={blocks[0][0]: "C3D20R"})
    ccx_nodes(path)
    ortho, aniso = _materials()
    orient = None
    lines = ["*MATERIAL, NAME=LINING"]
    if case in ("rect", "cyl", "cload"):
        lines += ["*ELASTIC, TYPE=ENGINEERING CONSTANTS", *_numbers(list(ENG))]
        orient = ("CYLINDRICAL", (0, 0, 0), (0, 0, 1)) if case == "cyl" else ("RECTANGULAR", *RECT)
    elif case == "ortho":
        lines += ["*ELASTIC, TYPE=ORTHO", *_numbers(ortho)]
        orient = ("RECTANGULAR", *RECT)
    else:
        lines += ["*ELASTIC, TYPE=ANISO", *_numbers(aniso)]
    lines += ["*DENSITY", f"{RHO}"]
    if orient:
        lines += [f"*ORIENTATION, NAME=OR1, SYSTEM={orient[0]}",
                  ", ".join(f"{v:.17g}" for v in (*orient[1], *orient[2]))]
    lines += ["*SOLID SECTION, ELSET=PLATE, MATERIAL=LINING" + (", ORIENTATION=OR1" if orient else ""),
              "*BOUNDARY", "CLAMP, 1, 3"]
    if case == "cload":
        lines += ["*STEP", "*STATIC", "*CLOAD", *(f"LOADED, {k + 1}, {f!r}" for k, f in enumerate(LOAD)),
                  "*NODE PRINT, NSET=RIM", "U", "*END STEP"]
    lines += ["*STEP" + (", PERTURBATION" if case == "cload" else ""), "*FREQUENCY", f"{N_MODES + 2}", "*END STEP"]
    with open(path, "a") as f:
        f.write("\n".join(lines) + "\n")


def ccx_displacements(dat: Path) -> dict[int, np.ndarray]:
    """Node -> (ux, uy, uz) of ccx's ``*NODE PRINT`` (the first block: the static step)."""
    text = dat.read_text()
    i = text.find("displacements (vx,vy,vz)")
    out = {}
    for row in text[i:].splitlines()[1:]:
        f = row.split()
        if len(f) == 4 and re.fullmatch(r"\d+", f[0]):
            out[int(f[0])] = np.array([float(v) for v in f[1:]])
        elif out and not row.strip():
            break
    return out


def fem_frequencies(folder: Path, deck: Path, overrides: list[str] = ()) -> tuple[np.ndarray, float]:
    """``fem-squeal run deck.inp [--set ...]`` (this process): the ten lowest frequencies and the wall time."""
    from fem_squeal.app.cli import main as cli

    out = folder / f"{deck.stem}_fem{len(overrides)}"
    t = time.perf_counter()
    code = cli(["--cache-dir", str(folder / "cache"), "--log-level", "warning", "run", str(deck), "-o", str(out),
                "--no-fields", "--no-report", *[a for o in overrides for a in ("--set", o)]])
    if code != 0:
        raise RuntimeError(f"fem-squeal run {deck.name}: exit {code}")
    res = json.loads((out / "results.json").read_text())
    return np.array([m["freq_hz"] for m in res["real_modes"]])[:N_MODES], time.perf_counter() - t


def fem_static(deck: Path) -> tuple[dict[int, np.ndarray], int]:
    """The deck's static displacement K u = f (the ``*CLOAD`` as ``loads.point``) at the corner nodes of its
    ``RIM`` (the serendipity element's edge DOFs are moments, not nodal values), through
    the scene ``fem-squeal run`` builds (deck_scene, validate, model_spec, the mesh, the operators)."""
    from mpi4py import MPI

    from fem_squeal.app.analyses.mesh import build_mesh
    from fem_squeal.app.deck import deck_scene
    from fem_squeal.app.scene import model_spec, validate
    from fem_squeal.fe import hexahedra
    from fem_squeal.fe.assembly import assemble_operators
    from fem_squeal.fe.preload import static_displacement
    from geometry.abaqus_model import read_model

    scene = validate(deck_scene(deck).raw)
    ops = assemble_operators(build_mesh(MPI.COMM_WORLD, scene), model_spec(scene))
    u = static_displacement(ops, {}).array_r.reshape(-1, 3)
    x = hexahedra.dof_coordinates(ops.V)[:len(u)]
    m = read_model(deck)
    out = {}
    for n in m.mesh.nsets["RIM"]:
        d = np.linalg.norm(x - m.mesh.points[n], axis=1)
        if d.min() < 1e-12:
            out[int(m.mesh.node_ids[n])] = u[int(np.argmin(d))]
    return out, ops.V.dofmap.index_map.size_global * 3


def motion_check(folder: Path) -> dict:
    """The frictional ring deck of cea_calculix.py (h 3 mm) with its prescribed rotation of the plates
    (second static step) replaced by *MOTION, ROTATION, TYPE=VELOCITY about +z of the same sign: the same
    scene, hence the same run, for either sign."""
    from cea_calculix import ccx_deck, make_mesh

    from fem_squeal.app.deck import deck_scene

    mesh = make_mesh(folder, 0.003)
    out = {}
    for sign in (1, -1):
        rot = folder / "ring_rotation.inp"
        text = ccx_deck(mesh, 0.3, 1e13, 1e12, 10)
        if sign < 0:        # the rotation reversed: every prescribed in-plane value of step 2 negated
            i = text.index("*STEP\n*STATIC\n0.1, 1.0")
            j = text.index("*END STEP", i)
            text = text[:i] + re.sub(r"(\d+, [12], [12], )(-?)", lambda m: m[1] + ("" if m[2] else "-"),
                                     text[i:j]) + text[j:]
        rot.write_text(text)
        i = text.index("*STEP\n*STATIC\n0.1, 1.0")
        j = text.index("*END STEP", i)
        motion = folder / "ring_motion.inp"
        motion.write_text(text[:i] + "*STEP\n*STATIC\n0.1, 1.0\n*MOTION, ROTATION, TYPE=VELOCITY\n"
                          + "".join(f"{n}, {sign * 50.0!r}, 0., 0., 0., 0., 0., 1.\n" for n in ("NPTOP", "NPBOT"))
                          + text[j:])
        a, b = deck_scene(rot).raw, deck_scene(motion).raw
        for raw in (a, b):      # the deck's own name aside
            raw.pop("title")
            raw["geometry"].pop("file")
        out[sign] = {"same_scene": a == b,
                     "sliding": sorted({t.get("sliding") for t in b["interfaces"].values()})}
    return {"same_scene": all(v["same_scene"] for v in out.values()),
            "sliding": {k: v["sliding"] for k, v in out.items()}}


def tet_case(folder: Path, quick: bool) -> list[dict]:
    """The plate's annulus as curved C3D10 tetrahedra (gmsh, geometry.annular_disc; 6 mm, or 4 mm) of the
    lining material in the cylindrical orientation, clamped on its inner cylinder: ccx against fem_squeal's P2
    tetrahedra with the default rule for a varying frame (degree 6) and with degree 2 (4 points, CalculiX's
    C3D10 rule for the stiffness)."""
    from mpi4py import MPI

    from fem_squeal.app.convert import write_mesh_file
    from geometry.annular_disc import annular_disc_model
    from geometry.gmsh_io import write_msh
    from geometry.mesh_file import _facet_nodes, read_mesh_file

    write_msh(MPI.COMM_SELF, annular_disc_model(mean_radius=(A + B) / 2, width=A - B, thickness=H,
                                                mesh_size=0.006 if quick else 0.004, order=2), folder / "tets.msh")
    mf = read_mesh_file(folder / "tets.msh")
    write_mesh_file(mf, folder / "tets.inp")
    ccx_nodes(folder / "tets.inp")
    inner = np.unique(np.concatenate([_facet_nodes(mf.cells[c], f) for c, f in mf.surfaces["inner"]])) + 1
    inner = [", ".join(str(int(k)) for k in inner[i:i + 8]) for i in range(0, len(inner), 8)]
    lines = ["*INCLUDE, INPUT=tets.inp", "*NSET, NSET=INNERN", *inner, "*MATERIAL, NAME=LINING",
             "*ELASTIC, TYPE=ENGINEERING CONSTANTS", *_numbers(list(ENG)), "*DENSITY", f"{RHO}",
             "*ORIENTATION, NAME=CYL, SYSTEM=CYLINDRICAL", "0., 0., 0., 0., 0., 1.",
             "*SOLID SECTION, ELSET=disc, MATERIAL=LINING, ORIENTATION=CYL", "*BOUNDARY", "INNERN, 1, 3",
             "*STEP", "*FREQUENCY", f"{N_MODES + 2}", "*END STEP"]
    (folder / "tets_cyl.inp").write_text("\n".join(lines) + "\n")
    f_ccx, _ = run_ccx(folder, "tets_cyl")
    rows = []
    for label, extra in (("tet10 cyl, default rule (degree 6)", []),
                         ("tet10 cyl, degree 2 (C3D10's 4 points)", ["discretisation.quadrature_degree=2"])):
        f, t = fem_frequencies(folder, folder / "tets_cyl.inp", extra)
        rel = np.abs(f / f_ccx[:N_MODES] - 1)
        rows.append({"case": label, "max_rel": float(rel.max()), "f_ccx": f_ccx[:N_MODES].tolist(),
                     "f": f.tolist(), "seconds": t, "elements": len(mf.cells)})
        print(f"{label}: max |f/f_ccx - 1| = {rel.max():.2e}", flush=True)
    return rows


def main(quick: bool, workdir: Path) -> dict:
    grid = QUICK_GRID if quick else GRID
    workdir.mkdir(parents=True, exist_ok=True)
    rows = []
    for case in ("rect", "cyl", "ortho", "aniso"):
        deck = workdir / f"plate_{case}.inp"
        write_deck(deck, case, grid)
        f_ccx, t_ccx = run_ccx(workdir, deck.stem)
        f, t = fem_frequencies(workdir, deck)
        rel = np.abs(f / f_ccx[:N_MODES] - 1)
        rows.append({"case": case, "max_rel": float(rel.max()), "f_ccx": f_ccx[:N_MODES].tolist(), "f": f.tolist(),
                     "seconds": t, "ccx_seconds": t_ccx})
        print(f"{case}: max |f/f_ccx - 1| = {rel.max():.2e}", flush=True)
    rows += tet_case(workdir, quick)
    deck = workdir / "plate_cload.inp"
    write_deck(deck, "cload", grid)
    run_ccx(workdir, deck.stem)
    u_ccx = ccx_displacements(workdir / f"{deck.stem}.dat")
    u_fem, dofs = fem_static(deck)
    common = sorted(set(u_ccx) & set(u_fem))
    scale = max(np.linalg.norm(u_ccx[n]) for n in common)
    err = max(np.linalg.norm(u_fem[n] - u_ccx[n]) for n in common) / scale
    loaded = [n for n in common if np.linalg.norm(u_ccx[n]) == scale][0]
    cload = {"nodes": len(common), "max_rel": float(err), "u_max_ccx": u_ccx[loaded].tolist(),
             "u_max_fem": u_fem[loaded].tolist(), "dofs": dofs}
    print(f"cload: {len(common)} rim corner nodes, max |u - u_ccx| / max |u_ccx| = {err:.2e}", flush=True)
    motion = motion_check(workdir)
    print(f"motion: same scene as the prescribed rotation: {motion['same_scene']}", flush=True)
    lines = [f"Annular plate b = {B} m, a = {A} m, h = {H * 1e3:g} mm, {grid[0]} x {grid[1]} x {grid[2]} C3D20R, "
             "clamped at r = b, orthotropic lining material; CalculiX 2.20 and fem-squeal run on the same deck",
             "",
             "| deck | max abs(f - f_ccx)/f_ccx, ten lowest | f1 … f3 (ccx) [Hz] |", "|---|---:|---|"]
    for r in rows:
        lines.append(f"| {r['case']} | {r['max_rel']:.2e} | "
                     + ", ".join(f"{v:.2f}" for v in r["f_ccx"][:3]) + " |")
    lines += ["", f"*CLOAD {LOAD} N on a rim node (rect material), static: {cload['nodes']} rim corner nodes, "
              f"max |u − u_ccx| / max |u_ccx| = {cload['max_rel']:.2e}; loaded node u_ccx = "
              + ", ".join(f"{v:.6e}" for v in cload["u_max_ccx"]) + " m, fem_squeal "
              + ", ".join(f"{v:.6e}" for v in cload["u_max_fem"]) + " m",
              "*MOTION, ROTATION, TYPE=VELOCITY in place of the prescribed rotation (cea_calculix ring deck): "
              f"same scene {motion['same_scene']}, sliding {motion['sliding']}"]
    text = "\n".join(lines)
    print(text)
    out_path("deck_orthotropic", 1, quick, "md").write_text(text + "\n")
    out_path("deck_orthotropic", 1, quick, "json").write_text(json.dumps(
        {"frequencies": rows, "cload": cload, "motion": motion}, indent=1))
    return {"rows": rows, "cload": cload, "motion": motion}


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help=f"{QUICK_GRID[0]} x {QUICK_GRID[1]} x {QUICK_GRID[2]} "
                    "elements")
    ap.add_argument("--workdir", type=Path, help="keep the decks and ccx files here (default: a temporary folder)")
    a = ap.parse_args()
    if a.workdir:
        main(a.quick, a.workdir)
    else:
        with tempfile.TemporaryDirectory() as d:
            main(a.quick, Path(d))
