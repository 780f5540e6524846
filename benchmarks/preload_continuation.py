"""The pressure continuation of the preload (issue 39): the static contact state at 10 brake pressures
against one single-pressure preload, in one run on the brake corner (scenes/brake_corner_cea.toml).

Rows: the scene's linear penalty (the contact set does not change with the pressure on this brake: every
continued state is the previous one scaled, accepted without a Newton step) and, with ``--k3``, a cubic
penalty σ = k_n g + k₃ g³ (the response is nonlinear in p: every continued pressure takes Newton steps,
solved by updates of the kept factorisation).  Per row: the single preload's seconds at the scene's
pressure (solved cold, as a run does), the 10 pressures' seconds by continuation, their ratio (target
≤ 3), the Newton iterations, factorisations and update columns per pressure, and the relative difference
of the continued states from cold solves at two pressures (between samples and the largest).

    .venv/bin/python benchmarks/preload_continuation.py [--mesh-size 0.016] [--k3 1e23] [--jacobian symmetric]
    mpirun -n 2 .venv/bin/python benchmarks/preload_continuation.py --mesh-size 0.012

Writes benchmarks/out/preload_continuation_<ranks>ranks.md and .json.
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import casework  # noqa: E402

SCENE = Path(__file__).resolve().parents[1] / "scenes" / "brake_corner_cea.toml"
SCALES = np.linspace(0.25, 2.5, 10).round(6).tolist()       # × loads.pressure


def row(ops, friction: bool, k3: float, check: bool, jacobian: str = "update") -> dict:
    from mpi4py import MPI

    from fem_squeal.fe.preload import solve_preload
    from fem_squeal.fe.preload_continuation import continue_preload

    comm = MPI.COMM_WORLD
    comm.Barrier()
    t = time.perf_counter()
    one = solve_preload(ops, friction=friction, k3=k3, jacobian=jacobian)
    single = comm.allreduce(time.perf_counter() - t, op=MPI.MAX)
    comm.Barrier()
    t = time.perf_counter()
    states = continue_preload(ops, SCALES, friction=friction, k3=k3, jacobian=jacobian)
    total = comm.allreduce(time.perf_counter() - t, op=MPI.MAX)
    out = {"k3": k3, "single_s": single, "single_iterations": one.iterations,
           "single_factorisations": one.factorisations, "continuation_s": total, "ratio": total / single,
           "pressures": [{"scale": s.scale, "seconds": s.seconds, "iterations": s.result.iterations,
                          "factorisations": s.result.factorisations, "update_columns": s.result.update_columns,
                          "closed": s.result.history[-1][0],
                          "normal_force": sum(s.result.normal_force.values())} for s in states]}
    one.u.destroy()
    if check:
        diffs = {}
        for s in (states[4], states[-1]):
            cold = solve_preload(ops, friction=friction, k3=k3, scale=s.scale)
            d = cold.u.copy()
            d.axpy(-1.0, s.result.u)
            diffs[s.scale] = d.norm() / cold.u.norm()
            d.destroy()
            cold.u.destroy()
        out["relative_difference_from_cold"] = diffs
    for s in states:
        s.result.u.destroy()
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--mesh-size", type=float, default=0.016)
    ap.add_argument("--k3", type=float, nargs="*", default=[0.0, 1e23], help="penalty cubic terms, one row each")
    ap.add_argument("--no-check", action="store_true", help="skip the cold solves the states are compared with")
    ap.add_argument("--taper", type=float, default=None,
                    help="both pads' taper wear: initial_gap gradient [m/m] along y, so that the contact set "
                         "changes with the pressure")
    ap.add_argument("--jacobian", default="update", choices=("update", "refactorise", "symmetric"),
                    help="the Newton steps' linear solves (fem_squeal.fe.preload.solve_preload)")
    a = ap.parse_args()
    from mpi4py import MPI

    from fem_squeal.app.analyses.mesh import build_mesh
    from fem_squeal.app.scene import load_scene, model_spec
    from fem_squeal.fe.assembly import assemble_operators

    comm = MPI.COMM_WORLD
    taper = [] if a.taper is None else [f"interfaces.{pad}.initial_gap={{gradient = [0.0, {a.taper}, 0.0]}}"
                                        for pad in ("pad_inner", "pad_outer")]
    scene = load_scene(SCENE, [f"geometry.mesh_size={a.mesh_size}", *taper])
    ops = assemble_operators(build_mesh(comm, scene), model_spec(scene), parts=False)
    dofs = ops.K.getSize()[0]
    rows = [{"dofs": dofs, "ranks": comm.size, "jacobian": a.jacobian,
             **row(ops, scene["preload"]["friction"], k3, not a.no_check, a.jacobian)} for k3 in a.k3]
    if comm.rank:
        return
    lines = [f"# Preload pressure continuation, brake corner ({dofs} DOFs, {comm.size} ranks, jacobian "
             f"{a.jacobian}), {len(SCALES)} pressures × {SCALES[0]:g}..{SCALES[-1]:g} loads.pressure", "",
             "| k₃ | single preload [s] (its, LU) | 10 pressures [s] | ratio (≤ 3) | its per pressure | "
             "LU per pressure | closed points | max rel. diff. from cold |", "|---|---|---|---|---|---|---|---|"]
    for r in rows:
        ps = r["pressures"]
        diff = max(r.get("relative_difference_from_cold", {0: float("nan")}).values())
        lines.append(f"| {r['k3']:g} | {r['single_s']:.2f} ({r['single_iterations']}, "
                     f"{r['single_factorisations']}) "
                     f"| {r['continuation_s']:.2f} | {r['ratio']:.2f} | {[p['iterations'] for p in ps]} | "
                     f"{[p['factorisations'] for p in ps]} | {[p['closed'] for p in ps]} | {diff:.1e} |")
    casework.save("preload_continuation", lines, rows, comm.size, False)


if __name__ == "__main__":
    main()
