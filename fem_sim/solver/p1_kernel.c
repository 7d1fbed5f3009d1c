/* P1 tetrahedra with one quadrature point (FEBio's tet4): deformation gradients, internal forces,
 * and the stiffness assembled straight into the value array of a CSR matrix whose pattern is
 * known. Built with cffi by fem_sim/p1.py,
 * which documents the measured gain and is tested against dolfinx's assembly.
 *
 * For cell c with shape-function gradients dN[a][J] (a = 0..3 nodes, J = 0..2), volume V and
 * tangent A[iJ][kL] = dP_iJ / dF_kL (row-major 9 x 9), the element matrix is
 *   K[(a,i),(b,k)] = V sum_J sum_L dN[a][J] A[iJ][kL] dN[b][L],
 * added at values[pos[c][(3a+i)*12 + 3b+k]].
 */
#include <stdint.h>

void p1_stiffness(int ncells, const double *dN_all, const double *vol, const double *A_all,
                  const int32_t *pos_all, double *values) {
  for (int c = 0; c < ncells; c++) {
    const double *dN = dN_all + 12 * (int64_t)c;
    const double *A = A_all + 81 * (int64_t)c;
    const int32_t *pos = pos_all + 144 * (int64_t)c;
    double T[9][12]; /* T[iJ][(b,k)] = sum_L A[iJ][kL] dN[b][L] */
    for (int iJ = 0; iJ < 9; iJ++)
      for (int b = 0; b < 4; b++)
        for (int k = 0; k < 3; k++) {
          const double *row = A + 9 * iJ + 3 * k;
          T[iJ][3 * b + k] = row[0] * dN[3 * b] + row[1] * dN[3 * b + 1] + row[2] * dN[3 * b + 2];
        }
    const double v = vol[c];
    for (int a = 0; a < 4; a++)
      for (int i = 0; i < 3; i++) {
        const double g0 = v * dN[3 * a], g1 = v * dN[3 * a + 1], g2 = v * dN[3 * a + 2];
        const double *t0 = T[3 * i], *t1 = T[3 * i + 1], *t2 = T[3 * i + 2];
        const int32_t *p = pos + (3 * a + i) * 12;
        for (int bk = 0; bk < 12; bk++)
          values[p[bk]] += g0 * t0[bk] + g1 * t1[bk] + g2 * t2[bk];
      }
  }
}

/* F = I + sum_a u_a (x) dN_a for every cell (row-major 3 x 3); u is (nodes, 3). */
void p1_deformation(int ncells, const int32_t *cells, const double *dN_all, const double *u,
                    double *F_all) {
  for (int c = 0; c < ncells; c++) {
    const double *dN = dN_all + 12 * (int64_t)c;
    double *F = F_all + 9 * (int64_t)c;
    for (int k = 0; k < 9; k++) F[k] = (k % 4 == 0) ? 1.0 : 0.0;
    for (int a = 0; a < 4; a++) {
      const double *ua = u + 3 * (int64_t)cells[4 * (int64_t)c + a];
      for (int i = 0; i < 3; i++)
        for (int J = 0; J < 3; J++) F[3 * i + J] += ua[i] * dN[3 * a + J];
    }
  }
}

/* Internal forces: b[3 node_a + i] += V sum_J P[iJ] dN[a][J] (b is not zeroed here). */
void p1_forces(int ncells, const int32_t *cells, const double *dN_all, const double *vol,
               const double *P_all, double *b) {
  for (int c = 0; c < ncells; c++) {
    const double *dN = dN_all + 12 * (int64_t)c;
    const double *P = P_all + 9 * (int64_t)c;
    const double v = vol[c];
    for (int a = 0; a < 4; a++) {
      double *ba = b + 3 * (int64_t)cells[4 * (int64_t)c + a];
      for (int i = 0; i < 3; i++)
        ba[i] += v * (P[3 * i] * dN[3 * a] + P[3 * i + 1] * dN[3 * a + 1]
                      + P[3 * i + 2] * dN[3 * a + 2]);
    }
  }
}
