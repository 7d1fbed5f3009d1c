"""Surface files in, clean closed surfaces and their gmsh meshes out: the low-level pieces
of the file route (:mod:`fem_sim.geometry.repair` is the route itself).

Reads legacy VTK POLYDATA (ASCII or binary; meshio 5 cannot) and OBJ here, STL/PLY/VTP
through meshio; cleans a triangulation (largest connected component, merged duplicate
vertices, no degenerate triangles, consistent outward orientation) and checks that it is
closed; meshes the solid inside a clean closed surface with gmsh at the requested size.
"""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np

from data_spec.geometry import Geometry
from fem_sim.geometry.errors import GeometryError
from fem_sim.geometry.meshing import check_mesh_size

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


def split_pieces(points, tris, drop_flat: bool = False,
                 source: str = "surface") -> list[tuple[np.ndarray, np.ndarray]]:
    """Every connected piece (points, triangles renumbered), the most triangles first:
    duplicate vertices merged, degenerate triangles dropped (``drop_flat``: also those of
    near-zero area); GeometryError naming ``source`` when no triangle is left.
    """
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    _, inv = np.unique(np.round(points, 9), axis=0, return_inverse=True)
    inv = inv.ravel()
    pts = np.zeros((inv.max() + 1, 3))
    pts[inv] = points
    tris = inv[tris]
    tris = tris[(tris[:, 0] != tris[:, 1]) & (tris[:, 1] != tris[:, 2])
                & (tris[:, 0] != tris[:, 2])]
    if drop_flat and len(tris):
        a = np.linalg.norm(np.cross(pts[tris[:, 1]] - pts[tris[:, 0]],
                                    pts[tris[:, 2]] - pts[tris[:, 0]]), axis=1)
        tris = tris[a > 1e-12 * a.max()]
    if len(tris) == 0:
        raise GeometryError(f"{source}: no triangle with three distinct vertices (every face "
                            "repeats a vertex, or two vertices coincide): not a surface")
    e = np.concatenate([tris[:, [0, 1]], tris[:, [1, 2]]])
    g = coo_matrix((np.ones(len(e)), (e[:, 0], e[:, 1])), shape=(len(pts),) * 2)
    label = connected_components(g, directed=False)[1][tris[:, 0]]
    out = []
    for k in np.argsort(-np.bincount(label), kind="stable"):
        piece = tris[label == k]
        if len(piece) == 0:
            continue
        used = np.unique(piece)
        renum = np.full(len(pts), -1)
        renum[used] = np.arange(used.size)
        out.append((pts[used], renum[piece]))
    return out


def largest_piece(points, tris, drop_flat: bool = False,
                  source: str = "surface") -> tuple[np.ndarray, np.ndarray, list]:
    """(points, triangles, triangles of each dropped piece): the piece of
    :func:`split_pieces` with the most triangles.
    """
    parts = split_pieces(points, tris, drop_flat, source)
    return parts[0][0], parts[0][1], [len(t) for _, t in parts[1:]]


def orient_consistently(tris) -> tuple[np.ndarray, int]:
    """(triangles, how many were turned): each triangle turned, where needed, to run every
    manifold edge opposite to its neighbour there, the larger part of each connected piece
    kept as it faced (a file half of whose triangles face inward is one surface, and its
    enclosed volume is only right once they agree).
    """
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import breadth_first_order, connected_components

    tris = np.asarray(tris, dtype=np.int64)
    n = len(tris)
    directed = np.concatenate([tris[:, [0, 1]], tris[:, [1, 2]], tris[:, [2, 0]]])
    owner = np.tile(np.arange(n), 3)
    _, inv, counts = np.unique(np.sort(directed, axis=1), axis=0, return_inverse=True,
                               return_counts=True)
    inv = inv.ravel()
    order = np.argsort(inv, kind="stable")
    starts = np.r_[0, np.cumsum(counts)[:-1]][counts == 2]
    first, second = order[starts], order[starts + 1]   # the two uses of each manifold edge
    a, b = owner[first], owner[second]
    turn = (directed[first, 0] == directed[second, 0]).astype(np.int8)  # same way: one turns
    _, once = np.unique(np.sort(np.column_stack([a, b]), axis=1), axis=0, return_index=True)
    a, b, turn = a[once], b[once], turn[once]   # two triangles sharing two edges: one link
    graph = coo_matrix((turn + 1, (a, b)), shape=(n, n)).tocsr()
    graph = graph + graph.T
    parity = np.zeros(n, dtype=np.int8)
    n_parts, part = connected_components(graph, directed=False)
    for k in range(n_parts):
        nodes, pred = breadth_first_order(graph, int(np.flatnonzero(part == k)[0]),
                                          directed=False, return_predecessors=True)
        rel = np.asarray(graph[nodes[1:], pred[nodes[1:]]]).ravel() - 1
        for node, p, r in zip(nodes[1:], pred[nodes[1:]], rel):
            parity[node] = parity[p] ^ r
        if 2 * parity[nodes].sum() > nodes.size:
            parity[nodes] ^= 1
    out = tris.copy()
    out[parity == 1] = out[parity == 1][:, [0, 2, 1]]
    return out, int(parity.sum())


def clean_surface(points, tris, source: str = "surface") -> tuple[np.ndarray, np.ndarray]:
    """Largest closed component, outward orientation, no duplicates or degenerate triangles."""
    if len(tris) == 0:
        raise GeometryError(f"{source}: empty surface")
    pts, tris, dropped = largest_piece(points, tris, drop_flat=True, source=source)
    if dropped:
        log.warning("%s: %d separate surface pieces; kept the largest (%d triangles), dropped "
                    "pieces of %s triangles", source, len(dropped) + 1, len(tris),
                    dropped[:10])
    edges = np.sort(np.concatenate([tris[:, [0, 1]], tris[:, [1, 2]], tris[:, [2, 0]]]), axis=1)
    _, counts = np.unique(edges, axis=0, return_counts=True)
    if np.any(counts != 2):
        raise GeometryError(f"{source}: the surface is not closed ({int(np.sum(counts == 1))} "
                            f"boundary edges, {int(np.sum(counts > 2))} non-manifold edges)")
    if enclosed_volume(pts, tris) < 0:
        tris = tris[:, [0, 2, 1]]
    return pts, tris


def mesh_closed_surface(points, tris, mesh_size: float, description: str = "") -> Geometry:
    """Tetrahedral mesh of the solid bounded by a clean closed surface (gmsh), the surface
    remeshed at the mesh size.
    """
    from fem_sim.geometry.meshing import discrete_surface_solid

    check_mesh_size(abs(enclosed_volume(points, tris)), mesh_size, description or "surface")
    return discrete_surface_solid(points, tris, mesh_size, description, reparametrise=True)


def read_obj(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """(points, triangles) of a Wavefront OBJ: ``v`` lines, ``f`` lines with ``i``, ``i/t``,
    ``i//n`` or ``i/t/n`` entries (1-based or negative), polygons fanned into triangles.
    """
    verts, faces = [], []
    for k, line in enumerate(path.read_text(errors="replace").splitlines(), 1):
        parts = line.split()
        if not parts:
            continue
        try:
            if parts[0] == "v":
                verts.append([float(x) for x in parts[1:4]])
            elif parts[0] == "f":
                idx = [int(p.split("/")[0]) for p in parts[1:]]
                idx = [i - 1 if i > 0 else len(verts) + i for i in idx]
                faces += [[idx[0], idx[j], idx[j + 1]] for j in range(1, len(idx) - 1)]
        except (ValueError, IndexError):
            raise GeometryError(f"{path}: line {k}: cannot read {line.strip()[:60]!r}") from None
    points, tris = np.asarray(verts, dtype=np.float64), np.asarray(faces, dtype=np.int64)
    if points.ndim != 2 or points.shape[1] != 3 or tris.size == 0:
        raise GeometryError(f"{path}: no vertices or no faces")
    if tris.min() < 0 or tris.max() >= len(points):
        raise GeometryError(f"{path}: a face refers to a vertex that does not exist")
    return points, tris
