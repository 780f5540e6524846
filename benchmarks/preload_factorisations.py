"""The preload's Newton steps: refactorising every step against a kept factorisation with low-rank
(Woodbury) updates or GMRES preconditioned by it (``preload.jacobian``, fem_squeal.fe.kept_factorisation),
in one run on the brake corner (scenes/brake_corner_cea.toml) at the given mesh sizes.

Both are exact Newton (the same closed sets at each iteration); the table gives per mesh: DOFs,
Newton iterations, factorisations, update columns, GMRES iterations, seconds of each, their ratio, and
the relative difference of the static displacements (the issue's bound: 1e-10).

    .venv/bin/python benchmarks/preload_factorisations.py [--sizes 0.012 0.008] [--out DIR]
    mpirun -n 2 .venv/bin/python benchmarks/preload_factorisations.py --sizes 0.008
"""
from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

from mpi4py import MPI

SCENE = Path(__file__).resolve().parents[1] / "scenes" / "brake_corner_cea.toml"


def run(size: float) -> dict:
    from fem_squeal.app.analyses.mesh import build_mesh
    from fem_squeal.app.scene import load_scene, model_spec
    from fem_squeal.fe.assembly import assemble_operators
    from fem_squeal.fe.preload import solve_preload

    comm = MPI.COMM_WORLD
    scene = load_scene(SCENE, [f"geometry.mesh_size={size}"])
    ops = assemble_operators(build_mesh(comm, scene), model_spec(scene), parts=False)
    row = {"mesh_size": size, "dofs": ops.K.getSize()[0], "ranks": comm.size}
    out = {}
    for mode in ("refactorise", "update"):
        comm.Barrier()
        t = time.perf_counter()
        pre = solve_preload(ops, friction=scene["preload"]["friction"], jacobian=mode)
        out[mode] = pre
        row[mode] = {"seconds": comm.allreduce(time.perf_counter() - t, op=MPI.MAX),
                     "iterations": pre.iterations, "factorisations": pre.factorisations,
                     "update_columns": pre.update_columns, "krylov_iterations": pre.krylov_iterations,
                     "closed": [n for n, _ in pre.history]}
    du = out["update"].u.copy()
    du.axpy(-1.0, out["refactorise"].u)
    row["relative_difference"] = du.norm() / out["refactorise"].u.norm()
    row["speedup"] = row["refactorise"]["seconds"] / row["update"]["seconds"]
    return row


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", type=float, nargs="+", default=[0.012, 0.008])
    ap.add_argument("--out", type=Path, default=None)
    a = ap.parse_args()
    rows = [run(s) for s in a.sizes]
    if MPI.COMM_WORLD.rank:
        return
    print(f"{'h':>7} {'DOFs':>8} {'its':>4} {'refactorise s (LU)':>20} {'update s (LU, cols, GMRES its)':>30} "
          f"{'ratio':>6} {'|du|/|u|':>9}")
    for r in rows:
        f, u = r["refactorise"], r["update"]
        print(f"{r['mesh_size']:7.4f} {r['dofs']:8d} {f['iterations']:4d} "
              f"{f['seconds']:12.1f} ({f['factorisations']})".ljust(47)
              + f"{u['seconds']:10.1f} ({u['factorisations']}, {u['update_columns']}, "
                f"{u['krylov_iterations']})".rjust(28)
              + f" {r['speedup']:6.2f} {r['relative_difference']:9.1e}")
        assert f["closed"] == u["closed"], "the closed sets differ between the two paths"
        assert r["relative_difference"] <= 1e-10
    if a.out:
        a.out.mkdir(parents=True, exist_ok=True)
        (a.out / "preload_factorisations.json").write_text(json.dumps(rows, indent=1))


if __name__ == "__main__":
    main()
