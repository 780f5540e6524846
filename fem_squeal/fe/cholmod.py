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

from fem_squeal.fe.ordering import is_permutation
from fem_squeal.util.blas import serial_openmp
from fem_squeal.util.native import address, compiled_library, first_library

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
# defaults are (4, 16, 48) and (0.8, 0.1, 0.05).  Chosen by the sum of analysis + factorisation
# and 13 block solves of 8 columns (the 20 modes' Lanczos), clamped P2 disc, CHOLMOD's OpenMP off
# (fem_squeal.util.blas.serial_openmp), the 12-column solve kernel, min of 2-5 repeats, seconds at
# 26k / 87k / 255k DOFs: defaults 0.171 / 0.946 / 4.97; (16, 64, 192) with (0.9, 0.2, 0.1), the
# choice while CHOLMOD's 4 OpenMP threads woke for every supernode, 0.174 / 0.983 / 5.20; these
# 0.164 / 0.938 / 4.91 (and (16, 64, 192) with these zrelax 0.167 / 0.935 / 4.89).
NRELAX = (8, 32, 64)
ZRELAX = (0.5, 0.1, 0.05)


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


class _Factor(ctypes.Structure):
    """``cholmod_factor`` (CHOLMOD 3): the supernodal fields the block solve reads."""
    _fields_ = [("n", ctypes.c_size_t), ("minor", ctypes.c_size_t), ("Perm", ctypes.c_void_p),
                ("ColCount", ctypes.c_void_p), ("IPerm", ctypes.c_void_p), ("nzmax", ctypes.c_size_t),
                ("p", ctypes.c_void_p), ("i", ctypes.c_void_p), ("x", ctypes.c_void_p), ("z", ctypes.c_void_p),
                ("nz", ctypes.c_void_p), ("next", ctypes.c_void_p), ("prev", ctypes.c_void_p),
                ("nsuper", ctypes.c_size_t), ("ssize", ctypes.c_size_t), ("xsize", ctypes.c_size_t),
                ("maxcsize", ctypes.c_size_t), ("maxesize", ctypes.c_size_t), ("super", ctypes.c_void_p),
                ("pi", ctypes.c_void_p), ("px", ctypes.c_void_p), ("s", ctypes.c_void_p),
                ("ordering", ctypes.c_int), ("is_ll", ctypes.c_int), ("is_super", ctypes.c_int),
                ("is_monotonic", ctypes.c_int), ("itype", ctypes.c_int), ("xtype", ctypes.c_int),
                ("dtype", ctypes.c_int), ("useGPU", ctypes.c_int)]


_P = ctypes.POINTER

# The block solve L Lᵀ X = B on CHOLMOD's supernodal factor, up to 16 right-hand sides per pass:
# CHOLMOD's own (cholmod_solve2) calls BLAS dtrsm and dgemm per supernode, whose packing of L
# doubles the memory traffic when B has a few columns.  Here each supernode's column panel
# (nsrow × nscol, column major, L->x + px[s]; rows L->s[pi[s] ...]) is read from memory once per
# sweep, CB columns at a time against the panel's rows of Y gathered into a small row-major buffer
# (8 right-hand sides are one 64-byte line; a second 8 reuse the CB columns from cache).
# Built twice from one text (_SOLVE_KERNEL): for AVX-512 (x86-64-v4) with the 8 right-hand sides
# of a row in one 512-bit register, and for AVX2 + FMA (x86-64-v3) with them in two 256-bit ones
# (GCC splits a 512-bit vector type badly there: 2.5× slower); sn_level picks one for the CPU, and
# without AVX2 CHOLMOD's solve is used (faster than this kernel there).  Both make the same
# operations in the same order: the same result to the bit.  Clamped P2 disc, 1 thread, 8 columns
# at 26k / 87k / 260k DOFs: CHOLMOD 13.1 / 64 / 267 ms; this kernel with 4 columns per pass
# (AVX2) 10.9 / 49 / 186 ms; with 12 (CB) 8.4 / 38 / 147 ms (AVX2) and 6.7 / 31 / 120 ms
# (AVX-512, Zen 5).  16 columns at 26k / 260k: CHOLMOD 19.6 / 372 ms, AVX-512 10.1 / 171 ms.  The
# same solution as CHOLMOD's to round-off (1e-20 of max |x|).
_SOLVE_VECTORS = {
    "v3": r"""
typedef double v4_v3 __attribute__((vector_size(32)));       /* Y and buf rows are 64-byte aligned */
typedef struct { v4_v3 lo, hi; } v8_v3;
INLINE v8_v3 ld_v3(const double *p)
{ v8_v3 v; v.lo = *(const v4_v3 *)p; v.hi = *(const v4_v3 *)(p + 4); return v; }
INLINE void st_v3(double *p, v8_v3 v) { *(v4_v3 *)p = v.lo; *(v4_v3 *)(p + 4) = v.hi; }
INLINE v8_v3 zero_v3(void) { v8_v3 v; v.lo = v.hi = (v4_v3){0, 0, 0, 0}; return v; }
INLINE v8_v3 fms_v3(v8_v3 y, double a, v8_v3 x) { y.lo -= a * x.lo; y.hi -= a * x.hi; return y; }
INLINE v8_v3 fma_v3(v8_v3 y, double a, v8_v3 x) { y.lo += a * x.lo; y.hi += a * x.hi; return y; }
INLINE v8_v3 sub_v3(v8_v3 y, v8_v3 x) { y.lo -= x.lo; y.hi -= x.hi; return y; }
INLINE v8_v3 divs_v3(v8_v3 y, double d) { y.lo /= d; y.hi /= d; return y; }
""",
    "v4": r"""
typedef double v8_v4 __attribute__((vector_size(64)));       /* Y and buf rows are 64-byte aligned */
INLINE v8_v4 ld_v4(const double *p) { return *(const v8_v4 *)p; }
INLINE void st_v4(double *p, v8_v4 v) { *(v8_v4 *)p = v; }
INLINE v8_v4 zero_v4(void) { return (v8_v4){0, 0, 0, 0, 0, 0, 0, 0}; }
INLINE v8_v4 fms_v4(v8_v4 y, double a, v8_v4 x) { return y - a * x; }
INLINE v8_v4 fma_v4(v8_v4 y, double a, v8_v4 x) { return y + a * x; }
INLINE v8_v4 sub_v4(v8_v4 y, v8_v4 x) { return y - x; }
INLINE v8_v4 divs_v4(v8_v4 y, double d) { return y / d; }
"""}
# One build of the kernel: "_V" names its vector type and helpers, replaced by "_v3" or "_v4".
_SOLVE_KERNEL = r"""
/* rows r0 … nsrow−1 of b −= Σ_{c<n} L0[c·nsrow + r] x[c] (the panel's rows below a block) */
INLINE void update_V(int32_t n, int32_t r0, int32_t nsrow, const double *L0, const v8_V *x, double *b, int32_t w)
{
    for (int32_t r = r0; r < nsrow; ++r) {
        v8_V v = ld_V(b + (int64_t)r * w);
        for (int32_t c = 0; c < n; ++c)
            v = fms_V(v, L0[(int64_t)c * nsrow + r], x[c]);
        st_V(b + (int64_t)r * w, v);
    }
}

/* acc[c] = Σ_{r ≥ r0} L0[c·nsrow + r] b[r] for c < n (a block's products with the rows below it) */
INLINE void sums_V(int32_t n, int32_t r0, int32_t nsrow, const double *L0, const double *b, int32_t w, v8_V *acc)
{
    for (int32_t c = 0; c < n; ++c)
        acc[c] = zero_V();
    for (int32_t r = r0; r < nsrow; ++r) {
        const v8_V y = ld_V(b + (int64_t)r * w);
        for (int32_t c = 0; c < n; ++c)
            acc[c] = fma_V(acc[c], L0[(int64_t)c * nsrow + r], y);
    }
}

/* L y = b on one panel: buf holds the panel's rows of Y (the first nscol are its own columns), w
   right-hand sides per row (a multiple of 8), 8 at a time against each CB-column block of the panel
   (the block stays in cache between them: the panel is read from memory once) */
INLINE void forward_V(int32_t nscol, int32_t nsrow, const double *L, double *buf, int32_t w)
{
    for (int32_t c0 = 0; c0 < nscol; c0 += CB) {
        const int32_t cb = nscol - c0 < CB ? nscol - c0 : CB;
        const double *L0 = L + (int64_t)c0 * nsrow;
        for (int32_t q = 0; q < w; q += 8) {
            double *b = buf + q;
            v8_V x[CB];
            for (int32_t c = 0; c < cb; ++c) {                 /* the block's triangle */
                const double *Lc = L + (int64_t)(c0 + c) * nsrow;
                x[c] = divs_V(ld_V(b + (int64_t)(c0 + c) * w), Lc[c0 + c]);
                st_V(b + (int64_t)(c0 + c) * w, x[c]);
                for (int32_t r = c0 + c + 1; r < c0 + cb; ++r)
                    st_V(b + (int64_t)r * w, fms_V(ld_V(b + (int64_t)r * w), Lc[r], x[c]));
            }
            if (cb == CB)       /* the same loop; a constant count lets the compiler unroll it */
                update_V(CB, c0 + CB, nsrow, L0, x, b, w);
            else
                update_V(cb, c0 + cb, nsrow, L0, x, b, w);
        }
    }
}

/* Lᵀ x = y on one panel: rows past nscol of buf hold the solution already */
INLINE void backward_V(int32_t nscol, int32_t nsrow, const double *L, double *buf, int32_t w)
{
    for (int32_t c0 = (nscol - 1) / CB * CB; c0 >= 0; c0 -= CB) {
        const int32_t cb = nscol - c0 < CB ? nscol - c0 : CB;
        const double *L0 = L + (int64_t)c0 * nsrow;
        for (int32_t q = 0; q < w; q += 8) {
            double *b = buf + q;
            v8_V acc[CB];
            if (cb == CB)       /* as in forward_V */
                sums_V(CB, c0 + CB, nsrow, L0, b, w, acc);
            else
                sums_V(cb, c0 + cb, nsrow, L0, b, w, acc);
            for (int32_t c = cb - 1; c >= 0; --c) {             /* the block's triangle */
                const double *Lc = L + (int64_t)(c0 + c) * nsrow;
                v8_V v = sub_V(ld_V(b + (int64_t)(c0 + c) * w), acc[c]);
                for (int32_t r = c0 + c + 1; r < c0 + cb; ++r)
                    v = fms_V(v, Lc[r], ld_V(b + (int64_t)r * w));
                st_V(b + (int64_t)(c0 + c) * w, divs_V(v, Lc[c0 + c]));
            }
        }
    }
}

/* One panel of a sweep: its rows of Y into buf, the panel's solve, back into Y (forward: all its
   rows changed; backward: its own columns only). */
INLINE void sweep_V(int32_t sn, int back, const int32_t *super, const int32_t *pi, const int32_t *px,
                    const int32_t *s, const double *Lx, double *Y, double *buf, int32_t w)
{
    const int32_t nscol = super[sn + 1] - super[sn], nsrow = pi[sn + 1] - pi[sn];
    const int32_t *rows = s + pi[sn];
    for (int32_t r = 0; r < nsrow; ++r)
        for (int32_t q = 0; q < w; q += 8)
            st_V(buf + (int64_t)r * w + q, ld_V(Y + (int64_t)rows[r] * w + q));
    if (back)
        backward_V(nscol, nsrow, Lx + px[sn], buf, w);
    else
        forward_V(nscol, nsrow, Lx + px[sn], buf, w);
    for (int32_t r = 0; r < (back ? nscol : nsrow); ++r)
        for (int32_t q = 0; q < w; q += 8)
            st_V(Y + (int64_t)rows[r] * w + q, ld_V(buf + (int64_t)r * w + q));
}

static void solve_V(int32_t n, int32_t nsuper, const int32_t *super, const int32_t *pi, const int32_t *px,
                    const int32_t *s, const double *Lx, const int32_t *perm, int32_t k, const double *B,
                    int64_t ldb, double *X, int64_t ldx, double *Y, double *buf)
{
    for (int32_t j0 = 0; j0 < k; j0 += WMAX) {
        const int32_t m = k - j0 < WMAX ? k - j0 : WMAX, w = (m + 7) / 8 * 8;
        for (int32_t i = 0; i < n; ++i)
            for (int32_t j = 0; j < w; ++j)
                Y[(int64_t)i * w + j] = j < m ? B[perm[i] + ldb * (j0 + j)] : 0.0;
        for (int32_t sn = 0; sn < nsuper; ++sn)               /* L y = b, panel by panel */
            sweep_V(sn, 0, super, pi, px, s, Lx, Y, buf, w);
        for (int32_t sn = nsuper - 1; sn >= 0; --sn)          /* Lᵀ x = y, in reverse */
            sweep_V(sn, 1, super, pi, px, s, Lx, Y, buf, w);
        for (int32_t i = 0; i < n; ++i)
            for (int32_t j = 0; j < m; ++j)
                X[perm[i] + ldx * (j0 + j)] = Y[(int64_t)i * w + j];
    }
}
"""
_SOLVE_SOURCE = r"""
#include <stdint.h>
#if !defined(__GNUC__) || defined(__clang__) || !defined(__x86_64__)
#error "GCC on x86-64 only (#pragma GCC target per build)"   /* no build: CHOLMOD's solve is used */
#endif
#define INLINE static inline __attribute__((always_inline))
/* Columns of a panel per pass over its rows: each row of buf is loaded and stored once per CB
   columns, and those loads and stores bound the row loops (8-column solve at 26k DOFs, AVX2 /
   AVX-512: 4 columns 10.9 / 9.4 ms, 8: 8.7 / 7.4, 12: 8.5 / 6.6, 16: 9.8 / 6.6, 20: 8.4 / 12.1 ms,
   the AVX-512 registers exhausted).  The same in both builds: the same sums in the same order. */
#define CB 12
#define WMAX 16     /* right-hand sides per pass over the factor, padded to a multiple of 8 */
""" + "".join(f"""
#pragma GCC push_options
#pragma GCC target("arch=x86-64-{isa}")
{_SOLVE_VECTORS[isa]}{_SOLVE_KERNEL.replace("_V", "_" + isa)}
#pragma GCC pop_options
""" for isa in ("v3", "v4")) + r"""
/* 4: AVX-512 (x86-64-v4), 3: AVX2 + FMA, 0: neither (the caller keeps CHOLMOD's solve) */
int sn_level(void)
{
    __builtin_cpu_init();
    if (__builtin_cpu_supports("avx512f") && __builtin_cpu_supports("avx512dq")
            && __builtin_cpu_supports("avx512bw") && __builtin_cpu_supports("avx512vl")
            && __builtin_cpu_supports("avx512cd"))
        return 4;
    return __builtin_cpu_supports("avx2") && __builtin_cpu_supports("fma") ? 3 : 0;
}

/* X = A⁻¹ B, A = Pᵀ L Lᵀ P (row i of P A Pᵀ is row perm[i] of A); B and X column-major n × k with
   leading dimensions ldb, ldx; Y: n × WMAX and buf: maxrows × WMAX doubles, both 64-byte aligned.
   level: sn_level's. */
void sn_solve(int32_t level, int32_t n, int32_t nsuper, const int32_t *super, const int32_t *pi,
              const int32_t *px, const int32_t *s, const double *Lx, const int32_t *perm, int32_t k,
              const double *B, int64_t ldb, double *X, int64_t ldx, double *Y, double *buf)
{
    if (level == 4)
        solve_v4(n, nsuper, super, pi, px, s, Lx, perm, k, B, ldb, X, ldx, Y, buf);
    else
        solve_v3(n, nsuper, super, pi, px, s, Lx, perm, k, B, ldb, X, ldx, Y, buf);
}
"""
# Blocks of MIN_BLOCK to MAX_BLOCK columns take the compiled solve (padded to a multiple of 8);
# others CHOLMOD's: at 260k DOFs 3 columns cost the same in both, and a single column is CHOLMOD's.
WMAX = 16        # right-hand sides per pass of the compiled solve (its C constant)
MIN_BLOCK, MAX_BLOCK = 4, WMAX


@lru_cache(maxsize=1)
def _solve_lib() -> tuple[ctypes.CDLL, int] | None:
    """The compiled block solve and the CPU's level for it (4: AVX-512, 3: AVX2 + FMA), where it
    builds (GCC, x86-64) and the CPU has at least AVX2 and FMA; else None (CHOLMOD's solve)."""
    lib = compiled_library("supernodal_solve", _SOLVE_SOURCE, ("-O3",))
    if lib is None:
        return None
    lib.sn_level.restype = ctypes.c_int
    level = lib.sn_level()
    if level < 3:
        return None
    i32, i64, p = ctypes.c_int32, ctypes.c_int64, ctypes.c_void_p
    lib.sn_solve.argtypes = [i32, i32, i32, p, p, p, p, p, p, i32, p, i64, p, i64, p, p]
    lib.sn_solve.restype = None
    return lib, level


def _aligned(n: int) -> np.ndarray:
    """``n`` doubles starting on a 64-byte boundary."""
    raw = np.empty(n + 8)
    off = (-raw.ctypes.data % 64) // 8
    return raw[off:off + n]


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
        self._lib, self._c, self._L, self._panels = lib, _Common(), ctypes.c_void_p(), None
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
            with serial_openmp():         # CHOLMOD's 4 OpenMP threads cost more than they save
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
        self._panels = self._supernodes()

    def _supernodes(self) -> tuple | None:
        """What the compiled block solve reads from the factor (views of CHOLMOD's arrays, valid
        while it lives) and its workspace; None where it does not apply.  The layout is checked
        against what is known: a supernodal LLᵀ of this size whose last pointers close the arrays
        and whose permutation is one."""
        got = _solve_lib()
        if got is None:
            return None
        L = ctypes.cast(self._L, _P(_Factor)).contents
        n, ns = self.n, L.nsuper
        if not (L.n == n and L.is_super == 1 and L.is_ll == 1 and L.itype == _INT and L.xtype == _REAL
                and L.dtype == _DOUBLE and ns > 0 and L.Perm and L.x):
            return None

        def ints(ptr, m):
            return np.ctypeslib.as_array(ctypes.cast(ptr, _P(ctypes.c_int32)), shape=(m,))
        sup, pi, px = ints(L.super, ns + 1), ints(L.pi, ns + 1), ints(L.px, ns + 1)
        perm = ints(L.Perm, n)
        if not (sup[0] == 0 and sup[-1] == n and pi[0] == 0 and pi[-1] == L.ssize and px[0] == 0
                and px[-1] == L.xsize and np.all(np.diff(sup) > 0) and np.all(np.diff(pi) >= np.diff(sup))
                and is_permutation(perm)):
            return None
        s = ints(L.s, L.ssize)
        return (*got, ns, sup, pi, px, s, ctypes.c_void_p(L.x), perm, _aligned(WMAX * n),
                _aligned(WMAX * int(np.max(np.diff(pi)))))

    def _raise(self, what: str) -> None:
        status = self._c.status
        if status == _NOT_POSDEF:
            raise NotPositiveDefinite(f"CHOLMOD {what}: the matrix is not positive definite")
        if status == -2:
            raise MemoryError(f"CHOLMOD {what}: out of memory")
        if status != _OK or not self._L.value:
            raise RuntimeError(f"CHOLMOD {what} failed (status {status})")

    def solve(self, B: np.ndarray) -> np.ndarray:
        """A⁻¹ B, B of shape (n,) or (n, k); the result is a new column-major array.  Blocks of
        :data:`MIN_BLOCK` to :data:`MAX_BLOCK` columns go through the compiled supernodal block solve where it
        applies, others through ``cholmod_solve2``."""
        B = np.asfortranarray(B, dtype=np.float64)
        vec = B.ndim == 1
        B2 = B.reshape(self.n, -1, order="F")
        k = B2.shape[1]
        if self._panels is not None and MIN_BLOCK <= k <= MAX_BLOCK:
            lib, level, ns, sup, pi, px, s, Lx, perm, Y, buf = self._panels
            out = np.empty((self.n, k), order="F")
            lib.sn_solve(level, self.n, ns, address(sup), address(pi), address(px), address(s), Lx,
                         address(perm), k, address(B2), self.n, address(out), self.n, address(Y), address(buf))
            return out
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
        lib, c = getattr(self, "_lib", None), getattr(self, "_c", None)
        if c is None or lib is None:
            return
        self._panels = None                  # views of the factor's arrays: gone with it
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
