"""BLAS threads.  Debian's OpenBLAS (libopenblas0-pthread) starts one thread per core in every
process; under ``mpirun -n N`` with N ranks on N cores that oversubscribes the machine and
OpenBLAS's spinning threads slow dense work by 10-100× (measured: a batch of 100×100
eigenvalue problems went from ~3 ms to 212 ms each with 2 ranks on 2 cores)."""
from __future__ import annotations

import ctypes
import os
from contextlib import contextmanager

from fem_squeal.util.native import first_library


def _openblas() -> ctypes.CDLL | None:
    try:
        with open("/proc/self/maps") as f:
            paths = {line.split()[-1] for line in f if "openblas" in line and line.split()[-1].startswith("/")}
    except OSError:
        return None
    return first_library(sorted(paths), "openblas_set_num_threads")


def limit_threads(ranks_per_node: int) -> int | None:
    """Give each of ``ranks_per_node`` ranks cores/ranks BLAS threads (at least 1), unless the
    user set OPENBLAS_NUM_THREADS or OMP_NUM_THREADS; returns the count set (None: no OpenBLAS)."""
    if "OPENBLAS_NUM_THREADS" in os.environ or "OMP_NUM_THREADS" in os.environ:
        return None
    lib = _openblas()
    if lib is None:
        return None
    n = max(1, (os.cpu_count() or 1) // max(ranks_per_node, 1))
    lib.openblas_set_num_threads(n)
    return n


def limit_threads_for(comm) -> int | None:
    """:func:`limit_threads` for the ranks of ``comm`` that share this node."""
    from mpi4py import MPI  # heavy: MPI initialisation

    node = comm.Split_type(MPI.COMM_TYPE_SHARED)
    try:
        return limit_threads(node.size)
    finally:
        node.Free()


@contextmanager
def single_threaded():
    """Run the block with one OpenBLAS thread, then restore the previous count.

    Time integration of friction-induced vibration is chaotic in stick-slip: a last-bit change
    (a BLAS reduction split over another number of threads) grows into a different trajectory.
    One thread makes a transient the same whatever the rank count or core count of the run."""
    lib = _openblas()
    if lib is None:
        yield
        return
    n = lib.openblas_get_num_threads()
    lib.openblas_set_num_threads(1)
    try:
        yield
    finally:
        lib.openblas_set_num_threads(n)
