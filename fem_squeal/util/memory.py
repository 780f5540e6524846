"""Freed memory given back to the system.

A sparse factorisation (MUMPS, CHOLMOD) allocates its fronts with malloc.  glibc serves blocks below its
mmap threshold from the heap, and that threshold rises with every large block freed (to 32 MiB), so
after the first factorisation most of the next one's blocks come from the heap; freed, they stay in the
process (RSS) and outside the system's MemAvailable.  Measured on the brake corner, one rank: the preload's
factorisations left 3.0 GB in the heap at 163k DOFs (RSS 3.85 GB, 0.80 GB after ``malloc_trim``), and at
711k DOFs the heap the preload and the CEA left was why the coupling's block Lanczos found no room for its
vectors (``fem_squeal.fe.eigen.block_krylov``) and the run peaked at 24.2 GB on a 24 GiB machine.
:func:`release_freed_memory` returns the heap's free pages (glibc ``malloc_trim(0)``): the runner calls it
after every stage (``app/run.py``), the CEA after its solver is destroyed, before the coupling's real
modes in the same stage, and every factorisation before it allocates its factor
(``fem_squeal.fe.factorisation.factor_solver``, ``refactorise``: the symmetric preload's peak at 348k DOFs,
one rank, fell from 4.18 to 3.49 GiB with its J as products, 0.4 GiB of it the heap the pattern copies
left).  :func:`peak_rss_bytes` is the process's peak so far (results.json records it
after every stage computed).
"""
from __future__ import annotations

import ctypes
import resource
from functools import cache


@cache
def _malloc_trim():
    try:
        trim = ctypes.CDLL(None).malloc_trim      # the C library this process runs on (glibc)
    except (OSError, AttributeError):
        return None
    trim.argtypes = [ctypes.c_size_t]
    trim.restype = ctypes.c_int
    return trim


def release_freed_memory() -> bool:
    """Give the free pages of the C heap back to the system (glibc ``malloc_trim(0)``; nothing where
    the C library has no such call).  True where memory was released."""
    trim = _malloc_trim()
    return bool(trim(0)) if trim is not None else False


def peak_rss_bytes() -> int:
    """This process's peak resident memory so far [bytes] (getrusage's high-water mark: it never falls,
    so the stage after which it rose is the one that set it)."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024      # Linux: kilobytes
