"""Checks before any stage runs: the size of the model and the memory of its largest solve, and the
output folder.

Memory model (measured by ``benchmarks/mpi_scaling.py`` on the brake corner CEA with its preload,
peak RSS summed over the ranks): 9.0 GiB at 347,853 P2 DOFs and 22.7 GiB at 711,351, i.e. memory ∝
DOFs^(4/3) (the fill-in of a nested-dissection factorisation in 3D; the two points give 1.30):

    M(N) = 9.0 GiB · (N / 347,853)^(4/3).

A run is refused (:class:`~fem_squeal.util.errors.ResourceError`, exit 2, before gmsh or any solver
starts) when M exceeds 90 % of the memory of the machines it runs on, and warned about above 60 %.
The same model says how many such machines an N-DOF model needs under MPI.
"""
from __future__ import annotations

import math
import os
import socket
import tempfile
from dataclasses import asdict, dataclass
from pathlib import Path

from fem_squeal.util.errors import InputError, ResourceError
from geometry.estimate import ESTIMATORS

GIB = 2.0 ** 30
#: P2/P1 displacement DOFs per tetrahedron: measured 6.3 (ring), 5.7-5.9 (brake) for P2; P1 has about
#: one vertex per 5 cells in the bulk and more in thin parts
DOFS_PER_CELL = {1: 0.9, 2: 5.8}
MEMORY_REF_DOFS, MEMORY_REF_BYTES, MEMORY_EXPONENT = 347_853, 9.0 * GIB, 4.0 / 3.0
REFUSE_SHARE, WARN_SHARE = 0.9, 0.6


def solve_memory(dofs: float) -> float:
    """Bytes the largest solve of an N-DOF model needs, summed over the ranks (module docstring)."""
    return MEMORY_REF_BYTES * (dofs / MEMORY_REF_DOFS) ** MEMORY_EXPONENT


def machine_memory() -> float:
    """Physical memory of this machine [bytes]."""
    return float(os.sysconf("SC_PHYS_PAGES") * os.sysconf("SC_PAGE_SIZE"))


@dataclass(frozen=True)
class Estimate:
    """What a scene's model will take: cells, DOFs, memory of the largest solve, and what is there."""
    cells: float
    dofs: float
    memory_gib: float          # of the largest solve, summed over the ranks
    available_gib: float       # physical memory of the machines of this run
    machines: int              # machines like this one the model needs (90 % of each usable)

    def as_dict(self) -> dict:
        return asdict(self)


def estimate(scene: dict, nodes: int = 1) -> Estimate | None:
    """The size of ``scene``'s model before its mesh is built (None for a mesh file or a lumped scene:
    the file fixes the size, the mesh stage reports it)."""
    geo = scene.get("geometry")
    if geo is None or geo["builder"] not in ESTIMATORS:
        return None
    params = {k: v for k, v in geo.items() if k != "builder"}
    cells = sum(ESTIMATORS[geo["builder"]](**params).values())
    dofs = cells * DOFS_PER_CELL[scene["discretisation"]["degree"]]
    memory, machine = solve_memory(dofs), machine_memory()
    return Estimate(cells, dofs, memory / GIB, nodes * machine / GIB,
                    max(1, math.ceil(memory / (REFUSE_SHARE * machine))))


def check_resources(scene: dict, comm) -> tuple[Estimate | None, list[str]]:
    """:func:`estimate` on the machines of ``comm``; raises :class:`ResourceError` naming the mesh size
    when the largest solve cannot fit, returns warnings when it is close."""
    nodes = len(set(comm.allgather(socket.gethostname())))
    est = comm.bcast(estimate(scene, nodes) if comm.rank == 0 else None, root=0)
    if est is None:
        return None, []
    geo = scene["geometry"]
    what = (f"geometry.mesh_size: {geo['mesh_size']:g} m gives about {est.cells:.3g} elements and "
            f"{est.dofs:.3g} DOFs (P{scene['discretisation']['degree']}); its largest solve needs about "
            f"{est.memory_gib:.3g} GiB (memory ∝ DOFs^(4/3), 9 GiB at 348k DOFs)")
    if est.memory_gib > REFUSE_SHARE * est.available_gib:
        raise ResourceError(f"{what}, more than {100 * REFUSE_SHARE:.0f} % of the {est.available_gib:.3g} GiB of "
                            f"the {nodes} machine(s) of this run: it needs {est.machines} such machines under "
                            "MPI; use a larger mesh_size")
    if est.memory_gib > WARN_SHARE * est.available_gib:
        return est, [f"{what}: close to the {est.available_gib:.3g} GiB of this run's machine(s)"]
    return est, []


def check_outdir(outdir: Path) -> None:
    """Create ``outdir`` (with its parents) and check that a file can be written there, before any stage
    runs; :class:`InputError` names the folder and the reason."""
    try:
        outdir.mkdir(parents=True, exist_ok=True)
        with tempfile.NamedTemporaryFile(dir=outdir, prefix=".write-test."):
            pass
    except OSError as e:
        raise InputError(f"output folder {outdir}: cannot be created or written ({e.strerror or e})") from None
