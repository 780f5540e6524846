"""Shared fixtures: ring models assembled once per session and reused across tests."""
from __future__ import annotations

import functools
import os
import shutil
from pathlib import Path

import numpy as np
import pytest
from mpi4py import MPI

ROOT = Path(__file__).resolve().parents[1]
RING = dict(mean_radius=0.05, width=0.005, thickness=0.004)
MAT = dict(E=3e9, nu=0.4, rho=1400.0)


@functools.cache
def ring_mesh(width: float = 0.005, thickness: float = 0.004, mesh_size: float = 0.0025, order: int = 2):
    from geometry import annular_disc_mesh

    return annular_disc_mesh(MPI.COMM_WORLD, mean_radius=0.05, width=width, thickness=thickness,
                             mesh_size=mesh_size, order=order)


@functools.cache
def ring_operators(width=0.005, thickness=0.004, mesh_size=0.0025, kn=1e10, mu=0.3, sliding=(1, 1),
                   nu=0.4, alpha=0.0, beta=0.0, degree=2, clamped=()):
    """Operators of the ring between two plates (kn = 0: free ring without plates)."""
    from fem_squeal.fe.assembly import assemble_operators
    from fem_squeal.fe.model import Material, ModelSpec, RigidPlate

    plates = () if kn == 0 else (RigidPlate("top", kn, mu, sliding[0]), RigidPlate("bottom", kn, mu, sliding[1]))
    spec = ModelSpec({"disc": Material(3e9, nu, 1400.0, alpha, beta)}, plates, tuple(clamped), degree)
    return assemble_operators(ring_mesh(width, thickness, mesh_size), spec)


def clean_env() -> dict[str, str]:
    """Environment for child processes.  ``os.environ`` is Python's snapshot from start-up; the
    C environ (used when ``env=None``) also holds the PMIX_/OMPI_ variables that this process's
    singleton MPI_Init added, and those make a child ``mpirun`` misbehave."""
    # every OMPI_*/PMIX_* variable but the run-as-root ones: a pytest-xdist worker inherits in its
    # os.environ what the controlling process's singleton MPI_Init set (OMPI_MCA_ess, OMPI_MCA_pmix,
    # OMPI_APP_CTX_NUM_PROCS), and a child mpirun given them exits 1 without a word
    env = {k: v for k, v in os.environ.items()
           if not k.startswith(("PMIX_", "OMPI_")) or k.startswith("OMPI_ALLOW_RUN_AS_ROOT")}
    env.update(OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1")
    return env


def two_rank_signature(mpirun: list[str], module: str, out) -> dict:
    """``module.signature()`` (a test module's dict of numbers) computed by an ``mpirun -n 2`` child,
    as rank 0 wrote it to the JSON file ``out``."""
    import json
    import subprocess
    import sys

    code = ("import json, sys; sys.path.insert(0, 'tests'); from mpi4py import MPI; "
            f"import {module} as t; "
            f"s = t.signature(); MPI.COMM_WORLD.rank == 0 and open({str(out)!r}, 'w').write(json.dumps(s))")
    p = subprocess.run(mpirun + [sys.executable, "-c", code], capture_output=True, text=True, timeout=900,
                       env=clean_env(), cwd=ROOT)
    assert p.returncode == 0, p.stdout[-3000:] + p.stderr[-3000:]
    return json.loads(Path(out).read_text())


def assert_same_spectrum(sig_a: dict, sig_b: dict, prefix: str, rel: float) -> None:
    """The eigenvalues ``<prefix>re`` + i ``<prefix>im`` of two signatures agree as sets: as many, and
    every one has its twin in the other within ``rel``·|λ| (the order may differ between runs)."""
    a = np.array(sig_a[prefix + "re"]) + 1j * np.array(sig_a[prefix + "im"])
    b = np.array(sig_b[prefix + "re"]) + 1j * np.array(sig_b[prefix + "im"])
    assert len(a) == len(b)
    for u, w in ((a, b), (b, a)):
        assert all(np.min(np.abs(w - lam)) <= rel * abs(lam) for lam in u)


@pytest.fixture
def child_env() -> dict[str, str]:
    """The environment for a child process (:func:`clean_env`)."""
    return clean_env()


@pytest.fixture(scope="session")
def mpirun():
    """Command prefix for 2 MPI ranks, or skip when mpirun is missing."""
    exe = shutil.which("mpirun")
    if exe is None:
        pytest.skip("mpirun not installed")
    return [exe, "-n", "2", "--oversubscribe", "--stdin", "none"]
