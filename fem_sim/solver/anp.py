"""A linear tetrahedron that does not lock: averaged nodal pressure (ANP, Bonet and Burton 1998).

P1 tetrahedra with one point lock at K/mu = 200: every cell must keep its volume, and a mesh
has ~5.5 cells per node, so the constraints outnumber the displacement dofs. ANP integrates
the volumetric energy at the nodes instead: with V0_a = sum_(e at a) V0_e / 4 and

    Jbar_a = sum_(e at a) (V0_e / 4) J_e / V0_a      (the volume ratio of node a's share)

the potential energy is

    Pi(u) = sum_e V0_e W_iso(F_e) + sum_a V0_a U(Jbar_a) - f . u,

one volume constraint per node (3 dofs per node against 1 constraint: no locking). The isochoric
part is the element's own (the uncoupled Ogden law splits exactly), so no stabilisation is
needed. Writing sum_a V0_a U(Jbar_a) = sum_e V0_e mean_(a in e) U(Jbar_a), everything is still
a per-cell quantity except one term of the tangent:

    P_e = P_iso(F_e) + pbar_e J_e F_e^-T,            pbar_e = mean_(a in e) U'(Jbar_a)
    A_e = A_iso(F_e) + pbar_e d(J F^-T)/dF           (cell-local)
    K   = assembled A_e  +  sum_a V0_a U''(Jbar_a) g_a g_a^T,   g_a = dJbar_a/du

and g_a couples the nodes of the cells around a, so the Jacobian's pattern reaches two rings of
neighbours instead of one (its price: a denser factorisation). The cell-local parts are the full
material point values with the cell's own volumetric terms swapped for the averaged ones, so
the one compiled Ogden kernel serves both elements. For a homogeneous deformation Jbar = J and
the element reproduces P1 exactly (the closed-form tests hold). One process, P1, C assembly.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from fem_sim.material.ogden import _volumetric as volumetric_energy
from fem_sim.solver import dolfinx_compat as dc
from fem_sim.solver import tet
from fem_sim.solver.assembly import CAssembler, Jacobian
from fem_sim.solver.discretisation import Discretisation, DofConstraints


def _volumetric(mat, J: np.ndarray):
    """U(J), U'(J), U''(J) of the material's volumetric energy (from the material module's
    U, U' J, (U'' J + U') J).
    """
    U, UpJ, UppJ = volumetric_energy(mat, J)
    Up = UpJ / J
    return U, Up, (UppJ / J - Up) / J


def _cofactor(F: np.ndarray) -> np.ndarray:
    """The cofactor matrices J F^-T (= dJ/dF) of ``F`` (n, 3, 3), in closed form."""
    C = np.empty_like(F)
    C[:, 0, 0] = F[:, 1, 1] * F[:, 2, 2] - F[:, 1, 2] * F[:, 2, 1]
    C[:, 0, 1] = F[:, 1, 2] * F[:, 2, 0] - F[:, 1, 0] * F[:, 2, 2]
    C[:, 0, 2] = F[:, 1, 0] * F[:, 2, 1] - F[:, 1, 1] * F[:, 2, 0]
    C[:, 1, 0] = F[:, 0, 2] * F[:, 2, 1] - F[:, 0, 1] * F[:, 2, 2]
    C[:, 1, 1] = F[:, 0, 0] * F[:, 2, 2] - F[:, 0, 2] * F[:, 2, 0]
    C[:, 1, 2] = F[:, 0, 1] * F[:, 2, 0] - F[:, 0, 0] * F[:, 2, 1]
    C[:, 2, 0] = F[:, 0, 1] * F[:, 1, 2] - F[:, 0, 2] * F[:, 1, 1]
    C[:, 2, 1] = F[:, 0, 2] * F[:, 1, 0] - F[:, 0, 0] * F[:, 1, 2]
    C[:, 2, 2] = F[:, 0, 0] * F[:, 1, 1] - F[:, 0, 1] * F[:, 1, 0]
    return C


class ANPAssembler(CAssembler):
    """P1 with averaged nodal pressure (see the module docstring); one process."""

    relaxable = False  # the hot-spot relaxation solves the plain P1 equations, not these

    def __init__(self, disc: Discretisation):
        if not (disc.comm.size == 1 and disc.degree == 1 and disc.qdeg == 1
                and tet.load() is not None):
            raise ValueError("the ANP tetrahedron needs P1 with one quadrature point, one "
                             "process and the compiled assembly")
        if not disc.q_contiguous:
            raise ValueError("the ANP tetrahedron needs the quadrature values numbered cell by "
                             "cell")
        super().__init__(disc)
        c = self.c
        cells = c.cells.astype(np.int64)
        nc, nb = cells.shape[0], c.indptr.size // 3
        # The two-ring pattern: block pairs that share a node's star.
        star = sp.csr_matrix((np.ones(4 * nc), (cells.ravel(), np.repeat(np.arange(nc), 4))),
                             shape=(nb, nc))
        ring1 = (star @ star.T).tocsr()
        ring2 = (ring1 @ ring1).tocsr()
        ring2.data[:] = 1.0
        pattern = sp.kron(ring2, np.ones((3, 3)), format="csr")
        pattern.sort_indices()
        points, weights = dc.quadrature_rule(1)
        self.c = tet.TetAssembler(cells, c.vertices, 1, points, weights, pattern.indptr,
                                  pattern.indices)
        V0 = self.c.w[:, 0]                                  # cell volumes
        self.V0_node = np.bincount(cells.ravel(), np.repeat(V0 / 4.0, 4), minlength=nb)
        # Jbar = Mw @ J: Mw[a, e] = (V0_e / 4) / V0_a for a in e (also g's weights).
        self.w_ae = w_ae = np.ascontiguousarray((V0[:, None] / 4.0) / self.V0_node[cells])
        self.Mw = sp.csr_matrix((w_ae.ravel(), (cells.ravel(), np.repeat(np.arange(nc), 4))),
                                shape=(nb, nc))
        self._index_nonlocal(cells, nb)
        self._nonlocal = None

    def _index_nonlocal(self, cells: np.ndarray, nb: int) -> None:
        """Where the averaged pressure's coupling lands: ``g_index`` maps each term of
        g_a = sum_(e at a) w_ae dJ_e/du (entries (a, dof of (e, b, k)) for a, b in e) to its
        entry, and ``pair_pos`` each pair of entries of a row of g (K_nl = sum_a d_a g_a g_a^T)
        to its position in the two-ring pattern's value array.
        """
        a_loc, b_loc, k = np.meshgrid(np.arange(4), np.arange(4), np.arange(3), indexing="ij")
        a_loc, b_loc, k = a_loc.ravel(), b_loc.ravel(), k.ravel()      # 48 terms per cell
        rows = cells[:, a_loc]                                         # (nc, 48)
        cols = 3 * cells[:, b_loc] + k
        keys = (rows * (3 * nb) + cols).ravel()
        ukeys, g_index = np.unique(keys, return_inverse=True)
        self.g_index = np.ascontiguousarray(g_index, dtype=np.int64)
        g_row, g_col = ukeys // (3 * nb), ukeys % (3 * nb)
        ptr = np.searchsorted(g_row, np.arange(nb + 1))
        lengths = np.diff(ptr)
        p_list, q_list = [], []
        for L in np.unique(lengths):
            rows_L = np.flatnonzero(lengths == L)
            ii, jj = np.meshgrid(np.arange(L), np.arange(L), indexing="ij")
            p_list.append((ptr[rows_L][:, None] + ii.ravel()[None]).ravel())
            q_list.append((ptr[rows_L][:, None] + jj.ravel()[None]).ravel())
        self.pair_p = np.concatenate(p_list).astype(np.int32)
        self.pair_q = np.concatenate(q_list).astype(np.int32)
        self.pair_node = g_row[self.pair_p].astype(np.int32)
        n = 3 * nb
        pkeys = np.repeat(np.arange(n, dtype=np.int64), np.diff(self.c.indptr)) * n \
            + self.c.indices
        want = g_col[self.pair_p] * n + g_col[self.pair_q]
        pos = np.searchsorted(pkeys, want)
        if np.any(pkeys[np.minimum(pos, pkeys.size - 1)] != want):
            raise ValueError("ANPAssembler: the two-ring pattern misses coupled entries")
        self.pair_pos = pos.astype(np.int32)
        self.n_g = ukeys.size

    # ------------------------------------------------------------------------------------------
    def update_points(self, tangent: bool) -> bool:
        if not super().update_points(tangent):
            return False
        d, mat = self.disc, self.material
        F = self.deformation_gradients().reshape(-1, 3, 3)
        JFinvT = _cofactor(F)                                # dJ/dF = J F^-T
        J = np.einsum("nij,nij->n", F, JFinvT) / 3.0         # each row of F . cof F is J
        Jbar = self.Mw @ J
        if not (np.all(Jbar > 0) and np.all(np.isfinite(Jbar))):
            self.min_J = float(min(np.min(J), np.min(Jbar)))
            return False
        self.min_J = float(min(np.min(J), np.min(Jbar)))
        cells = self.c.cells
        U_e, Up_e, Upp_e = _volumetric(mat, J)
        U_a, Up_a, Upp_a = _volumetric(mat, Jbar)
        pbar = Up_a[cells].mean(axis=1)
        dp = pbar - Up_e
        W = d.point_values(d.W_q, 1)
        P = d.point_values(d.P_q, 9)
        W[:, 0] += U_a[cells].mean(axis=1) - U_e
        P += (dp[:, None, None] * JFinvT).reshape(-1, 9)
        if tangent:
            A = d.point_values(d.A_q, 81)  # a view of the tangents: updated in place
            # d(J F^-T)_iJ / dF_kL = J (F^-T_iJ F^-T_kL - F^-T_iL F^-T_kJ); with C = J F^-T:
            # dp d(J F^-T)/dF - U''(J) C (x) C = (dp / J - U''(J)) C_iJ C_kL - dp / J C_iL C_kJ
            # (in C, one pass: numpy's four 81-wide temporaries cost ~2.5 s of a 31 s
            # simulation at 5 mm)
            s = dp / J
            C = np.ascontiguousarray(JFinvT)
            s1, s2 = np.ascontiguousarray(s - Upp_e), np.ascontiguousarray(s)
            if not (A.flags.c_contiguous and A.base is not None):
                raise RuntimeError("ANPAssembler: the tangents are not a contiguous view")
            cast = self.c.ffi.cast
            self.c.lib.anp_tangent(C.shape[0], cast("double *", C.ctypes.data),
                                   cast("double *", s1.ctypes.data),
                                   cast("double *", s2.ctypes.data),
                                   cast("double *", A.ctypes.data), self.c._threads())
            # g terms: w_ae dJ_e/du_(b,k) = w_ae J_e (F^-T dN_b)_k, summed into g (in C)
            g = np.zeros(self.n_g)
            self.c.lib.anp_g(C.shape[0], cast("double *", C.ctypes.data),
                             cast("double *", self.c.dN.ctypes.data),
                             cast("double *", self.w_ae.ctypes.data),
                             cast("int64_t *", self.g_index.ctypes.data),
                             cast("double *", g.ctypes.data))
            # d_a g_a g_a^T, added at assembly (in C: the pairs are ~2000 per node)
            self._nonlocal = (np.ascontiguousarray(self.V0_node * Upp_a), g)
        return True

    def jacobian(self, cons: DofConstraints, rhs=None, lift=None) -> Jacobian:
        self.c.assemble(self.disc.point_values(self.disc.A_q, 81))
        dnode, g = self._nonlocal
        cast = self.c.ffi.cast
        self.c.lib.anp_pairs(self.pair_pos.size, cast("int32_t *", self.pair_pos.ctypes.data),
                             cast("int32_t *", self.pair_node.ctypes.data),
                             cast("int32_t *", self.pair_p.ctypes.data),
                             cast("int32_t *", self.pair_q.ctypes.data),
                             cast("double *", dnode.ctypes.data),
                             cast("double *", g.ctypes.data),
                             cast("double *", self.c.values.ctypes.data))
        self.c.apply_dirichlet(cons.owned, rhs.array if lift is not None else None,
                               lift.array_r if lift is not None else None)
        return Jacobian(csr=(self.c.indptr, self.c.indices, self.c.values))
