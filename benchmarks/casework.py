"""Shared plumbing of the benchmark scripts: run one case in a fresh (MPI) process, print its
JSON on rank 0, and collect it in the parent."""
from __future__ import annotations

import json
import os
import subprocess
import sys


def spawn(script: str, args: list[str], ranks: int) -> dict:
    """Run ``script --case *args`` on ``ranks`` MPI ranks and return the JSON it prints last."""
    cmd = [sys.executable, script, "--case", *args]
    if ranks > 1:
        cmd = ["mpirun", "-n", str(ranks), "--oversubscribe"] + cmd
    env = dict(os.environ, OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1")
    out = subprocess.run(cmd, capture_output=True, text=True, env=env, check=True).stdout
    return json.loads(out.strip().splitlines()[-1])


def report(result: dict) -> None:
    """Print a case's result on rank 0 (the parent reads the last line)."""
    from mpi4py import MPI

    if MPI.COMM_WORLD.rank == 0:
        print(json.dumps(result))


def save(name: str, lines: list[str], rows: list[dict], ranks: int, quick: bool) -> None:
    """Print the table and write benchmarks/out/<name>_<ranks>ranks[_quick].md and .json."""
    from pathlib import Path

    text = "\n".join(lines)
    print(text)
    out = Path(__file__).resolve().parent / "out"
    out.mkdir(parents=True, exist_ok=True)
    suffix = f"_{ranks}ranks" + ("_quick" if quick else "")
    (out / f"{name}{suffix}.md").write_text(text + "\n")
    (out / f"{name}{suffix}.json").write_text(json.dumps(rows, indent=1))
