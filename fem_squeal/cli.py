"""Command line: ``fem-squeal run SCENE.toml [--set key=value ...] [-o OUTDIR] [--petsc-option k=v]``."""
from __future__ import annotations

import argparse
import sys
from pathlib import Path


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="fem-squeal", description=__doc__)
    sub = p.add_subparsers(dest="command", required=True)
    r = sub.add_parser("run", help="run the analyses of a scene")
    r.add_argument("scene", type=Path)
    r.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE",
                   help="override a scene value, e.g. --set geometry.width=0.005")
    r.add_argument("--petsc-option", action="append", default=[], metavar="KEY=VALUE",
                   help="PETSc option with its prefix, e.g. cea_st_pc_factor_mat_solver_type=superlu_dist")
    r.add_argument("-o", "--outdir", type=Path, default=None, help="output folder (default out/<scene>)")
    r.add_argument("--no-fields", action="store_true",
                   help="skip the XDMF field files (results.json and PNG only)")
    args = p.parse_args(argv)

    from mpi4py import MPI

    from fem_squeal.eigen import EigenSolveError
    from fem_squeal.preload import PreloadError
    from fem_squeal.reduction import ReductionError
    from fem_squeal.scene import SceneError, load_scene

    comm = MPI.COMM_WORLD
    try:
        overrides = list(args.overrides)
        for item in args.petsc_option:
            if "=" not in item:
                raise SceneError(f"--petsc-option {item}: expected key=value")
            k, v = item.split("=", 1)
            overrides.append(f"solver.petsc_options.{k.lstrip('-')}={v}")
        scene = load_scene(args.scene, overrides)
    except SceneError as e:
        if comm.rank == 0:
            print(f"fem-squeal: error: {e}", file=sys.stderr)
        return 2
    from fem_squeal.run import run_scene

    outdir = args.outdir or Path("out") / args.scene.stem
    try:
        run_scene(scene, outdir, comm, write_fields=not args.no_fields)
    except (EigenSolveError, PreloadError, ReductionError, ValueError, KeyError) as e:
        print(f"fem-squeal: error (rank {comm.rank}): {e}", file=sys.stderr)
        return 3
    if comm.rank == 0:
        print(f"[fem_squeal] results in {outdir}/results.json")
    return 0


if __name__ == "__main__":
    sys.exit(main())
