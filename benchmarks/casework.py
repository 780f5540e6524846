"""Shared plumbing of the benchmark scripts: run one case in a fresh (MPI) process, print its
JSON on rank 0, and collect it in the parent."""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path


def spawn(script: str, args: list[str], ranks: int, env: dict[str, str] | None = None) -> dict:
    """Run ``script --case *args`` on ``ranks`` MPI ranks (``env``: extra environment variables)
    and return the JSON it prints last."""
    cmd = [sys.executable, script, "--case", *args]
    if ranks > 1:
        cmd = ["mpirun", "-n", str(ranks), "--oversubscribe"] + cmd
    env = dict(os.environ, OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1", **(env or {}))
    out = subprocess.run(cmd, capture_output=True, text=True, env=env, check=True).stdout
    return json.loads(out.strip().splitlines()[-1])


def linearised_brake(comm, quick: bool):
    """scenes/brake_corner_cea.toml (``quick``: the coarse 0.016 m mesh), preloaded and linearised about
    its contact state, with the part stiffnesses: (scene, spec, ops, preload)."""
    from fem_squeal.app.analyses.mesh import build_mesh
    from fem_squeal.app.scene import load_scene, model_spec
    from fem_squeal.fe.assembly import assemble_operators, linearise
    from fem_squeal.fe.preload import solve_preload

    scene = load_scene(Path(__file__).resolve().parents[1] / "scenes" / "brake_corner_cea.toml",
                       ["geometry.mesh_size=0.016"] if quick else [])
    spec = model_spec(scene)
    ops = assemble_operators(build_mesh(comm, scene), spec, parts=True)
    pre = solve_preload(ops)
    return scene, spec, linearise(ops, pre.active), pre


def brake_args(mesh_size: float = 0.0056, repeats: int = 2, ranks: int = 2, more=None):
    """The command line of a brake-corner benchmark: ``--mesh-size``, ``--repeats``, ``--ranks``, and what
    ``more`` (a callable given the argparse parser) adds."""
    import argparse

    ap = argparse.ArgumentParser()
    ap.add_argument("--mesh-size", type=float, default=mesh_size)
    ap.add_argument("--repeats", type=int, default=repeats)
    ap.add_argument("--ranks", type=int, default=ranks)
    if more is not None:
        more(ap)
    return ap.parse_args()


def report(result: dict) -> None:
    """Print a case's result on rank 0 (the parent reads the last line)."""
    from mpi4py import MPI

    if MPI.COMM_WORLD.rank == 0:
        print(json.dumps(result))


def save(name: str, lines: list[str], rows: list[dict], ranks: int, quick: bool) -> None:
    """Print the table and write benchmarks/out/<name>_<ranks>ranks[_quick].md and .json."""
    from pathlib import Path

    from fem_squeal.util.atomic import atomic_path

    text = "\n".join(lines)
    print(text)
    for ext, body in (("md", text + "\n"), ("json", json.dumps(rows, indent=1))):
        with atomic_path(out_path(name, ranks, quick, ext)) as tmp:
            Path(tmp).write_text(body)


def out_path(name: str, ranks: int, quick: bool, ext: str):
    """benchmarks/out (or $FEM_SQUEAL_BENCH_OUT)/<name>_<ranks>ranks[_quick].<ext> (the directory is created)."""
    from pathlib import Path

    out = Path(os.environ.get("FEM_SQUEAL_BENCH_OUT", Path(__file__).resolve().parent / "out"))
    out.mkdir(parents=True, exist_ok=True)
    return out / f"{name}_{ranks}ranks{'_quick' if quick else ''}.{ext}"


def save_plot(fig, name: str, ranks: int, quick: bool) -> None:
    """Write a matplotlib figure to benchmarks/out/<name>_<ranks>ranks[_quick].png (atomically)."""
    from fem_squeal.util.atomic import save_figure_atomic

    save_figure_atomic(fig, out_path(name, ranks, quick, "png"))


# ---------------------------------------------------------------- CalculiX decks

def ccx_real(v: float) -> str:
    """A real in at most 20 characters (ccx reads node coordinates with Fortran (f20.0) per field)."""
    s = f"{v:.17f}" if abs(v) < 1.0 else f"{v:.13e}"
    return s if len(s) <= 20 else f"{v:.12e}"


def ccx_nodes(inp: Path) -> None:
    """Re-print the *NODE block of the Abaqus deck ``inp`` for CalculiX (meshio writes 23-character
    reals that ccx rejects)."""
    out, in_nodes = [], False
    for line in inp.read_text().splitlines():
        if line.startswith("*"):
            in_nodes = line.upper().replace(" ", "").startswith("*NODE")
        elif in_nodes and line.strip():
            n, *x = line.split(",")
            line = n.strip() + ", " + ", ".join(ccx_real(float(v)) for v in x)
        out.append(line)
    inp.write_text("\n".join(out) + "\n")
