"""Threads of the numerical libraries.

- OpenBLAS: Debian's (libopenblas0-pthread) starts one thread per core in every process; under
  ``mpirun -n N`` with N ranks on N cores that oversubscribes the machine and OpenBLAS's spinning
  threads slow dense work by 10-100× (measured: a batch of 100×100 eigenvalue problems went from
  ~3 ms to 212 ms each with 2 ranks on 2 cores).  Its thread count is set through threadpoolctl
  (Debian's python3-threadpoolctl), which finds the OpenBLAS behind Debian's libblas.so.3.
- OpenMP: CHOLMOD 3 (SuiteSparse 5, Debian's) runs the loops of its supernodal factorisation
  (zeroing a supernode, scattering A and the descendants' updates into it) with
  ``num_threads(CHOLMOD_OMP_NUM_THREADS)``, compiled in as 4, which OMP_NUM_THREADS does not
  override: :func:`serial_openmp`.  That is OpenMP's max-active-levels, which threadpoolctl does not
  set (its OpenMP limit is the thread count, which the compiled-in clause overrides): libgomp is
  called directly."""
from __future__ import annotations

import ctypes
import os
from contextlib import contextmanager

from threadpoolctl import threadpool_info, threadpool_limits

from fem_squeal.util.native import first_library


def _loaded(fragment: str, symbol: str) -> ctypes.CDLL | None:
    """The library this process has loaded whose path contains ``fragment`` and that exports
    ``symbol``; None if there is none."""
    try:
        with open("/proc/self/maps") as f:
            paths = {line.split()[-1] for line in f if fragment in line and line.split()[-1].startswith("/")}
    except OSError:
        return None
    return first_library(sorted(paths), symbol)


def blas_threads() -> int | None:
    """The thread count of the BLAS this process has loaded (threadpoolctl); None if it has none."""
    counts = [i["num_threads"] for i in threadpool_info() if i["user_api"] == "blas"]
    return counts[0] if counts else None


_GOMP: list[ctypes.CDLL] = []      # libgomp once found (it is never unloaded)


def _gomp() -> ctypes.CDLL | None:
    if not _GOMP:
        lib = _loaded("libgomp", "omp_set_max_active_levels")
        if lib is None:
            return None
        _GOMP.append(lib)
    return _GOMP[0]


@contextmanager
def _temporarily(lib: ctypes.CDLL | None, get: str, put: str, value: int):
    """``lib.<put>(value)`` for the block, then ``lib.<put>`` of what ``lib.<get>()`` returned
    before it (also on an exception); nothing where ``lib`` is None."""
    if lib is None:
        yield
        return
    old = getattr(lib, get)()
    getattr(lib, put)(value)
    try:
        yield
    finally:
        getattr(lib, put)(old)


def limit_threads(ranks_per_node: int) -> int | None:
    """Give each of ``ranks_per_node`` ranks cores/ranks BLAS threads (at least 1), unless the
    user set OPENBLAS_NUM_THREADS or OMP_NUM_THREADS; returns the count set (None: no OpenBLAS)."""
    if "OPENBLAS_NUM_THREADS" in os.environ or "OMP_NUM_THREADS" in os.environ:
        return None
    if blas_threads() is None:
        return None
    n = max(1, (os.cpu_count() or 1) // max(ranks_per_node, 1))
    threadpool_limits(n, user_api="blas")
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
    with threadpool_limits(1, user_api="blas"):
        yield


@contextmanager
def serial_openmp():
    """Run the block with OpenMP's parallel regions on the calling thread alone (the
    max-active-levels ICV set to 0), then restore the previous value.  Nothing changes where
    libgomp is not loaded.

    For CHOLMOD's factorisation (see the module's note): its OpenMP loops are memory-bound scatters
    between BLAS calls, and waking 4 threads for each of them costs more than they save.  Measured
    on the clamped P2 disc (CHOLMOD's numeric factorisation, 4 repeats in one process; 2-core
    machine): 26k DOFs, one BLAS thread, 0.17 s with them and 0.076 s without; two BLAS threads
    0.10 and 0.06 s; 255k DOFs, one BLAS thread, 4.4 and 3.3 s.  The factor is the same to the
    bit (the loops move and add the same numbers)."""
    with _temporarily(_gomp(), "omp_get_max_active_levels", "omp_set_max_active_levels", 0):
        yield
