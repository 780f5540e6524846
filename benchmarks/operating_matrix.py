"""The operating matrix of issue 39 on the brake corner: 120 conditions on the reduced model, after set-up.

Runs scenes/brake_operating_matrix.toml as a user does (one process or ``mpirun -n 2``) with the issue's
matrix: 5 pressures (0.5–2 × loads.pressure) × 4 temperatures × 3 speeds × 2 directions = 120 conditions,
with a friction table μ(p, T, Ω) (the scene's table at p = 0.5, 0.03 lower at p = 2).  The preload stage
continues the scene's preload to the other 4 pressures (fe.preload_continuation) and checks that their
contact set is the scene's; the matrix then runs on the one reduced model.  Reports the set-up (preload,
its continuation, reduced basis), the matrix's seconds and seconds per condition against the issue's
≤ 10 min target, and the reduced-vs-full check at the 16 corner conditions (worst relative error of the
unstable eigenvalues, ≤ 1e-3 targeted, and the unstable counts).  ``--speeds 15`` gives the former
variant: the scene's pressure, 4 temperatures × 15 speeds × 2 directions (8 corners).

    mpirun -n 2 .venv/bin/python benchmarks/operating_matrix.py [--mesh-size 0.016] [--set key=value ...]

Default: the scene's coarse mesh (0.016 m); ``--mesh-size 0.008`` is brake_corner_cea.toml's default mesh,
the issue's 163k-DOF model.  Writes benchmarks/out/operating_matrix_<ranks>ranks.md and .json.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import casework  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
SPEEDS = [round(10.0 + 140.0 * k / 14, 6) for k in range(15)]    # |Ω| 10..150 rad/s, 15 values
PRESSURES = [0.5, 0.75, 1.0, 1.5, 2.0]                            # × loads.pressure
#: μ(p, T, Ω): the scene's table at p = 0.5 and 0.03 lower at p = 2 (friction falls with the pressure)
TABLE = ("{law = 'table', pressure = [0.5, 2.0], temperature = [0.0, 200.0, 400.0], speed = [0.0, 150.0], "
         "mu = [[[0.45, 0.42], [0.40, 0.38], [0.30, 0.28]], [[0.42, 0.39], [0.37, 0.35], [0.27, 0.25]]]}")


def table(res: dict, ranks: int) -> tuple[list[str], dict]:
    """The benchmark's table from a results.json ``res``."""
    t, om = res["timings_s"], res["operating_matrix"]
    ver = om.get("verification", [])
    pressures = om.get("pressure", {}).get("continuation", {}).get("pressures", [])
    row = {"dofs": res["model"].get("dofs"), "ranks": ranks, "conditions": om["n_conditions"],
           "preload_s": t.get("preload"), "continuation_s": t.get("preload_continuation"),
           "pressures": sorted({c["pressure"] for c in om["conditions"]}),
           "same_contact_set": [p["same_contact_set"] for p in pressures],
           "changed_points": [p["changed_points"] for p in pressures],
           "reduced_basis_s": t.get("reduced_basis"),
           "reduced_size": res["reduced"]["size"], "matrix_s": om["seconds"],
           "s_per_condition": om["seconds_per_condition"], "unstable_conditions": om["unstable_conditions"],
           "corners": len(ver), "max_rel_error": max((v["max_rel_error"] for v in ver), default=None),
           "unstable_counts_match": (all(v["n_unstable_full"] == v["n_unstable_reduced"] for v in ver)
                                     if ver else None),
           "full_cea_s": [v["full_cea_s"] for v in ver]}
    lines = [f"# Operating matrix, brake corner ({row['dofs']} DOFs, {ranks} ranks)", "",
             "| conditions (pressures) | preload [s] (+ continuation) | basis [s] (size) | matrix [s] | "
             "per condition [ms] | ≤ 10 min | corners: max rel. error | unstable counts equal |",
             "|---|---|---|---|---|---|---|---|",
             f"| {row['conditions']} ({len(row['pressures'])}) | {row['preload_s'] or 0:.1f} "
             f"(+ {row['continuation_s'] or 0:.1f}) | {row['reduced_basis_s'] or 0:.1f} "
             f"({row['reduced_size']}) | {row['matrix_s']:.2f} | {1e3 * row['s_per_condition']:.1f} | "
             f"{'yes' if row['matrix_s'] <= 600 else 'no'} | "
             f"{'—' if row['max_rel_error'] is None else format(row['max_rel_error'], '.1e')} | "
             f"{row['unstable_counts_match']} |"]
    return lines, row


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--mesh-size", type=float, default=0.016, help="geometry.mesh_size [m] (0.008: 163k DOFs)")
    ap.add_argument("--speeds", type=int, default=3, choices=(3, 15),
                    help="3: the issue's 5 p × 4 T × 3 Ω × 2 matrix; 15: the scene's p, 4 T × 15 Ω × 2")
    ap.add_argument("--set", action="append", default=[], help="more scene overrides key=value")
    ap.add_argument("--taper", type=float, default=None,
                    help="both pads' taper wear: initial_gap gradient [m/m] along y (the sliding direction at "
                         "the pads' centre), so that the contact set changes with the pressure; written as "
                         "operating_matrix_taper_<ranks>ranks")
    args = ap.parse_args()
    from mpi4py import MPI

    from fem_squeal.app.run import run_scene
    from fem_squeal.app.scene import load_scene

    comm = MPI.COMM_WORLD
    matrix = ([f"analyses.operating_matrix.speed={SPEEDS}"] if args.speeds == 15 else
              [f"analyses.operating_matrix.pressure={PRESSURES}",
               f"analyses.operating_matrix.friction.default={TABLE}"])
    taper = [] if args.taper is None else [f"interfaces.{pad}.initial_gap={{gradient = [0.0, {args.taper}, 0.0]}}"
                                           for pad in ("pad_inner", "pad_outer")]
    sets = [f"geometry.mesh_size={args.mesh_size}", *matrix, *taper, *args.set]
    scene = load_scene(ROOT / "scenes" / "brake_operating_matrix.toml", sets)
    run = "operating_matrix_run" if args.taper is None else "operating_matrix_taper_run"
    out = casework.out_path(run, comm.size, False, "d").with_name(run)
    res = run_scene(scene, out, comm, write_fields=False, report=False)
    if comm.rank == 0:
        lines, row = table(res, comm.size)
        casework.save("operating_matrix" if args.taper is None else "operating_matrix_taper", lines, [row],
                      comm.size, False)


if __name__ == "__main__":
    main()
