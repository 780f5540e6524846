#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#define PANEL 16

/* Y = A X for m <= 8 columns, read in place */
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

/* row i of A times the panel T (row-major, PANEL columns); m columns of Y written */
static inline __attribute__((always_inline))
void row1(int32_t i, const int32_t *ai, const int32_t *aj, const double *av, int32_t m,
          const double *T, double *Y, int64_t ldy)
{
    double a0[PANEL] = {0};
    for (int32_t p = ai[i]; p < ai[i + 1]; ++p) {
        const double b = av[p];
        const double *x = T + (int64_t)aj[p] * PANEL;
        for (int c = 0; c < PANEL; ++c)
            a0[c] += b * x[c];
    }
    for (int c = 0; c < m; ++c)
        Y[i + ldy * c] = a0[c];
}

/* rows i, i + 1, i + 2 of one column pattern: each row of T loaded once for the three */
static inline __attribute__((always_inline))
void row3(int32_t i, const int32_t *ai, const int32_t *aj, const double *av, int32_t m,
          const double *T, double *Y, int64_t ldy)
{
    double a0[PANEL] = {0}, a1[PANEL] = {0}, a2[PANEL] = {0};
    const int32_t len = ai[i + 1] - ai[i];
    const double *v0 = av + ai[i], *v1 = av + ai[i + 1], *v2 = av + ai[i + 2];
    const int32_t *jj = aj + ai[i];
    for (int32_t q = 0; q < len; ++q) {
        const double *x = T + (int64_t)jj[q] * PANEL;
        const double b0 = v0[q], b1 = v1[q], b2 = v2[q];
        for (int c = 0; c < PANEL; ++c) {
            a0[c] += b0 * x[c];
            a1[c] += b1 * x[c];
            a2[c] += b2 * x[c];
        }
    }
    for (int c = 0; c < m; ++c) {
        Y[i + ldy * c] = a0[c];
        Y[i + 1 + ldy * c] = a1[c];
        Y[i + 2 + ldy * c] = a2[c];
    }
}

static inline __attribute__((always_inline))
void panel(int32_t n, const int32_t *ai, const int32_t *aj, const double *av, const uint8_t *tri, int32_t m,
           const double *T, double *Y, int64_t ldy)
{
    for (int32_t i = 0; i < n;) {
        if (tri[i]) {
            row3(i, ai, aj, av, m, T, Y, ldy);
            i += 3;
        } else {
            row1(i, ai, aj, av, m, T, Y, ldy);
            i += 1;
        }
    }
}

/* returns 0, or 1 where a buffer could not be had (Y untouched) */
__attribute__((target_clones("arch=x86-64-v4", "arch=x86-64-v3", "default")))
int csr_block(int32_t n, int32_t ncol, const int32_t *ai, const int32_t *aj, const double *av, int32_t k,
              const double *X, int64_t ldx, double *Y, int64_t ldy)
{
    if (k <= 8) {
        if (k == 8)                     /* the same loop with a constant width: unrolled */
            rows(n, ai, aj, av, 8, X, ldx, Y, ldy);
        else
            rows(n, ai, aj, av, k, X, ldx, Y, ldy);
        return 0;
    }
    uint8_t *tri = malloc((size_t)n + 1);
    double *T = aligned_alloc(64, ((size_t)ncol * PANEL * sizeof(double) + 63) / 64 * 64);
    if (!tri || !T) {
        free(tri);
        free(T);
        return 1;
    }
    for (int32_t i = 0; i < n; ++i) {   /* rows i, i + 1, i + 2 of one pattern (i a multiple of 3) */
        const int32_t len = ai[i + 1] - ai[i];
        tri[i] = i % 3 == 0 && i + 2 < n && ai[i + 2] - ai[i + 1] == len && ai[i + 3] - ai[i + 2] == len
                 && !memcmp(aj + ai[i], aj + ai[i + 1], sizeof(int32_t) * len)
                 && !memcmp(aj + ai[i], aj + ai[i + 2], sizeof(int32_t) * len);
    }
    for (int32_t c0 = 0; c0 < k; c0 += PANEL) {
        const int32_t m = k - c0 < PANEL ? k - c0 : PANEL;
        const double *Xc = X + ldx * c0;
        for (int32_t j = 0; j < ncol; ++j) {
            double *t = T + (int64_t)j * PANEL;
            for (int c = 0; c < m; ++c)
                t[c] = Xc[j + ldx * c];
            for (int c = m; c < PANEL; ++c)
                t[c] = 0.0;
        }
        if (m == PANEL)
            panel(n, ai, aj, av, tri, PANEL, T, Y + ldy * c0, ldy);
        else
            panel(n, ai, aj, av, tri, m, T, Y + ldy * c0, ldy);
    }
    free(tri);
    free(T);
    return 0;
}

/* for each of npts coefficient sets c[t * npts + q]: max over rows of sum_j |sum_t c_tq A_t(i, j)|,
   the infinity norms of sums of CSR matrices of one shape without forming them, into best[q];
   acc (ncol * npts doubles), stamp (ncol ints) zero on entry, touched (ncol ints) */
void csr_sum_norm_inf(int32_t nterms, int32_t npts, int32_t n, const int32_t *const *ai,
                      const int32_t *const *aj, const double *const *av, const double *c, double *acc,
                      int32_t *stamp, int32_t *touched, double *best)
{
    for (int32_t q = 0; q < npts; ++q)
        best[q] = 0.0;
    for (int32_t i = 0; i < n; ++i) {
        int32_t nt = 0;
        for (int32_t t = 0; t < nterms; ++t)
            for (int32_t p = ai[t][i]; p < ai[t][i + 1]; ++p) {
                const int32_t j = aj[t][p];
                double *a = acc + (int64_t)j * npts;
                if (stamp[j] != i + 1) {
                    stamp[j] = i + 1;
                    for (int32_t q = 0; q < npts; ++q)
                        a[q] = 0.0;
                    touched[nt++] = j;
                }
                const double v = av[t][p];
                for (int32_t q = 0; q < npts; ++q)
                    a[q] += c[t * npts + q] * v;
            }
        for (int32_t q = 0; q < npts; ++q) {
            double row = 0.0;
            for (int32_t u = 0; u < nt; ++u) {
                const double x = acc[(int64_t)touched[u] * npts + q];
                row += x < 0 ? -x : x;
            }
            if (row > best[q])
                best[q] = row;
        }
    }
}
