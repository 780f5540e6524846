"""The Ryzhik ring (seed 003) between two rigid plates, meshed and assembled once per process.

Cached plain functions, not fixtures: module-level helpers of the tests call them, and so does the
``mpirun -n 2`` child of :func:`support.ranks.two_rank_signature`, which runs without pytest.  Tests
that only call them in their bodies take the ``ring_mesh``/``ring_operators`` fixtures of
``tests/conftest.py`` (the same functions)."""
from __future__ import annotations

import functools

from mpi4py import MPI


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
