/* The block solve L Lᵀ X = B on CHOLMOD's supernodal factor, up to WMAX right-hand sides per pass
   (the rationale and the timings: fem_squeal/fe/cholmod.py).  The kernel (supernodal_kernel.h) is
   built twice, for AVX-512 (x86-64-v4, 8 right-hand sides of a row in one 512-bit register) and for
   AVX2 + FMA (x86-64-v3, in two 256-bit ones); sn_level() picks one for the CPU.  Both make the same
   operations in the same order: the same result to the bit.  Elsewhere (another compiler or
   architecture) sn_level() returns 0 and the caller keeps CHOLMOD's own solve. */
#include <stdint.h>

#define INLINE static inline __attribute__((always_inline))
/* Columns of a panel per pass over its rows: each row of buf is loaded and stored once per CB
   columns, and those loads and stores bound the row loops (8-column solve at 26k DOFs, AVX2 /
   AVX-512: 4 columns 10.9 / 9.4 ms, 8: 8.7 / 7.4, 12: 8.5 / 6.6, 16: 9.8 / 6.6, 20: 8.4 / 12.1 ms,
   the AVX-512 registers exhausted).  The same in both builds: the same sums in the same order. */
#define CB 12
#define WMAX 16     /* right-hand sides per pass over the factor, padded to a multiple of 8 */

int sn_wmax(void) { return WMAX; }

#if defined(__GNUC__) && !defined(__clang__) && defined(__x86_64__)

#pragma GCC push_options
#pragma GCC target("arch=x86-64-v3")
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
#define V(name) name##_v3
#include "supernodal_kernel.h"
#undef V
#pragma GCC pop_options

#pragma GCC push_options
#pragma GCC target("arch=x86-64-v4")
typedef double v8_v4 __attribute__((vector_size(64)));       /* Y and buf rows are 64-byte aligned */
INLINE v8_v4 ld_v4(const double *p) { return *(const v8_v4 *)p; }
INLINE void st_v4(double *p, v8_v4 v) { *(v8_v4 *)p = v; }
INLINE v8_v4 zero_v4(void) { return (v8_v4){0, 0, 0, 0, 0, 0, 0, 0}; }
INLINE v8_v4 fms_v4(v8_v4 y, double a, v8_v4 x) { return y - a * x; }
INLINE v8_v4 fma_v4(v8_v4 y, double a, v8_v4 x) { return y + a * x; }
INLINE v8_v4 sub_v4(v8_v4 y, v8_v4 x) { return y - x; }
INLINE v8_v4 divs_v4(v8_v4 y, double d) { return y / d; }
#define V(name) name##_v4
#include "supernodal_kernel.h"
#undef V
#pragma GCC pop_options

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

/* The partial sweeps (V(partial) in supernodal_kernel.h) on Y, n × w row-major (w a multiple of 8,
   64-byte aligned, as buf: maxrows × w) */
void sn_partial(int32_t level, int32_t back, int32_t ncols, int32_t nsuper, const int32_t *super,
                const int32_t *pi, const int32_t *px, const int32_t *s, const double *Lx, double *Y, double *buf,
                int32_t w)
{
    if (level == 4)
        partial_v4(back, ncols, nsuper, super, pi, px, s, Lx, Y, buf, w);
    else
        partial_v3(back, ncols, nsuper, super, pi, px, s, Lx, Y, buf, w);
}

#else   /* not GCC on x86-64: no build of the kernel; CHOLMOD's solve is used */

int sn_level(void) { return 0; }

void sn_solve(int32_t level, int32_t n, int32_t nsuper, const int32_t *super, const int32_t *pi,
              const int32_t *px, const int32_t *s, const double *Lx, const int32_t *perm, int32_t k,
              const double *B, int64_t ldb, double *X, int64_t ldx, double *Y, double *buf)
{
    (void)level; (void)n; (void)nsuper; (void)super; (void)pi; (void)px; (void)s; (void)Lx; (void)perm;
    (void)k; (void)B; (void)ldb; (void)X; (void)ldx; (void)Y; (void)buf;
}

void sn_partial(int32_t level, int32_t back, int32_t ncols, int32_t nsuper, const int32_t *super,
                const int32_t *pi, const int32_t *px, const int32_t *s, const double *Lx, double *Y, double *buf,
                int32_t w)
{
    (void)level; (void)back; (void)ncols; (void)nsuper; (void)super; (void)pi; (void)px; (void)s; (void)Lx;
    (void)Y; (void)buf; (void)w;
}

#endif
