"""A serial sparse Cholesky factorisation A = L Lᵀ by CHOLMOD, called directly.

PETSc's CHOLMOD interface serves a Krylov solver one vector at a time; a block eigensolver wants
the factorisation itself: a fill-reducing order handed in (no permuted copies of K and M), the
supernodal factor, and block solves on column-major NumPy arrays without PETSc dense matrices on
the way.  This module gives that and nothing else: :class:`Cholesky` owns one CHOLMOD workspace
and one factor (state with a lifecycle: :meth:`Cholesky.close` frees them).

CHOLMOD is reached through the package's compiled shim (``fem_squeal/fe/kernels/cholmod_shim.c``,
built with the package against the ``cholmod.h`` of the CHOLMOD it links: Debian's SuiteSparse),
so no CHOLMOD structure is laid out by hand here; 32-bit indices.  Where the shim was not built,
:func:`available` is False and the callers keep PETSc's path (``results.json`` says which ran).
"""
from __future__ import annotations

import ctypes
import time
from functools import lru_cache

import numpy as np

from fem_squeal.fe import kernels
from fem_squeal.fe.ordering import is_permutation
from fem_squeal.util.blas import serial_openmp
from fem_squeal.util.native import address

_OK, _NOT_POSDEF, _OUT_OF_MEMORY = 0, 1, -2        # CHOLMOD's Common->status
# Relaxed supernode amalgamation: fundamental supernodes merge into larger ones (more BLAS-3 work
# per call, a few explicit zeros) while a merged supernode has fewer than nrelax[0] columns, or
# fewer than nrelax[1] / nrelax[2] with at most zrelax[0] / [1] / [2] of its entries zero.  CHOLMOD's
# defaults are (4, 16, 48) and (0.8, 0.1, 0.05).  Chosen by the sum of analysis + factorisation
# and 13 block solves of 8 columns (the 20 modes' Lanczos), clamped P2 disc, CHOLMOD's OpenMP off
# (fem_squeal.util.blas.serial_openmp), the 12-column solve kernel, min of 2-5 repeats, seconds at
# 26k / 87k / 255k DOFs: defaults 0.171 / 0.946 / 4.97; (16, 64, 192) with (0.9, 0.2, 0.1), the
# choice while CHOLMOD's 4 OpenMP threads woke for every supernode, 0.174 / 0.983 / 5.20; these
# 0.164 / 0.938 / 4.91 (and (16, 64, 192) with these zrelax 0.167 / 0.935 / 4.89).
NRELAX = (8, 32, 64)
ZRELAX = (0.5, 0.1, 0.05)


# The block solve L Lᵀ X = B on CHOLMOD's supernodal factor, up to 16 right-hand sides per pass:
# CHOLMOD's own (cholmod_solve2) calls BLAS dtrsm and dgemm per supernode, whose packing of L
# doubles the memory traffic when B has a few columns.  Here each supernode's column panel
# (nsrow × nscol, column major, L->x + px[s]; rows L->s[pi[s] ...]) is read from memory once per
# sweep, CB columns at a time against the panel's rows of Y gathered into a small row-major buffer
# (8 right-hand sides are one 64-byte line; a second 8 reuse the CB columns from cache).
# Built twice (fem_squeal/fe/kernels/supernodal_solve.c, with the package): for AVX-512 (x86-64-v4)
# with the 8 right-hand sides of a row in one 512-bit register, and for AVX2 + FMA (x86-64-v3) with
# them in two 256-bit ones (GCC splits a 512-bit vector type badly there: 2.5× slower); sn_level
# picks one for the CPU, and without AVX2 (or off x86-64) CHOLMOD's solve is used.  Both make the same
# operations in the same order: the same result to the bit.  Clamped P2 disc, 1 thread, 8 columns
# at 26k / 87k / 260k DOFs: CHOLMOD 13.1 / 64 / 267 ms; this kernel with 4 columns per pass
# (AVX2) 10.9 / 49 / 186 ms; with 12 (CB) 8.4 / 38 / 147 ms (AVX2) and 6.7 / 31 / 120 ms
# (AVX-512, Zen 5).  16 columns at 26k / 260k: CHOLMOD 19.6 / 372 ms, AVX-512 10.1 / 171 ms.  The
# same solution as CHOLMOD's to round-off (1e-20 of max |x|).
# Blocks of MIN_BLOCK to MAX_BLOCK columns take the compiled solve (padded to a multiple of 8);
# others CHOLMOD's: at 260k DOFs 3 columns cost the same in both, and a single column is CHOLMOD's.
WMAX = 16        # right-hand sides per pass of the compiled solve (its C constant)
MIN_BLOCK, MAX_BLOCK = 4, WMAX




@lru_cache(maxsize=1)
def _solve_lib() -> tuple[ctypes.CDLL, int] | None:
    """The compiled block solve and the CPU's level for it (4: AVX-512, 3: AVX2 + FMA), where it was
    built and the CPU has at least AVX2 and FMA; else None (CHOLMOD's solve)."""
    lib = kernels.library("supernodal_solve")
    if lib is None:
        return None
    lib.sn_level.restype = ctypes.c_int
    level = lib.sn_level()
    if level < 3:
        return None
    lib.sn_wmax.restype = ctypes.c_int
    if lib.sn_wmax() != WMAX:
        return None
    i32, i64, p = ctypes.c_int32, ctypes.c_int64, ctypes.c_void_p
    lib.sn_solve.argtypes = [i32, i32, i32, p, p, p, p, p, p, i32, p, i64, p, i64, p, p]
    lib.sn_solve.restype = None
    lib.sn_partial.argtypes = [i32, i32, i32, i32, p, p, p, p, p, p, p, i32]
    lib.sn_partial.restype = None
    return lib, level


def _aligned(n: int) -> np.ndarray:
    """``n`` doubles starting on a 64-byte boundary."""
    raw = np.empty(n + 8)
    off = (-raw.ctypes.data % 64) // 8
    return raw[off:off + n]


def aligned_rows(n: int, w: int) -> np.ndarray:
    """An n × w row-major array of doubles starting on a 64-byte boundary (for :meth:`Cholesky.sweep`)."""
    return _aligned(n * w).reshape(n, w)


class NotPositiveDefinite(ArithmeticError):
    """CHOLMOD met a non-positive pivot (the matrix is not positive definite)."""


@lru_cache(maxsize=1)
def _lib() -> ctypes.CDLL | None:
    """The CHOLMOD shim with its signatures, or None where it was not built."""
    lib = kernels.library("cholmod_shim")
    if lib is None:
        return None
    p, i32, i64, dp = ctypes.c_void_p, ctypes.c_int32, ctypes.c_int64, ctypes.POINTER(ctypes.c_double)
    for name, args, res in (("fsc_version", [], ctypes.c_int), ("fsc_new", [p, p], p),
                            ("fsc_analyze", [p, i32, p, p, p, p], ctypes.c_int),
                            ("fsc_factorize", [p, i32, p, p, p], ctypes.c_int), ("fsc_stats", [p, dp, dp], None),
                            ("fsc_supernodes", [p, p, p], ctypes.c_int),
                            ("fsc_solve", [p, i32, i32, p, i64, p, i64], ctypes.c_int), ("fsc_free", [p], None),
                            ("fsc_set_postorder", [p, ctypes.c_int], None)):
        f = getattr(lib, name)
        f.argtypes, f.restype = args, res
    return lib


def available() -> bool:
    """CHOLMOD is reachable: the package's shim was built (against cholmod.h) and loads."""
    return _lib() is not None


def version() -> str | None:
    """The CHOLMOD version the shim was built against (``"3.0.14"``), or None."""
    lib = _lib()
    if lib is None:
        return None
    v = lib.fsc_version()
    return f"{v // 10000}.{v // 100 % 100}.{v % 100}"


class Cholesky:
    """The supernodal factorisation P A Pᵀ = L Lᵀ of a symmetric positive definite matrix given by
    its CSR arrays (both triangles or the upper one: entries below the diagonal are not read).

    ``perm``: the fill-reducing order (new row i = old row perm[i]), used as given; None lets
    CHOLMOD choose (its default: AMD, then METIS where AMD's fill is poor).  ``keep_order``: the
    factor's order is ``perm`` exactly (CHOLMOD does not postorder its elimination tree after it), so
    that rows ordered last stay last (:meth:`sweep`).  Raises :class:`NotPositiveDefinite` if a pivot
    is not positive, ``MemoryError`` if CHOLMOD runs out.  :meth:`solve` returns A⁻¹B for
    column-major blocks B; :meth:`close` frees the factor."""

    def __init__(self, indptr: np.ndarray, indices: np.ndarray, data: np.ndarray,
                 perm: np.ndarray | None = None, keep_order: bool = False) -> None:
        lib = _lib()
        if lib is None:
            raise RuntimeError("CHOLMOD is not available (the package's cholmod_shim kernel was not built)")
        self._lib, self._panels = lib, None
        self._h = ctypes.c_void_p(lib.fsc_new(address(np.array(NRELAX, np.int64)),
                                              address(np.array(ZRELAX, np.float64))))
        if not self._h.value:
            raise MemoryError("CHOLMOD: out of memory starting a workspace")
        n = len(indptr) - 1
        # the arrays need to live only through analysis and factorisation (the factor is CHOLMOD's own)
        ip, ii, x = (np.ascontiguousarray(indptr, np.int32), np.ascontiguousarray(indices, np.int32),
                     np.ascontiguousarray(data, np.float64))
        self.n = n
        user = None
        if perm is not None:
            perm = np.ascontiguousarray(perm, np.int32)
            user = address(perm)
        if keep_order:
            lib.fsc_set_postorder(self._h, 0)
        try:
            with serial_openmp():         # CHOLMOD's 4 OpenMP threads cost more than they save
                t0 = time.perf_counter()
                self._raise("analysis", lib.fsc_analyze(self._h, n, address(ip), address(ii), address(x), user))
                t1 = time.perf_counter()
                self._raise("factorisation", lib.fsc_factorize(self._h, n, address(ip), address(ii), address(x)))
            self.seconds = {"analysis": t1 - t0, "numeric": time.perf_counter() - t1}
        except BaseException:
            self.close()
            raise
        fl, lnz = ctypes.c_double(), ctypes.c_double()
        lib.fsc_stats(self._h, ctypes.byref(fl), ctypes.byref(lnz))
        self.flops, self.factor_entries = fl.value, lnz.value
        self._panels = self._supernodes()

    def _supernodes(self) -> tuple | None:
        """What the compiled block solve reads from the factor (views of CHOLMOD's arrays, valid
        while it lives) and its workspace; None where it does not apply.  The arrays are checked
        against what is known: a supernodal LLᵀ of this size whose last pointers close the arrays
        and whose permutation is one."""
        got = _solve_lib()
        panels = self.supernodes()
        if got is None or panels is None:
            return None
        sup, pi, px, s, x, perm = panels
        return (*got, len(sup) - 1, sup, pi, px, s, ctypes.c_void_p(x.ctypes.data), perm,
                _aligned(WMAX * self.n), _aligned(WMAX * int(np.max(np.diff(pi)))))

    def supernodes(self) -> tuple[np.ndarray, ...] | None:
        """The supernodal factor as views of CHOLMOD's arrays (valid while it lives): super, pi, px, s
        (int32), x (the values), Perm (the factor's order); None where it is not a supernodal LLᵀ.
        Panel k holds columns super[k] … super[k+1] − 1, column major with rows s[pi[k] …] from
        x[px[k]].  The arrays are checked against what is known: this size, last pointers that close
        the arrays, a permutation."""
        sizes = np.zeros(4, np.int64)
        ptrs = (ctypes.c_void_p * 6)()
        if not self._lib.fsc_supernodes(self._h, address(sizes), ptrs):
            return None
        n, ns, ssize, xsize = (int(v) for v in sizes)
        if n != self.n:
            return None

        def ints(ptr, m):
            return np.ctypeslib.as_array(ctypes.cast(ptr, ctypes.POINTER(ctypes.c_int32)), shape=(m,))
        sup, pi, px = ints(ptrs[0], ns + 1), ints(ptrs[1], ns + 1), ints(ptrs[2], ns + 1)
        perm = ints(ptrs[5], n)
        if not (sup[0] == 0 and sup[-1] == n and pi[0] == 0 and pi[-1] == ssize and px[0] == 0
                and px[-1] == xsize and np.all(np.diff(sup) > 0) and np.all(np.diff(pi) >= np.diff(sup))
                and is_permutation(perm)):
            return None
        x = np.ctypeslib.as_array(ctypes.cast(ptrs[4], ctypes.POINTER(ctypes.c_double)), shape=(xsize,))
        return sup, pi, px, ints(ptrs[3], ssize), x, perm

    def factor_values(self) -> np.ndarray | None:
        """A copy of the supernodal factor's values (L->x, xsize doubles); None where it is not one."""
        panels = self.supernodes()
        return None if panels is None else panels[4].copy()

    def trailing_block(self, start: int) -> np.ndarray:
        """L₂₂: rows and columns ``start`` … n − 1 of the factor L (in its order), dense lower triangular."""
        sup, pi, px, s, x, _ = self.supernodes()
        m = self.n - start
        out = np.zeros((m, m))
        for k in range(int(np.searchsorted(sup, start, side="right")) - 1, len(sup) - 1):
            ncol, nrow = sup[k + 1] - sup[k], pi[k + 1] - pi[k]
            panel = x[px[k]:px[k] + ncol * nrow].reshape(ncol, nrow)        # row c: column sup[k] + c
            rows = s[pi[k]:pi[k + 1]] - start
            for c in range(max(0, start - sup[k]), ncol):
                out[rows[c:], sup[k] + c - start] = panel[c, c:]
        return out

    def can_sweep(self) -> bool:
        """:meth:`sweep` is available (the compiled block solve applies to this factor)."""
        return self._panels is not None

    def sweep(self, Y: np.ndarray, ncols: int, back: bool) -> None:
        """In place on Y (rows in the factor's order, row major, a multiple of 8 columns, 64-byte
        aligned: :func:`aligned_rows`): with L = [L₁₁ 0; L₂₁ L₂₂] split after ``ncols`` columns,
        forward Y₁ ← L₁₁⁻¹Y₁, Y₂ ← Y₂ − L₂₁Y₁; backward (``back``) Y₁ ← L₁₁⁻ᵀ(Y₁ − L₂₁ᵀY₂)."""
        lib, level, ns, sup, pi, px, s, Lx, _, _, buf = self._panels
        w = Y.shape[1]
        if not (Y.flags.c_contiguous and Y.shape[0] == self.n and w % 8 == 0 and w <= WMAX
                and Y.ctypes.data % 64 == 0):
            raise ValueError("sweep: Y must be C-contiguous n × (8 or 16), 64-byte aligned")
        lib.sn_partial(level, int(back), ncols, ns, address(sup), address(pi), address(px), address(s), Lx,
                       address(Y), address(buf), w)

    @staticmethod
    def _raise(what: str, status: int) -> None:
        if status == _NOT_POSDEF:
            raise NotPositiveDefinite(f"CHOLMOD {what}: the matrix is not positive definite")
        if status == _OUT_OF_MEMORY:
            raise MemoryError(f"CHOLMOD {what}: out of memory")
        if status != _OK:
            raise RuntimeError(f"CHOLMOD {what} failed (status {status})")

    def solve(self, B: np.ndarray) -> np.ndarray:
        """A⁻¹ B, B of shape (n,) or (n, k); the result is a new column-major array.  Blocks of
        :data:`MIN_BLOCK` to :data:`MAX_BLOCK` columns go through the compiled supernodal block solve where it
        applies, others through ``cholmod_solve2``."""
        B = np.asfortranarray(B, dtype=np.float64)
        vec = B.ndim == 1
        B2 = B.reshape(self.n, -1, order="F")
        k = B2.shape[1]
        out = np.empty((self.n, k), order="F")
        if self._panels is not None and MIN_BLOCK <= k <= MAX_BLOCK:
            lib, level, ns, sup, pi, px, s, Lx, perm, Y, buf = self._panels
            lib.sn_solve(level, self.n, ns, address(sup), address(pi), address(px), address(s), Lx,
                         address(perm), k, address(B2), self.n, address(out), self.n, address(Y), address(buf))
            kernels.note("block_solve", "compiled-avx512" if level == 4 else "compiled-avx2")
            return out
        kernels.note("block_solve", "cholmod")
        status = self._lib.fsc_solve(self._h, self.n, k, address(B2), self.n, address(out), self.n)
        if status != _OK:
            raise RuntimeError(f"CHOLMOD solve failed (status {status})")
        return out[:, 0] if vec else out

    def close(self) -> None:
        """Free the factor, the solve workspace and CHOLMOD's own workspace (idempotent)."""
        h = getattr(self, "_h", None)
        if h is None or not h.value:
            return
        self._panels = None                  # views of the factor's arrays: gone with it
        self._lib.fsc_free(h)
        self._h = None

    def __enter__(self) -> Cholesky:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def __del__(self) -> None:
        self.close()
