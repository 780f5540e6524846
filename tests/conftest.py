"""Fixtures for every test folder (unit/<layer>, integration, mpi): child processes, mpirun, the ring.

Plain helpers that module-level code or child processes call (no fixture can reach them) are in
the ``support`` package (tests/support); no test imports this file."""
from __future__ import annotations

import shutil

import pytest
from support import ring
from support.processes import clean_env
from support.threads import import_gmsh


def pytest_configure(config) -> None:
    """gmsh imported once per process before any test module does, on whatever thread the session
    runs (a pytest-xdist worker may run off the main thread: :mod:`support.threads`)."""
    import_gmsh()


@pytest.fixture
def child_env() -> dict[str, str]:
    """The environment for a child process (:func:`support.processes.clean_env`)."""
    return clean_env()


@pytest.fixture(scope="session")
def mpirun():
    """Command prefix for 2 MPI ranks, or skip when mpirun is missing."""
    exe = shutil.which("mpirun")
    if exe is None:
        pytest.skip("mpirun not installed")
    return [exe, "-n", "2", "--oversubscribe", "--stdin", "none"]


@pytest.fixture(scope="session")
def ring_mesh():
    """``ring_mesh(width, thickness, mesh_size, order)``: the ring's mesh, built once per process
    (:func:`support.ring.ring_mesh`)."""
    return ring.ring_mesh


@pytest.fixture(scope="session")
def ring_operators():
    """``ring_operators(..., kn, mu, sliding, ...)``: the ring's operators between two plates,
    assembled once per process (:func:`support.ring.ring_operators`)."""
    return ring.ring_operators
