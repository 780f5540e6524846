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
from contextlib import ExitStack, contextmanager
from functools import lru_cache

import numpy as np
import scipy.sparse as sp
from mpi4py import MPI
from petsc4py import PETSc

from fem_squeal.fe import kernels
from fem_squeal.util.native import address, first_library

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
                       ("MatSeqAIJRestoreArray", [ctypes.c_void_p, ctypes.POINTER(_PDOUBLE)]),
                       ("MatMPIAIJGetSeqAIJ", [ctypes.c_void_p, ctypes.POINTER(ctypes.c_void_p),
                                               ctypes.POINTER(ctypes.c_void_p), ctypes.POINTER(_PINT)]),
                       ("MatSetOption", [ctypes.c_void_p, ctypes.c_int, ctypes.c_int])):
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


def find_sorted(keys: np.ndarray, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(position, found) of each of ``x`` in the sorted index array ``keys`` (a position in range
    where not found; all False for empty ``keys``)."""
    x = np.asarray(x)
    if not len(keys):
        return np.zeros(x.shape, np.int64), np.zeros(x.shape, bool)
    pos = np.minimum(np.searchsorted(keys, x), len(keys) - 1)
    return pos, keys[pos] == x


def drop_zeros(A: PETSc.Mat) -> PETSc.Mat:
    """A copy of the AIJ matrix ``A`` without its stored zeros (``A`` itself if it has none or is
    not AIJ).  A vector mass matrix is assembled on the stiffness pattern, whole 3×3 blocks of which
    two thirds are zero: without them each product with M in the Krylov iteration (two per step:
    the operator and the M-inner product) reads a third of the memory; the contact stiffness of a
    state without its open points (:func:`fem_squeal.fe.assembly.contact.linearise`) does not carry
    their couplings into a factorisation's pattern."""
    if "aij" not in A.getType():
        return A
    with csr_view(A) as (ai, aj, av):       # serial: PETSc's arrays (the check alone copies nothing)
        keep = av != 0.0
        if A.getComm().tompi4py().allreduce(bool(keep.all()), op=MPI.LAND):
            return A
        counts = np.concatenate([[0], np.cumsum(keep)])
        B = PETSc.Mat().createAIJ(A.getSizes(), csr=(counts[ai].astype(PETSc.IntType), aj[keep], av[keep]),
                                  comm=A.getComm())
    known, symmetric = A.isSymmetricKnown()
    if known:
        B.setOption(PETSc.Mat.Option.SYMMETRIC, symmetric)
    return B


def local_rows(A: PETSc.Mat) -> sp.csr_matrix:
    """This rank's rows of the AIJ matrix ``A`` with global column numbers, as SciPy CSR (copies)."""
    ai, aj, av = A.getValuesCSR()
    return sp.csr_matrix((av, aj, ai), shape=(len(ai) - 1, A.getSize()[1]))


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


# Y = A X for a CSR matrix A and a column-major block X of k columns.
# SciPy's csr_matvecs wants row-major blocks (a transposing copy in and out of a Krylov method's
# column-major ones) and does not vectorise its inner loop: the P2 mass at 255k DOFs (6.4M entries)
# times 8 columns took 33 ms with SciPy, 14 ms here (1.0 against 3 ms at 26k).
# Up to 8 columns (a Krylov block) the columns are read where they are.  Wider blocks (a reduced
# basis) go in panels of 16 columns copied row-major into a buffer, so that each stored entry loads
# one contiguous row of the panel, and the three rows of a node that share one column pattern (a
# vector stiffness on 3 × 3 blocks) load it once for the three: the 50k-DOF brake's stiffness times
# 233 columns takes 0.14 s here, 0.19 s by columns of 8 and 0.26 s in PETSc's MatMatMult.
# The C source: fem_squeal/fe/kernels/csr_block.c, built with the package.


@lru_cache(maxsize=1)
def _product_lib() -> ctypes.CDLL | None:
    lib = kernels.library("csr_block")
    if lib is None:
        return None
    i32, i64, p = ctypes.c_int32, ctypes.c_int64, ctypes.c_void_p
    lib.csr_block.argtypes = [i32, i32, p, p, p, i32, p, i64, p, i64]
    lib.csr_block.restype = ctypes.c_int
    lib.csr_sum_norm_inf.argtypes = [i32, i32, i32, p, p, p, p, p, p, p, p]
    lib.csr_sum_norm_inf.restype = None
    return lib


def block_product(csr: tuple[np.ndarray, np.ndarray, np.ndarray], ncol: int | None = None
                  ) -> Callable[[np.ndarray], np.ndarray] | None:
    """X ↦ A X for the CSR matrix ``csr`` = (indptr, indices, data) with 32-bit indices, ``ncol``
    columns (default: square) and column-major blocks X (ncol, k); the result is a new column-major
    array (n, k).  The arrays must outlive the function (views of PETSc's memory: inside the
    ``csr_view`` block).  None where the compiled kernel cannot be had (the caller keeps another
    product)."""
    lib = _product_lib()
    ai, aj, av = csr
    if lib is None or ai.dtype != np.int32 or aj.dtype != np.int32 or av.dtype != np.float64:
        return None
    ai, aj, av = (np.ascontiguousarray(a) for a in (ai, aj, av))
    n = len(ai) - 1
    ncol = n if ncol is None else int(ncol)

    def product(X: np.ndarray) -> np.ndarray:
        X = np.asfortranarray(X, dtype=np.float64)
        if X.shape[0] != ncol:
            raise ValueError(f"block_product: X has {X.shape[0]} rows, the matrix {ncol} columns")
        X2 = X.reshape(ncol, -1, order="F")
        Y = np.empty((n, X2.shape[1]), order="F")
        if lib.csr_block(n, ncol, address(ai), address(aj), address(av), X2.shape[1], address(X2), ncol,
                         address(Y), n):
            raise MemoryError(f"block_product: no buffer for {ncol} × 16 doubles")
        return Y.reshape((n, *X.shape[1:]), order="F")
    return product


def sum_norms_inf(mats: list[PETSc.Mat], coefs: np.ndarray) -> np.ndarray:
    """‖Σ_i C[i, q] A_i‖∞ for each column q of ``coefs`` (len(mats) × n_sets), AIJ matrices of one
    shape, over the ranks: the terms' rows merged once, row by row, for every set (compiled; SciPy's
    sums where the kernel cannot be had), on PETSc's arrays on one rank and ``getValuesCSR``'s
    copies of the local rows on more.  Forming K(p) for its norm took four sparse additions of a new
    pattern per design point (60 ms at 50k DOFs); the 7 check points of the brake's basis take
    one pass."""
    A0 = mats[0]
    comm, ncol = A0.getComm().tompi4py(), A0.getSize()[1]
    coefs = np.ascontiguousarray(coefs, dtype=float).reshape(len(mats), -1)
    npts = coefs.shape[1]
    lib = _product_lib()
    with ExitStack() as stack:
        csrs = [tuple(np.ascontiguousarray(a, dtype=t) for a, t in zip(stack.enter_context(csr_view(A)),
                                                                        (np.int32, np.int32, np.float64)))
                for A in mats]
        n = len(csrs[0][0]) - 1
        local = np.zeros(npts)
        if n == 0:
            pass
        elif lib is not None:
            ptrs = [(ctypes.c_void_p * len(mats))(*[x[k].ctypes.data for x in csrs]) for k in range(3)]
            acc, stamp, touched = np.zeros(ncol * npts), np.zeros(ncol, np.int32), np.empty(ncol, np.int32)
            lib.csr_sum_norm_inf(len(mats), npts, n, *ptrs, address(coefs), address(acc), address(stamp),
                                 address(touched), address(local))
        else:
            for q in range(npts):
                S = sum(c * sp.csr_matrix((x[2], x[1], x[0]), shape=(n, ncol)) for c, x in zip(coefs[:, q], csrs))
                local[q] = float(np.max(np.asarray(abs(S).sum(axis=1))))
    out = np.empty_like(local)
    comm.Allreduce(local, out, op=MPI.MAX)
    return out
