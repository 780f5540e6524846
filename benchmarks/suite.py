"""The benchmark suite: one entry point for every time-against-error table and stress sweep.

    fem-squeal bench [--quick] [--only NAME ...] [--list]      (or: make bench / make bench-quick)

Each benchmark is a script in this folder that runs its cases in fresh processes and writes
``benchmarks/out/<name>_<ranks>ranks[_quick].md`` (Markdown table), ``.json`` (raw rows) and, where
it has one, ``.png``.  This runner calls the scripts in turn (each with its own MPI launches),
then writes ``benchmarks/out/SUMMARY.md`` (``SUMMARY_quick.md`` for ``--quick``): the machine, the
command, the wall time of each benchmark and its tables.  A failing benchmark is reported and the
others still run; the exit status is 1 if any failed.  ``FEM_SQUEAL_BENCH_OUT`` redirects the
output folder (the CI smoke test uses it).

Benchmarks whose input is a demo's reduced model (``masa_brake``, ``transient_brake``) first run the
demo (the pipeline's cache makes a second run cheap); they have no quick version.
"""
from __future__ import annotations

import argparse
import os
import platform
import shutil
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
MPI_ENV = {"OMPI_ALLOW_RUN_AS_ROOT": "1", "OMPI_ALLOW_RUN_AS_ROOT_CONFIRM": "1"}


def out_dir() -> Path:
    return Path(os.environ.get("FEM_SQUEAL_BENCH_OUT", HERE / "out"))


@dataclass(frozen=True)
class Bench:
    """A benchmark: the argument lists of its full and quick runs (each: one invocation of
    ``script``; ``mpirun:N`` as the first item runs it under ``mpirun -n N``), what it needs."""

    name: str
    what: str
    script: str
    full: tuple[tuple[str, ...], ...]
    quick: tuple[tuple[str, ...], ...] = ()
    prepare: tuple[str, ...] = ()          # a demo to run first (under mpirun -n 2)
    needs: tuple[str, ...] = ()            # executables (or "py:module") that must be present
    tags: tuple[str, ...] = field(default=())


SUITE: tuple[Bench, ...] = (
    Bench("modal_peers", "clamped annular disc, 20 modes, P2: fem_squeal vs CalculiX vs scikit-fem",
          "modal_peers.py", (("--ranks", "2"),), (("--quick",),), needs=("ccx", "py:skfem")),  # 2: also serial
    Bench("ring_convergence", "ring CEA: DOFs vs error vs time, P1/P2, curved/straight",
          "ring_convergence.py", (("--ranks", "1"), ("--ranks", "2")), (("--quick",),)),
    Bench("brake_cea", "brake corner CEA: mesh convergence, time, memory",
          "brake_cea.py", (("--ranks", "2"),), (("--quick", "--ranks", "1"),)),
    Bench("mpi_scaling", "1 vs 2 ranks on a >=300k-DOF CEA; the largest model in the memory budget",
          "mpi_scaling.py", ((),), (("--quick",),)),
    Bench("reduced_brake", "reduced vs full CEA: basis size vs error vs time per point",
          "reduced_brake.py", (("mpirun:2",),), (("--quick",),)),
    Bench("operating_matrix", "120 conditions (T, |Ω|, direction) on the reduced brake; corners vs full CEA",
          "operating_matrix.py", (("mpirun:2", "--mesh-size", "0.008"),), (("mpirun:2",),)),
    Bench("masa_aft", "MASA: AFT samples per period vs error in K1; sweep cost",
          "masa_aft.py", ((),), (("--quick",),)),
    Bench("masa_brake", "MASA on the reduced brake: cost vs contact elements",
          "masa_brake.py", (("out/masa_brake/reduced_model.npz",),), prepare=("demos/masa_brake.py",)),
    Bench("transient_order", "Newmark/HHT: dt vs error (order) vs cost; large dt; energy drift",
          "transient_order.py", ((),), (("--quick",),)),
    Bench("transient_brake", "reduced brake transient: cost per step vs basis and contact elements",
          "transient_brake.py", (("out/transient_brake/reduced_model.npz", "--steps=1000"),),
          prepare=("demos/transient_brake.py",)),
    Bench("stress_penalty", "penalty kn over 1e8..1e16: residuals, conditioning, spurious modes, warning",
          "stress_penalty.py", ((),), (("--quick",),)),
    Bench("stress_coalescence", "near exceptional points: condition numbers, tracker, real parts past mu_c",
          "stress_coalescence.py", ((),), (("--quick",),)),
    Bench("stress_extremes", "mu up to 2, nu 0.49 lining, thin/thick parts, distorted meshes, determinism",
          "stress_extremes.py", ((),), (("--quick",),)),
    Bench("hex_plate", "C3D20 clamped annular plate vs Kirchhoff/Mindlin and a fine P2 tet mesh, refinement",
          "hex_plate.py", ((),), (("--quick",),)),
    Bench("hex_brake", "mixed hex/tet brake deck vs its all-tet twins (structured, gmsh): CEA, refinement",
          "hex_brake.py", ((),), (("--quick",),)),
    Bench("hex_native", "native hexahedra (S2 2x2x2 = C3D20R, Q1 = C3D8) vs CalculiX on the issue-37 plate",
          "hex_native.py", ((),), (("--quick",),), needs=("ccx",)),
    Bench("cea_calculix", "frictional CEA with tangential slip stiffness kt vs CalculiX 2.20 on the same mesh",
          "cea_calculix.py", ((),), (("--quick",),), needs=("ccx",)),
    Bench("deck_orthotropic", "orthotropic/anisotropic decks with *ORIENTATION, *CLOAD, *MOTION vs CalculiX 2.20",
          "deck_orthotropic.py", ((),), (("--quick",),), needs=("ccx",)),
)


def _missing(b: Bench) -> list[str]:
    out = []
    for n in b.needs:
        if n.startswith("py:"):
            import importlib.util

            if importlib.util.find_spec(n[3:]) is None:
                out.append(f"Python module {n[3:]} (scripts/setup.sh --bench installs it)")
        elif shutil.which(n) is None:
            out.append(f"executable {n} (scripts/setup.sh --bench installs it)")
    return out


def _command(script: str, args: tuple[str, ...]) -> list[str]:
    cmd = [sys.executable, str(HERE / script)]
    if args and args[0].startswith("mpirun:"):
        return ["mpirun", "-n", args[0].split(":")[1], "--oversubscribe", *cmd, *args[1:]]
    return [*cmd, *args]


def _run(cmd: list[str], log) -> int:
    env = dict(os.environ, **MPI_ENV)
    log.write(f"$ {' '.join(cmd)}\n")
    log.flush()
    return subprocess.run(cmd, cwd=ROOT, env=env, stdout=log, stderr=subprocess.STDOUT).returncode


def _machine() -> str:
    try:
        blas = os.path.realpath(f"/etc/alternatives/libblas.so.3-{platform.machine()}-linux-gnu")
    except OSError:
        blas = "?"
    return (f"{platform.node()}: {os.cpu_count()} cores, {platform.machine()}, "
            f"Python {platform.python_version()}, BLAS {blas}")


def run_suite(names: list[str] | None, quick: bool) -> int:
    """Run the selected benchmarks; write SUMMARY[_quick].md; 0 if all ran, 1 otherwise."""
    out = out_dir()
    out.mkdir(parents=True, exist_ok=True)
    chosen = [b for b in SUITE if not names or b.name in names]
    unknown = sorted(set(names or []) - {b.name for b in SUITE})
    if unknown:
        raise SystemExit(f"fem-squeal bench: unknown benchmark(s) {unknown}; known: {[b.name for b in SUITE]}")
    suffix = "_quick" if quick else ""
    rows, failed = [], 0
    for b in chosen:
        runs = b.quick if quick else b.full
        if not runs:
            rows.append((b, "skipped (no quick version)", 0.0, []))
            continue
        missing = _missing(b)
        if missing:
            rows.append((b, "skipped: missing " + ", ".join(missing), 0.0, []))
            failed += 1
            continue
        print(f"[bench] {b.name}: {b.what}", flush=True)
        t0 = time.perf_counter()
        status = "ok"
        with open(out / f"{b.name}{suffix}.log", "w") as log:
            if b.prepare and _run(_command_demo(b.prepare[0]), log) != 0:
                status = f"failed preparing {b.prepare[0]}"
            for args in runs if status == "ok" else ():
                if _run(_command(b.script, args), log) != 0:
                    status = f"failed: {' '.join(args)} (see {b.name}{suffix}.log)"
                    break
        dt = time.perf_counter() - t0
        failed += status != "ok"
        fresh = time.time() - dt - 1
        tables = sorted(p for p in out.glob(f"{b.name}_*ranks{suffix}.md") if p.stat().st_mtime >= fresh)
        print(f"[bench] {b.name}: {status} in {dt:.0f} s", flush=True)
        rows.append((b, status, dt, tables))
    _summary(out / f"SUMMARY{suffix}.md", rows, quick)
    return 1 if failed else 0


def _command_demo(demo: str) -> list[str]:
    return ["mpirun", "-n", "2", "--oversubscribe", sys.executable, str(ROOT / demo)]


def _summary(path: Path, rows, quick: bool) -> None:
    lines = [f"# Benchmark summary{' (quick)' if quick else ''}", "",
             f"{time.strftime('%Y-%m-%d %H:%M')}, {_machine()}", "",
             f"Regenerate: `fem-squeal bench{' --quick' if quick else ''}` (or `make bench"
             f"{'-quick' if quick else ''}`)", "",
             "| benchmark | what | status | wall [s] |", "|---|---|---|---:|"]
    lines += [f"| {b.name} | {b.what} | {st} | {dt:.0f} |" for b, st, dt, _ in rows]
    for _, _, _, tables in rows:
        for t in tables:
            lines += ["", f"## {t.stem}", "", t.read_text().rstrip()]
            png = t.with_suffix(".png")
            if png.exists():
                lines += ["", f"![{t.stem}]({png.name})"]
    tmp = path.with_name(f".{path.name}.tmp")
    tmp.write_text("\n".join(lines) + "\n")
    os.replace(tmp, path)
    print(f"[bench] wrote {path}")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="fem-squeal bench", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--quick", action="store_true", help="the smoke version of each benchmark (minutes in all)")
    ap.add_argument("--only", nargs="+", metavar="NAME", help="run only these benchmarks")
    ap.add_argument("--list", action="store_true", help="list the benchmarks and exit")
    a = ap.parse_args(argv)
    if a.list:
        for b in SUITE:
            print(f"{b.name:20s} {b.what}")
        return 0
    return run_suite(a.only, a.quick)


if __name__ == "__main__":
    sys.exit(main())
