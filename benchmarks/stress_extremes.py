"""Stress tests at the extremes, on the ring of seed 003 against its analytic growth rates.

The corrected ring theory (:mod:`fem_squeal.theory.ring_theory`, verified to 0.5 % at μ = 0.3) gives
Re λ of the in-plane flutter pairs k = 2..6 for any μ, ν and thickness h, so each extreme has an
independent reference.  Each case runs the CEA (24 modes nearest 2.5 kHz) in a fresh process:

* **μ up to 2**: the coupling g = μνα_k grows 7×; eq. 10 is exact in g for one pair, the rest
  (coupling to other modes) is O(g²).
* **ν up to 0.499** (the ring is the lining-like polymer pressed between plates): P1 and P2 against
  the theory and against P2 on a finer mesh; volumetric locking shows as P1 errors that grow as
  ν → ½.  The run warns (``fem_squeal.fe.assembly``) for P1 with ν ≥ 0.45 and P2 with ν ≥ 0.499.
* **thin and thick parts**: h from 0.5 mm (h/b = 0.1, one element through the thickness) to
  16 mm (h/b = 3.2), at the default 2 mm mesh size, with the mesh quality of each.
* **distorted meshes**: interior nodes moved at random by a share of the mean edge length (boundary
  kept, mid-edge nodes of interior edges re-centred); read back through ``geometry.builder =
  "mesh_file"``, which checks quality (warning above aspect ratio 10, error on inverted elements).
* **determinism**: the same CEA twice in one process and in two processes (bitwise), and on 1
  against 2 ranks (relative difference).

    .venv/bin/python benchmarks/stress_extremes.py [--quick]
"""
from __future__ import annotations

import argparse
import json
import sys
import tempfile
import warnings
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import casework  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
SCENE = ROOT / "scenes" / "ryzhik_ring.toml"
KS = range(2, 7)


def ring_cea(overrides: list[str], scene_path: Path = SCENE, comm=None) -> dict:
    """CEA of the ring scene with ``overrides``: the unstable in-plane pairs, residuals, warnings,
    mesh quality, and the theory's growth rate at each FE frequency."""
    import time

    from mpi4py import MPI

    from fem_squeal.app.analyses.mesh import build_mesh
    from fem_squeal.app.scene import load_scene, model_spec
    from fem_squeal.fe.assembly import assemble_operators
    from fem_squeal.fe.descriptors import CircumferentialBasis
    from fem_squeal.fe.eigen import solve_complex_modes
    from fem_squeal.theory import ring_theory as rt
    from geometry.quality import tet_quality

    comm = comm or MPI.COMM_WORLD
    scene = load_scene(scene_path, overrides)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        md = build_mesh(comm, scene)
        spec = model_spec(scene)
        t0 = time.perf_counter()
        ops = assemble_operators(md, spec)
        cm = solve_complex_modes(ops.K_total(), ops.M, None, 24, 2500.0, band_hz=(100.0, 5000.0),
                                 max_residual=1.0)
        t1 = time.perf_counter()
    basis = CircumferentialBasis(ops.V, ops.M, ops.M_axial)
    pairs = {}
    for lam, xr, xi in zip(cm.eigenvalues, cm.vectors_re, cm.vectors_im):
        d = basis.describe(xr, xi)
        if lam.real > 0 and d.in_plane_share > 0.99 and d.nodal_diameter in KS:
            pairs[d.nodal_diameter] = lam
    g, mat, plate = scene["geometry"], scene["materials"]["disc"], scene["interfaces"]["top_plate"]
    if g["builder"] == "annular_disc":
        s = rt.RingSection(g["mean_radius"], g["width"], g["thickness"], mat["E"], mat["nu"], mat["rho"])
    else:
        s = rt.RingSection(0.05, 0.005, 0.004, mat["E"], mat["nu"], mat["rho"])
    theory = {k: rt.corrected_growth_rate(k, s, plate["kn"], plate["mu"], omega=lam.imag)
              for k, lam in pairs.items()}
    x = md.mesh.geometry.x
    dm = md.mesh.geometry.dofmap
    n_local = md.mesh.topology.index_map(3).size_local
    cells = np.array([dm.links(c) for c in range(n_local)])
    q = tet_quality(x, cells if cells.shape[1] == 4 else _vtk_order(cells))
    worst = comm.allreduce(float(np.max(q.aspect_ratio)), op=MPI.MAX)
    min_jac = comm.allreduce(float(np.min(q.jacobian_ratio)), op=MPI.MIN)
    return {"dofs": ops.V.dofmap.index_map.size_global * 3, "ranks": comm.size,
            "pairs": {k: [v.real, v.imag] for k, v in pairs.items()}, "theory": theory,
            "eigenvalues": [[v.real, v.imag] for v in cm.eigenvalues],
            "max_residual": float(np.max(cm.residuals)), "seconds": t1 - t0,
            "warnings": sorted({str(w.message)[:160] for w in caught
                                if issubclass(w.category, (UserWarning, RuntimeWarning))}),
            "worst_aspect_ratio": worst, "min_jacobian_ratio": min_jac}


def _vtk_order(cells: np.ndarray) -> np.ndarray:
    """dolfinx P2 geometry nodes → VTK tetra10 order (edges (0,1),(1,2),(0,2),(0,3),(1,3),(2,3))."""
    from dolfinx import cpp
    from dolfinx.mesh import CellType

    out = np.empty_like(cells)
    out[:, cpp.io.perm_vtk(CellType.tetrahedron, 10)] = cells        # as fem_squeal.output.vtu_mesh
    return out


def distorted_ring(amplitude: float, folder: Path, seed: int = 0) -> Path:
    """Write the default ring mesh with interior nodes moved by ``amplitude`` × the mean edge length
    (uniform in a ball), as a scene reading it; returns the scene path."""
    from mpi4py import MPI

    from fem_squeal.app.convert import write_mesh_file
    from fem_squeal.app.scene import load_scene
    from geometry import MODELS, write_msh
    from geometry.mesh_file import read_mesh_file

    g = dict(load_scene(SCENE)["geometry"])
    g.pop("builder")
    msh = folder / "ring.msh"
    write_msh(MPI.COMM_SELF, MODELS["annular_disc"](**g), msh)
    mf = read_mesh_file(msh)
    c = mf.cells
    faces = np.sort(np.concatenate([c[:, [1, 2, 3]], c[:, [0, 2, 3]], c[:, [0, 1, 3]], c[:, [0, 1, 2]]]), axis=1)
    uniq, count = np.unique(faces, axis=0, return_counts=True)
    bfaces = uniq[count == 1]
    bverts = np.unique(bfaces)
    bedges = {tuple(e) for f in bfaces for e in ((f[0], f[1]), (f[0], f[2]), (f[1], f[2]))}
    edges = [(0, 1), (1, 2), (0, 2), (0, 3), (1, 3), (2, 3)]
    mean_edge = np.mean([np.linalg.norm(mf.points[c[:, a]] - mf.points[c[:, b]], axis=1).mean() for a, b in edges])
    rng = np.random.default_rng(seed)
    verts = np.unique(c[:, :4])
    inner = np.setdiff1d(verts, bverts)
    d = rng.standard_normal((inner.size, 3))
    d *= (amplitude * mean_edge * rng.random(inner.size) ** (1 / 3) / np.linalg.norm(d, axis=1))[:, None]
    pts = mf.points.copy()
    pts[inner] += d
    if c.shape[1] == 10:
        for j, (a, b) in enumerate(edges):
            for i in range(c.shape[0]):
                e = tuple(sorted((c[i, a], c[i, b])))
                if e not in bedges:
                    pts[c[i, 4 + j]] = 0.5 * (pts[c[i, a]] + pts[c[i, b]])
    mf.points = pts
    out = folder / "ring_distorted.vtu"
    write_mesh_file(mf, out)
    scene = folder / "scene.toml"
    scene.write_text(f'extends = "{SCENE}"\n[geometry]\nbuilder = "mesh_file"\nfile = "{out.name}"\n'
                     '[geometry.parts]\ndisc = ["disc"]\n[geometry.faces]\ntop = ["top"]\nbottom = ["bottom"]\n'
                     'inner = ["inner"]\nouter = ["outer"]\n')
    return scene


def run_case(study: str, value: str) -> dict:
    v = float(value) if study != "repeat" else 0.0
    if study == "mu":
        r = ring_cea([f"interfaces.top_plate.mu={v}", f"interfaces.bottom_plate.mu={v}"])
    elif study in ("nu_p1", "nu_p2c", "nu_p2", "nu_ref"):
        deg, size = {"nu_p1": (1, 0.001), "nu_p2c": (2, 0.003), "nu_p2": (2, 0.002), "nu_ref": (2, 0.0012)}[study]
        r = ring_cea([f"materials.disc.nu={v}", f"discretisation.degree={deg}", f"geometry.order={deg}",
                      f"geometry.mesh_size={size}"])
    elif study == "thickness":
        r = ring_cea([f"geometry.thickness={v}"])
    elif study == "distortion":
        from mpi4py import MPI

        from geometry.mesh_file import MeshImportError

        with tempfile.TemporaryDirectory() as tmp:
            tmp = MPI.COMM_WORLD.bcast(tmp, root=0)
            path = distorted_ring(v, Path(tmp)) if MPI.COMM_WORLD.rank == 0 else None
            path = MPI.COMM_WORLD.bcast(path, root=0)
            try:
                r = ring_cea([], Path(path))
            except MeshImportError as e:
                r = {"refused": str(e)[:200]}
    elif study == "repeat":
        a, b = ring_cea([]), ring_cea([])
        r = {**a, "repeat_identical": a["eigenvalues"] == b["eigenvalues"]}
    else:
        raise ValueError(f"study: unknown {study!r}")
    return {"study": study, "value": value, **r}


def _freq_errors(r: dict, ref: dict) -> str:
    both = set(r["pairs"]) & set(ref["pairs"])
    return " ".join(f"{abs(r['pairs'][k][1] / ref['pairs'][k][1] - 1):.1e}" if k in both
                    else "–" for k in map(str, KS))


def _ratio_cells(r: dict) -> str:
    if "refused" in r:
        return "refused"
    p, t = r["pairs"], r["theory"]
    return " ".join(f"{p[k][0] / t[k]:.3f}" if k in p else "–" for k in map(str, KS))


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--case", nargs=2)
    ap.add_argument("--ranks", type=int, default=1)
    ap.add_argument("--quick", action="store_true")
    a = ap.parse_args()
    if a.case:
        casework.report(json.loads(json.dumps(run_case(*a.case), default=float)))
        return
    q = a.quick
    plan = {"mu": [0.3, 2.0] if q else [0.3, 0.6, 1.0, 1.5, 2.0],
            "nu": [0.3, 0.49] if q else [0.3, 0.4, 0.45, 0.49, 0.499],
            "thickness": [0.001, 0.008] if q else [0.0005, 0.001, 0.002, 0.004, 0.008, 0.016],
            "distortion": [0.0, 0.3] if q else [0.0, 0.1, 0.2, 0.3, 0.4]}
    sp = lambda s, v, n=1: casework.spawn(__file__, [s, repr(v)], n)  # noqa: E731
    rows = {"mu": [sp("mu", v) for v in plan["mu"]],
            "nu": [[sp(s, v) for s in ("nu_p1", "nu_p2c", "nu_p2", "nu_ref")] for v in plan["nu"]],
            "thickness": [sp("thickness", v) for v in plan["thickness"]],
            "distortion": [sp("distortion", v) for v in plan["distortion"]],
            "repeat": [sp("repeat", 0), sp("repeat", 0), sp("repeat", 0, 2)]}
    L = ["Ring (seed 003: R 50 mm, b 5 mm, h 4 mm, E 3 GPa, ν 0.4, kn 1e10, μ 0.3), P2 curved 2 mm unless "
         "stated. 'FE/theory' = Re λ of the FE flutter pair over the corrected ring theory at the FE frequency, "
         "for k = 2 3 4 5 6.", "", "### μ up to 2", "",
         "| μ | DOFs | FE/theory k=2..6 | Re λ k=2 [1/s] | largest residual | eigensolve [s] |",
         "|---|---|---|---|---|---|"]
    for r in rows["mu"]:
        re2 = f"{r['pairs']['2'][0]:.1f}" if "2" in r["pairs"] else "–"
        L.append(f"| {r['value']} | {r['dofs']} | {_ratio_cells(r)} | {re2} | {r['max_residual']:.1e} | "
                 f"{r['seconds']:.2f} |")
    L += ["", "### ν up to 0.499: P1 (1 mm) and P2 (3 mm, 2 mm) against P2 at 1.2 mm", "",
          "| ν | P1 DOFs | P1 FE/theory | P1 freq. error k=2..6 | P2 3 mm FE/theory | P2 2 mm DOFs | "
          "P2 2 mm FE/theory | P2 2 mm freq. error | warnings |", "|---|---|---|---|---|---|---|---|---|"]
    for p1, p2c, p2, ref in rows["nu"]:
        w = "; ".join(f"P{d}: {x.split(' tetrahedra')[0]}" for d, r in ((1, p1), (2, p2)) for x in r["warnings"]
                      if "locking" in x or "incompressible" in x) or "none"
        L.append(f"| {p1['value']} | {p1['dofs']} | {_ratio_cells(p1)} | {_freq_errors(p1, ref)} | "
                 f"{_ratio_cells(p2c)} | {p2['dofs']} | {_ratio_cells(p2)} | {_freq_errors(p2, ref)} | {w} |")
    L += ["", "### Thin and thick rings (h/b from 0.1 to 3.2)", "",
          "| h [mm] | DOFs | FE/theory k=2..6 | worst aspect ratio | min Jacobian ratio | largest residual |",
          "|---|---|---|---|---|---|"]
    for r in rows["thickness"]:
        L.append(f"| {1e3 * float(r['value']):g} | {r['dofs']} | {_ratio_cells(r)} | "
                 f"{r['worst_aspect_ratio']:.2f} | "
                 f"{r['min_jacobian_ratio']:.3f} | {r['max_residual']:.1e} |")
    L += ["", "### Distorted meshes (interior nodes moved by a share of the mean edge length)", "",
          "| amplitude | FE/theory k=2..6 | worst aspect ratio | min Jacobian ratio | max Δλ/|λ| vs undistorted | "
          "import diagnostics |", "|---|---|---|---|---|---|"]
    base = rows["distortion"][0]
    for r in rows["distortion"]:
        if "refused" in r:
            L.append(f"| {r['value']} | refused | – | – | – | {r['refused']} |")
            continue
        dl = max((abs(complex(*r["pairs"][k]) - complex(*base["pairs"][k])) / abs(complex(*base["pairs"][k]))
                  for k in r["pairs"] if k in base["pairs"]), default=float("nan"))
        w = "; ".join(x for x in r["warnings"] if "aspect" in x or "Jacobian" in x) or "none"
        L.append(f"| {r['value']} | {_ratio_cells(r)} | {r['worst_aspect_ratio']:.2f} | "
                 f"{r['min_jacobian_ratio']:.3f} | "
                 f"{dl:.1e} | {w[:120]} |")
    r1, r2, r3 = rows["repeat"]
    ev = [np.array([complex(*e) for e in r["eigenvalues"]]) for r in (r1, r2, r3)]
    ranks_diff = float(np.max(np.abs(ev[2] - ev[0]) / np.abs(ev[0])))
    L += ["", "### Determinism", "",
          "| check | result |", "|---|---|",
          f"| same CEA twice in one process | {'bitwise identical' if r1['repeat_identical'] else 'DIFFERENT'} |",
          f"| two processes | {'bitwise identical' if ev[0].tolist() == ev[1].tolist() else 'DIFFERENT'} |",
          f"| 1 against 2 ranks | max relative difference of the {len(ev[0])} eigenvalues {ranks_diff:.1e} |"]
    casework.save("stress_extremes", L, rows, a.ranks, q)


if __name__ == "__main__":
    main()
