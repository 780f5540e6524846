"""Shared libraries loaded through ctypes (OpenBLAS for its thread count, METIS for an ordering,
PETSc for the calls petsc4py does not wrap).  The package's own compiled kernels are built with the
package and loaded by :mod:`fem_squeal.fe.kernels`; nothing is compiled at run time."""
from __future__ import annotations

import ctypes
import ctypes.util
from collections.abc import Iterable, Iterator


def first_library(candidates: Iterable[str | None], symbol: str, search: Iterable[str] = ()) -> ctypes.CDLL | None:
    """The first of ``candidates`` (paths or sonames; None entries skipped), then of the libraries
    ``ctypes.util.find_library`` finds for the names in ``search``, that loads and exports ``symbol``;
    None if none does.  ``search`` is looked up only when no candidate loads: find_library runs the
    compiler or ldconfig, 20 ms each in a fresh process."""
    def names() -> Iterator[str | None]:
        yield from candidates
        for name in search:
            yield ctypes.util.find_library(name)
    for name in names():
        if not name:
            continue
        try:
            lib = ctypes.CDLL(name)
            getattr(lib, symbol)
            return lib
        except (OSError, AttributeError):
            continue
    return None


def address(a) -> ctypes.c_void_p:
    """The address of a NumPy array's data, for a ctypes call."""
    return a.ctypes.data_as(ctypes.c_void_p)
