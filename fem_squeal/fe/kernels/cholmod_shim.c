/* CHOLMOD's supernodal Cholesky behind a handful of plain functions, for fem_squeal/fe/cholmod.py.

   Every CHOLMOD structure (cholmod_common, cholmod_sparse, cholmod_factor, cholmod_dense) is read and
   written here, compiled against the cholmod.h of the CHOLMOD it links, so no layout is copied by hand
   into Python: Python sees an opaque handle, arrays and numbers.  32-bit indices (cholmod_*, not
   cholmod_l_*).  Built by the package's build (setup.py) against Debian's libsuitesparse-dev. */
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include <cholmod.h>

typedef struct {
    cholmod_common c;
    cholmod_factor *L;
    cholmod_dense *X, *Y, *E;       /* cholmod_solve2's workspace, kept between solves */
} fsc_handle;

/* CHOLMOD's version as 10000 main + 100 sub + subsub (of the header this was built against) */
int fsc_version(void)
{
    return 10000 * CHOLMOD_MAIN_VERSION + 100 * CHOLMOD_SUB_VERSION + CHOLMOD_SUBSUB_VERSION;
}

/* A new handle: CHOLMOD started quiet, supernodal, returning at the first non-positive pivot, with
   the supernode amalgamation nrelax[3] / zrelax[3] (CHOLMOD's defaults where NULL). */
fsc_handle *fsc_new(const int64_t *nrelax, const double *zrelax)
{
    fsc_handle *h = calloc(1, sizeof(fsc_handle));
    if (!h)
        return NULL;
    cholmod_start(&h->c);
    h->c.print = 0;
    h->c.supernodal = CHOLMOD_SUPERNODAL;
    h->c.quick_return_if_not_posdef = 1;
    for (int j = 0; j < 3; ++j) {
        if (nrelax)
            h->c.nrelax[j] = (size_t)nrelax[j];
        if (zrelax)
            h->c.zrelax[j] = zrelax[j];
    }
    return h;
}

/* Keep a given order as it is (on = 0: no postorder of the elimination tree after it), so that a
   block of rows ordered last stays last (fem_squeal/fe/substructured.py); on = 1: CHOLMOD's default. */
void fsc_set_postorder(fsc_handle *h, int on)
{
    h->c.postorder = on;
}

/* The symmetric matrix given by CSR arrays (n rows, both triangles or the upper one: CSR of a
   symmetric matrix is CSC of the same, so its "lower" triangle in CHOLMOD's view is read). */
static cholmod_sparse view(int32_t n, const int32_t *p, const int32_t *i, const double *x)
{
    cholmod_sparse A;
    memset(&A, 0, sizeof A);
    A.nrow = A.ncol = (size_t)n;
    A.nzmax = (size_t)p[n];
    A.p = (void *)p;
    A.i = (void *)i;
    A.x = (void *)x;
    A.stype = -1;
    A.itype = CHOLMOD_INT;
    A.xtype = CHOLMOD_REAL;
    A.dtype = CHOLMOD_DOUBLE;
    A.sorted = 0;
    A.packed = 1;
    return A;
}

/* Symbolic analysis with the fill-reducing order perm (new row k = old row perm[k]; NULL: CHOLMOD's
   own choice).  Returns CHOLMOD's status (0: ok; 1: not positive definite; < 0: an error). */
int fsc_analyze(fsc_handle *h, int32_t n, const int32_t *p, const int32_t *i, const double *x, const int32_t *perm)
{
    cholmod_sparse A = view(n, p, i, x);
    if (perm) {
        h->c.nmethods = 1;
        h->c.method[0].ordering = CHOLMOD_GIVEN;
    }
    h->L = cholmod_analyze_p(&A, (int *)perm, NULL, 0, &h->c);
    return h->L ? h->c.status : (h->c.status ? h->c.status : CHOLMOD_INVALID);
}

/* Numeric factorisation of the matrix analysed (the same pattern). */
int fsc_factorize(fsc_handle *h, int32_t n, const int32_t *p, const int32_t *i, const double *x)
{
    cholmod_sparse A = view(n, p, i, x);
    if (!h->L)
        return CHOLMOD_INVALID;
    cholmod_factorize(&A, h->L, &h->c);
    return h->c.status;
}

/* Statistics of the last analysis/factorisation: flops, entries of L. */
void fsc_stats(const fsc_handle *h, double *flops, double *lnz)
{
    *flops = h->c.fl;
    *lnz = h->c.lnz;
}

/* The supernodal factor's arrays (views, valid while the handle lives), for the compiled block solve:
   sizes[0..3] = n, nsuper, ssize, xsize; ptrs = super, pi, px, s (int32), x (double), Perm (int32).
   Returns 1 for a supernodal LLᵀ of real doubles with 32-bit indices, else 0. */
int fsc_supernodes(const fsc_handle *h, int64_t *sizes, void **ptrs)
{
    const cholmod_factor *L = h->L;
    if (!L || !L->is_super || !L->is_ll || L->itype != CHOLMOD_INT || L->xtype != CHOLMOD_REAL
            || L->dtype != CHOLMOD_DOUBLE || L->nsuper == 0 || !L->Perm || !L->x)
        return 0;
    sizes[0] = (int64_t)L->n;
    sizes[1] = (int64_t)L->nsuper;
    sizes[2] = (int64_t)L->ssize;
    sizes[3] = (int64_t)L->xsize;
    ptrs[0] = L->super;
    ptrs[1] = L->pi;
    ptrs[2] = L->px;
    ptrs[3] = L->s;
    ptrs[4] = L->x;
    ptrs[5] = L->Perm;
    return 1;
}

/* X = A⁻¹ B by cholmod_solve2: B and X column-major n × k (leading dimensions ldb, ldx).  Returns
   CHOLMOD's status, or -100 where the solve gave no result. */
int fsc_solve(fsc_handle *h, int32_t n, int32_t k, const double *B, int64_t ldb, double *X, int64_t ldx)
{
    cholmod_dense D;
    memset(&D, 0, sizeof D);
    D.nrow = (size_t)n;
    D.ncol = (size_t)k;
    D.nzmax = (size_t)ldb * (size_t)k;
    D.d = (size_t)ldb;
    D.x = (void *)B;
    D.xtype = CHOLMOD_REAL;
    D.dtype = CHOLMOD_DOUBLE;
    if (!cholmod_solve2(CHOLMOD_A, h->L, &D, NULL, &h->X, NULL, &h->Y, &h->E, &h->c) || !h->X)
        return h->c.status ? h->c.status : -100;
    const double *x = h->X->x;
    const size_t d = h->X->d;
    for (int32_t j = 0; j < k; ++j)
        memcpy(X + ldx * j, x + d * (size_t)j, sizeof(double) * (size_t)n);
    return h->c.status;
}

/* Free the factor, the solve workspace, CHOLMOD's workspace and the handle. */
void fsc_free(fsc_handle *h)
{
    if (!h)
        return;
    if (h->X)
        cholmod_free_dense(&h->X, &h->c);
    if (h->Y)
        cholmod_free_dense(&h->Y, &h->c);
    if (h->E)
        cholmod_free_dense(&h->E, &h->c);
    if (h->L)
        cholmod_free_factor(&h->L, &h->c);
    cholmod_finish(&h->c);
    free(h);
}
