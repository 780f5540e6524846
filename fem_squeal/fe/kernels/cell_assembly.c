#include <stdint.h>
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

/* Node row k of the DOF matrix in `val` (the layout of assemble_cells: b rows of b entries per node
   column, row-major) added into a parallel matrix through PETSc's MatSetValuesBlockedLocal (`set`,
   local node numbers mapped by the matrix's block local-to-global map; a ghost node's row goes to
   its owner at the assembly), for every node k with node_ptr[k] < node_ptr[k + 1]. */
int add_node_rows(setvalues_t set, void *mat, int32_t n_nodes, int32_t b, const int64_t *node_ptr,
                  const int32_t *node_col, const int64_t *row_ptr, const double *val)
{
    for (int32_t k = 0; k < n_nodes; ++k) {
        const int32_t len = (int32_t)(node_ptr[k + 1] - node_ptr[k]);
        if (len == 0)
            continue;
        const int rc = set(mat, 1, &k, len, node_col + node_ptr[k], val + row_ptr[(int64_t)b * k],
                           2 /* ADD_VALUES */);
        if (rc)
            return rc;
    }
    return 0;
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
