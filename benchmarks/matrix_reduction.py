"""The reduced model of a model given as matrices: eigenvalue error against basis size (as in the ZAMM
2016 study of parametric model reduction for brake squeal), for the three bases of
:func:`fem_squeal.reduced.matrix_reduction.reduce_matrix_model`: real modes of the symmetric part alone,
real modes + static corrections of the non-symmetric and parameter terms, and eigenvector snapshots of
the non-symmetric problem at sampled parameter values.

The reference at each check value of the swept parameter is the full sparse CEA of the assembled
matrices (PETSc/SLEPc, :func:`fem_squeal.fe.eigen.solve_complex_modes`, as the sweep's own check); the
error is the worst relative distance of a full eigenvalue in the band to the nearest reduced one, over
the check values.

    .venv/bin/python benchmarks/matrix_reduction.py                       # the 48-DOF stand-in, W
    .venv/bin/fem-squeal export scenes/brake_corner_cea.toml out/brake_matrices --set geometry.mesh_size=0.016
    .venv/bin/python benchmarks/matrix_reduction.py --scene out/brake_matrices/scene.toml --parameter mu \\
        --range 0.1 0.6 --band 500 5000 --modes 20 40 80 --snapshots 10 20

Writes benchmarks/out/matrix_reduction_<scene>.md and .json.
"""
from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

from fem_squeal.app.analyses.matrices import model_of
from fem_squeal.app.scene import load_scene
from fem_squeal.reduced.matrix_reduction import reduce_matrix_model
from fem_squeal.reduced.sweep import solve_points
from fem_squeal.util.matrix_files import read_matrix

ROOT = Path(__file__).resolve().parents[1]


def full_eigenvalues(model, mats, par, value, band, nev):
    """The full sparse CEA at ``par = value`` (PETSc/SLEPc, this process), the eigenvalues in ``band``."""
    from mpi4py import MPI

    from fem_squeal.fe.eigen import solve_complex_modes
    from fem_squeal.fe.matrix_operators import operators

    ops = operators(model, mats, MPI.COMM_SELF, {par: value})
    target = float(np.sqrt(0.5 * (band[0] ** 2 + band[1] ** 2)))
    cm = solve_complex_modes(ops["K"], ops["M"], ops.get("C"), nev, target, band_hz=tuple(band))
    for x in (*cm.vectors_re, *cm.vectors_im, *ops.values()):
        x.destroy()
    return np.asarray(cm.eigenvalues)


def worst_error(red, par, refs) -> float:
    out = 0.0
    for value, full in refs.items():
        lam = solve_points(red, {par: np.array([value])})[0]
        if full.size:
            out = max(out, float(np.max(np.min(np.abs(full[:, None] - lam[None, :]), axis=1) / np.abs(full))))
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--scene", default=str(ROOT / "scenes" / "matrices_brake.toml"))
    ap.add_argument("--parameter", default="W")
    ap.add_argument("--band", type=float, nargs=2, default=[100.0, 1000.0])
    ap.add_argument("--range", type=float, nargs=2, default=None, help="default: the parameter's range")
    ap.add_argument("--checks", type=int, default=4, help="check values over the parameter's range")
    ap.add_argument("--nev", type=int, default=30, help="full CEA: eigenvalues asked for")
    ap.add_argument("--modes", type=int, nargs="+", default=[4, 8, 12, 16, 20])
    ap.add_argument("--snapshots", type=int, nargs="+", default=[6, 10, 14],
                    help="eigenvectors per sampled value (5 values over the range)")
    ap.add_argument("--target", type=float, default=None, help="snapshots: near this frequency [Hz]")
    a = ap.parse_args()
    scene = load_scene(a.scene)
    sec = scene.matrices
    model = model_of(sec)
    t = time.perf_counter()
    mats = {k: read_matrix(f.file, f.format, f.variable, k) for k, f in sec.files.items()}
    read_s = time.perf_counter() - t
    lo, hi = a.range if a.range is not None else sec.parameters[a.parameter]["range"]
    values = np.linspace(lo, hi, a.checks)
    t = time.perf_counter()
    refs = {float(v): full_eigenvalues(model, mats, a.parameter, float(v), a.band, a.nev) for v in values}
    full_s = (time.perf_counter() - t) / len(values)
    target = a.target if a.target is not None else float(np.sqrt(0.5 * (a.band[0] ** 2 + a.band[1] ** 2)))
    rows = []
    for kind, sizes in (("modes", a.modes), ("modes+corrections", a.modes), ("snapshots", a.snapshots)):
        for k in sizes:
            t = time.perf_counter()
            red = reduce_matrix_model(
                model, mats, basis="snapshots" if kind == "snapshots" else "modes", modes=k,
                corrections=kind == "modes+corrections", snapshot_modes=k, target_hz=target,
                snapshot_points=[{a.parameter: float(v)} for v in np.linspace(lo, hi, 5)])
            build = time.perf_counter() - t
            t = time.perf_counter()
            err = worst_error(red, a.parameter, refs)
            per_point = (time.perf_counter() - t) / len(refs)
            rows.append({"basis": kind, "k": k, "size": red.size, "max_rel_error": err, "build_s": build,
                         "solve_s_per_point": per_point})
            print(f"{kind:18s} k = {k:3d}  size {red.size:4d}  error {err:.2e}  build {build:.2f} s", flush=True)
    name = Path(a.scene).stem if Path(a.scene).stem != "scene" else Path(a.scene).parent.name
    n = next(iter(mats.values())).shape[0]
    lines = [f"# Reduced model of {name} (matrices): eigenvalue error vs basis size", "",
             f"{n} DOFs; parameter {a.parameter} over [{lo:g}, {hi:g}], {len(values)} check values; "
             f"full eigenvalues in {a.band[0]:g}-{a.band[1]:g} Hz per check value: "
             f"{[int(r.size) for r in refs.values()]} "
             f"(full sparse CEA, {full_s:.2f} s each; matrices read in {read_s:.2f} s).  k: real modes "
             "(modes bases) or eigenvectors per sampled value (snapshots, 5 values over the range).  "
             "Error: worst relative distance of a full eigenvalue in the band to the nearest reduced one.", "",
             "| basis | k | size | max rel. error | build [s] | reduced solve per point [s] |",
             "|---|---|---|---|---|---|"]
    lines += [f"| {r['basis']} | {r['k']} | {r['size']} | {r['max_rel_error']:.2e} | {r['build_s']:.2f} | "
              f"{r['solve_s_per_point']:.4f} |" for r in rows]
    out = ROOT / "benchmarks" / "out"
    out.mkdir(parents=True, exist_ok=True)
    (out / f"matrix_reduction_{name}.md").write_text("\n".join(lines) + "\n")
    (out / f"matrix_reduction_{name}.json").write_text(json.dumps(
        {"scene": str(a.scene), "dofs": n, "parameter": a.parameter, "band_hz": a.band, "check_values": list(refs),
         "full_counts": [int(r.size) for r in refs.values()], "full_cea_s": full_s, "rows": rows}, indent=1))
    print("\n".join(lines))


if __name__ == "__main__":
    main()
