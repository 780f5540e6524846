"""A serial sparse Cholesky factorisation A = L Lᵀ by CHOLMOD, called directly (ctypes).

PETSc's CHOLMOD interface serves a Krylov solver one vector at a time; a block eigensolver wants
the factorisation itself: a fill-reducing order handed in (no permuted copies of K and M), the
supernodal factor, and block solves on column-major NumPy arrays without PETSc dense matrices on
the way.  This module gives that and nothing else: :class:`Cholesky` owns one CHOLMOD workspace
and one factor (state with a lifecycle: :meth:`Cholesky.close` frees them).

CHOLMOD is the ``libcholmod.so.3`` that Debian's PETSc links (SuiteSparse 5), with 32-bit indices
(``cholmod_*``, not ``cholmod_l_*``).  The ``cholmod_common`` layout below is that of CHOLMOD 3.0
(SuiteSparse 5.x); :func:`available` checks it field by field against the defaults
``cholmod_start`` writes, so another layout is detected and the caller keeps PETSc's path.
"""
from __future__ import annotations

import ctypes
import time
from functools import lru_cache

import numpy as np

from fem_squeal.util.native import first_library

# cholmod_core.h / cholmod_cholesky.h (SuiteSparse 5.12)
_INT, _REAL, _DOUBLE = 0, 1, 0         # itype, xtype, dtype
_OK, _NOT_POSDEF = 0, 1                # Common->status
_GIVEN, _AMD, _METIS = 1, 2, 3         # method[].ordering
_SUPERNODAL = 2
_SOLVE_A = 0                           # cholmod_solve: A x = b
_MAXMETHODS = 9
_HOST_BUFFERS = 8
# Relaxed supernode amalgamation: fundamental supernodes merge into larger ones (more BLAS-3 work
# per call, a few explicit zeros) while a merged supernode has fewer than nrelax[0] columns, or
# fewer than nrelax[1] / nrelax[2] with at most zrelax[0] / [1] / [2] of its entries zero.  CHOLMOD's
# defaults are (4, 16, 48) and (0.8, 0.1, 0.05).  Measured on the clamped P2 disc, 255k DOFs, METIS
# node order, 4 interleaved repeats (min / median seconds of analysis + factorisation): defaults
# 3.71 / 3.95, (16, 48, 128) with the default zrelax 3.11 / 3.49, (16, 64, 192) with
# (0.9, 0.2, 0.1) 2.98 / 3.22; block solves of 8 and 16 columns unchanged (0.25, 0.29 s).
NRELAX = (16, 64, 192)
ZRELAX = (0.9, 0.2, 0.1)


class _Method(ctypes.Structure):
    _fields_ = [("lnz", ctypes.c_double), ("fl", ctypes.c_double), ("prune_dense", ctypes.c_double),
                ("prune_dense2", ctypes.c_double), ("nd_oksep", ctypes.c_double),
                ("other_1", ctypes.c_double * 4), ("nd_small", ctypes.c_size_t),
                ("other_2", ctypes.c_size_t * 4), ("aggressive", ctypes.c_int), ("order_for_lu", ctypes.c_int),
                ("nd_compress", ctypes.c_int), ("nd_camd", ctypes.c_int), ("nd_components", ctypes.c_int),
                ("ordering", ctypes.c_int), ("other_3", ctypes.c_size_t * 4)]


class _Common(ctypes.Structure):
    """``cholmod_common`` up to the statistics this module reads, then room for the rest (SPQR, GPU
    and timing fields: ~1 kB; 16 kB reserved)."""
    _fields_ = [("dbound", ctypes.c_double), ("grow0", ctypes.c_double), ("grow1", ctypes.c_double),
                ("grow2", ctypes.c_size_t), ("maxrank", ctypes.c_size_t), ("supernodal_switch", ctypes.c_double),
                ("supernodal", ctypes.c_int), ("final_asis", ctypes.c_int), ("final_super", ctypes.c_int),
                ("final_ll", ctypes.c_int), ("final_pack", ctypes.c_int), ("final_monotonic", ctypes.c_int),
                ("final_resymbol", ctypes.c_int), ("zrelax", ctypes.c_double * 3),
                ("nrelax", ctypes.c_size_t * 3), ("prefer_zomplex", ctypes.c_int),
                ("prefer_upper", ctypes.c_int), ("quick_return_if_not_posdef", ctypes.c_int),
                ("prefer_binary", ctypes.c_int), ("print", ctypes.c_int), ("precise", ctypes.c_int),
                ("try_catch", ctypes.c_int), ("error_handler", ctypes.c_void_p), ("nmethods", ctypes.c_int),
                ("current", ctypes.c_int), ("selected", ctypes.c_int),
                ("method", _Method * (_MAXMETHODS + 1)), ("postorder", ctypes.c_int),
                ("default_nesdis", ctypes.c_int), ("metis_memory", ctypes.c_double),
                ("metis_dswitch", ctypes.c_double), ("metis_nswitch", ctypes.c_size_t),
                ("nrow", ctypes.c_size_t), ("mark", ctypes.c_long), ("iworksize", ctypes.c_size_t),
                ("xworksize", ctypes.c_size_t), ("Flag", ctypes.c_void_p), ("Head", ctypes.c_void_p),
                ("Xwork", ctypes.c_void_p), ("Iwork", ctypes.c_void_p), ("itype", ctypes.c_int),
                ("dtype", ctypes.c_int), ("no_workspace_reallocate", ctypes.c_int), ("status", ctypes.c_int),
                ("fl", ctypes.c_double), ("lnz", ctypes.c_double), ("anz", ctypes.c_double),
                ("modfl", ctypes.c_double), ("malloc_count", ctypes.c_size_t),
                ("memory_usage", ctypes.c_size_t), ("memory_inuse", ctypes.c_size_t),
                ("_rest", ctypes.c_char * 16384)]


class _Sparse(ctypes.Structure):
    _fields_ = [("nrow", ctypes.c_size_t), ("ncol", ctypes.c_size_t), ("nzmax", ctypes.c_size_t),
                ("p", ctypes.c_void_p), ("i", ctypes.c_void_p), ("nz", ctypes.c_void_p), ("x", ctypes.c_void_p),
                ("z", ctypes.c_void_p), ("stype", ctypes.c_int), ("itype", ctypes.c_int), ("xtype", ctypes.c_int),
                ("dtype", ctypes.c_int), ("sorted", ctypes.c_int), ("packed", ctypes.c_int)]


class _Dense(ctypes.Structure):
    _fields_ = [("nrow", ctypes.c_size_t), ("ncol", ctypes.c_size_t), ("nzmax", ctypes.c_size_t),
                ("d", ctypes.c_size_t), ("x", ctypes.c_void_p), ("z", ctypes.c_void_p), ("xtype", ctypes.c_int),
                ("dtype", ctypes.c_int)]


_P = ctypes.POINTER


class NotPositiveDefinite(ArithmeticError):
    """CHOLMOD met a non-positive pivot (the matrix is not positive definite)."""


@lru_cache(maxsize=1)
def _lib() -> ctypes.CDLL | None:
    lib = first_library(("libcholmod.so.3",), "cholmod_analyze_p", search=("cholmod",))
    if lib is None:
        return None
    c = _P(_Common)
    sigs = {"cholmod_start": [c], "cholmod_finish": [c],
            "cholmod_analyze_p": [_P(_Sparse), ctypes.c_void_p, ctypes.c_void_p, ctypes.c_size_t, c],
            "cholmod_factorize": [_P(_Sparse), ctypes.c_void_p, c],
            "cholmod_solve2": [ctypes.c_int, ctypes.c_void_p, _P(_Dense), ctypes.c_void_p, _P(_P(_Dense)),
                               ctypes.c_void_p, _P(_P(_Dense)), _P(_P(_Dense)), c],
            "cholmod_free_factor": [_P(ctypes.c_void_p), c], "cholmod_free_dense": [_P(_P(_Dense)), c]}
    for name, args in sigs.items():
        f = getattr(lib, name)
        f.argtypes = args
        f.restype = ctypes.c_void_p if name == "cholmod_analyze_p" else ctypes.c_int
    return lib if _layout_ok(lib) else None


def _layout_ok(lib: ctypes.CDLL) -> bool:
    """``cholmod_start``'s documented defaults, read through this module's ``cholmod_common``: a
    different layout (another CHOLMOD version) puts other numbers in these fields."""
    c = _Common()
    lib.cholmod_start(ctypes.byref(c))
    try:
        return (c.dbound == 0.0 and c.grow0 == 1.2 and c.grow1 == 1.2 and c.grow2 == 5 and c.maxrank == 8
                and c.supernodal_switch == 40.0 and c.final_asis == 1 and list(c.zrelax) == [0.8, 0.1, 0.05]
                and list(c.nrelax) == [4, 16, 48] and c.nmethods == 0 and c.method[0].ordering == _GIVEN
                and c.method[1].ordering == _AMD and c.method[2].ordering == _METIS and c.postorder == 1
                and c.metis_nswitch == 3000 and c.status == _OK and c.itype == _INT and c.dtype == _DOUBLE)
    finally:
        lib.cholmod_finish(ctypes.byref(c))


def available() -> bool:
    """libcholmod is loadable and has the ``cholmod_common`` layout this module was written for."""
    return _lib() is not None


class Cholesky:
    """The supernodal factorisation P A Pᵀ = L Lᵀ of a symmetric positive definite matrix given by
    its CSR arrays (both triangles or the upper one: entries below the diagonal are not read).

    ``perm``: the fill-reducing order (new row i = old row perm[i]), used as given; None lets
    CHOLMOD choose (its default: AMD, then METIS where AMD's fill is poor).  Raises
    :class:`NotPositiveDefinite` if a pivot is not positive, ``MemoryError`` if CHOLMOD runs out.
    :meth:`solve` returns A⁻¹B for column-major blocks B; :meth:`close` frees the factor."""

    def __init__(self, indptr: np.ndarray, indices: np.ndarray, data: np.ndarray,
                 perm: np.ndarray | None = None) -> None:
        lib = _lib()
        if lib is None:
            raise RuntimeError("CHOLMOD (libcholmod.so.3, SuiteSparse 5) is not available")
        self._lib, self._c, self._L = lib, _Common(), ctypes.c_void_p()
        self._work = [ctypes.POINTER(_Dense)() for _ in range(3)]     # X, Y, E of cholmod_solve2
        lib.cholmod_start(ctypes.byref(self._c))
        c = self._c
        c.print = 0                           # no messages: the status is checked here
        c.supernodal = _SUPERNODAL
        c.quick_return_if_not_posdef = 1
        c.nrelax[:] = NRELAX
        c.zrelax[:] = ZRELAX
        n = len(indptr) - 1
        # CSR of a symmetric matrix = CSC of the same: "upper" in CHOLMOD's column view is "lower" here;
        # the arrays need to live only through analysis and factorisation (the factor is CHOLMOD's own)
        ip, ii, x = (np.ascontiguousarray(indptr, np.int32), np.ascontiguousarray(indices, np.int32),
                     np.ascontiguousarray(data, np.float64))
        A = _Sparse(nrow=n, ncol=n, nzmax=len(ii), p=ip.ctypes.data, i=ii.ctypes.data, nz=None,
                    x=x.ctypes.data, z=None, stype=-1, itype=_INT, xtype=_REAL, dtype=_DOUBLE, sorted=0,
                    packed=1)
        self.n = n
        user = None
        if perm is not None:
            perm = np.ascontiguousarray(perm, np.int32)
            user = perm.ctypes.data
            c.nmethods, c.method[0].ordering = 1, _GIVEN
        try:
            t0 = time.perf_counter()
            self._L.value = lib.cholmod_analyze_p(ctypes.byref(A), user, None, 0, ctypes.byref(c))
            self._raise("analysis")
            t1 = time.perf_counter()
            lib.cholmod_factorize(ctypes.byref(A), self._L, ctypes.byref(c))
            self._raise("factorisation")
            self.seconds = {"analysis": t1 - t0, "numeric": time.perf_counter() - t1}
        except BaseException:
            self.close()
            raise
        self.flops, self.factor_entries = float(c.fl), float(c.lnz)

    def _raise(self, what: str) -> None:
        status = self._c.status
        if status == _NOT_POSDEF:
            raise NotPositiveDefinite(f"CHOLMOD {what}: the matrix is not positive definite")
        if status == -2:
            raise MemoryError(f"CHOLMOD {what}: out of memory")
        if status != _OK or not self._L.value:
            raise RuntimeError(f"CHOLMOD {what} failed (status {status})")

    def solve(self, B: np.ndarray) -> np.ndarray:
        """A⁻¹ B, B of shape (n,) or (n, k); the result is a new column-major array."""
        B = np.asfortranarray(B, dtype=np.float64)
        vec = B.ndim == 1
        B2 = B.reshape(self.n, -1, order="F")
        k = B2.shape[1]
        D = _Dense(nrow=self.n, ncol=k, nzmax=self.n * k, d=self.n, x=B2.ctypes.data, z=None, xtype=_REAL,
                   dtype=_DOUBLE)
        X, Y, E = self._work
        ok = self._lib.cholmod_solve2(_SOLVE_A, self._L, ctypes.byref(D), None, ctypes.byref(X), None,
                                      ctypes.byref(Y), ctypes.byref(E), ctypes.byref(self._c))
        if not ok or self._c.status != _OK:
            raise RuntimeError(f"CHOLMOD solve failed (status {self._c.status})")
        out = np.array(np.ctypeslib.as_array(ctypes.cast(X.contents.x, _P(ctypes.c_double)),
                                             shape=(k, X.contents.d)).T[:self.n], order="F")
        return out[:, 0] if vec else out

    def close(self) -> None:
        """Free the factor, the solve workspace and CHOLMOD's own workspace (idempotent)."""
        lib, c = self._lib, getattr(self, "_c", None)
        if c is None:
            return
        for w in self._work:
            if w:
                lib.cholmod_free_dense(ctypes.byref(w), ctypes.byref(c))
        if self._L.value:
            lib.cholmod_free_factor(ctypes.byref(self._L), ctypes.byref(c))
        lib.cholmod_finish(ctypes.byref(c))
        self._c = None

    def __enter__(self) -> Cholesky:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def __del__(self) -> None:
        self.close()
