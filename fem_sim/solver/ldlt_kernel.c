/* Serial symmetric LDL^T through the MUMPS C interface, in double (dmumps) or single (smumps)
 * precision, with a METIS nested-dissection ordering passed as MUMPS' user ordering.
 *
 * Why not PETSc's MUMPS: Debian's MUMPS is built without METIS/SCOTCH (only PORD, AMD, AMF,
 * QAMD), and PETSc 3.18 hands a user ordering to MUMPS only for LU. Built with cffi by
 * fem_sim/ldlt.py (via fem_sim/cext.py), which also documents the measured gains.
 * One instance per process, on MPI_COMM_SELF (MPI must be initialised: mpi4py does it).
 */
#include <stdint.h>
#include <stdlib.h>
#include <string.h>
#include <mpi.h>
#include <metis.h>
#include "dmumps_c.h"
#include "smumps_c.h"

#define ICNTL(I) icntl[(I) - 1]
#define INFOG(I) infog[(I) - 1]
#define RINFOG(I) rinfog[(I) - 1]

typedef struct {
  int single;
  DMUMPS_STRUC_C d;
  SMUMPS_STRUC_C s;
} ldlt_t;

/* Run one MUMPS job on whichever precision the handle holds; `setup` may refer to `m`. */
#define RUN(h, JOB, setup)                                                   \
  do {                                                                       \
    if ((h)->single) { SMUMPS_STRUC_C *m = &(h)->s; setup; m->job = (JOB); smumps_c(m); } \
    else { DMUMPS_STRUC_C *m = &(h)->d; setup; m->job = (JOB); dmumps_c(m); }             \
  } while (0)

#define INIT(m, SYM)                                                         \
  do {                                                                       \
    (m)->par = 1; (m)->sym = (SYM); /* 2: LDL^T with 2x2 pivots; 1: no pivoting */ \
    (m)->comm_fortran = (MUMPS_INT)MPI_Comm_c2f(MPI_COMM_SELF);             \
  } while (0)

#define QUIET(m)                                                             \
  do {                                                                       \
    (m)->ICNTL(1) = -1; (m)->ICNTL(2) = -1; (m)->ICNTL(3) = -1; (m)->ICNTL(4) = 0;   \
  } while (0)

void *ldlt_new(int single, int sym) {
  ldlt_t *h = calloc(1, sizeof(ldlt_t));
  if (!h) return NULL;
  h->single = single;
  RUN(h, -1, INIT(m, sym)); /* JOB=-1 sets the default ICNTL; QUIET is applied before analysis */
  return h;
}

/* Set ICNTL(i) = v (before the analysis or factorisation it should affect). */
void ldlt_set_icntl(void *hv, int i, int v) {
  ldlt_t *h = hv;
  if (h->single) h->s.ICNTL(i) = v; else h->d.ICNTL(i) = v;
}

int ldlt_info(void *hv, int i) {
  ldlt_t *h = hv;
  return h->single ? h->s.INFOG(i) : h->d.INFOG(i);
}

double ldlt_rinfo(void *hv, int i) {
  ldlt_t *h = hv;
  return h->single ? h->s.RINFOG(i) : h->d.RINFOG(i);
}

/* Analysis of the upper triangle (1-based irn, jcn; the arrays must outlive the handle).
 * perm_in: 1-based pivot position of each variable, or NULL for MUMPS' own choice (AMD). */
int ldlt_analyse(void *hv, int n, int64_t nnz, int *irn, int *jcn, int *perm_in,
                 int mem_relax) {
  ldlt_t *h = hv;
  RUN(h, 1, {
    QUIET(m);
    m->n = n; m->nnz = nnz; m->irn = irn; m->jcn = jcn;
    m->ICNTL(7) = perm_in ? 1 : 0;
    m->perm_in = perm_in;
    m->ICNTL(14) = mem_relax;
  });
  return ldlt_info(h, 1);
}

/* Numerical factorisation; `a` (double or float, as the handle) must outlive the factors. */
int ldlt_factor(void *hv, void *a) {
  ldlt_t *h = hv;
  if (h->single) h->s.a = a; else h->d.a = a;
  RUN(h, 2, {});
  return ldlt_info(h, 1);
}

/* Solve in place: rhs (n values, the handle's precision) becomes the solution. */
int ldlt_solve(void *hv, void *rhs) {
  ldlt_t *h = hv;
  RUN(h, 3, { m->rhs = rhs; m->nrhs = 1; m->lrhs = m->n; });
  return ldlt_info(h, 1);
}

void ldlt_free(void *hv) {
  ldlt_t *h = hv;
  if (!h) return;
  RUN(h, -2, {});
  free(h);
}

/* METIS nested dissection of a graph in CSR form (no self loops): perm[new] = old,
 * iperm[old] = new. Returns METIS' status (METIS_OK = 1). */
int nested_dissection(int n, const int *xadj, const int *adj, int *perm, int *iperm) {
  idx_t nv = n;
  idx_t *xa = malloc(sizeof(idx_t) * (n + 1));
  idx_t *ad = malloc(sizeof(idx_t) * (xadj[n] > 0 ? xadj[n] : 1));
  idx_t *p = malloc(sizeof(idx_t) * n), *ip = malloc(sizeof(idx_t) * n);
  idx_t options[METIS_NOPTIONS];
  int status = 0;
  if (xa && ad && p && ip) {
    for (int i = 0; i <= n; i++) xa[i] = xadj[i];
    for (int k = 0; k < xadj[n]; k++) ad[k] = adj[k];
    METIS_SetDefaultOptions(options);
    options[METIS_OPTION_NUMBERING] = 0;
    status = METIS_NodeND(&nv, xa, ad, NULL, options, p, ip);
    for (int i = 0; i < n; i++) { perm[i] = (int)p[i]; iperm[i] = (int)ip[i]; }
  }
  free(xa); free(ad); free(p); free(ip);
  return status;
}
