/* Lagrange tetrahedra (P1 or P2, affine geometry) with nq quadrature points per cell:
 * deformation gradients, internal forces, and the stiffness assembled straight into the value
 * array of a CSR matrix whose pattern is known. Built with cffi by fem_sim/solver/tet.py, which
 * documents the measured gain and is tested against dolfinx's assembly.
 *
 * Layouts (cell-major, points within a cell in basix order):
 *   dN[c][q][a][J]  gradient of the shape function of cell node a at point q (nn nodes);
 *   w[c][q]         quadrature weight times |det| of the cell map;
 *   A[c][q][iJ][kL] tangent dP_iJ / dF_kL (row-major 9 x 9); P[c][q][iJ] first Piola stress.
 * The element matrix
 *   K[(a,i),(b,k)] = sum_q w sum_J sum_L dN[q][a][J] A[q][iJ][kL] dN[q][b][L]
 * is added at values[pos[c][(3a+i)*3nn + 3b+k]].
 *
 * Threads (OpenMP): the cells are coloured (tet_colour) and each colour is shared among the
 * threads; the sums into shared entries run colour by colour, so every result is the same bit
 * for bit whatever the thread count.
 */
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#define MAXN 10 /* nodes per cell: P2 */
#define COLOUR_WORDS 4 /* at most 64 * 4 colours */

/* Greedy colouring of the cells: no two cells of one colour share a node, so the cells of a
 * colour can add into the same arrays (forces, CSR values) from several threads without
 * conflicts, and the sums come out in the same order for any thread count. colour[c] gets the
 * smallest colour none of the cells sharing a node with c has so far. Returns the number of
 * colours, -1 if more than 64 * COLOUR_WORDS are needed, -2 if out of memory. */
int tet_colour(int ncells, int nn, int nnodes, const int32_t *cells, int32_t *colour) {
  uint64_t *used = calloc((size_t)nnodes * COLOUR_WORDS, sizeof(uint64_t));
  if (!used) return -2;
  int ncolours = 0;
  for (int c = 0; c < ncells; c++) {
    uint64_t taken[COLOUR_WORDS] = {0};
    const int32_t *nodes = cells + (int64_t)nn * c;
    for (int a = 0; a < nn; a++)
      for (int w = 0; w < COLOUR_WORDS; w++) taken[w] |= used[(int64_t)COLOUR_WORDS * nodes[a] + w];
    int col = -1;
    for (int w = 0; w < COLOUR_WORDS && col < 0; w++)
      if (~taken[w]) col = 64 * w + __builtin_ctzll(~taken[w]);
    if (col < 0) {
      free(used);
      return -1;
    }
    colour[c] = col;
    if (col + 1 > ncolours) ncolours = col + 1;
    for (int a = 0; a < nn; a++)
      used[(int64_t)COLOUR_WORDS * nodes[a] + col / 64] |= (uint64_t)1 << (col % 64);
  }
  free(used);
  return ncolours;
}

/* The element matrix of cell c, upper triangle (rows r = 3a + i, columns >= r), added into the
 * CSR values together with its mirror image: the assembled matrix is exactly symmetric. The
 * tangent A has major symmetry (A[iJ][kL] = A[kL][iJ], the second derivative of an energy), so
 * the lower triangle is the mirror of the upper one up to round-off. */
static void element_stiffness(int64_t c, int nn, int nq, const double *dN_all,
                              const double *w_all, const double *A_all, const int32_t *pos_all,
                              double *values) {
  const int nd = 3 * nn;
  double K[3 * MAXN * 3 * MAXN];
  memset(K, 0, sizeof(double) * nd * nd);
  for (int q = 0; q < nq; q++) {
    const int64_t cq = c * nq + q;
    const double *dN = dN_all + cq * nd;
    const double *A = A_all + 81 * cq;
    const double wq = w_all[cq];
    double T[9][3 * MAXN]; /* T[iJ][(b,k)] = sum_L A[iJ][kL] dN[b][L] */
    for (int iJ = 0; iJ < 9; iJ++)
      for (int b = 0; b < nn; b++)
        for (int k = 0; k < 3; k++) {
          const double *row = A + 9 * iJ + 3 * k;
          T[iJ][3 * b + k] = row[0] * dN[3 * b] + row[1] * dN[3 * b + 1] + row[2] * dN[3 * b + 2];
        }
    for (int a = 0; a < nn; a++)
      for (int i = 0; i < 3; i++) {
        const int r = 3 * a + i;
        const double g0 = wq * dN[3 * a], g1 = wq * dN[3 * a + 1], g2 = wq * dN[3 * a + 2];
        const double *t0 = T[3 * i], *t1 = T[3 * i + 1], *t2 = T[3 * i + 2];
        double *Krow = K + r * nd;
        for (int bk = r; bk < nd; bk++) Krow[bk] += g0 * t0[bk] + g1 * t1[bk] + g2 * t2[bk];
      }
  }
  const int32_t *pos = pos_all + c * nd * nd;
  for (int r = 0; r < nd; r++) {
    values[pos[r * nd + r]] += K[r * nd + r];
    for (int bk = r + 1; bk < nd; bk++) {
      values[pos[r * nd + bk]] += K[r * nd + bk];
      values[pos[bk * nd + r]] += K[r * nd + bk];
    }
  }
}

/* Cells in colour order: order[starts[k] .. starts[k+1]) are the cells of colour k. */
int tet_stiffness(int ncells, int nn, int nq, const double *dN_all, const double *w_all,
                  const double *A_all, const int32_t *pos_all, double *values, int ncolours,
                  const int64_t *starts, const int32_t *order, int nthreads) {
  if (nn < 1 || nn > MAXN) return -1;
  (void)ncells;
  (void)nthreads;
#pragma omp parallel num_threads(nthreads)
  for (int k = 0; k < ncolours; k++) {
#pragma omp for schedule(static)
    for (int64_t t = starts[k]; t < starts[k + 1]; t++)
      element_stiffness(order[t], nn, nq, dN_all, w_all, A_all, pos_all, values);
  }
  return 0;
}

/* F = I + sum_a u_a (x) dN_a at every point (row-major 3 x 3); u is (nodes, 3). */
void tet_deformation(int ncells, int nn, int nq, const int32_t *cells, const double *dN_all,
                     const double *u, double *F_all, int nthreads) {
  (void)nthreads;
#pragma omp parallel for schedule(static) num_threads(nthreads)
  for (int c = 0; c < ncells; c++)
    for (int q = 0; q < nq; q++) {
      const int64_t cq = (int64_t)c * nq + q;
      const double *dN = dN_all + cq * 3 * nn;
      double *F = F_all + 9 * cq;
      for (int k = 0; k < 9; k++) F[k] = (k % 4 == 0) ? 1.0 : 0.0;
      for (int a = 0; a < nn; a++) {
        const double *ua = u + 3 * (int64_t)cells[(int64_t)nn * c + a];
        for (int i = 0; i < 3; i++)
          for (int J = 0; J < 3; J++) F[3 * i + J] += ua[i] * dN[3 * a + J];
      }
    }
}

/* Internal forces: b[3 node_a + i] += sum_q w P[iJ] dN[a][J] (b is not zeroed here), cells in
 * colour order as tet_stiffness. */
void tet_forces(int ncells, int nn, int nq, const int32_t *cells, const double *dN_all,
                const double *w_all, const double *P_all, double *b, int ncolours,
                const int64_t *starts, const int32_t *order, int nthreads) {
  (void)ncells;
  (void)nthreads;
#pragma omp parallel num_threads(nthreads)
  for (int k = 0; k < ncolours; k++) {
#pragma omp for schedule(static)
    for (int64_t t = starts[k]; t < starts[k + 1]; t++) {
      const int64_t c = order[t];
      for (int q = 0; q < nq; q++) {
        const int64_t cq = c * nq + q;
        const double *dN = dN_all + cq * 3 * nn;
        const double *P = P_all + 9 * cq;
        const double wq = w_all[cq];
        for (int a = 0; a < nn; a++) {
          double *ba = b + 3 * (int64_t)cells[(int64_t)nn * c + a];
          for (int i = 0; i < 3; i++)
            ba[i] += wq * (P[3 * i] * dN[3 * a] + P[3 * i + 1] * dN[3 * a + 1]
                           + P[3 * i + 2] * dN[3 * a + 2]);
        }
      }
    }
  }
}

/* The averaged-nodal-pressure correction of one-point tangents (fem_sim/solver/anp.py), cell
 * by cell: with C = J F^-T of the cell (row-major 3 x 3),
 *   A[iJ][kL] += s1 C[iJ] C[kL],  then  A[iJ][kL] -= s2 C[iL] C[kJ],
 * each product and sum rounded as numpy's elementwise expression rounds it. */
void anp_tangent(int64_t n, const double *C_all, const double *s1, const double *s2,
                 double *A_all, int nthreads) {
  (void)nthreads;
#pragma omp parallel for schedule(static) num_threads(nthreads)
  for (int64_t c = 0; c < n; c++) {
    const double *C = C_all + 9 * c;
    double *A = A_all + 81 * c;
    for (int i = 0; i < 3; i++)
      for (int J = 0; J < 3; J++)
        for (int k = 0; k < 3; k++)
          for (int L = 0; L < 3; L++) {
            double *a = A + 9 * (3 * i + J) + 3 * k + L;
            *a = *a + s1[c] * (C[3 * i + J] * C[3 * k + L]);
            *a = *a - s2[c] * (C[3 * i + L] * C[3 * k + J]);
          }
  }
}

/* The ANP gradients g_a = dJbar_a/du (fem_sim/solver/anp.py) as a sum of per-cell terms: for
 * cell c and (a, b, k) in that nesting order (t = 12 a + 3 b + k),
 *   g[g_index[48 c + t]] += w_ae[c][a] * dJ_c/du_(b,k),  dJ_c/du_(b,k) = sum_j C[k][j] dN[b][j]
 * (C = J F^-T of the cell, dN its four P1 gradients), serially in (c, t) order: the sums of
 * numpy's einsum + bincount, in their order. */
void anp_g(int64_t n, const double *C_all, const double *dN_all, const double *w_ae,
           const int64_t *g_index, double *g) {
  for (int64_t c = 0; c < n; c++) {
    const double *C = C_all + 9 * c, *dN = dN_all + 12 * c;
    double dJ[4][3];
    for (int b = 0; b < 4; b++)
      for (int k = 0; k < 3; k++) {
        double s = C[3 * k] * dN[3 * b];
        s += C[3 * k + 1] * dN[3 * b + 1];
        s += C[3 * k + 2] * dN[3 * b + 2];
        dJ[b][k] = s;
      }
    const int64_t *gi = g_index + 48 * c;
    for (int a = 0; a < 4; a++)
      for (int b = 0; b < 4; b++)
        for (int k = 0; k < 3; k++) g[gi[12 * a + 3 * b + k]] += w_ae[4 * c + a] * dJ[b][k];
  }
}

/* Sum of rank-one terms d_a g_a g_a^T into the CSR values (the averaged-nodal-pressure
 * coupling, fem_sim/solver/anp.py): for every pair t of entries (p[t], q[t]) of the same row
 * node[t] of g, values[pos[t]] += d[node[t]] g[p[t]] g[q[t]]. */
void anp_pairs(int64_t n, const int32_t *pos, const int32_t *node, const int32_t *p,
               const int32_t *q, const double *d, const double *g, double *values) {
  for (int64_t t = 0; t < n; t++) values[pos[t]] += d[node[t]] * g[p[t]] * g[q[t]];
}

/* y = A x for a CSR matrix, rows split among the threads (each row's sum in column order:
 * the same bits on any thread count). */
void csr_matvec(int64_t n, const int32_t *indptr, const int32_t *indices, const double *values,
                const double *x, double *y, int nthreads) {
  (void)nthreads;
#pragma omp parallel for schedule(static) num_threads(nthreads)
  for (int64_t i = 0; i < n; i++) {
    double s = 0.0;
    for (int32_t e = indptr[i]; e < indptr[i + 1]; e++) s += values[e] * x[indices[e]];
    y[i] = s;
  }
}
