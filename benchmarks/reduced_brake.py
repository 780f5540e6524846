"""Reduced against full CEA on the brake corner: work–precision and the 101 × 21 map.

One MPI run builds the brake's operators and preload once, then for each basis (modes up to
factor × 10 kHz, with E samples at ±20 % and static corrections) reports: basis size, build time,
time per parameter point (batched dense solve, eigenvalues only as for a map; with vectors as for
tracking), the speed-up over the full CEA at the same point, and the worst relative error of
the unstable eigenvalues against the full CEA at the nominal point and at sign(v)μ = ±1 with
the disc E at −20 % and +20 %.  The last column is the 101 × 21 (sign(v)μ, E) map time.

    mpirun -n 2 .venv/bin/python benchmarks/reduced_brake.py [--quick]

Writes benchmarks/out/reduced_brake_<ranks>ranks[_quick].md and .json.
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import casework  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true", help="coarse mesh (0.016), two bases")
    args = ap.parse_args()
    from mpi4py import MPI

    from fem_squeal.app.analyses.mesh import build_mesh
    from fem_squeal.app.analyses.reduced import full_cea
    from fem_squeal.app.scene import load_scene, model_spec
    from fem_squeal.fe.assembly import assemble_operators, linearise
    from fem_squeal.fe.preload import solve_preload
    from fem_squeal.fe.projection import ParametricOperators, build_basis, common_mu, reduce, relative_change
    from fem_squeal.reduced.eigensolve import unstable
    from fem_squeal.reduced.model import MU
    from fem_squeal.reduced.stability_map import equal_bands, stability_map
    from fem_squeal.reduced.sweep import Grid, evaluate, signed_mu_axis, solve_points
    from fem_squeal.util.blas import limit_threads_for

    comm = MPI.COMM_WORLD
    limit_threads_for(comm)
    scene = load_scene(ROOT / "scenes" / "brake_corner_cea.toml",
                       ["geometry.mesh_size=0.016"] if args.quick else [])
    spec = model_spec(scene)
    md = build_mesh(comm, scene)
    ops = assemble_operators(md, spec, parts=True)
    pre = solve_preload(ops)
    ops = linearise(ops, pre.active)
    ndofs = ops.K.getSize()[0]
    mu0 = common_mu(spec)
    par = ParametricOperators(ops, spec, mu0, ["disc"])
    E0 = par.E0["disc"]
    band = (0.0, 10000.0)
    points = [{MU: mu0}, {MU: -1.0, "E.disc": 0.8 * E0}, {MU: 1.0, "E.disc": 1.2 * E0},
              {MU: 1.0, "E.disc": 0.8 * E0}]
    samples = [{"E.disc": 0.8 * E0}, {"E.disc": 1.2 * E0}]
    full = []
    for p in points:  # full CEA once per point; the errors below compare every basis with it
        lam, sec = full_cea(par, p, band, 60, {})
        full.append({"unstable_full": lam[unstable(lam)], "n_unstable_full": int(unstable(lam).sum()),
                     "full_cea_s": sec})
    rows = []
    for factor in ((1.1, 1.25) if args.quick else (1.1, 1.25, 1.6, 2.0)):
        t = time.perf_counter()
        basis = build_basis(ops, par, factor * band[1], samples=samples)
        model = reduce(ops, par, basis, pre)
        t_build = comm.allreduce(time.perf_counter() - t, op=MPI.MAX)
        errs = []
        for p, f in zip(points, full):
            lam = solve_points(model, {k: np.array([v]) for k, v in p.items()})[0]
            unst = np.array(f["unstable_full"])
            errs.append(relative_change(unst, lam) if unst.size else 0.0)
        pts = {MU: np.full(64, mu0)}
        t = time.perf_counter()
        solve_points(model, pts)
        t_vals = (time.perf_counter() - t) / 64
        t = time.perf_counter()
        solve_points(model, {MU: pts[MU][:16]}, vectors=True)
        t_vecs = (time.perf_counter() - t) / 16
        grid = Grid({"E.disc": np.linspace(0.8 * E0, 1.2 * E0, 21), MU: signed_mu_axis(1.0, 101)})
        res = evaluate(model, grid, comm)
        smap = stability_map(res, equal_bands(band, 6))
        t_full = float(np.mean([f["full_cea_s"] for f in full]))
        rows.append({"dofs": ndofs, "factor": factor, "size": model.size, **basis.counts, "build_s": t_build,
                     "point_s": t_vals, "point_vectors_s": t_vecs, "full_cea_s": t_full,
                     "speedup": t_full / t_vals, "max_rel_error": max(errs), "errors": errs,
                     "map_s": res.seconds, "map_max_unstable": int(smap.total.max())})
    if comm.rank == 0:
        lines = [f"Brake corner, {ndofs} DOFs, {comm.size} rank(s); full CEA per point "
                 f"{rows[0]['full_cea_s']:.1f} s (unstable modes at the 4 points: "
                 f"{[f['n_unstable_full'] for f in full]})", "",
                 "| cut | basis | modes | sampled | static | build [s] | point [ms] | +vectors [ms] | "
                 "speed-up | max rel. error (unstable) | 101×21 map [s] |",
                 "|---|---|---|---|---|---|---|---|---|---|---|"]
        for r in rows:
            lines.append(f"| {r['factor']:g}×10 kHz | {r['size']} | {r['modes']} | {r['sampled_modes']} | "
                         f"{r['static']} | {r['build_s']:.1f} | {1e3 * r['point_s']:.2f} | "
                         f"{1e3 * r['point_vectors_s']:.2f} | {r['speedup']:.0f}× | {r['max_rel_error']:.1e} | "
                         f"{r['map_s']:.1f} |")
        casework.save("reduced_brake", lines, rows, comm.size, args.quick)


if __name__ == "__main__":
    main()
