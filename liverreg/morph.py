"""Moving a tetrahedral mesh by its surface: the surface nodes go where a registration puts
them, the interior follows by harmonic extension (each interior displacement the mean of its
edge neighbours'). The CPD field evaluated deep inside the template would fold the mesh where
the surface moved far; the extension keeps the interior in step with the surface.
"""

from __future__ import annotations

import numpy as np

from data_spec.geometry import signed_volumes


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
