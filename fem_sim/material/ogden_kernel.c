/* Uncoupled Ogden point kernel: the same formulas as fem_sim/ogden.py (see its docstring for
 * the derivation), one point at a time instead of batched numpy. Compiled at first use by
 * fem_sim/ogden_c.py; tests/fem_sim/test_ogden.py checks it against the numpy kernel.
 *
 * Layout: F, P row-major 3x3 per point; A row-major 9x9 per point, rows (i, J), columns (k, L).
 * Points with det F <= 0 or non-finite F get NaN in W, P, A; the return value counts them.
 */
#include <math.h>
#include <stdlib.h>
#ifdef _OPENMP
#include <omp.h>
#endif

/* Threads for the point loop (points are independent, so the results do not depend on the
 * count). n > 0 sets it, n <= 0 only asks; returns the count in force. The default is
 * OMP_NUM_THREADS, else the processors OpenMP sees; the batch generator sets 1 per MPI rank.
 * Kept here, not in OpenMP's global setting: MUMPS resets that to 1 during a factorisation
 * (measured: 2 before a simulation, 1 after). */
static int kernel_threads = 0;

int ogden_threads(int n)
{
#ifdef _OPENMP
    if (n > 0) {
        kernel_threads = n;
    } else if (kernel_threads <= 0) {
        const char *env = getenv("OMP_NUM_THREADS");
        int from_env = env ? atoi(env) : 0;
        kernel_threads = from_env > 0 ? from_env : omp_get_num_procs();
    }
    return kernel_threads;
#else
    (void)n;
    return 1;
#endif
}

/* The Jacobi rotation (c, s) that zeroes apq of the symmetric 2x2 block [[app, apq], [apq,
 * aqq]] (apq != 0): the smaller rotation angle, computed stably. */
static void jacobi_rotation(double app, double aqq, double apq, double *c, double *s)
{
    double theta = 0.5 * (aqq - app) / apq;
    double t = 1.0 / (fabs(theta) + sqrt(theta * theta + 1.0));
    if (theta < 0.0)
        t = -t;
    *c = 1.0 / sqrt(t * t + 1.0);
    *s = t * *c;
}

/* Cyclic Jacobi rotations on a symmetric 3x3 matrix a = Q0^T C Q0, v = Q0 on entry (Q0
 * orthonormal, the columns are the current eigenvector estimates). On return a[0], a[4], a[8]
 * hold the eigenvalues and v's columns the eigenvectors: v diag(a) v^T equals C up to an
 * off-diagonal remainder below 1e-16 of the diagonal (sum of squares <= 1e-32 diag^2), i.e. the
 * decomposition is exact for a matrix within the round-off of C's own entries. Orthonormal
 * vectors even for coinciding eigenvalues. */
static void jacobi3_from(double a[9], double v[9])
{
    for (int sweep = 0; sweep < 50; ++sweep) {
        double off = a[1] * a[1] + a[2] * a[2] + a[5] * a[5];
        double diag = a[0] * a[0] + a[4] * a[4] + a[8] * a[8];
        if (off <= 1e-32 * diag || off == 0.0)
            return;
        for (int p = 0; p < 2; ++p) {
            for (int q = p + 1; q < 3; ++q) {
                double apq = a[3 * p + q];
                if (apq == 0.0)
                    continue;
                double c, s;
                jacobi_rotation(a[3 * p + p], a[3 * q + q], apq, &c, &s);
                /* A <- R^T A R with R the rotation in the (p, q) plane */
                for (int k = 0; k < 3; ++k) {
                    double akp = a[3 * k + p], akq = a[3 * k + q];
                    a[3 * k + p] = c * akp - s * akq;
                    a[3 * k + q] = s * akp + c * akq;
                }
                for (int k = 0; k < 3; ++k) {
                    double apk = a[3 * p + k], aqk = a[3 * q + k];
                    a[3 * p + k] = c * apk - s * aqk;
                    a[3 * q + k] = s * apk + c * aqk;
                }
                a[3 * p + q] = a[3 * q + p] = 0.0;
                for (int k = 0; k < 3; ++k) {
                    double vkp = v[3 * k + p], vkq = v[3 * k + q];
                    v[3 * k + p] = c * vkp - s * vkq;
                    v[3 * k + q] = s * vkp + c * vkq;
                }
            }
        }
    }
}

static void cross3(const double *x, const double *y, double *z)
{
    z[0] = x[1] * y[2] - x[2] * y[1];
    z[1] = x[2] * y[0] - x[0] * y[2];
    z[2] = x[0] * y[1] - x[1] * y[0];
}

/* An orthonormal Q (columns) close to the eigenvectors of the symmetric C, in closed form:
 * the eigenvalues from the trigonometric solution of the characteristic cubic, the
 * eigenvector of the most separated one (its gap is at least half the spread) as the longest
 * cross product of two rows of C - lambda I, the other two by the exact rotation that
 * diagonalises C in the plane orthogonal to it. Q is orthonormal to round-off by
 * construction; its accuracy only decides how much work the Jacobi polish has left (measured
 * at 75k random F near the identity: Q^T C Q off-diagonal at 1e-15..1e-17 of the diagonal in
 * 99 % of the points). Returns 0 with the identity when C is too close to a multiple of the
 * identity (or too degenerate) for the construction to mean anything. */
static int eig3_start(const double C[9], double Q[9])
{
    for (int i = 0; i < 9; ++i)
        Q[i] = (i % 4 == 0) ? 1.0 : 0.0;
    double q = (C[0] + C[4] + C[8]) / 3.0;
    double b0 = C[0] - q, b4 = C[4] - q, b8 = C[8] - q;
    double p2 = (b0 * b0 + b4 * b4 + b8 * b8
                 + 2.0 * (C[1] * C[1] + C[2] * C[2] + C[5] * C[5])) / 6.0;
    if (!(p2 > 1e-24 * q * q) || !isfinite(p2))
        return 0;
    double p = sqrt(p2), ip = 1.0 / p;
    /* det((C - q I) / p) / 2 = cos(3 phi) */
    double d = (b0 * (b4 * b8 - C[5] * C[5]) - C[1] * (C[1] * b8 - C[5] * C[2])
                + C[2] * (C[1] * C[5] - b4 * C[2])) * ip * ip * ip * 0.5;
    d = d > 1.0 ? 1.0 : (d < -1.0 ? -1.0 : d);
    double phi = acos(d) / 3.0;
    double cphi = cos(phi), sphi = sin(phi);  /* one sincos */
    double l1 = q + 2.0 * p * cphi;                                  /* largest */
    double l3 = q - p * (cphi + 1.7320508075688772 * sphi);          /* cos(phi + 2 pi / 3) */
    double l2 = 3.0 * q - l1 - l3;
    double lam = (l1 - l2 >= l2 - l3) ? l1 : l3;
    double r[3][3], x[3][3], n[3];
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j)
            r[i][j] = C[3 * i + j] - (i == j ? lam : 0.0);
    cross3(r[0], r[1], x[0]);
    cross3(r[0], r[2], x[1]);
    cross3(r[1], r[2], x[2]);
    int best = 0;
    for (int k = 0; k < 3; ++k) {
        n[k] = x[k][0] * x[k][0] + x[k][1] * x[k][1] + x[k][2] * x[k][2];
        if (n[k] > n[best])
            best = k;
    }
    if (!(n[best] > 1e-30 * p2 * p2) || !isfinite(n[best]))
        return 0;
    double s = 1.0 / sqrt(n[best]);
    double v[3] = {x[best][0] * s, x[best][1] * s, x[best][2] * s};
    int ax = 0;  /* u: orthogonal to v, from the axis least aligned with v; w = v x u */
    for (int k = 1; k < 3; ++k)
        if (fabs(v[k]) < fabs(v[ax]))
            ax = k;
    double e[3] = {0.0, 0.0, 0.0}, u[3], w[3];
    e[ax] = 1.0;
    cross3(e, v, u);
    s = 1.0 / sqrt(u[0] * u[0] + u[1] * u[1] + u[2] * u[2]);
    for (int i = 0; i < 3; ++i)
        u[i] *= s;
    cross3(v, u, w);
    double Cu[3], Cw[3];
    for (int i = 0; i < 3; ++i) {
        Cu[i] = C[3 * i] * u[0] + C[3 * i + 1] * u[1] + C[3 * i + 2] * u[2];
        Cw[i] = C[3 * i] * w[0] + C[3 * i + 1] * w[1] + C[3 * i + 2] * w[2];
    }
    double muu = u[0] * Cu[0] + u[1] * Cu[1] + u[2] * Cu[2];
    double mww = w[0] * Cw[0] + w[1] * Cw[1] + w[2] * Cw[2];
    double muw = u[0] * Cw[0] + u[1] * Cw[1] + u[2] * Cw[2];
    double c = 1.0, sn = 0.0;
    if (muw != 0.0)
        jacobi_rotation(muu, mww, muw, &c, &sn);
    for (int i = 0; i < 3; ++i) {
        Q[3 * i] = v[i];
        Q[3 * i + 1] = c * u[i] - sn * w[i];
        Q[3 * i + 2] = sn * u[i] + c * w[i];
    }
    return 1;
}

/* Eigen-decomposition of a symmetric 3x3 matrix: the closed-form start, then Jacobi sweeps
 * until the off-diagonal test of jacobi3_from holds (none for most points; the start alone
 * would lose accuracy where two eigenvalues nearly coincide, the sweeps do not). On return,
 * a[0], a[4], a[8] hold the eigenvalues, v's columns the eigenvectors (v[3 * r + col]).
 * ~2x faster than Jacobi sweeps from the identity (3-4 sweeps; bench/bench_kernel.py). */
static void eig3(double a[9], double v[9])
{
    double T[9];
    eig3_start(a, v);
    for (int i = 0; i < 3; ++i)  /* T = C v */
        for (int j = 0; j < 3; ++j)
            T[3 * i + j] = a[3 * i] * v[j] + a[3 * i + 1] * v[3 + j] + a[3 * i + 2] * v[6 + j];
    for (int i = 0; i < 3; ++i)  /* a = v^T T */
        for (int j = i; j < 3; ++j)
            a[3 * i + j] = a[3 * j + i] = v[i] * T[j] + v[3 + i] * T[3 + j] + v[6 + i] * T[6 + j];
    jacobi3_from(a, v);
}

/* (x^e - y^e) / (x - y) for x, y > 0, exact as x -> y (limit e y^(e-1)); given
 * t = ln x - ln y and ye1 = y^(e-1). */
static double divided_power(double t, double ye1, double e)
{
    double ratio = (t == 0.0) ? e : expm1(e * t) / expm1(t);
    return ye1 * ratio;
}

int ogden_points(int n, const double *F_all, int nterms, const double *ck, const double *mk,
                 double K, int vol_log, int want_tangent, double *W_all, double *P_all,
                 double *A_all, double *J_all)
{
    int bad_count = 0;
    const double nan = NAN;
    const int nthreads = ogden_threads(0);
    (void)nthreads;
#pragma omp parallel for schedule(static) reduction(+ : bad_count) num_threads(nthreads)
    for (int pt = 0; pt < n; ++pt) {
        const double *F = F_all + 9 * pt;
        double *P = P_all + 9 * pt;
        double *A = want_tangent ? A_all + 81 * pt : 0;
        double J = F[0] * (F[4] * F[8] - F[5] * F[7]) - F[1] * (F[3] * F[8] - F[5] * F[6])
                   + F[2] * (F[3] * F[7] - F[4] * F[6]);
        J_all[pt] = J;
        int finite = 1;
        for (int i = 0; i < 9; ++i)
            finite &= isfinite(F[i]);
        if (!(finite && isfinite(J) && J > 0.0)) {
            ++bad_count;
            W_all[pt] = nan;
            for (int i = 0; i < 9; ++i)
                P[i] = nan;
            if (A)
                for (int i = 0; i < 81; ++i)
                    A[i] = nan;
            continue;
        }
        double C[9], Q[9];
        for (int I = 0; I < 3; ++I)
            for (int L = 0; L < 3; ++L)
                C[3 * I + L] = F[I] * F[L] + F[3 + I] * F[3 + L] + F[6 + I] * F[6 + L];
        eig3(C, Q);
        double c[3] = {C[0], C[4], C[8]};
        for (int a = 0; a < 3; ++a)
            if (c[a] < 2.2250738585072014e-308)
                c[a] = 2.2250738585072014e-308;
        double D = J * J;
        double U, UpJ, UppJ;
        if (vol_log) {
            double lnJ = log(J);
            U = 0.5 * K * lnJ * lnJ;
            UpJ = K * lnJ;
            UppJ = K;
        } else {
            U = 0.5 * K * (J - 1.0) * (J - 1.0);
            UpJ = K * (J - 1.0) * J;
            UppJ = K * (2.0 * J - 1.0) * J;
        }
        double W = U, Phi[3] = {0.0, 0.0, 0.0}, B = 0.5 * UpJ;
        double Phi2[9] = {0}, gam[9] = {0};
        double inv[3] = {1.0 / c[0], 1.0 / c[1], 1.0 / c[2]};
        double lnc[3] = {log(c[0]), log(c[1]), log(c[2])};
        for (int k = 0; k < nterms; ++k) {
            double m = mk[k], p = 0.5 * m, q = -m / 6.0;
            double Dq = pow(D, q), a = ck[k] / (m * m) * Dq;
            double cp[3], g[3];
            for (int i = 0; i < 3; ++i) {
                cp[i] = exp(p * lnc[i]);
                g[i] = p * cp[i] * inv[i];
            }
            double T = cp[0] + cp[1] + cp[2];
            W += ck[k] / (m * m) * (Dq * T - 3.0);
            for (int i = 0; i < 3; ++i)
                Phi[i] += a * g[i];
            B += q * a * T;
            if (A) {
                for (int i = 0; i < 3; ++i) {
                    double dg = (p - 1.0) * g[i] * inv[i];  /* p (p-1) c^(p-2) */
                    for (int j = 0; j < 3; ++j)
                        Phi2[3 * i + j] += a * ((i == j ? dg : 0.0)
                                                + q * (g[i] * inv[j] + inv[i] * g[j])
                                                + q * q * T * inv[i] * inv[j]);
                }
                /* only the off-diagonal pairs enter the tangent; g_k[x, y] = p (x^(p-1) -
                 * y^(p-1)) / (x - y) and p y^(p-2) = g(y) / y */
                for (int i = 0; i < 2; ++i)
                    for (int j = i + 1; j < 3; ++j) {
                        double v = a * divided_power(lnc[i] - lnc[j], g[j] * inv[j], p - 1.0);
                        gam[3 * i + j] += v;
                        gam[3 * j + i] += v;
                    }
            }
        }
        for (int i = 0; i < 3; ++i)
            Phi[i] += B * inv[i];
        W_all[pt] = W;
        double S[9];
        for (int I = 0; I < 3; ++I)
            for (int L = 0; L < 3; ++L) {
                double s = 0.0;
                for (int a = 0; a < 3; ++a)
                    s += Q[3 * I + a] * 2.0 * Phi[a] * Q[3 * L + a];
                S[3 * I + L] = s;
            }
        for (int i = 0; i < 3; ++i)
            for (int L = 0; L < 3; ++L)
                P[3 * i + L] = F[3 * i] * S[L] + F[3 * i + 1] * S[3 + L] + F[3 * i + 2] * S[6 + L];
        if (!A)
            continue;
        for (int i = 0; i < 3; ++i)
            for (int j = 0; j < 3; ++j) {
                Phi2[3 * i + j] += 0.25 * UppJ * inv[i] * inv[j];
                gam[3 * i + j] -= B * inv[i] * inv[j];
            }
        for (int i = 0; i < 3; ++i)
            Phi2[4 * i] -= B * inv[i] * inv[i];
        /* Fn[a][i] = (F n_a)_i; M_ab[i, J] = Fn[a][i] n_b[J]; the six vectors G_s:
         * M_00, M_11, M_22, M_01 + M_10, M_02 + M_20, M_12 + M_21 (see ogden.py). */
        double Fn[9];
        for (int a = 0; a < 3; ++a)
            for (int i = 0; i < 3; ++i)
                Fn[3 * a + i] = F[3 * i] * Q[a] + F[3 * i + 1] * Q[3 + a] + F[3 * i + 2] * Q[6 + a];
        static const int pa[6] = {0, 1, 2, 0, 0, 1}, pb[6] = {0, 1, 2, 1, 2, 2};
        double G[6][9];
        for (int s = 0; s < 6; ++s) {
            int a = pa[s], b = pb[s];
            for (int i = 0; i < 3; ++i)
                for (int Jj = 0; Jj < 3; ++Jj) {
                    double v = Fn[3 * a + i] * Q[3 * Jj + b];
                    if (s >= 3)
                        v += Fn[3 * b + i] * Q[3 * Jj + a];
                    G[s][3 * i + Jj] = v;
                }
        }
        /* H = Wm G with Wm = [[4 Phi2, 0], [0, diag(2 gam_01, 2 gam_02, 2 gam_12)]] */
        double H[6][9];
        for (int s = 0; s < 3; ++s)
            for (int r = 0; r < 9; ++r)
                H[s][r] = 4.0 * (Phi2[3 * s] * G[0][r] + Phi2[3 * s + 1] * G[1][r]
                                 + Phi2[3 * s + 2] * G[2][r]);
        for (int s = 3; s < 6; ++s) {
            double w = 2.0 * gam[3 * pa[s] + pb[s]];
            for (int r = 0; r < 9; ++r)
                H[s][r] = w * G[s][r];
        }
        for (int r = 0; r < 9; ++r)
            for (int col = r; col < 9; ++col) {
                double v = 0.0;
                for (int s = 0; s < 6; ++s)
                    v += G[s][r] * H[s][col];
                A[9 * r + col] = v;
                A[9 * col + r] = v;
            }
        /* + delta_ik S_JL */
        for (int i = 0; i < 3; ++i)
            for (int Jj = 0; Jj < 3; ++Jj)
                for (int L = 0; L < 3; ++L)
                    A[9 * (3 * i + Jj) + 3 * i + L] += S[3 * Jj + L];
    }
    return bad_count;
}
