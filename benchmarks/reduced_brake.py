"""Reduced against full CEA on the brake corner: work–precision and the 101 × 21 map.

One MPI run builds the brake's operators and preload once, then for each basis (modes up to
factor × 10 kHz, with E samples at ±20 % and static corrections) reports: basis size, build time,
time per parameter point (batched dense solve, eigenvalues only as for a map; with vectors as for
tracking), the speed-up over the full CEA at the same point, and the worst relative error of
the unstable eigenvalues against the full CEA at the nominal point and at sign(v)μ = ±1 with
the disc E at −20 % and +20 %.  The last column is the 101 × 21 (sign(v)μ, E) map time.

    mpirun -n 2 .venv/bin/python benchmarks/reduced_brake.py [--quick]

Writes benchmarks/out/reduced_brake_<ranks>ranks[_quick].md and .json.

``--stage`` (issue 23): the scene scenes/brake_mu_E_map.toml as a user runs it (coarse mesh
0.016, 50k DOFs; ``--set`` more), in one process, and the table of what the parametric stages cost
against the analysis they serve: reduced basis ÷ one full CEA (the verification's CEA at the
nominal point, same model, same run), the basis rounds by part, the sweep's seconds per value ÷
the map's seconds per point, and the accuracy: reduced vs full CEA at the design corners (worst
relative error of the unstable eigenvalues, unstable counts), the map's counts at its corners and,
with ``--compare results.json`` of another run, the critical values of the sweep against it.

    .venv/bin/python benchmarks/reduced_brake.py --stage [--compare old/results.json]

Writes benchmarks/out/reduced_stage_<ranks>ranks.md and .json (and the run in benchmarks/out/reduced_stage_run).
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


PARTS = ("factor_seconds", "modes_seconds", "directions_seconds", "basis_seconds", "project_seconds",
         "checks_seconds")


def stage_table(res: dict, old: dict | None = None) -> tuple[list[str], dict]:
    """The --stage table from a results.json ``res`` (and ``old``, another run's, for the critical values)."""
    t, red, sw, mp = res["timings_s"], res["reduced"], res["sweep"], res["map"]
    ver = red["verification"]
    cea = ver[0]["full_cea_s"]                     # the full CEA at the nominal point, this run
    row = {"dofs": res["model"].get("dofs"),
           "cea_stage_s": t.get("cea"), "full_cea_s": cea, "reduced_basis_s": t["reduced_basis"],
           "basis_over_cea": t["reduced_basis"] / cea, "verify_s": t.get("reduced_verify"),
           "size": red["size"], "rounds": red["rounds"], "estimated_error": red["estimated_error"],
           "max_rel_error": max(v["max_rel_error"] for v in ver),
           "errors": [v["max_rel_error"] for v in ver],
           "unstable_full_reduced": [(v["n_unstable_full"], v["n_unstable_reduced"]) for v in ver],
           "sweep_s": sw["seconds"], "sweep_s_per_value": sw["seconds"] / len(sw["values"]),
           "sweep_solves": sw["solves"], "map_s_per_point": mp["seconds_per_point"],
           "sweep_over_map": sw["seconds"] / len(sw["values"]) / mp["seconds_per_point"],
           "map_corner_totals": [mp["total"][i][j] for i in (0, -1) for j in (0, -1)],
           "critical": [c["value"] for c in sw["critical"]]}
    lines = [f"Brake, scenes/brake_mu_E_map.toml, {res['model'].get('dofs', '?')} DOFs, "
             f"{res['run'].get('ranks', 1)} rank(s); one run",
             "", "| full CEA [s] | reduced basis [s] | basis ÷ CEA | size | est. error | max rel. error at the "
             "corners (unstable) | unstable full/reduced | sweep [s/value] | map [s/point] | sweep ÷ map |",
             "|---|---|---|---|---|---|---|---|---|---|",
             f"| {cea:.1f} | {row['reduced_basis_s']:.1f} | {row['basis_over_cea']:.1f} | {row['size']} | "
             f"{row['estimated_error']:.1e} | {row['max_rel_error']:.1e} | {row['unstable_full_reduced']} | "
             f"{row['sweep_s_per_value']:.3f} | {row['map_s_per_point']:.3f} | {row['sweep_over_map']:.1f} |",
             "", "| round: cut [Hz] | size | change | seconds | " + " | ".join(
                 k.removesuffix("_seconds") for k in PARTS) + " |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    for r in red["rounds"]:
        lines.append(f"| {r['cut_hz']:.0f} | {r['size']} | {float(r['change']):.1e} | {r['seconds']:.1f} | "
                     + " | ".join(f"{r[k]:.1f}" if k in r else "–" for k in PARTS) + " |")
    lines += ["", f"map totals at its corners (E lo/hi × μ −/+): {row['map_corner_totals']}; sweep: "
              f"{len(row['critical'])} critical values, {row['sweep_solves']} tracking solves"]
    if old is not None:
        oc = np.array([c["value"] for c in old["sweep"]["critical"]])
        nc = np.array(row["critical"])
        if oc.size == nc.size:
            row["critical_max_diff"] = float(np.max(np.abs(np.sort(oc) - np.sort(nc)))) if oc.size else 0.0
        om = old["map"]["total"]
        row["old_map_corner_totals"] = [om[i][j] for i in (0, -1) for j in (0, -1)]
        row["old_unstable_full_reduced"] = [(v["n_unstable_full"], v["n_unstable_reduced"])
                                            for v in old["reduced"]["verification"]]
        lines += [f"against {old['reduced']['size']}-vector run: critical values {oc.size} → {nc.size}, max |Δ| "
                  f"{row.get('critical_max_diff', float('nan')):.1e} (range 2, estimated error "
                  f"{row['estimated_error']:.1e}); map corners {row['old_map_corner_totals']} → "
                  f"{row['map_corner_totals']}; map totals identical at "
                  f"{float(np.mean(np.array(om) == np.array(res['map']['total']))):.1%} of the points"]
    return lines, row


def stage(args) -> None:
    import json

    from mpi4py import MPI

    from fem_squeal.app.run import run_scene
    from fem_squeal.app.scene import load_scene

    comm = MPI.COMM_WORLD
    scene = load_scene(ROOT / "scenes" / "brake_mu_E_map.toml", ["geometry.mesh_size=0.016", *args.set])
    out = casework.out_path("reduced_stage_run", comm.size, False, "d")
    out = out.with_name("reduced_stage_run")
    res = run_scene(scene, out, comm, write_fields=False, report=False)
    if comm.rank == 0:
        old = json.loads(Path(args.compare).read_text()) if args.compare else None
        lines, row = stage_table(res, old)
        casework.save("reduced_stage", lines, [row], comm.size, False)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true", help="coarse mesh (0.016), two bases")
    ap.add_argument("--stage", action="store_true", help="the brake_mu_E_map scene's stages (issue 23)")
    ap.add_argument("--set", action="append", default=[], help="scene override for --stage")
    ap.add_argument("--compare", default=None, help="results.json of another --stage run")
    args = ap.parse_args()
    if args.stage:
        return stage(args)
    from mpi4py import MPI

    from fem_squeal.app.analyses.reduced import full_cea
    from fem_squeal.fe.projection import ParametricOperators, build_basis, common_mu, reduce, relative_change
    from fem_squeal.reduced.eigensolve import unstable
    from fem_squeal.reduced.model import MU
    from fem_squeal.reduced.stability_map import equal_bands, stability_map
    from fem_squeal.reduced.sweep import Grid, evaluate, signed_mu_axis, solve_points
    from fem_squeal.util.blas import limit_threads_for

    comm = MPI.COMM_WORLD
    limit_threads_for(comm)
    scene, spec, ops, pre = casework.linearised_brake(comm, args.quick)
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
