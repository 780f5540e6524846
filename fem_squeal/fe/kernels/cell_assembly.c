#include <stdint.h>
#include <stdlib.h>
#include <string.h>

typedef void (*kernel_t)(double *, const double *, const double *, const double *,
                         const int *, const uint8_t *);
typedef int (*setvalues_t)(void *, int32_t, const int32_t *, int32_t, const int32_t *, const double *, int);

/* Add the element matrices of `ncells` cells into the CSR values `val`.
   Cell c's n nodes are dofmap[c*n .. c*n + n); its geometry nodes xdofmap[c*nx .. c*nx + nx) with
   coordinates x[3*node ..].  The element matrix (b·n)² is row-major with DOF a*b + i for node a,
   component i.  Node pattern: node_ptr/node_col (sorted columns); row r = b*node + i of the DOF
   matrix starts at row_ptr[r] and holds b entries per node column, so block (a, d) of the node pair
   at position p of the row lies at row_ptr[b*na + i] + b*p + j.  bc[r] != 0: a Dirichlet DOF, its
   row and column of the element matrix are zeroed (as dolfinx does).  Returns 0, or -1 if a node
   pair is missing from the pattern. */
int assemble_cells(kernel_t kernel, int32_t ncells, const int32_t *cells, const int32_t *dofmap, int32_t n,
                   int32_t b, const double *x, const int32_t *xdofmap, int32_t nx, const double *constants,
                   const int64_t *node_ptr, const int32_t *node_col, const int64_t *row_ptr,
                   const int8_t *bc, double *A, double *coords, int64_t *pos, double *val)
{
    const int32_t m = n * b;
    for (int32_t k = 0; k < ncells; ++k) {
        const int32_t c = cells[k];
        const int32_t *nodes = dofmap + (int64_t)c * n;
        const int32_t *xn = xdofmap + (int64_t)c * nx;
        for (int32_t a = 0; a < nx; ++a)
            memcpy(coords + 3 * a, x + 3 * (int64_t)xn[a], 3 * sizeof(double));
        memset(A, 0, (size_t)m * m * sizeof(double));
        kernel(A, NULL, constants, coords, NULL, NULL);
        for (int32_t a = 0; a < n; ++a)
            for (int32_t i = 0; i < b; ++i)
                if (bc[(int64_t)b * nodes[a] + i]) {
                    memset(A + (int64_t)(a * b + i) * m, 0, m * sizeof(double));
                    for (int32_t r = 0; r < m; ++r)
                        A[(int64_t)r * m + a * b + i] = 0.0;
                }
        for (int32_t a = 0; a < n; ++a) {
            const int32_t na = nodes[a];
            const int64_t lo = node_ptr[na], hi = node_ptr[na + 1];
            for (int32_t d = 0; d < n; ++d) {
                const int32_t nd = nodes[d];
                int64_t l = lo, h = hi;
                while (l < h) {
                    const int64_t mid = (l + h) / 2;
                    if (node_col[mid] < nd) l = mid + 1; else h = mid;
                }
                if (l == hi || node_col[l] != nd)
                    return -1;
                pos[d] = b * (l - lo);
            }
            for (int32_t i = 0; i < b; ++i) {
                double *row = val + row_ptr[(int64_t)b * na + i];
                const double *Ar = A + (int64_t)(a * b + i) * m;
                for (int32_t d = 0; d < n; ++d)
                    for (int32_t j = 0; j < b; ++j)
                        row[pos[d] + j] += Ar[d * b + j];
            }
        }
    }
    return 0;
}

/* The pattern of the DOF matrix, row by row through PETSc's MatSetValues (`set`, on a matrix
   preallocated with exactly these rows and MAT_SORTED_FULL set: a copy per row): row b*k + i of
   node k holds, for each node column q of node row k, the columns b*q .. b*q + b - 1.  `cols` and
   `zeros` hold the longest row. */
int fill_pattern(setvalues_t set, void *mat, int32_t n_nodes, int32_t b, const int64_t *node_ptr,
                 const int32_t *node_col, int32_t *cols, const double *zeros)
{
    for (int32_t k = 0; k < n_nodes; ++k) {
        int32_t len = 0;
        for (int64_t p = node_ptr[k]; p < node_ptr[k + 1]; ++p)
            for (int32_t j = 0; j < b; ++j)
                cols[len++] = b * node_col[p] + j;
        for (int32_t i = 0; i < b; ++i) {
            const int32_t r = b * k + i;
            const int rc = set(mat, 1, &r, len, cols, zeros, 1 /* INSERT_VALUES */);
            if (rc)
                return rc;
        }
    }
    return 0;
}

/* One entry of a merged node row: its global node column, and where its b × b block lies (row -1:
   the rank's own row, position q in it; otherwise received row `row`, position q in it). */
typedef struct {
    int64_t col;
    int32_t row, q;
} entry_t;

/* The owned node rows of a matrix assembled rank-locally, merged with the rows other ranks
   assembled for the same nodes, written into PETSc's two parts of a parallel AIJ matrix.
   Own node row k < n_own: entries node_ptr[k] .. node_ptr[k + 1] with global node columns gcol[p];
   DOF row b*k + i holds b values per entry at val[row_ptr[b*k + i] + b*q + j] (the layout of
   assemble_cells).  Received row r: entries recv_ptr[r] .. recv_ptr[r + 1] with global node columns
   recv_col[x], its values row-major by DOF row: recv_val[b*b*recv_ptr[r] + i*b*L + b*q + j] (L its
   length); the received rows of owned node k are in_rows[in_ptr[k] .. in_ptr[k + 1]) in the order
   they are to be added.  The block of a column that several rows hold is their sum, own row first,
   then the received ones in that order.  Columns of the owned nodes lo .. hi - 1 go to the diagonal
   part, the others to the off-diagonal part.
   set == NULL: n_diag[k] and n_off[k], the distinct node columns of node row k in either part.
   Otherwise every DOF row b*k + i, columns in increasing order, through `set` (MatSetValues with
   MAT_SORTED_FULL on both parts, preallocated with b·n_diag and b·n_off per DOF row): into `diag` at
   local columns b*(col - lo) + j, into `off` at global columns b*col + j (as PETSc's MPIAIJ holds
   them before its first assembly).  Returns 0, MatSetValues' error code, or -1 if the scratch
   cannot be had. */
int merge_rows(int32_t n_own, int32_t b, int64_t lo, int64_t hi, const int64_t *node_ptr, const int64_t *gcol,
               const int64_t *row_ptr, const double *val, const int64_t *in_ptr, const int32_t *in_rows,
               const int64_t *recv_ptr, const int64_t *recv_col, const double *recv_val, int32_t *n_diag,
               int32_t *n_off, setvalues_t set, void *diag, void *off)
{
    int64_t longest = 1;
    for (int32_t k = 0; k < n_own; ++k) {
        int64_t len = node_ptr[k + 1] - node_ptr[k];
        for (int64_t t = in_ptr[k]; t < in_ptr[k + 1]; ++t)
            len += recv_ptr[in_rows[t] + 1] - recv_ptr[in_rows[t]];
        if (len > longest)
            longest = len;
    }
    entry_t *e = malloc((size_t)longest * sizeof(entry_t));
    int32_t *cols = malloc((size_t)longest * b * sizeof(int32_t));
    double *vals = malloc((size_t)longest * b * b * sizeof(double));
    int rc = (e && cols && vals) ? 0 : -1;
    for (int32_t k = 0; k < n_own && rc == 0; ++k) {
        int32_t m = 0;
        for (int64_t p = node_ptr[k]; p < node_ptr[k + 1]; ++p)
            e[m++] = (entry_t){gcol[p], -1, (int32_t)(p - node_ptr[k])};
        for (int64_t t = in_ptr[k]; t < in_ptr[k + 1]; ++t) {
            const int32_t r = in_rows[t];
            for (int64_t x = recv_ptr[r]; x < recv_ptr[r + 1]; ++x)
                e[m++] = (entry_t){recv_col[x], r, (int32_t)(x - recv_ptr[r])};
        }
        for (int32_t s = 1; s < m; ++s) {        /* stable insertion sort by column: own entries first */
            const entry_t cur = e[s];
            int32_t t = s;
            while (t > 0 && e[t - 1].col > cur.col) {
                e[t] = e[t - 1];
                --t;
            }
            e[t] = cur;
        }
        /* the distinct columns: n_lo below lo, n_in in lo .. hi - 1, the rest above */
        int32_t u = 0, n_lo = 0, n_in = 0;
        for (int32_t s = 0; s < m; ++s)
            if (s == 0 || e[s].col != e[s - 1].col) {
                n_lo += e[s].col < lo;
                n_in += e[s].col >= lo && e[s].col < hi;
                ++u;
            }
        if (!set) {
            n_diag[k] = n_in;
            n_off[k] = u - n_in;
            continue;
        }
        /* values: block row i of distinct column v at vals[(i*u + v)*b + j] */
        memset(vals, 0, (size_t)u * b * b * sizeof(double));
        int32_t v = -1;
        for (int32_t s = 0; s < m; ++s) {
            if (s == 0 || e[s].col != e[s - 1].col)
                ++v;
            for (int32_t i = 0; i < b; ++i) {
                const double *in;
                if (e[s].row < 0)
                    in = val + row_ptr[(int64_t)b * k + i] + (int64_t)b * e[s].q;
                else {
                    const int64_t r0 = recv_ptr[e[s].row], L = recv_ptr[e[s].row + 1] - r0;
                    in = recv_val + (int64_t)b * b * r0 + (int64_t)i * b * L + (int64_t)b * e[s].q;
                }
                double *out = vals + ((int64_t)i * u + v) * b;
                for (int32_t j = 0; j < b; ++j)
                    out[j] += in[j];
            }
        }
        /* the distinct columns in order, then each DOF row's diagonal and off-diagonal parts */
        v = -1;
        for (int32_t s = 0; s < m; ++s)
            if (s == 0 || e[s].col != e[s - 1].col)
                e[++v].col = e[s].col;
        for (int32_t i = 0; i < b && rc == 0; ++i) {
            const int32_t r = b * k + i;
            double *row = vals + (int64_t)i * u * b;
            for (int32_t t = 0; t < n_in; ++t)
                for (int32_t j = 0; j < b; ++j)
                    cols[t * b + j] = (int32_t)(b * (e[n_lo + t].col - lo) + j);
            if (n_in)
                rc = set(diag, 1, &r, b * n_in, cols, row + (int64_t)n_lo * b, 1 /* INSERT_VALUES */);
            if (rc || u == n_in)
                continue;
            /* the off-diagonal part: below lo, then above hi (the values moved next to each other) */
            int32_t c = 0;
            for (int32_t t = 0; t < u; ++t)
                if (t < n_lo || t >= n_lo + n_in) {
                    for (int32_t j = 0; j < b; ++j)
                        cols[c * b + j] = (int32_t)(b * e[t].col + j);
                    ++c;
                }
            memmove(row + (int64_t)n_lo * b, row + (int64_t)(n_lo + n_in) * b,
                    (size_t)(u - n_lo - n_in) * b * sizeof(double));
            rc = set(off, 1, &r, b * c, cols, row, 1 /* INSERT_VALUES */);
        }
    }
    free(e);
    free(cols);
    free(vals);
    return rc;
}

/* A ⊗ W without the rows and columns flagged in `drop` (A: n rows ai, aj, av with sorted columns,
   its first row global row `row0` (0 on one rank), aj global; W: b × b row-major; drop: indexed by
   global DOF): row b*i + c holds W[c][d] * A[i][j] at column b*j + d for W[c][d] != 0 and neither
   b*(row0 + i) + c nor b*j + d dropped, j before d.  kronecker_rows: the entries per row. */
void kronecker_rows(int32_t n, int32_t b, int32_t row0, const int32_t *ai, const int32_t *aj,
                    const double *W, const int8_t *drop, int32_t *count)
{
    for (int32_t i = 0; i < n; ++i)
        for (int32_t c = 0; c < b; ++c) {
            int32_t len = 0;
            if (!drop[(int64_t)b * (row0 + i) + c])
                for (int32_t k = ai[i]; k < ai[i + 1]; ++k)
                    for (int32_t d = 0; d < b; ++d)
                        len += W[c * b + d] != 0.0 && !drop[(int64_t)b * aj[k] + d];
            count[(int64_t)b * i + c] = len;
        }
}

/* Row b*i + c of A ⊗ W (see kronecker_rows) into cols/vals; returns its length. */
static int32_t kronecker_row(int32_t i, int32_t c, int32_t b, int32_t row0, const int32_t *ai,
                             const int32_t *aj, const double *av, const double *W, const int8_t *drop,
                             int32_t *cols, double *vals)
{
    int32_t len = 0;
    if (drop[(int64_t)b * (row0 + i) + c])
        return 0;
    for (int32_t k = ai[i]; k < ai[i + 1]; ++k)
        for (int32_t d = 0; d < b; ++d)
            if (W[c * b + d] != 0.0 && !drop[(int64_t)b * aj[k] + d]) {
                cols[len] = b * aj[k] + d;
                vals[len++] = av[k] * W[c * b + d];
            }
    return len;
}

/* The rows of A ⊗ W (see kronecker_rows; one rank, row0 = 0) through MatSetValues with
   MAT_SORTED_FULL set. */
int fill_kronecker(setvalues_t set, void *mat, int32_t n, int32_t b, const int32_t *ai, const int32_t *aj,
                   const double *av, const double *W, const int8_t *drop, int32_t *cols, double *vals)
{
    for (int32_t i = 0; i < n; ++i)
        for (int32_t c = 0; c < b; ++c) {
            const int32_t r = b * i + c;
            const int32_t len = kronecker_row(i, c, b, 0, ai, aj, av, W, drop, cols, vals);
            if (len) {
                const int rc = set(mat, 1, &r, len, cols, vals, 1 /* INSERT_VALUES */);
                if (rc)
                    return rc;
            }
        }
    return 0;
}

/* The rows of A ⊗ W (see kronecker_rows) as CSR: indptr (b*n + 1, from kronecker_rows' counts),
   indices and data filled here. */
void kronecker_csr(int32_t n, int32_t b, int32_t row0, const int32_t *ai, const int32_t *aj, const double *av,
                   const double *W, const int8_t *drop, const int32_t *indptr, int32_t *indices, double *data)
{
    for (int32_t i = 0; i < n; ++i)
        for (int32_t c = 0; c < b; ++c) {
            const int64_t at = indptr[(int64_t)b * i + c];
            kronecker_row(i, c, b, row0, ai, aj, av, W, drop, indices + at, data + at);
        }
}
