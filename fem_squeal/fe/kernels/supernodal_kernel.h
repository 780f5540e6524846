/* One build of the supernodal block solve, included by supernodal_solve.c once per instruction set
   with V(name) naming its vector type and helpers (name##_v3, name##_v4): v8 (8 doubles), ld, st,
   zero, fms (y - a x), fma (y + a x), sub, divs; CB and WMAX come from the including file. */
/* rows r0 … nsrow−1 of b −= Σ_{c<n} L0[c·nsrow + r] x[c] (the panel's rows below a block) */
INLINE void V(update)(int32_t n, int32_t r0, int32_t nsrow, const double *L0, const V(v8) *x, double *b, int32_t w)
{
    for (int32_t r = r0; r < nsrow; ++r) {
        V(v8) v = V(ld)(b + (int64_t)r * w);
        for (int32_t c = 0; c < n; ++c)
            v = V(fms)(v, L0[(int64_t)c * nsrow + r], x[c]);
        V(st)(b + (int64_t)r * w, v);
    }
}

/* acc[c] = Σ_{r ≥ r0} L0[c·nsrow + r] b[r] for c < n (a block's products with the rows below it) */
INLINE void V(sums)(int32_t n, int32_t r0, int32_t nsrow, const double *L0, const double *b, int32_t w, V(v8) *acc)
{
    for (int32_t c = 0; c < n; ++c)
        acc[c] = V(zero)();
    for (int32_t r = r0; r < nsrow; ++r) {
        const V(v8) y = V(ld)(b + (int64_t)r * w);
        for (int32_t c = 0; c < n; ++c)
            acc[c] = V(fma)(acc[c], L0[(int64_t)c * nsrow + r], y);
    }
}

/* L y = b on one panel: buf holds the panel's rows of Y (the first nscol are its own columns), w
   right-hand sides per row (a multiple of 8), 8 at a time against each CB-column block of the panel
   (the block stays in cache between them: the panel is read from memory once) */
INLINE void V(forward)(int32_t nscol, int32_t nsrow, const double *L, double *buf, int32_t w)
{
    for (int32_t c0 = 0; c0 < nscol; c0 += CB) {
        const int32_t cb = nscol - c0 < CB ? nscol - c0 : CB;
        const double *L0 = L + (int64_t)c0 * nsrow;
        for (int32_t q = 0; q < w; q += 8) {
            double *b = buf + q;
            V(v8) x[CB];
            for (int32_t c = 0; c < cb; ++c) {                 /* the block's triangle */
                const double *Lc = L + (int64_t)(c0 + c) * nsrow;
                x[c] = V(divs)(V(ld)(b + (int64_t)(c0 + c) * w), Lc[c0 + c]);
                V(st)(b + (int64_t)(c0 + c) * w, x[c]);
                for (int32_t r = c0 + c + 1; r < c0 + cb; ++r)
                    V(st)(b + (int64_t)r * w, V(fms)(V(ld)(b + (int64_t)r * w), Lc[r], x[c]));
            }
            if (cb == CB)       /* the same loop; a constant count lets the compiler unroll it */
                V(update)(CB, c0 + CB, nsrow, L0, x, b, w);
            else
                V(update)(cb, c0 + cb, nsrow, L0, x, b, w);
        }
    }
}

/* Lᵀ x = y on one panel: rows past nscol of buf hold the solution already */
INLINE void V(backward)(int32_t nscol, int32_t nsrow, const double *L, double *buf, int32_t w)
{
    for (int32_t c0 = (nscol - 1) / CB * CB; c0 >= 0; c0 -= CB) {
        const int32_t cb = nscol - c0 < CB ? nscol - c0 : CB;
        const double *L0 = L + (int64_t)c0 * nsrow;
        for (int32_t q = 0; q < w; q += 8) {
            double *b = buf + q;
            V(v8) acc[CB];
            if (cb == CB)       /* as in V(forward) */
                V(sums)(CB, c0 + CB, nsrow, L0, b, w, acc);
            else
                V(sums)(cb, c0 + cb, nsrow, L0, b, w, acc);
            for (int32_t c = cb - 1; c >= 0; --c) {             /* the block's triangle */
                const double *Lc = L + (int64_t)(c0 + c) * nsrow;
                V(v8) v = V(sub)(V(ld)(b + (int64_t)(c0 + c) * w), acc[c]);
                for (int32_t r = c0 + c + 1; r < c0 + cb; ++r)
                    v = V(fms)(v, Lc[r], V(ld)(b + (int64_t)r * w));
                V(st)(b + (int64_t)(c0 + c) * w, V(divs)(v, Lc[c0 + c]));
            }
        }
    }
}

/* One panel of a sweep over its first nscol columns: its rows of Y into buf, the panel's solve,
   back into Y (forward: all its rows changed; backward: those nscol only).  nscol is the panel's
   width, or fewer where a partial sweep stops inside it (its further columns then act as rows). */
INLINE void V(sweep)(int32_t sn, int32_t nscol, int back, const int32_t *pi, const int32_t *px,
                    const int32_t *s, const double *Lx, double *Y, double *buf, int32_t w)
{
    const int32_t nsrow = pi[sn + 1] - pi[sn];
    const int32_t *rows = s + pi[sn];
    for (int32_t r = 0; r < nsrow; ++r)
        for (int32_t q = 0; q < w; q += 8)
            V(st)(buf + (int64_t)r * w + q, V(ld)(Y + (int64_t)rows[r] * w + q));
    if (back)
        V(backward)(nscol, nsrow, Lx + px[sn], buf, w);
    else
        V(forward)(nscol, nsrow, Lx + px[sn], buf, w);
    for (int32_t r = 0; r < (back ? nscol : nsrow); ++r)
        for (int32_t q = 0; q < w; q += 8)
            V(st)(Y + (int64_t)rows[r] * w + q, V(ld)(buf + (int64_t)r * w + q));
}

static void V(solve)(int32_t n, int32_t nsuper, const int32_t *super, const int32_t *pi, const int32_t *px,
                    const int32_t *s, const double *Lx, const int32_t *perm, int32_t k, const double *B,
                    int64_t ldb, double *X, int64_t ldx, double *Y, double *buf)
{
    for (int32_t j0 = 0; j0 < k; j0 += WMAX) {
        const int32_t m = k - j0 < WMAX ? k - j0 : WMAX, w = (m + 7) / 8 * 8;
        for (int32_t i = 0; i < n; ++i)
            for (int32_t j = 0; j < w; ++j)
                Y[(int64_t)i * w + j] = j < m ? B[perm[i] + ldb * (j0 + j)] : 0.0;
        for (int32_t sn = 0; sn < nsuper; ++sn)               /* L y = b, panel by panel */
            V(sweep)(sn, super[sn + 1] - super[sn], 0, pi, px, s, Lx, Y, buf, w);
        for (int32_t sn = nsuper - 1; sn >= 0; --sn)          /* Lᵀ x = y, in reverse */
            V(sweep)(sn, super[sn + 1] - super[sn], 1, pi, px, s, Lx, Y, buf, w);
        for (int32_t i = 0; i < n; ++i)
            for (int32_t j = 0; j < m; ++j)
                X[perm[i] + ldx * (j0 + j)] = Y[(int64_t)i * w + j];
    }
}

/* The sweeps of L's first ncols columns only, on Y as the caller holds it (row-major, w columns, a
   multiple of 8; rows in the factor's order).  Forward (back = 0): y₁ = L₁₁⁻¹ b₁ in rows < ncols and
   rows ≥ ncols become b₂ − L₂₁ y₁.  Backward: x₁ = L₁₁⁻ᵀ (y₁ − L₂₁ᵀ x₂) with x₂ given in rows ≥ ncols.
   With L = [L₁₁ 0; L₂₁ L₂₂] of A = [A₁₁ A₁₂; A₂₁ A₂₂], these are the two halves of a solve with the
   Schur complement of A₁₁ in between (fem_squeal/fe/substructured.py). */
static void V(partial)(int back, int32_t ncols, int32_t nsuper, const int32_t *super, const int32_t *pi,
                       const int32_t *px, const int32_t *s, const double *Lx, double *Y, double *buf, int32_t w)
{
    int32_t last = 0;                     /* the panels that hold columns < ncols: 0 … last − 1 */
    while (last < nsuper && super[last] < ncols)
        ++last;
    if (!back)
        for (int32_t sn = 0; sn < last; ++sn)
            V(sweep)(sn, (super[sn + 1] < ncols ? super[sn + 1] : ncols) - super[sn], 0, pi, px, s, Lx, Y, buf, w);
    else
        for (int32_t sn = last - 1; sn >= 0; --sn)
            V(sweep)(sn, (super[sn + 1] < ncols ? super[sn + 1] : ncols) - super[sn], 1, pi, px, s, Lx, Y, buf, w);
}
