"""Closed liver surfaces in, tetrahedral meshes out.

Reads legacy VTK POLYDATA (ASCII or binary; meshio 5 cannot) and, through meshio, STL/OBJ/PLY/
VTU surfaces; cleans the triangulation (largest connected component, merged duplicate
vertices, no degenerate triangles, consistent outward orientation), checks that it is closed,
and remeshes the volume with gmsh at the requested size (the surface is re-triangulated too).
"""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np

from data_spec.geometry import Geometry
from fem_sim.geometry.errors import GeometryError
from fem_sim.geometry.meshing import check_mesh_size
from fem_sim.geometry.regions import default_vena_cava

log = logging.getLogger(__name__)


def read_vtk_polydata(path: str | Path) -> tuple[np.ndarray, np.ndarray]:
    """(points (n, 3), triangles (m, 3)) of a legacy VTK POLYDATA file (polygons must be
    triangles).
    """
    path = Path(path)
    data = path.read_bytes()
    if not data.startswith(b"# vtk DataFile"):
        raise GeometryError(f"{path}: not a legacy VTK file")
    head = data[:256].split(b"\n")
    binary = head[2].strip().upper() == b"BINARY"
    if b"POLYDATA" not in head[3]:
        raise GeometryError(f"{path}: expected DATASET POLYDATA, got {head[3].decode()!r}")

    def section(keyword: bytes):
        i = data.find(b"\n" + keyword + b" ")
        if i < 0:
            raise GeometryError(f"{path}: no {keyword.decode()} section")
        j = data.index(b"\n", i + 1)
        return data[i + 1:j].split(), j + 1

    (_, n, dtype), start = section(b"POINTS")
    n = int(n)
    ftype = {b"float": ">f4", b"double": ">f8"}[dtype]
    if binary:
        pts = np.frombuffer(data, dtype=ftype, count=3 * n, offset=start).astype(np.float64)
    else:
        pts = np.array(data[start:].split()[: 3 * n], dtype=np.float64)
    (_, m, size), start = section(b"POLYGONS")
    m, size = int(m), int(size)
    if binary:
        conn = np.frombuffer(data, dtype=">i4", count=size, offset=start).astype(np.int64)
    else:
        conn = np.array(data[start:].split()[:size], dtype=np.int64)
    if size != 4 * m or np.any(conn[::4] != 3):
        raise GeometryError(f"{path}: only triangle polygons are supported")
    return pts.reshape(-1, 3), conn.reshape(-1, 4)[:, 1:]


def read_surface(path: str | Path) -> tuple[np.ndarray, np.ndarray]:
    """(points, triangles) of a surface file: legacy VTK POLYDATA and OBJ read here, the rest
    (STL, PLY, VTP) through meshio; polygons are fanned into triangles.
    """
    path = Path(path)
    if path.suffix.lower() == ".vtk":
        return read_vtk_polydata(path)
    if path.suffix.lower() == ".obj":
        from fem_sim.geometry.repair import read_obj

        return read_obj(path)
    import meshio

    try:
        m = meshio.read(path)
    except Exception as exc:
        raise GeometryError(f"{path}: cannot read surface: {exc}") from None
    tris = [c.data for c in m.cells if c.type == "triangle"]
    tris += [c.data[:, [0, k, k + 1]] for c in m.cells if c.type in ("quad", "polygon")
             for k in range(1, c.data.shape[1] - 1)]
    if not tris:
        raise GeometryError(f"{path}: no triangles")
    return np.asarray(m.points, dtype=np.float64)[:, :3], np.concatenate(tris).astype(np.int64)


def enclosed_volume(points, tris) -> float:
    """Signed volume (mm^3) enclosed by a closed triangle surface (divergence theorem):
    positive when the triangles face outward.
    """
    x = np.asarray(points, dtype=float)[np.asarray(tris)]
    return float(np.einsum("ij,ij->", x[:, 0], np.cross(x[:, 1], x[:, 2])) / 6.0)


def clean_surface(points, tris, source: str = "surface") -> tuple[np.ndarray, np.ndarray]:
    """Largest closed component, outward orientation, no duplicates or degenerate triangles."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    if len(tris) == 0:
        raise GeometryError(f"{source}: empty surface")
    _, inv = np.unique(np.round(points, 9), axis=0, return_inverse=True)
    tris = inv.ravel()[tris]
    tris = tris[(tris[:, 0] != tris[:, 1]) & (tris[:, 1] != tris[:, 2]) &
                (tris[:, 0] != tris[:, 2])]
    pts = np.zeros((inv.max() + 1, 3))
    pts[inv.ravel()] = points
    a = np.linalg.norm(np.cross(pts[tris[:, 1]] - pts[tris[:, 0]],
                                pts[tris[:, 2]] - pts[tris[:, 0]]), axis=1)
    tris = tris[a > 1e-12 * a.max()]
    n = pts.shape[0]
    e = np.concatenate([tris[:, [0, 1]], tris[:, [1, 2]], tris[:, [2, 0]]])
    g = coo_matrix((np.ones(len(e)), (e[:, 0], e[:, 1])), shape=(n, n))
    _, label = connected_components(g, directed=False)
    sizes = np.bincount(label[tris[:, 0]])
    keep = sizes.argmax()
    dropped = sorted((int(sizes[i]) for i in np.flatnonzero(sizes) if i != keep), reverse=True)
    if dropped:
        log.warning("%s: %d separate surface pieces; kept the largest (%d triangles), dropped "
                    "pieces of %s triangles", source, int(np.sum(sizes > 0)), int(sizes[keep]),
                    dropped[:10])
    tris = tris[label[tris[:, 0]] == keep]
    edges = np.sort(np.concatenate([tris[:, [0, 1]], tris[:, [1, 2]], tris[:, [2, 0]]]), axis=1)
    _, counts = np.unique(edges, axis=0, return_counts=True)
    if np.any(counts != 2):
        raise GeometryError(f"{source}: the surface is not closed ({int(np.sum(counts == 1))} "
                            f"boundary edges, {int(np.sum(counts > 2))} non-manifold edges)")
    used = np.unique(tris)
    renum = np.full(n, -1)
    renum[used] = np.arange(used.size)
    pts, tris = pts[used], renum[tris]
    if enclosed_volume(pts, tris) < 0:
        tris = tris[:, [0, 2, 1]]
    return pts, tris


def mesh_closed_surface(points, tris, mesh_size: float, description: str = "") -> Geometry:
    """Tetrahedral mesh of the solid bounded by a clean closed surface (gmsh), the surface
    remeshed at the mesh size.
    """
    from fem_sim.geometry.meshing import discrete_surface_solid

    check_mesh_size(abs(enclosed_volume(points, tris)), mesh_size, description or "surface")
    return discrete_surface_solid(points, tris, mesh_size, description, reparametrise=True,
                                  algorithm=1)


def mesh_surface_file(path: str | Path, mesh_size: float, scale_to_mm: float = 1.0,
                      fixed_radius: float = 25.0) -> Geometry:
    """Read, repair and mesh a surface file (:mod:`fem_sim.geometry.repair`: every repair
    logged; a liver the repair would move beyond its bounds refused). As a default fixed
    region (``vena_cava``) it marks the surface nodes within ``fixed_radius`` mm of the most
    posterior (max y) surface point; scenes can select any other region.
    """
    from fem_sim.geometry.repair import mesh_liver_file

    g, report = mesh_liver_file(path, mesh_size, scale_to_mm, flag="geometry.scale_to_mm")
    if report.route != "remeshed surface" or report.pieces_dropped:
        log.warning("%s: %d holes closed (%.0f mm^2), %d self-intersecting triangles, pieces "
                    "of %s triangles dropped; %s; volume %+.2f%%, the input within %.1f mm",
                    path, report.holes, report.area_added_mm2,
                    report.self_intersecting_triangles, report.pieces_dropped[:5],
                    report.route, 100 * report.volume_change, report.max_distance_mm)
    g.regions["vena_cava"] = default_vena_cava(g, fixed_radius)
    return g
