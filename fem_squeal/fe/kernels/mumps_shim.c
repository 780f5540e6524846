/* MUMPS (double, MPI) behind a handful of plain functions, for fem_squeal/fe/mumps.py.

   The DMUMPS_STRUC_C structure is read and written here, compiled against the dmumps_c.h of the MUMPS
   it links, so no layout is copied by hand into Python: Python sees an opaque handle, arrays and
   numbers.  The matrix is given distributed (ICNTL(18) = 3: each rank its own triplets, 1-based global
   indices), the right-hand sides distributed (ICNTL(20) = 10: each rank its own rows, in any order)
   and the solution comes back distributed as MUMPS holds it (ICNTL(21) = 1: rows ISOL_loc on each
   rank), which is what PETSc's MatMatSolve_MUMPS does not do for its right-hand sides (it gathers
   them on rank 0 at every solve).  The communicator is MPI's Fortran handle (MPI_Comm_c2f), so no
   mpi.h is needed here.  Built by the package's build (setup.py) against Debian's libmumps-dev. */
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include <dmumps_c.h>

#define ICNTL(I) icntl[(I)-1]

typedef struct {
    DMUMPS_STRUC_C id;
    int started;
} fsm_handle;

/* MUMPS's version string as built against (e.g. "5.5.1") into buf (len bytes). */
void fsm_version(char *buf, int len)
{
    strncpy(buf, MUMPS_VERSION, (size_t)len - 1);
    buf[len - 1] = 0;
}

static void quiet(DMUMPS_STRUC_C *id)
{
    id->ICNTL(1) = -1;      /* error messages */
    id->ICNTL(2) = -1;      /* diagnostics */
    id->ICNTL(3) = -1;      /* global information */
    id->ICNTL(4) = 0;       /* print level */
}

/* A new MUMPS instance on the communicator comm_f (Fortran handle), sym = 1 (symmetric positive
   definite: LDLᵀ without pivoting) or 2 (general symmetric: LDLᵀ with pivoting) or 0 (LU); the host
   works (par = 1).  Collective.  NULL where out of memory or MUMPS's initialisation fails. */
fsm_handle *fsm_new(int comm_f, int sym)
{
    fsm_handle *h = calloc(1, sizeof(fsm_handle));
    if (!h)
        return NULL;
    h->id.comm_fortran = (MUMPS_INT)comm_f;
    h->id.par = 1;
    h->id.sym = sym;
    h->id.job = -1;
    dmumps_c(&h->id);
    if (h->id.infog[0] < 0) {
        free(h);
        return NULL;
    }
    h->started = 1;
    quiet(&h->id);
    return h;
}

/* Analysis and factorisation of the matrix of n rows given by this rank's triplets (irn, jcn, a:
   nnz entries, 1-based global indices; for sym > 0 one triangle, entries repeated are summed).
   ordering: ICNTL(7) (7: MUMPS chooses).  Collective.  Returns INFOG(1) (0: success; < 0: error,
   -10: numerically singular, -40: sym = 1 and a pivot not positive). */
int fsm_factor(fsm_handle *h, int n, int64_t nnz, int *irn, int *jcn, double *a, int ordering)
{
    DMUMPS_STRUC_C *id = &h->id;
    id->n = n;
    id->ICNTL(5) = 0;           /* assembled matrix */
    id->ICNTL(18) = 3;          /* distributed input: triplets on every rank */
    id->ICNTL(7) = ordering;
    id->nnz_loc = nnz;
    id->irn_loc = irn;
    id->jcn_loc = jcn;
    id->a_loc = a;
    id->job = 4;                /* analysis, then factorisation */
    dmumps_c(id);
    id->irn_loc = id->jcn_loc = NULL;     /* the caller's arrays need not outlive this call */
    id->a_loc = NULL;
    return id->infog[0];
}

/* Rows of the solution this rank will hold (INFO(23)), valid after the factorisation. */
int fsm_solution_rows(fsm_handle *h)
{
    return h->id.info[22];
}

/* A⁻¹B for nrhs columns: this rank's rows of B are rhs (column-major, leading dimension nloc) with
   global 1-based row numbers irhs; the solution's rows on this rank come back in sol (column-major,
   leading dimension lsol >= fsm_solution_rows) with their global 1-based row numbers in isol.
   Collective.  Returns INFOG(1). */
int fsm_solve(fsm_handle *h, int nrhs, int nloc, int *irhs, double *rhs, int lsol, double *sol, int *isol)
{
    DMUMPS_STRUC_C *id = &h->id;
    id->ICNTL(20) = 10;         /* distributed dense right-hand sides */
    id->ICNTL(21) = 1;          /* distributed solution */
    id->nrhs = nrhs;
    id->nloc_rhs = nloc;
    id->lrhs_loc = nloc > 0 ? nloc : 1;
    id->irhs_loc = irhs;
    id->rhs_loc = rhs;
    id->lsol_loc = lsol;
    id->sol_loc = sol;
    id->isol_loc = isol;
    id->job = 3;
    dmumps_c(id);
    id->irhs_loc = id->isol_loc = NULL;
    id->rhs_loc = id->sol_loc = NULL;
    return id->infog[0];
}

/* INFOG(1..80) and RINFOG(1..40) into the caller's arrays. */
void fsm_info(fsm_handle *h, int *infog, double *rinfog)
{
    for (int i = 0; i < 80; ++i)
        infog[i] = h->id.infog[i];
    for (int i = 0; i < 40; ++i)
        rinfog[i] = h->id.rinfog[i];
}

/* Frees MUMPS's factor and the handle.  Collective. */
void fsm_free(fsm_handle *h)
{
    if (!h)
        return;
    if (h->started) {
        h->id.job = -2;
        dmumps_c(&h->id);
    }
    free(h);
}
