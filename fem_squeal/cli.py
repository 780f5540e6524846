"""Command line of fem_squeal.

    fem-squeal plan SCENE.toml [--set key=value ...]      stages that would run, and the cached ones
    fem-squeal run SCENE.toml [--set ...] [-o OUTDIR] [--force STAGE] [--petsc-option k=v] [--no-fields]
    fem-squeal clean                                       remove the cache
    fem-squeal convert IN OUT [--scale S]                  convert a mesh (.msh .inp .bdf .vtu), keeping its sets
    fem-squeal mesh SCENE.toml OUT [--set ...] [--scale S] write a scene's mesh (e.g. the gmsh brake as .inp)

The cache is ``--cache-dir`` (default ``$FEM_SQUEAL_CACHE`` or ``.fem_squeal_cache``).  Exit
codes: 0 done, 2 invalid scene or command line, 3 a stage failed (the message names it).
"""
from __future__ import annotations

import argparse
import logging
import sys
from pathlib import Path
from typing import NamedTuple


class DemoArguments(NamedTuple):
    root: Path                  # the repository (demos/..)
    outdir: Path
    overrides: list[str]        # --set=key=value, as for ``fem-squeal run --set``


def demo_arguments(script: str, argv: list[str] | None = None) -> DemoArguments:
    """The command line shared by the demos: ``demos/X.py [OUTDIR] [--set=key=value ...]``,
    OUTDIR defaulting to ``out/X`` in the repository; other ``--flags`` are left to the demo."""
    argv = sys.argv[1:] if argv is None else argv
    root = Path(script).resolve().parents[1]
    positional = [a for a in argv if not a.startswith("--")]
    outdir = Path(positional[0]) if positional else root / "out" / Path(script).stem
    return DemoArguments(root, outdir, [a.split("=", 1)[1] for a in argv if a.startswith("--set=")])


def _scene_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("scene", type=Path)
    p.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE",
                   help="override a scene value, e.g. --set geometry.width=0.005")
    p.add_argument("--petsc-option", action="append", default=[], metavar="KEY=VALUE",
                   help="PETSc option with its prefix, e.g. cea_st_pc_factor_mat_solver_type=superlu_dist")
    p.add_argument("--no-fields", action="store_true",
                   help="skip the XDMF field files (results.json and PNG only)")


def _parser() -> argparse.ArgumentParser:
    from fem_squeal.pipeline import default_cache_dir

    p = argparse.ArgumentParser(prog="fem-squeal", description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--cache-dir", type=Path, default=default_cache_dir(), help="stage cache (default %(default)s)")
    p.add_argument("--log-level", default="info", choices=["debug", "info", "warning", "error"],
                   help="messages on rank 0 (warning: only problems; progress bars go to stderr at info)")
    sub = p.add_subparsers(dest="command", required=True)
    r = sub.add_parser("run", help="run the analyses of a scene")
    _scene_args(r)
    r.add_argument("-o", "--outdir", type=Path, default=None, help="output folder (default out/<scene>)")
    r.add_argument("--force", action="append", default=[], metavar="STAGE",
                   help="recompute STAGE and the stages after it even if cached ('all': everything)")
    r.add_argument("--no-report", action="store_true", help="skip report.html")
    pl = sub.add_parser("plan", help="print the stages a run would compute and the cached ones")
    _scene_args(pl)
    pl.add_argument("--force", action="append", default=[], metavar="STAGE")
    sub.add_parser("clean", help="remove the cache")
    c = sub.add_parser("convert", help="convert a mesh file, keeping its element sets, surfaces and node sets")
    c.add_argument("input", type=Path)
    c.add_argument("output", type=Path)
    c.add_argument("--scale", type=float, default=1.0, help="multiply the coordinates (1000: m -> mm)")
    c.add_argument("--input-format", default="", help="meshio format of the input (default: from the extension)")
    c.add_argument("--id-field", default="", help="integer cell data holding the set numbers (VTU)")
    m = sub.add_parser("mesh", help="write the mesh of a scene's geometry (parts and faces as named sets)")
    _scene_args(m)
    m.add_argument("output", type=Path)
    m.add_argument("--scale", type=float, default=1.0, help="multiply the coordinates (1000: m -> mm)")
    sub.add_parser("bench", add_help=False,
                   help="run the benchmark suite (benchmarks/suite.py: --quick, --only NAME ..., --list, --help)")
    return p


def _bench(bench_args: list[str]) -> int:
    """Run benchmarks/suite.py of the source tree in a plain process (it launches mpirun itself)."""
    import subprocess
    import sys

    suite = Path(__file__).resolve().parents[1] / "benchmarks" / "suite.py"
    if not suite.exists():
        print(f"fem-squeal bench: {suite} not found; the benchmarks live in the source tree "
              "(install with pip install -e)", file=sys.stderr)
        return 2
    return subprocess.call([sys.executable, str(suite), *bench_args])


def _convert(args, comm, say) -> None:
    from geometry.mesh_convert import convert

    if comm.rank != 0:
        return
    mf, warns = convert(args.input, args.output, scale=args.scale, fmt_in=args.input_format,
                        id_field=args.id_field)
    for w in warns:
        say(f"[fem_squeal] warning: {w}")
    say(f"[fem_squeal] {args.output}: {len(mf.points)} nodes, {len(mf.cells)} tetrahedra (P{mf.degree}); element "
        f"sets {sorted(mf.cell_sets)}; surfaces {sorted(mf.surfaces)}; node sets {sorted(mf.node_sets)}")


def _load(args):
    from fem_squeal.scene import SceneError, load_scene

    overrides = list(args.overrides)
    for item in args.petsc_option:
        if "=" not in item:
            raise SceneError(f"--petsc-option {item}: expected key=value")
        k, v = item.split("=", 1)
        overrides.append(f"solver.petsc_options.{k.lstrip('-')}={v}")
    return load_scene(args.scene, overrides)


def main(argv: list[str] | None = None) -> int:
    args, extra = _parser().parse_known_args(argv)
    if args.command == "bench":
        return _bench(extra)
    if extra:
        _parser().error(f"unrecognized arguments: {' '.join(extra)}")
    from mpi4py import MPI

    from fem_squeal.pipeline import Cache, PipelineError, format_plan, make_plan
    from fem_squeal.scene import SceneError

    comm = MPI.COMM_WORLD
    rank0 = comm.rank == 0
    logging.basicConfig(level=getattr(logging, args.log_level.upper()), format="%(message)s", stream=sys.stdout)
    log = logging.getLogger("fem_squeal")
    say = (lambda *a, **k: log.info(" ".join(str(x) for x in a))) if rank0 else (lambda *a, **k: None)

    def fail(code: int, msg: str) -> int:
        print(f"fem-squeal: error{'' if comm.size == 1 else f' (rank {comm.rank})'}: {msg}", file=sys.stderr)
        return code

    cache = Cache(args.cache_dir)
    if args.command == "clean":
        n = cache.clean() if rank0 else 0
        say(f"[fem_squeal] removed {n} cache entries from {args.cache_dir}")
        return 0
    from geometry.mesh_file import MeshImportError

    try:
        if args.command == "convert":
            _convert(args, comm, say)
            return 0
        scene = _load(args)
        if args.command == "mesh":
            from geometry import write_geometry

            for w in write_geometry(comm, scene["geometry"], args.output, args.scale):
                say(f"[fem_squeal] warning: {w}")
            say(f"[fem_squeal] wrote {args.output}")
            return 0
        if args.command == "plan":
            plan = make_plan(scene, cache, force=args.force, write_fields=not args.no_fields)
            if rank0:
                print(f"plan for {args.scene} (cache {args.cache_dir}):\n{format_plan(plan)}")
            return 0
    except (SceneError, PipelineError, MeshImportError) as e:
        return fail(2, str(e)) if rank0 else 2
    except OSError as e:
        return fail(2, f"{e.filename}: {e.strerror}") if rank0 else 2

    from fem_squeal.eigen import EigenSolveError
    from fem_squeal.preload import PreloadError
    from fem_squeal.reduced.masa import MasaError
    from fem_squeal.reduced.transient import TransientError
    from fem_squeal.reduction import ReductionError
    from fem_squeal.run import run_scene

    outdir = args.outdir or Path("out") / args.scene.stem
    try:
        run_scene(scene, outdir, comm, write_fields=not args.no_fields, log=say, cache=args.cache_dir,
                  force=args.force, report=not args.no_report)
    except (PipelineError, MeshImportError) as e:
        return fail(2, str(e))
    except (EigenSolveError, PreloadError, ReductionError, MasaError, TransientError, ValueError, KeyError) as e:
        return fail(3, str(e))
    if rank0:
        say(f"[fem_squeal] results in {outdir}/results.json"
            + ("" if args.no_report else f", {outdir}/report.html"))
    return 0


if __name__ == "__main__":
    sys.exit(main())
