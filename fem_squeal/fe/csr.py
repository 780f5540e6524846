"""The CSR arrays of a serial PETSc AIJ matrix as NumPy views of PETSc's own memory (no copy).

``Mat.getValuesCSR`` copies all three arrays: 232 MB for the stiffness of a 255k-DOF P2 model, and
in a fresh process every page of a copy is a page fault (1–6 µs each on this project's VM).  A
serial factorisation and the Krylov products that follow it only read the arrays, so
:func:`csr_view` lends PETSc's arrays for the duration of a ``with`` block (``MatGetRowIJ`` and
``MatSeqAIJGetArrayRead``, called through ctypes on the ``libpetsc`` petsc4py itself links, then
restored).  Where that cannot be had (another matrix type, more than one rank, a library that does
not answer as expected) it yields ``getValuesCSR``'s copies instead: the same numbers either way.
"""
from __future__ import annotations

import ctypes
from collections.abc import Iterator
from contextlib import contextmanager
from functools import lru_cache

import numpy as np
from petsc4py import PETSc

from fem_squeal.util.native import first_library

_INT = {np.dtype(np.int32): ctypes.c_int32, np.dtype(np.int64): ctypes.c_int64}[np.dtype(PETSc.IntType)]
_PINT = ctypes.POINTER(_INT)
_PDOUBLE = ctypes.POINTER(ctypes.c_double)


@lru_cache(maxsize=1)
def petsc_library() -> ctypes.CDLL | None:
    """The real-scalar ``libpetsc`` petsc4py links (ctypes), with the prototypes used here; None
    where it cannot be found or PETSc's scalars are not double."""
    if np.dtype(PETSc.ScalarType) != np.float64:
        return None
    version = ".".join(str(v) for v in PETSc.Sys.getVersion()[:2])
    lib = first_library((f"libpetsc_real.so.{version}", f"libpetsc.so.{version}"), "MatSeqAIJGetArrayRead",
                        search=("petsc_real", "petsc"))
    if lib is None:
        return None
    row_ij = [ctypes.c_void_p, _INT, ctypes.c_int, ctypes.c_int, _PINT, ctypes.POINTER(_PINT),
              ctypes.POINTER(_PINT), ctypes.POINTER(ctypes.c_int)]
    for name, args in (("MatGetRowIJ", row_ij), ("MatRestoreRowIJ", row_ij),
                       ("MatSeqAIJGetArrayRead", [ctypes.c_void_p, ctypes.POINTER(_PDOUBLE)]),
                       ("MatSeqAIJRestoreArrayRead", [ctypes.c_void_p, ctypes.POINTER(_PDOUBLE)]),
                       ("MatSeqAIJGetArray", [ctypes.c_void_p, ctypes.POINTER(_PDOUBLE)]),
                       ("MatSeqAIJRestoreArray", [ctypes.c_void_p, ctypes.POINTER(_PDOUBLE)])):
        getattr(lib, name).argtypes, getattr(lib, name).restype = args, ctypes.c_int
    return lib


@contextmanager
def csr_view(A: PETSc.Mat) -> Iterator[tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """(indptr, indices, data) of the serial AIJ matrix ``A``: read-only views of PETSc's arrays,
    valid inside the ``with`` block while ``A`` is neither changed nor destroyed; else copies."""
    lib = petsc_library()
    if lib is None or A.getComm().getSize() > 1 or A.getType() != "seqaij":
        yield _copies(A)
        return
    h = ctypes.c_void_p(A.handle)
    n, ia, ja, done = _INT(), _PINT(), _PINT(), ctypes.c_int()
    if lib.MatGetRowIJ(h, 0, 0, 0, ctypes.byref(n), ctypes.byref(ia), ctypes.byref(ja), ctypes.byref(done)) \
            or not done.value:
        yield _copies(A)
        return
    try:
        a = _PDOUBLE()
        if lib.MatSeqAIJGetArrayRead(h, ctypes.byref(a)):
            yield _copies(A)
            return
        try:
            rows = n.value
            indptr = np.ctypeslib.as_array(ia, shape=(rows + 1,))
            nnz = int(indptr[-1])
            views = (indptr, np.ctypeslib.as_array(ja, shape=(nnz,)), np.ctypeslib.as_array(a, shape=(nnz,)))
            if rows != A.getSize()[0] or nnz != int(A.getInfo()["nz_used"]):
                yield _copies(A)           # not the layout expected: do not trust the pointers
                return
            for v in views:
                v.flags.writeable = False
            yield views
        finally:
            lib.MatSeqAIJRestoreArrayRead(h, ctypes.byref(a))
    finally:
        lib.MatRestoreRowIJ(h, 0, 0, 0, ctypes.byref(n), ctypes.byref(ia), ctypes.byref(ja), ctypes.byref(done))


def _copies(A: PETSc.Mat) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    return A.getValuesCSR()


@contextmanager
def csr_values(A: PETSc.Mat) -> Iterator[np.ndarray]:
    """The value array of the serial AIJ matrix ``A`` (CSR order) as a writable view of PETSc's
    memory, inside the ``with`` block (``MatSeqAIJGetArray``; restoring it marks ``A`` changed).
    Raises where that cannot be had (the caller then has nothing to write into)."""
    lib = petsc_library()
    if lib is None or A.getComm().getSize() > 1 or A.getType() != "seqaij":
        raise RuntimeError("csr_values: a serial seqaij matrix and PETSc's library are needed")
    h = ctypes.c_void_p(A.handle)
    a = _PDOUBLE()
    if lib.MatSeqAIJGetArray(h, ctypes.byref(a)):
        raise RuntimeError("csr_values: MatSeqAIJGetArray failed")
    try:
        yield np.ctypeslib.as_array(a, shape=(int(A.getInfo()["nz_used"]),))
    finally:
        lib.MatSeqAIJRestoreArray(h, ctypes.byref(a))
