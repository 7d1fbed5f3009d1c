"""Meshing helpers shared by the phantom and the surface importer (gmsh output, volumes)."""

from __future__ import annotations

import numpy as np

from data_spec.geometry import Geometry


def gmsh_tetrahedra() -> tuple[np.ndarray, np.ndarray]:
    """Nodes and linear tetrahedra of the current gmsh model, compactly renumbered."""
    import gmsh

    tags, coords, _ = gmsh.model.mesh.getNodes()
    coords = coords.reshape(-1, 3)
    etags, enodes = gmsh.model.mesh.getElementsByType(4)
    tet_tags = enodes.reshape(-1, 4).astype(np.int64)
    lookup = np.zeros(int(tags.max()) + 1, dtype=np.int64)
    lookup[tags.astype(np.int64)] = np.arange(tags.size)
    tets = lookup[tet_tags]
    used = np.unique(tets)
    renum = np.full(tags.size, -1, dtype=np.int64)
    renum[used] = np.arange(used.size)
    points, cells = coords[used], renum[tets]
    e = points[cells[:, 1:]] - points[cells[:, :1]]
    neg = np.linalg.det(e) < 0
    cells[neg] = cells[neg][:, [0, 2, 1, 3]]
    return points, cells


def mesh_volume(g: Geometry) -> float:
    """Volume (mm^3) from the tetrahedra."""
    p, c = g.points, g.cells
    return float(np.abs(np.linalg.det(p[c[:, 1:]] - p[c[:, :1]])).sum() / 6.0)
