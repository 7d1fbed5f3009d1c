"""Moving a tetrahedral mesh by its surface: the surface nodes go where a registration puts
them, the interior follows by harmonic extension (each interior displacement the mean of its
edge neighbours'). The CPD field evaluated deep inside the template would fold the mesh where
the surface moved far; the extension keeps the interior in step with the surface.

A surface registration may still fold the mesh: where the template is one element thick (a
thin lobe) two facing surfaces can be moved through each other, and a harmonic interior can
turn a tetrahedron inside out near a sharp bend. :meth:`SurfaceMorph.unfold` gives a move with
no inverted tetrahedron: the interior by harmonic extension, or, where that folds, by a
pseudo-elastic move in steps whose compressed cells stiffen (Young's modulus (V0/V)^2, the
mesh-moving rule of Jacobian-based stiffening); where the surface itself folds, the
displacements of the folded cells' surface nodes are relaxed toward their neighbours' (along
the tetrahedra's edges, so the two faces of a thin lobe move together), round by round, until
no cell is folded. The price is a larger residual there, which the caller measures.
"""

from __future__ import annotations

import functools

import numpy as np

from data_spec.geometry import signed_volumes

# SuperLU's column ordering for the pseudo-elastic move's symmetric systems
ORDERING = "MMD_AT_PLUS_A"
# rounds of the unfolding's relaxation between two widenings of the relaxed patch
WIDEN_EVERY = 50


class SurfaceMorph:
    """The template mesh's graph Laplacian, factorised once for many placements."""

    def __init__(self, points: np.ndarray, cells: np.ndarray, boundary: np.ndarray):
        from scipy.sparse import coo_matrix
        from scipy.sparse.linalg import splu

        self.points = np.asarray(points, dtype=np.float64)
        self.cells = np.asarray(cells, dtype=np.int64)
        self.boundary = np.asarray(boundary, dtype=np.int64)
        n = self.points.shape[0]
        pairs = np.array([(a, b) for a in range(4) for b in range(4) if a != b])
        i, j = self.cells[:, pairs[:, 0]].ravel(), self.cells[:, pairs[:, 1]].ravel()
        A = coo_matrix((np.ones(i.size), (i, j)), shape=(n, n)).tocsr()
        A.data[:] = 1.0  # an edge shared by many cells counts once
        L = (coo_matrix((np.asarray(A.sum(axis=1)).ravel(), (np.arange(n),) * 2),
                        shape=A.shape) - A).tocsr()
        self.inner = np.setdiff1d(np.arange(n), self.boundary)
        self._coupling = L[self.inner][:, self.boundary]
        self._lu = splu(L[self.inner][:, self.inner].tocsc()) if self.inner.size else None

    def move(self, boundary_points: np.ndarray) -> np.ndarray:
        """All nodes, the boundary nodes at ``boundary_points`` (in ``boundary`` order)."""
        u_b = np.asarray(boundary_points, dtype=np.float64) - self.points[self.boundary]
        out = self.points.copy()
        out[self.boundary] += u_b
        if self._lu is not None:
            out[self.inner] += self._lu.solve(-(self._coupling @ u_b))
        return out

    def inverted(self, moved: np.ndarray) -> int:
        """Tetrahedra the move turned inside out (non-positive volume)."""
        return int(np.sum(signed_volumes(moved, self.cells) <= 0))

    def min_jacobian(self, moved: np.ndarray) -> float:
        """The smallest ratio of moved to template volume over the cells (the determinant of
        each linear tetrahedron's deformation gradient): <= 0 where a cell folded.
        """
        return float(np.min(signed_volumes(moved, self.cells) / self._volumes))

    @functools.cached_property
    def _volumes(self) -> np.ndarray:
        return signed_volumes(self.points, self.cells)

    def place(self, boundary_points: np.ndarray) -> np.ndarray:
        """All nodes for the boundary at ``boundary_points``: the harmonic extension, or, when
        it folds a cell, the stiffened pseudo-elastic move if that folds fewer.
        """
        moved = self.move(boundary_points)
        if self.inverted(moved) == 0 or self.inner.size == 0:
            return moved
        elastic = stiffened_move(self.points, self.cells, self.boundary, boundary_points,
                                 assembly=self._assembly)
        return elastic if self.inverted(elastic) < self.inverted(moved) else moved

    def unfold(self, boundary_points: np.ndarray, rounds: int = 150, relax: float = 0.5,
               patience: int = 10) -> tuple[np.ndarray, int]:
        """(all nodes, rounds used): :meth:`place` of the boundary at ``boundary_points``,
        with the displacement of every surface node of a folded cell (and of its neighbours)
        relaxed by ``relax`` toward its neighbours' mean, round by round, until no cell is
        folded, or ``rounds`` ran out, or a widened patch (every :data:`WIDEN_EVERY` rounds
        it grows by a ring of neighbours) brought no fewer folded cells within ``patience``
        rounds (a fold the relaxation keeps: the caller counts what is left and tries a
        smoother registration).
        """
        d = np.asarray(boundary_points, dtype=np.float64) - self.points[self.boundary]
        A, degree = self._boundary_graph
        local = np.full(self.points.shape[0], -1)
        local[self.boundary] = np.arange(self.boundary.size)
        fewest, fewest_at = np.inf, 0
        for k in range(rounds + 1):
            moved = self.place(self.points[self.boundary] + d)
            bad = signed_volumes(moved, self.cells) <= 0
            if bad.sum() < fewest:
                fewest, fewest_at = bad.sum(), k
            widened = WIDEN_EVERY * (k // WIDEN_EVERY)  # the round of the last widening
            if not bad.any() or k == rounds or (widened and fewest_at < widened
                                                   and k >= widened + patience):
                return moved, k
            ids = local[self.cells[bad]]
            near = np.zeros(self.boundary.size, dtype=bool)
            near[ids[ids >= 0]] = True
            for _ in range(1 + k // WIDEN_EVERY):  # a fold that outlasts them: a wider patch
                near |= (A @ near) > 0
            mean = (A @ d) / degree[:, None]
            d[near] = (1.0 - relax) * d[near] + relax * mean[near]
        return moved, rounds

    @functools.cached_property
    def _assembly(self) -> ElasticAssembly:
        return ElasticAssembly(self.points.shape[0], self.cells, self.boundary)

    @functools.cached_property
    def _boundary_graph(self):
        """The boundary nodes' adjacency along the tetrahedra's edges, and its degrees."""
        from scipy.sparse import coo_matrix

        local = np.full(self.points.shape[0], -1)
        local[self.boundary] = np.arange(self.boundary.size)
        c = local[self.cells]
        e = np.concatenate([c[:, [a, b]] for a in range(4) for b in range(a + 1, 4)])
        e = e[(e >= 0).all(axis=1)]
        n = self.boundary.size
        A = coo_matrix((np.ones(2 * len(e)), (np.r_[e[:, 0], e[:, 1]], np.r_[e[:, 1], e[:, 0]])),
                       shape=(n, n)).tocsr()
        A.data[:] = 1.0
        return A, np.maximum(np.asarray(A.sum(axis=1)).ravel(), 1.0)


def element_stiffness(points: np.ndarray, cells: np.ndarray, young: np.ndarray,
                      poisson: float = 0.3) -> np.ndarray:
    """(c, 12, 12) the stiffness V B^T D B of each linear tetrahedron (small-strain
    elasticity, Young's modulus per cell): B the (6, 12) strain-displacement matrix of the
    shape functions' gradients g_a (Voigt order xx, yy, zz, yz, xz, xy; shear as engineering
    strain), D the isotropic elasticity (lam + 2 mu on the normal diagonal, lam off it, mu on
    the shear); rows and columns node by node, (x, y, z) within a node.
    """
    X = points[cells]
    r = X[:, 1:] - X[:, :1]  # the edges from node 0
    # the gradient of barycentric coordinate k + 1: column k of the edge matrix's inverse,
    # the cross product of the other two edges over the determinant
    grad = np.stack([np.cross(r[:, 1], r[:, 2]), np.cross(r[:, 2], r[:, 0]),
                     np.cross(r[:, 0], r[:, 1])], axis=1)
    det = np.einsum("ci,ci->c", r[:, 0], grad[:, 0])
    grad /= det[:, None, None]
    V = np.abs(det) / 6.0
    g = np.concatenate([-grad.sum(axis=1, keepdims=True), grad], axis=1)  # (c, 4 a, 3 i)
    c = len(cells)
    B = np.zeros((c, 6, 4, 3))
    for i in range(3):
        B[:, i, :, i] = g[:, :, i]
    for k, (i, j) in enumerate(((1, 2), (0, 2), (0, 1))):
        B[:, 3 + k, :, i] = g[:, :, j]
        B[:, 3 + k, :, j] = g[:, :, i]
    lam = young * poisson / ((1 + poisson) * (1 - 2 * poisson)) * V
    mu = young / (2 * (1 + poisson)) * V
    Dm = np.zeros((c, 6, 6))
    Dm[:, :3, :3] = lam[:, None, None]
    Dm[:, np.arange(6), np.arange(6)] += np.repeat([2.0, 1.0], 3) * mu[:, None]
    B = B.reshape(c, 6, 12)
    return np.matmul(B.transpose(0, 2, 1), np.matmul(Dm, B))


def elastic_stiffness(points: np.ndarray, cells: np.ndarray, young: np.ndarray,
                      poisson: float = 0.3):
    """The whole (3n, 3n) stiffness (:func:`element_stiffness` summed by scipy's COO format),
    the plain assembly :class:`ElasticAssembly` is checked against.
    """
    from scipy.sparse import coo_matrix

    n = 3 * points.shape[0]
    return coo_matrix((element_stiffness(points, cells, young, poisson).ravel(),
                       _entries(cells)), shape=(n, n)).tocsr()


def _entries(cells: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(rows, columns) of every entry of :func:`element_stiffness`'s matrices, flattened."""
    dof = (3 * np.asarray(cells)[:, :, None] + np.arange(3)).reshape(len(cells), 12)
    return np.repeat(dof, 12, axis=1).ravel(), np.tile(dof, (1, 12)).ravel()


class ElasticAssembly:
    """The stiffness of a tetrahedral mesh (:func:`element_stiffness`) split into free and
    fixed degrees of freedom, its sparsity worked out once: a pseudo-elastic move assembles
    the same connectivity many times, on moved points and with new moduli.
    """

    def __init__(self, n_points: int, cells: np.ndarray, fixed_nodes: np.ndarray):
        self.cells = np.asarray(cells, dtype=np.int64)
        rows, cols = _entries(self.cells)
        self.fixed = (3 * np.asarray(fixed_nodes, dtype=np.int64)[:, None]
                      + np.arange(3)).ravel()  # in the order of the fixed nodes
        fixed = np.zeros(3 * n_points, dtype=bool)
        fixed[self.fixed] = True
        self.free = np.flatnonzero(~fixed)
        local = np.empty(fixed.size, dtype=np.int64)
        local[self.free] = np.arange(self.free.size)
        local[self.fixed] = np.arange(self.fixed.size)
        n = self.free.size
        ff = ~fixed[rows] & ~fixed[cols]
        key = local[cols[ff]] * n + local[rows[ff]]  # column by column: a CSC matrix's order
        entries, self._slot = np.unique(key, return_inverse=True)
        self._ff = np.flatnonzero(ff)
        self._indices = entries % n
        self._indptr = np.searchsorted(entries // n, np.arange(n + 1))
        fx = ~fixed[rows] & fixed[cols]
        self._fx, self._fx_row, self._fx_col = np.flatnonzero(fx), local[rows[fx]], local[cols[fx]]

    def matrices(self, points: np.ndarray, young: np.ndarray):
        """(K_ff as CSC, K_fx as a function of the fixed displacements to the free forces)."""
        from scipy.sparse import csc_matrix

        Ke = element_stiffness(points, self.cells, young).ravel()
        n = self.free.size
        data = np.bincount(self._slot, weights=Ke[self._ff], minlength=self._indices.size)
        K = csc_matrix((data, self._indices, self._indptr), shape=(n, n))
        vals = Ke[self._fx]
        return K, lambda u: np.bincount(self._fx_row, weights=vals * u[self._fx_col], minlength=n)


def stiffened_move(points, cells, boundary, boundary_points, steps: int = 10,
                   assembly: ElasticAssembly | None = None) -> np.ndarray:
    """The interior moved with the boundary in ``steps`` pseudo-elastic increments, each on
    the current mesh with cells stiffened as they are compressed (E = (V0 / V)^2).
    ``assembly``: the mesh's, with ``boundary`` fixed, when the caller keeps one.
    """
    from scipy.sparse.linalg import splu

    P = np.asarray(points, dtype=np.float64).copy()
    asm = assembly or ElasticAssembly(P.shape[0], cells, boundary)
    du = (np.asarray(boundary_points, dtype=np.float64) - P[boundary]).ravel() / steps
    V0 = signed_volumes(P, cells)
    for _ in range(steps):
        V = np.maximum(signed_volumes(P, cells), 1e-3 * V0)
        K, coupling = asm.matrices(P, (V0 / V) ** 2)
        u = np.zeros(P.size)
        u[asm.fixed] = du
        u[asm.free] = splu(K, permc_spec=ORDERING).solve(-coupling(du))
        P += u.reshape(-1, 3)
    return P


def interpolation_matrix(nodes: np.ndarray, at: np.ndarray):
    """Sparse (len(at), len(nodes)) matrix of linear interpolation from values at ``nodes``
    to the points ``at``: barycentric in the Delaunay tetrahedra of the nodes, the nearest
    node's value for points outside their hull.
    """
    from scipy.sparse import csr_matrix
    from scipy.spatial import Delaunay, cKDTree

    tri = Delaunay(nodes)
    at = np.asarray(at, dtype=np.float64)
    simplex = tri.find_simplex(at)
    inside = simplex >= 0
    T = tri.transform[simplex[inside]]
    b = np.einsum("nij,nj->ni", T[:, :3], at[inside] - T[:, 3])
    bary = np.c_[b, 1.0 - b.sum(axis=1)]
    rows = [np.repeat(np.flatnonzero(inside), 4)]
    cols = [tri.simplices[simplex[inside]].ravel()]
    vals = [bary.ravel()]
    out = np.flatnonzero(~inside)
    if out.size:
        rows.append(out)
        cols.append(cKDTree(nodes).query(at[out])[1])
        vals.append(np.ones(out.size))
    return csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                      shape=(at.shape[0], nodes.shape[0]))
