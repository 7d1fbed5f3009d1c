"""Nonlinear elimination of the residual's hot spot before a global Newton step.

Under a point load on a fine mesh or a soft material, the predictor's error is local: on the
real liver at 14.6k nodes with scene 3's softest material, 95-99 % of |R|^2 after the predictor
sits within 10-20 mm of the loaded node (80 nodes), and the global Newton iterations there
(3-5 per load step, one factorisation each) are spent mostly on that neighbourhood. This piece
solves the equations of the hot spot alone (the nodes carrying the largest residuals, grown by
a few rings of neighbours; everything else held where it is) by a small sparse Newton iteration
with an energy line search, so that the global Newton starts from a state whose residual is
spread thin. It changes only the starting point of the global iteration: the converged answer
and its tolerance are the global Newton's.

Serial C assembly only (:class:`~fem_sim.solver.assembly.CAssembler`): the hot spot's cells are
assembled by a :class:`~fem_sim.solver.tet.TetAssembler` of their own.
"""

from __future__ import annotations

import logging
import warnings
from types import SimpleNamespace

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from fem_sim.material.ogden import point_kernel
from fem_sim.solver import ldlt, tet

log = logging.getLogger(__name__)


class LocalRelaxation:
    """Relaxes the hot spot of the residual of an :class:`Equations` (one process)."""

    def __init__(self, eqs, rings: int, max_nodes: int, seed_fraction: float = 0.1,
                 share: float = 0.5):
        self.eqs = eqs
        self.c = eqs.assembler.c  # the global TetAssembler
        self.rings, self.max_nodes = rings, max_nodes
        self.seed_fraction, self.share = seed_fraction, share
        xadj, adj = ldlt.block_graph(self.c.indptr, self.c.indices, 3)
        nb = xadj.size - 1
        # node adjacency with the diagonal (the sub-problems' patterns need it)
        self.graph = (sp.csr_matrix((np.ones(adj.size), adj, xadj), shape=(nb, nb))
                      + sp.identity(nb, format="csr")).tocsr()
        self.iterations = 0  # local Newton iterations of this simulation

    def reset(self) -> None:
        self.iterations = 0

    def region(self) -> np.ndarray | None:
        """Blocks of the hot spot, or None when the residual is not concentrated there."""
        e = (self.eqs.b.array_r.reshape(-1, 3) ** 2).sum(axis=1)
        total = e.sum()
        if not total > 0:
            return None
        mask = e >= self.seed_fraction ** 2 * e.max()
        for _ in range(self.rings):
            mask = mask | (self.graph @ mask.astype(np.float64) > 0)
        if mask.sum() > self.max_nodes or e[mask].sum() < self.share * total:
            return None
        return np.flatnonzero(mask)

    def _subproblem(self, region: np.ndarray) -> SimpleNamespace | None:
        """The hot spot's own problem: its cells' assembler on the global block graph
        restricted to its nodes, its dofs, and which of them are free (None: none is).
        """
        eqs, c = self.eqs, self.c
        in_region = np.zeros(self.graph.shape[0], dtype=bool)
        in_region[region] = True
        cells = np.flatnonzero(in_region[c.cells].any(axis=1))
        sub_blocks, local = np.unique(c.cells[cells], return_inverse=True)
        local = local.reshape(cells.size, -1)
        # The hot spot's pattern: the global block graph restricted to its nodes, in 3 x 3
        # blocks (it holds every pair of nodes that share a cell).
        pattern = sp.kron(self.graph[sub_blocks][:, sub_blocks], np.ones((3, 3)), format="csr")
        pattern.sort_indices()
        sub = tet.TetAssembler(local, c.vertices[cells], c.degree, c.points, c.weights,
                               pattern.indptr, pattern.indices)
        dofs = (3 * sub_blocks[:, None] + np.arange(3)).ravel()
        fixed = np.zeros(eqs.n_owned_dofs, dtype=bool)
        fixed[eqs.cons.owned] = True
        free = np.flatnonzero(in_region[sub_blocks].repeat(3) & ~fixed[dofs])
        if free.size == 0:
            return None
        return SimpleNamespace(sub=sub, dofs=dofs, free=free, fint=np.empty(dofs.size))

    def _evaluate(self, p: SimpleNamespace, u: np.ndarray, f_ext: np.ndarray):
        """(R on the free dofs, energy, tangents) of the hot spot at ``u``; None where
        det F <= 0 or the stress is not finite.
        """
        W, P, A, J = point_kernel(p.sub.deformation(u.reshape(-1, 3)),
                                  self.eqs.assembler.material, True)
        if not (np.all(J > 0) and np.all(np.isfinite(P))):
            return None
        p.sub.forces(P.reshape(-1, 9), p.fint)
        return p.fint[p.free] - f_ext[p.free], p.sub.integrate(W) - f_ext @ u, A

    def _step(self, p: SimpleNamespace, u, state, f_ext):
        """One local Newton step with backtracking: (u, state) accepted, or None."""
        R, energy, A = state
        r = float(np.linalg.norm(R))
        p.sub.assemble(A.reshape(-1, 81))
        K = p.sub.matrix()[p.free][:, p.free].tocsc()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", spla.MatrixRankWarning)
            du = spla.spsolve(K, -R)
        if not np.all(np.isfinite(du)):
            return None
        slope = float(R @ du)
        alpha = 1.0
        for _ in range(8):
            trial = u.copy()
            trial[p.free] += alpha * du
            s = self._evaluate(p, trial, f_ext)
            if s is not None and (np.linalg.norm(s[0]) < (1 - 1e-4 * alpha) * r
                                  or (slope < 0 and s[1] <= energy + 1e-4 * alpha * slope)):
                return trial, s
            alpha *= 0.5
        return None

    def relax(self, lam: float, tol: float, max_iterations: int = 8) -> int:
        """Local Newton on the hot spot at load ``lam`` until its residual is below ``tol`` or
        a tenth of the residual outside it; returns the local iterations (0: nothing done).
        The caller re-evaluates the global state afterwards.
        """
        eqs = self.eqs
        region = self.region()
        p = self._subproblem(region) if region is not None else None
        if p is None:
            return 0
        u_all = eqs.u.x.array
        f_ext = lam * eqs.f_ext.array_r[p.dofs]
        outside = np.ones(eqs.n_owned_dofs, dtype=bool)
        outside[p.dofs[p.free]] = False
        target = max(tol, 0.1 * float(np.linalg.norm(eqs.b.array_r[outside])))
        u = u_all[p.dofs].copy()
        state = self._evaluate(p, u, f_ext)
        its = 0
        while state is not None and its < max_iterations:
            r = float(np.linalg.norm(state[0]))
            log.debug("local |R| %.3e (target %.1e)", r, target)
            if r <= target:
                break
            accepted = self._step(p, u, state, f_ext)
            if accepted is None:
                break
            u, state = accepted
            its += 1
        if its:
            u_all[p.dofs[p.free]] = u[p.free]
            eqs.assembler.tangent_fresh = False
            self.iterations += its
            log.debug("local relaxation at %.4g: %d nodes, %d iterations", lam,
                      region.size, its)
        return its


def available(eqs) -> bool:
    """The hot spot can be relaxed: the serial C assembly of a Lagrange element is in use (the
    local problem is that element's; an assembler with another energy says no).
    """
    return eqs.assembler.relaxable
