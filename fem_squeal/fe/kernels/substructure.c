/* The local matrix of a substructured factorisation (fem_squeal/fe/substructured.py) from a rank's CSR
 * rows, in two passes: the A_ΓΓ triplets of this rank's interface rows, then the interior rows [A_II A_IΓ]
 * renumbered to the local order (interior 0 … n_i − 1, then the interface n_i … n_i + s − 1), written
 * straight into the arrays CHOLMOD reads (int32 pattern), with the A_II pattern of those rows for the
 * fill-reducing order.  The NumPy version it replaces made a dozen passes with an array per entry and a
 * concatenation of the whole matrix. */
#include <stdint.h>

/* position of x in the sorted g[0 .. m), or -1 */
static int64_t find(const int64_t *g, int64_t m, int64_t x)
{
    int64_t lo = 0, hi = m;
    while (lo < hi) {
        const int64_t mid = lo + (hi - lo) / 2;
        if (g[mid] < x)
            lo = mid + 1;
        else
            hi = mid;
    }
    return (lo < m && g[lo] == x) ? lo : -1;
}

/* the local column of global column c: owned rows through local[], other ranks' through Γ, else -1 */
static inline int64_t column(int64_t c, int64_t r0, int64_t r1, const int64_t *local, const int64_t *gamma,
                             int64_t s, int64_t n_i)
{
    if (c >= r0 && c < r1)
        return local[c - r0];
    const int64_t p = find(gamma, s, c);
    return p < 0 ? -1 : n_i + p;
}

/* The A_ΓΓ entries of this rank's n_g interface rows own_gamma (in order) as triplets (row, column in Γ's
 * numbering, value); the arrays hold at most those rows' entries.  Returns the triplets written. */
int64_t substructure_gamma(int64_t r0, int64_t r1, const int64_t *indptr, const int32_t *indices,
                           const double *data, const int64_t *local, const int64_t *gamma, int64_t s, int64_t n_i,
                           const int64_t *own_gamma, int64_t n_g, int64_t *gg_row, int64_t *gg_col, double *gg_val)
{
    int64_t g = 0;
    for (int64_t j = 0; j < n_g; ++j) {
        const int64_t row = own_gamma[j];
        const int64_t lr = local[row] - n_i;
        for (int64_t p = indptr[row]; p < indptr[row + 1]; ++p) {
            const int64_t w = column(indices[p], r0, r1, local, gamma, s, n_i);
            if (w >= n_i) {
                gg_row[g] = lr;
                gg_col[g] = w - n_i;
                gg_val[g++] = data[p];
            }
        }
    }
    return g;
}

/* The n_i interior rows (in order) renumbered: top_ptr[0 .. n_i], top_idx and top_val (sized by the caller:
 * the rows' entries), and their A_II pattern inner_ptr/inner_idx (at most as many).  counts[0]: the A_II
 * entries.  Returns 0, or 1 where an interior row couples to another rank's interior (the interface is not a
 * separator). */
int substructure_interior(int64_t r0, int64_t r1, const int64_t *indptr, const int32_t *indices,
                          const double *data, const int64_t *local, const int64_t *gamma, int64_t s, int64_t n_i,
                          const int64_t *interior, int32_t *top_ptr, int32_t *top_idx, double *top_val,
                          int64_t *inner_ptr, int64_t *inner_idx, int64_t *counts)
{
    int64_t t = 0, q = 0;
    int bad = 0;
    top_ptr[0] = 0;
    inner_ptr[0] = 0;
    for (int64_t i = 0; i < n_i; ++i) {
        const int64_t row = interior[i];
        for (int64_t p = indptr[row]; p < indptr[row + 1]; ++p) {
            const int64_t w = column(indices[p], r0, r1, local, gamma, s, n_i);
            bad |= w < 0;
            top_idx[t] = (int32_t)w;
            top_val[t++] = data[p];
            if (w >= 0 && w < n_i)
                inner_idx[q++] = w;
        }
        top_ptr[i + 1] = (int32_t)t;
        inner_ptr[i + 1] = q;
    }
    counts[0] = q;
    return bad;
}
