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
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from functools import lru_cache

import numpy as np
from petsc4py import PETSc

from fem_squeal.util.native import address, compiled_library, first_library

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


# Y = A X for a CSR matrix A and a column-major block X of k columns, 8 columns per sweep over A.
# SciPy's csr_matvecs wants row-major blocks (a transposing copy in and out of a Krylov method's
# column-major ones) and does not vectorise its inner loop: the P2 mass at 255k DOFs (6.4M entries)
# times 8 columns took 33 ms with SciPy, 14 ms here (1.0 against 3 ms at 26k).
_PRODUCT_SOURCE = r"""
#include <stdint.h>

/* Y = A X for m <= 8 columns */
static inline __attribute__((always_inline))
void rows(int32_t n, const int32_t *ai, const int32_t *aj, const double *av, int32_t m,
          const double *X, int64_t ldx, double *Y, int64_t ldy)
{
    for (int32_t i = 0; i < n; ++i) {
        double acc[8] = {0};
        for (int32_t p = ai[i]; p < ai[i + 1]; ++p) {
            const double a = av[p];
            const double *x = X + aj[p];
            for (int c = 0; c < m; ++c)
                acc[c] += a * x[ldx * c];
        }
        for (int c = 0; c < m; ++c)
            Y[i + ldy * c] = acc[c];
    }
}

__attribute__((target_clones("arch=x86-64-v4", "arch=x86-64-v3", "default")))
void csr_block(int32_t n, const int32_t *ai, const int32_t *aj, const double *av, int32_t k,
               const double *X, int64_t ldx, double *Y, int64_t ldy)
{
    for (int32_t c0 = 0; c0 < k; c0 += 8) {
        const int32_t m = k - c0 < 8 ? k - c0 : 8;
        const double *Xc = X + ldx * c0;
        double *Yc = Y + ldy * c0;
        if (m == 8)                     /* the same loop with a constant width: unrolled */
            rows(n, ai, aj, av, 8, Xc, ldx, Yc, ldy);
        else
            rows(n, ai, aj, av, m, Xc, ldx, Yc, ldy);
    }
}
"""


@lru_cache(maxsize=1)
def _product_lib() -> ctypes.CDLL | None:
    lib = compiled_library("csr_block", _PRODUCT_SOURCE, ("-O3",))
    if lib is None:
        return None
    i32, i64, p = ctypes.c_int32, ctypes.c_int64, ctypes.c_void_p
    lib.csr_block.argtypes = [i32, p, p, p, i32, p, i64, p, i64]
    lib.csr_block.restype = None
    return lib


def block_product(csr: tuple[np.ndarray, np.ndarray, np.ndarray]) -> Callable[[np.ndarray], np.ndarray] | None:
    """X ↦ A X for the square CSR matrix ``csr`` = (indptr, indices, data) with 32-bit indices and
    column-major blocks X (n, k); the result is a new column-major array.  The arrays must outlive
    the function (views of PETSc's memory: inside the ``csr_view`` block).  None where the compiled
    kernel cannot be had (the caller keeps SciPy's product)."""
    lib = _product_lib()
    ai, aj, av = csr
    if lib is None or ai.dtype != np.int32 or aj.dtype != np.int32 or av.dtype != np.float64:
        return None
    ai, aj, av = (np.ascontiguousarray(a) for a in (ai, aj, av))
    n = len(ai) - 1

    def product(X: np.ndarray) -> np.ndarray:
        X = np.asfortranarray(X, dtype=np.float64)
        X2 = X.reshape(n, -1, order="F")
        Y = np.empty(X2.shape, order="F")
        lib.csr_block(n, address(ai), address(aj), address(av), X2.shape[1], address(X2), n, address(Y), n)
        return Y.reshape(X.shape, order="F")
    return product
