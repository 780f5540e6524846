"""Command line of fem_squeal.

    fem-squeal plan SCENE.toml [--set key=value ...]      stages that would run, and the cached ones
    fem-squeal run SCENE.toml [--set ...] [-o OUTDIR] [--force STAGE] [--petsc-option k=v] [--no-fields]
    fem-squeal clean                                       remove the cache
    fem-squeal cache [--verify]                            list the cache's entries; --verify: check every
                                                           file and remove the bad entries only
    fem-squeal convert IN OUT [--scale S]                  convert a mesh (.msh .inp .bdf .vtu), keeping its sets
    fem-squeal convert MODEL.inp SCENE.toml                the scene of an Abaqus/CalculiX squeal deck (materials,
                                                           contacts, boundary conditions, steps; the mesh stays
                                                           the deck), each value commented with its keyword, line
    fem-squeal run MODEL.inp [...]                         run an Abaqus/CalculiX squeal deck as it is (converted
                                                           in memory; --set overrides the scene's keys)
    fem-squeal mesh SCENE.toml OUT [--set ...] [--scale S] write a scene's mesh (e.g. the gmsh brake as .inp)
    fem-squeal export SCENE.toml DIR [--set ...]           write the scene's operators (M, C, K and their
                                                           parametric terms, Matrix Market) and a
                                                           [matrices] scene DIR/scene.toml that reads them

The cache is ``--cache-dir`` (default ``$FEM_SQUEAL_CACHE``, else ``$XDG_CACHE_HOME/fem_squeal``, i.e.
``~/.cache/fem_squeal``); ``--cache-dir`` and ``--log-level`` go before or after the subcommand.  Exit
codes: 0 done, 2 invalid input (scene, command line, mesh file), 3 a stage failed (the message names it),
4 a file could not be written (no space, no permission: the message names the path; nothing half-written
is left and the output folder holds what it held before).

The application is imported inside the commands: importing it starts MPI (mpi4py, through the mesh
builders), and ``fem-squeal bench`` must not, because the ``mpirun`` that its suite launches would
inherit this process's singleton MPI environment.
"""
from __future__ import annotations

import argparse
import logging
import subprocess
import sys
from pathlib import Path
from typing import NamedTuple

from fem_squeal.util.errors import FemSquealError, SceneError


class DemoArguments(NamedTuple):
    root: Path                  # the repository (demos/..)
    outdir: Path
    overrides: list[str]        # --set=key=value, as for ``fem-squeal run --set``


def demo_arguments(script: str, argv: list[str] | None = None) -> DemoArguments:
    """The command line shared by every demo: ``demos/X.py [OUTDIR] [--set key=value | --set=key=value ...]``,
    OUTDIR defaulting to ``out/X`` in the repository; other ``--flags`` are left to the demo."""
    argv = sys.argv[1:] if argv is None else argv
    root = Path(script).resolve().parents[1]
    overrides, positional, i = [], [], 0
    while i < len(argv):
        a = argv[i]
        if a == "--set":
            if i + 1 == len(argv):
                raise SystemExit(f"{Path(script).name}: --set needs key=value")
            overrides.append(argv[i + 1])
            i += 1
        elif a.startswith("--set="):
            overrides.append(a.split("=", 1)[1])
        elif not a.startswith("--"):
            positional.append(a)
        i += 1
    outdir = Path(positional[0]) if positional else root / "out" / Path(script).stem
    return DemoArguments(root, outdir, overrides)


def _scene_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("scene", type=Path)
    p.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE",
                   help="override a scene value, e.g. --set geometry.width=0.005")
    p.add_argument("--petsc-option", action="append", default=[], metavar="KEY=VALUE",
                   help="PETSc option with its prefix, e.g. cea_st_pc_factor_mat_solver_type=superlu_dist")
    p.add_argument("--no-fields", action="store_true",
                   help="do not publish the field files (XDMF, VTU) into the output folder; the cache "
                        "keeps them, so a later run with fields computes nothing")


def _parser() -> argparse.ArgumentParser:
    from fem_squeal.app.pipeline import default_cache_dir  # heavy: MPI (see the module docstring)

    def global_options(parser: argparse.ArgumentParser, defaults: bool) -> None:
        # before the subcommand with their defaults; after it as well (SUPPRESS: set only when given)
        d = (lambda v: v) if defaults else (lambda v: argparse.SUPPRESS)
        parser.add_argument("--cache-dir", type=Path, default=d(default_cache_dir()),
                            help=f"stage cache (default {default_cache_dir()})")
        parser.add_argument("--log-level", default=d("info"), choices=["debug", "info", "warning", "error"],
                            help="messages on rank 0 (warning: only problems; progress bars go to stderr at info)")

    p = argparse.ArgumentParser(prog="fem-squeal", description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    global_options(p, True)
    common = argparse.ArgumentParser(add_help=False)
    global_options(common, False)
    sub = p.add_subparsers(dest="command", required=True)
    r = sub.add_parser("run", help="run the analyses of a scene", parents=[common])
    _scene_args(r)
    r.add_argument("-o", "--outdir", type=Path, default=None, help="output folder (default out/<scene>)")
    r.add_argument("--force", action="append", default=[], metavar="STAGE",
                   help="recompute STAGE and the stages after it even if cached ('all': everything)")
    r.add_argument("--no-report", action="store_true", help="skip report.html")
    pl = sub.add_parser("plan", help="print the stages a run would compute and the cached ones", parents=[common])
    _scene_args(pl)
    pl.add_argument("--force", action="append", default=[], metavar="STAGE")
    sub.add_parser("clean", help="remove the cache", parents=[common])
    k = sub.add_parser("cache", help="list the cache's entries (--verify: check them, remove the bad ones)",
                       parents=[common])
    k.add_argument("--verify", action="store_true",
                   help="check every entry's files against its manifest (size, SHA-256); remove the entries "
                        "that fail and leftovers of killed runs older than an hour")
    c = sub.add_parser("convert", help="convert a mesh file, keeping its element sets, surfaces and node sets",
                       parents=[common])
    c.add_argument("input", type=Path)
    c.add_argument("output", type=Path)
    c.add_argument("--scale", type=float, default=1.0, help="multiply the coordinates (1000: m -> mm)")
    c.add_argument("--input-format", default="", help="meshio format of the input (default: from the extension)")
    c.add_argument("--id-field", default="", help="integer cell data holding the set numbers (VTU)")
    m = sub.add_parser("mesh", help="write the mesh of a scene's geometry (parts and faces as named sets)",
                       parents=[common])
    _scene_args(m)
    m.add_argument("output", type=Path)
    m.add_argument("--scale", type=float, default=1.0, help="multiply the coordinates (1000: m -> mm)")
    e = sub.add_parser("export", help="write the scene's operators as Matrix Market files and a [matrices] scene "
                       "that reads them back", parents=[common])
    _scene_args(e)
    e.add_argument("output", type=Path, help="folder for the matrices and scene.toml")
    sub.add_parser("bench", add_help=False,
                   help="run the benchmark suite (benchmarks/suite.py: --quick, --only NAME ..., --list, --help)")
    return p


def _bench(bench_args: list[str]) -> int:
    """Run benchmarks/suite.py of the source tree in a plain process (it launches mpirun itself)."""
    suite = Path(__file__).resolve().parents[2] / "benchmarks" / "suite.py"
    if not suite.exists():
        print(f"fem-squeal bench: {suite} not found; the benchmarks live in the source tree "
              "(install with pip install -e)", file=sys.stderr)
        return 2
    return subprocess.call([sys.executable, str(suite), *bench_args])


def _convert(args, comm, say) -> None:
    from fem_squeal.app.convert import convert  # heavy: MPI (see the module docstring)

    if comm.rank != 0:
        return
    if args.input.suffix.lower() == ".inp" and args.output.suffix.lower() == ".toml":
        from fem_squeal.app.deck import write_scene  # heavy: MPI (see the module docstring)

        ds = write_scene(args.input, args.output)
        for n in ds.notes:
            say(f"[fem_squeal] note: {n}")
        say(f"[fem_squeal] {args.output}: the scene of {args.input} (parts {sorted(ds.raw['geometry']['parts'])}, "
            f"interfaces {sorted(ds.raw['interfaces'])}, analyses {sorted(ds.raw['analyses'])})")
        return
    mf, warns = convert(args.input, args.output, scale=args.scale, fmt_in=args.input_format,
                        id_field=args.id_field)
    for w in warns:
        say(f"[fem_squeal] warning: {w}")
    say(f"[fem_squeal] {args.output}: {len(mf.points)} nodes, {len(mf.cells)} tetrahedra (P{mf.degree}); element "
        f"sets {sorted(mf.cell_sets)}; surfaces {sorted(mf.surfaces)}; node sets {sorted(mf.node_sets)}")


def _cache_listing(cache, verify: bool) -> None:
    """``fem-squeal cache``: one line per entry (stage, key, size; with ``verify`` its verdict), the bad
    entries removed when verifying."""
    sizes = {p: sum(f.stat().st_size for f in p.rglob("*") if f.is_file()) for p in cache.entries()}
    found = cache.check_all(remove=True) if verify else [(p, None) for p in sizes]
    total = 0
    for p, v in found:
        size = sizes.get(p, 0)
        total += size
        state = "" if v is None else ("ok" if v.state == "ok" else f"BAD, removed: {v.reason}")
        print(f"  {p.name:<40} {size / 1e6:10.3f} MB  {state}")
    n_bad = sum(v is not None and v.state != "ok" for _, v in found)
    print(f"{len(found)} entries, {total / 1e6:.3f} MB in {cache.root}"
          + (f"; {n_bad} bad entries removed" if verify else ""))
    for t in cache.temporaries():
        print(f"  (temporary folder of a run in progress or killed: {t.name})")


def _load(args):
    from fem_squeal.app.scene import load_scene  # heavy: MPI (see the module docstring)

    overrides = list(args.overrides)
    for item in args.petsc_option:
        if "=" not in item:
            raise SceneError(f"--petsc-option {item}: expected key=value")
        k, v = item.split("=", 1)
        overrides.append(f"solver.petsc_options.{k.lstrip('-')}={v}")
    if args.scene.suffix.lower() == ".inp":     # an Abaqus/CalculiX squeal deck, converted in memory
        from fem_squeal.app.deck import deck_scene  # heavy: MPI (see the module docstring)
        from fem_squeal.app.scene import apply_overrides, validate  # heavy: MPI (see the module docstring)

        ds = deck_scene(args.scene)
        for n in ds.notes:
            logging.getLogger("fem_squeal").info(f"[fem_squeal] note: {n}")
        return validate(apply_overrides(ds.raw, overrides))
    return load_scene(args.scene, overrides)


def main(argv: list[str] | None = None) -> int:
    args, extra = _parser().parse_known_args(argv)
    if args.command == "bench":
        return _bench(extra)
    if extra:
        _parser().error(f"unrecognized arguments: {' '.join(extra)}")
    from mpi4py import MPI  # heavy: MPI (see the module docstring)

    from fem_squeal.app.pipeline import Cache, format_plan, make_plan  # heavy: MPI (see the module docstring)

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
    if args.command == "cache":
        if rank0:
            _cache_listing(cache, args.verify)
        return 0
    try:
        if args.command == "convert":
            _convert(args, comm, say)
            return 0
        scene = _load(args)
        if args.command == "mesh":
            from fem_squeal.app.convert import write_geometry  # heavy: MPI (see the module docstring)

            for w in write_geometry(comm, scene.geometry, args.output, args.scale):
                say(f"[fem_squeal] warning: {w}")
            say(f"[fem_squeal] wrote {args.output}")
            return 0
        if args.command == "export":
            from fem_squeal.app.export import export_scene  # heavy: MPI (see the module docstring)

            export_scene(scene, args.output, comm, say, source=str(args.scene))
            return 0
        if args.command == "plan":
            if rank0:
                plan = make_plan(scene, cache, force=args.force)
                print(f"plan for {args.scene} (cache {args.cache_dir}):\n{format_plan(plan)}")
            return 0
    except FemSquealError as e:
        return fail(e.exit_code, str(e)) if rank0 else e.exit_code
    except OSError as e:
        return fail(2, f"{e.filename}: {e.strerror}") if rank0 else 2

    from fem_squeal.app.run import run_scene  # heavy: MPI (see the module docstring)

    outdir = args.outdir or Path("out") / args.scene.stem
    try:
        run_scene(scene, outdir, comm, write_fields=not args.no_fields, log=say, cache=args.cache_dir,
                  force=args.force, report=not args.no_report,
                  provenance={"scene_file": str(args.scene), "overrides": list(args.overrides),
                              "petsc_options": list(args.petsc_option)})
    except FemSquealError as e:
        return fail(e.exit_code, str(e))
    if rank0:
        say(f"[fem_squeal] results in {outdir}/results.json"
            + ("" if args.no_report else f", {outdir}/report.html"))
    return 0


if __name__ == "__main__":
    sys.exit(main())
