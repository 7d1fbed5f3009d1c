"""Mesh checks before any simulation: a mesh that would give a wrong or singular problem is
refused with the reason, on rank 0, before MPI work starts.

* Orientation: tetrahedra with negative volume are reordered (files disagree on the node-order
  convention, some mix them); whether the mesh is *tangled* (an element folded over its
  neighbour) is decided geometrically, below, not from the node order.
* Degenerate elements: zero volume, or so flat (mean-ratio quality below ``MIN_QUALITY``) that
  the stiffness matrix is singular to working precision, refused. Poor but usable elements
  (slivers) are counted in a warning.
* Overlap: an interior triangle must separate its two tetrahedra (they lie on opposite sides
  of it); two on the same side, or a triangle shared by more than two, means elements cover
  some of the body twice (a folded or duplicated cell).
* Connectivity: every connected piece of the mesh must touch the fixed region, else it floats
  (a singular problem).
"""

from __future__ import annotations

import logging

import numpy as np

from data_spec.geometry import signed_volumes

log = logging.getLogger(__name__)

MIN_QUALITY = 1e-4   # refuse: nearly flat
WARN_QUALITY = 0.02  # warn: slivers


def mean_ratio(points: np.ndarray, cells: np.ndarray) -> np.ndarray:
    """Mean-ratio quality 12 (3 |V|)^(2/3) / sum of squared edge lengths: 1 for the regular
    tetrahedron, 0 for a flat one.
    """
    vol = np.abs(signed_volumes(points, cells))
    p = points[cells]
    edges = sum(np.sum((p[:, i] - p[:, j]) ** 2, axis=1)
                for i in range(4) for j in range(i + 1, 4))
    return 12.0 * (3.0 * vol) ** (2.0 / 3.0) / np.maximum(edges, 1e-300)


def flat_tetrahedra(q: np.ndarray) -> str:
    """How many of the tetrahedra of mean-ratio qualities ``q`` are too flat to solve on (zero
    volume included), or '' when none is.
    """
    bad = int(np.sum(q < MIN_QUALITY))
    return (f"{bad} of {q.size} tetrahedra are degenerate (mean-ratio quality < "
            f"{MIN_QUALITY:g}, min {q.min():.1e})") if bad else ""


def orient(points: np.ndarray, cells: np.ndarray, where: str) -> np.ndarray:
    """Cells reordered to positive volume (a copy); logs how many were negative."""
    neg = signed_volumes(points, cells) < 0
    if neg.any():
        cells = cells.copy()
        cells[neg] = cells[neg][:, [0, 2, 1, 3]]
        if not neg.all():
            log.info("%s: %d of %d tetrahedra had the other node order; reordered", where,
                     int(neg.sum()), cells.shape[0])
    return cells


def folded_faces(cells: np.ndarray) -> tuple[int, int]:
    """(interior triangles whose two positive tetrahedra lie on the same side, triangles
    shared by more than two tetrahedra). Each positive tetrahedron orients its faces outward;
    a triangle between two non-overlapping ones is seen once each way.
    """
    local = np.array([[1, 2, 3], [0, 3, 2], [0, 1, 3], [0, 2, 1]])
    faces = cells[:, local].reshape(-1, 3)
    order = np.argsort(faces, axis=1)
    # parity of the sorting permutation: +1 even, -1 odd
    inversions = ((order[:, 0] > order[:, 1]).astype(int) + (order[:, 1] > order[:, 2])
                  + (order[:, 0] > order[:, 2]))
    parity = np.where(inversions % 2 == 0, 1, -1)
    key = np.take_along_axis(faces, order, axis=1)
    _, inv, count = np.unique(key, axis=0, return_inverse=True, return_counts=True)
    total = np.zeros(count.size, dtype=np.int64)
    np.add.at(total, inv.ravel(), parity)
    return int(np.sum((count == 2) & (total != 0))), int(np.sum(count > 2))


def mesh_problems(points: np.ndarray, cells: np.ndarray,
                  fixed: np.ndarray | None = None) -> list[str]:
    """Everything that makes a (positively oriented) tetrahedral mesh unusable; logs a
    warning for slivers.
    """
    p = []
    vol = signed_volumes(points, cells)
    if np.any(vol <= 0):
        p.append(f"{int(np.sum(vol <= 0))} of {cells.shape[0]} tetrahedra have zero or negative "
                 "volume")
    q = mean_ratio(points, cells)
    flat = flat_tetrahedra(q)
    if flat:
        p.append(f"{flat}: the stiffness matrix would be singular")
    elif (q < WARN_QUALITY).any():
        log.warning("%d of %d tetrahedra are slivers (mean-ratio quality < %g, min %.3g): "
                    "expect a poorly conditioned problem", int(np.sum(q < WARN_QUALITY)),
                    cells.shape[0], WARN_QUALITY, q.min())
    if not p:
        folded, shared = folded_faces(cells)
        if folded or shared:
            p.append(f"elements overlap (a tangled mesh): {folded} interior triangles have "
                     f"both their tetrahedra on one side, {shared} are shared by more than "
                     "two tetrahedra")
    if fixed is not None and cells.size:
        labels = components(points.shape[0], cells)
        floating = np.setdiff1d(np.unique(labels[cells[:, 0]]), labels[np.asarray(fixed)])
        if floating.size:
            sizes = [int(np.sum(labels[cells[:, 0]] == c)) for c in floating]
            p.append(f"{floating.size} connected piece(s) of the mesh ({sizes} tetrahedra) "
                     "touch no fixed node: they would float freely")
    return p


def components(n_nodes: int, cells: np.ndarray) -> np.ndarray:
    """Connected-component label of every node (nodes joined by shared tetrahedra)."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    rows = np.repeat(cells[:, 0], 3)
    cols = cells[:, 1:].ravel()
    g = coo_matrix((np.ones(rows.size), (rows, cols)), shape=(n_nodes, n_nodes))
    return connected_components(g, directed=False)[1]


def dihedral_angles(points: np.ndarray, cells: np.ndarray) -> np.ndarray:
    """(n_cells, 6) interior dihedral angles in degrees at the six edges of each tetrahedron:
    pi minus the angle between the outward normals of the two faces that meet there (a
    regular tetrahedron: arccos(1/3) = 70.53 degrees everywhere; a flat one: near 0).
    """
    x = np.asarray(points, dtype=np.float64)[np.asarray(cells)[:, :4]]
    faces = ((1, 2, 3), (0, 3, 2), (0, 1, 3), (0, 2, 1))  # opposite vertex 0, 1, 2, 3
    n = []
    for a, b, c in faces:
        v = np.cross(x[:, b] - x[:, a], x[:, c] - x[:, a])
        n.append(v / np.maximum(np.linalg.norm(v, axis=1, keepdims=True), 1e-300))
    out = [np.pi - np.arccos(np.clip(np.einsum("ij,ij->i", n[i], n[j]), -1.0, 1.0))
           for i, j in ((0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3))]
    return np.degrees(np.stack(out, axis=1))
