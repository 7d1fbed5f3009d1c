"""Uncoupled first-order Ogden material (FEBio's convention), stress and tangent at points.

    W(F) = sum_k c_k / m_k^2 (l1~^m_k + l2~^m_k + l3~^m_k - 3) + U(J),   li~ = J^(-1/3) li
    U(J) = K/2 (ln J)^2   ("log", FEBio)      or      K/2 (J - 1)^2   ("quadratic")

Why point kernels in numpy rather than a closed-form UFL expression: the principal-stretch form is
singular where stretches coincide, and the undeformed state F = I is exactly that case. The UFL
closed form needs a perturbation of C to separate equal eigenvalues and its tangent at F = I is
then wrong (measured ~20 % too stiff). Written as a *spectral function* of C, W = Phi(c1, c2, c3)
(c_i the eigenvalues of C = F^T F), both derivatives have exact, finite expressions everywhere:

    dW/dC      = sum_a Phi_a n_a (x) n_a
    d2W/dC2    = sum_ab Phi_ab (n_a n_a)(n_b n_b)  +  sum_(a != b) gamma_ab/2 [(n_a n_b)(n_a n_b)
                                                                           + (n_a n_b)(n_b n_a)]
    gamma_ab   = (Phi_a - Phi_b) / (c_a - c_b)

and gamma_ab has a closed form that is continuous across c_a = c_b (below), so no perturbation and
no special case is needed: at F = I the stress is exactly 0 and the tangent is exactly the
linear-elastic one. The kernels are vectorised over points (batched small matrix products),
cost a few
milliseconds per 10^4 points, and keep the material parameters out of the compiled forms, so one
compiled form serves every material of a scene.

With D = det C = J^2, p_k = m_k / 2, q_k = -m_k / 6, a_k = c_k / m_k^2 D^q_k, T_k = sum_i c_i^p_k,
g_k(c) = p_k c^(p_k - 1):

    Phi_i      = sum_k a_k g_k(c_i) + B / c_i,     B = sum_k q_k a_k T_k + U'(J) J / 2
    gamma_ij   = sum_k a_k g_k[c_i, c_j] - B / (c_i c_j)     (g[x, y]: divided difference)
    Phi_ij     = sum_k a_k (delta_ij g_k'(c_i) + q_k g_k(c_i) / c_j + q_k g_k(c_j) / c_i
                           + q_k^2 T_k / (c_i c_j))
                 + (U'' J + U') J / (4 c_i c_j) - delta_ij B / c_i^2

    S = 2 dW/dC,  P = F S,  A_iJkL = dP_iJ/dF_kL = delta_ik S_JL + F_iI F_kK 4 d2W/dC_IJ dC_KL
"""

from __future__ import annotations

import numpy as np

from data_spec.material import OgdenMaterial

__all__ = ["OgdenMaterial", "ogden_point_kernel", "point_kernel"]


def _volumetric(mat: OgdenMaterial, J: np.ndarray):
    """U(J), U'(J) J and (U''(J) J + U'(J)) J."""
    K = mat.K
    if mat.volumetric == "log":
        lnJ = np.log(J)
        return 0.5 * K * lnJ**2, K * lnJ, np.full_like(J, K)
    return 0.5 * K * (J - 1.0) ** 2, K * (J - 1.0) * J, K * (2.0 * J - 1.0) * J


def _divided_power(x: np.ndarray, y: np.ndarray, p: float) -> np.ndarray:
    """(x^p - y^p) / (x - y) for x, y > 0, exact and stable when x -> y (limit p y^(p-1)).

    With t = ln(x / y): x^p - y^p = y^p expm1(p t) and x - y = y expm1(t), both accurate for
    small t, so the ratio never cancels catastrophically.
    """
    t = np.log(x / y)
    small = t == 0.0
    ts = np.where(small, 1.0, t)
    ratio = np.where(small, p, np.expm1(p * ts) / np.expm1(ts))
    return y ** (p - 1.0) * ratio


def _tangent(F, Q, c, S, B, UppJ, terms) -> np.ndarray:
    """(n, 9, 9) dP/dF from the principal stretches' energy derivatives (see
    :func:`ogden_point_kernel`): the material part in the eigenbasis of C and the geometric
    part, one batched product.
    """
    n = F.shape[0]
    inv = 1.0 / c
    Phi2 = -B[:, None, None] * np.eye(3)[None] * inv[:, :, None] ** 2
    Phi2 += (0.25 * UppJ)[:, None, None] * inv[:, :, None] * inv[:, None, :]
    gam = -B[:, None, None] * inv[:, :, None] * inv[:, None, :]
    for p, q, a, T, g in terms:
        dg = p * (p - 1.0) * c ** (p - 2.0)
        Phi2 += a[:, None, None] * (
            np.eye(3)[None] * dg[:, :, None]
            + q * (g[:, :, None] * inv[:, None, :] + inv[:, :, None] * g[:, None, :])
            + (q**2 * T)[:, None, None] * inv[:, :, None] * inv[:, None, :])
        gam += a[:, None, None] * p * _divided_power(c[:, :, None], c[:, None, :], p - 1.0)
    # M[a, b] = (F n_a) (x) n_b, flattened to 9 components (i, J). With gamma symmetric,
    # sum_(a != b) g_ab (M_ab M_ab^T + M_ab M_ba^T) = sum_(a < b) g_ab s_ab s_ab^T with
    # s_ab = M_ab + M_ba, so the geometric part is one batched (9x6)(6x6)(6x9) product.
    Fn = np.matmul(F, Q).transpose(0, 2, 1)  # (n, a, i)
    Qt = Q.transpose(0, 2, 1)  # (n, b, J)
    M = (Fn[:, :, None, :, None] * Qt[:, None, :, None, :]).reshape(n, 3, 3, 9)
    ia, ib = np.array([0, 0, 1]), np.array([1, 2, 2])
    G = np.concatenate([M[:, [0, 1, 2], [0, 1, 2]], M[:, ia, ib] + M[:, ib, ia]], axis=1)
    Wm = np.zeros((n, 6, 6))
    Wm[:, :3, :3] = 4.0 * Phi2
    Wm[:, [3, 4, 5], [3, 4, 5]] = 2.0 * gam[:, ia, ib]
    A = np.matmul(G.transpose(0, 2, 1), np.matmul(Wm, G))
    A5 = A.reshape(n, 3, 3, 3, 3)
    for i in range(3):
        A5[:, i, :, i, :] += S
    return A


def ogden_point_kernel(F: np.ndarray, mat: OgdenMaterial, tangent: bool = True):
    """Energy, first Piola stress and tangent at points.

    Args:
        F: deformation gradients, shape (n, 3, 3).
        mat: material parameters.
        tangent: also return the tangent.

    Returns:
        (W, P, A, J): W (n,) energy density (MPa = mJ/mm^3), P (n, 3, 3) first Piola stress
        (MPa), A (n, 9, 9) tangent dP/dF with rows (i, J) and columns (k, L) flattened row-major
        (None if ``tangent`` is False), J (n,) = det F as given. Points with J <= 0 or non-finite
        F give NaN in W, P and A; callers check J.
    """
    F = np.asarray(F, dtype=np.float64)
    n = F.shape[0]
    with np.errstate(invalid="ignore"):
        J_in = np.linalg.det(F)
    J = J_in
    ok = np.isfinite(J) & (J > 0)
    if not ok.all():
        F = np.where(ok[:, None, None], F, np.eye(3))  # compute on a dummy, poison afterwards
        J = np.where(ok, J, 1.0)
    C = np.matmul(F.transpose(0, 2, 1), F)
    c, Q = np.linalg.eigh(C)  # c ascending, Q[:, :, a] = n_a
    c = np.maximum(c, np.finfo(float).tiny)
    D = J**2  # det C from det F: exact where eigh rounds

    U, UpJ, UppJ = _volumetric(mat, J)
    W = U.copy()
    Phi = np.zeros((n, 3))
    B = 0.5 * UpJ
    terms = []
    for ck, mk in zip(mat.c, mat.m):
        p, q = 0.5 * mk, -mk / 6.0
        a = ck / mk**2 * D**q
        cp = c**p
        T = cp.sum(axis=1)
        g = p * cp / c
        W += ck / mk**2 * (D**q * T - 3.0)
        Phi += a[:, None] * g
        B = B + q * a * T
        terms.append((p, q, a, T, g))
    Phi += B[:, None] / c
    S_eig = 2.0 * Phi
    S = np.matmul(Q * S_eig[:, None, :], Q.transpose(0, 2, 1))
    P = np.matmul(F, S)

    A = _tangent(F, Q, c, S, B, UppJ, terms) if tangent else None
    if not ok.all():
        bad = ~ok
        W[bad] = np.nan
        P[bad] = np.nan
        if A is not None:
            A[bad] = np.nan
    return W, P, A, J_in


def point_kernel(F: np.ndarray, mat: OgdenMaterial, tangent: bool = True, out=None):
    """:func:`ogden_point_kernel` through the compiled kernel (:mod:`fem_sim.material.ogden_c`)
    when it can be built, else through numpy; same results to round-off (tested).

    ``out`` = (W (n,), P (n, 9), A (n, 81) or None, J (n,)) arrays to fill. Returns
    (W, P, A, J) shaped as ``out`` if given, else as :func:`ogden_point_kernel`.
    """
    from fem_sim.material import ogden_c

    if ogden_c.load() is not None:
        W, P, A, J = ogden_c.ogden_points(F, mat.c, mat.m, mat.K, mat.volumetric, tangent, out)
        if out is None:
            P = P.reshape(-1, 3, 3)
            A = A.reshape(-1, 9, 9) if tangent else None
        return W, P, A, J
    W, P, A, J = ogden_point_kernel(np.asarray(F).reshape(-1, 3, 3), mat, tangent)
    if out is None:
        return W, P, A, J
    out[0][:], out[1][:], out[3][:] = W, P.reshape(-1, 9), J
    if tangent:
        out[2][:] = A.reshape(-1, 81)
    return out
