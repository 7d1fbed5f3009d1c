"""Geometry files: one HDF5 file per liver mesh, shared by all shards that use it.

Layout (``data_spec/README.md`` documents every field):

    /points              (n_nodes, 3)   float64  mm, source-mesh node order
    /cells               (n_cells, 4)   int64    linear tetrahedra, 0-based node ids
    /surface_triangles   (n_tri, 3)     int64    boundary triangles, outward orientation
    /surface_nodes       (n_surf,)      int64    sorted ids of nodes on the boundary
    /regions/<name>      (k,)           int64    named node sets (e.g. vena_cava)
    /shape_coefficients  (n_pca,)       float64  optional: PCA shape coefficients
    attrs: format, schema_version, geometry_id, content_hash, units_length, description
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass, field
from pathlib import Path

import h5py
import numpy as np

from data_spec.atomic import atomic_path

GEOMETRY_FORMAT = "liver-fem-geometry"
GEOMETRY_SCHEMA_VERSION = 1


@dataclass
class Geometry:
    """A tetrahedral liver mesh with its surface and named node regions (plain numpy arrays)."""

    points: np.ndarray
    cells: np.ndarray
    surface_triangles: np.ndarray
    regions: dict[str, np.ndarray] = field(default_factory=dict)
    shape_coefficients: np.ndarray | None = None
    description: str = ""

    def __post_init__(self):
        self.points = np.ascontiguousarray(self.points, dtype=np.float64)
        self.cells = np.ascontiguousarray(self.cells, dtype=np.int64)
        self.surface_triangles = np.ascontiguousarray(self.surface_triangles, dtype=np.int64)
        self.regions = {k: np.asarray(v, dtype=np.int64) for k, v in self.regions.items()}
        if self.shape_coefficients is not None:
            self.shape_coefficients = np.asarray(self.shape_coefficients, dtype=np.float64)

    @property
    def n_nodes(self) -> int:
        return int(self.points.shape[0])

    @property
    def surface_nodes(self) -> np.ndarray:
        return np.unique(self.surface_triangles)

    @property
    def content_hash(self) -> str:
        """sha256 over points and cells: identifies the mesh independently of its file name."""
        h = hashlib.sha256()
        h.update(self.points.tobytes())
        h.update(self.cells.tobytes())
        return h.hexdigest()

    @property
    def geometry_id(self) -> str:
        return "g" + self.content_hash[:16]


def signed_volumes(points: np.ndarray, cells: np.ndarray) -> np.ndarray:
    """Signed volume of each tetrahedron (mm^3): positive when nodes 1, 2, 3 turn
    counter-clockwise seen from node 0's opposite side (the orientation every geometry file
    stores).
    """
    e = points[cells[:, 1:]] - points[cells[:, :1]]
    return np.linalg.det(e) / 6.0


def region_area(points: np.ndarray, triangles: np.ndarray, nodes: np.ndarray) -> float:
    """Area (mm^2) of the surface ``triangles`` whose three corners are all in ``nodes`` (a
    region's surface: its nodes' triangles, nothing of the triangles that only touch it).
    """
    T = points[triangles[np.isin(triangles, nodes).all(axis=1)]]
    return float(0.5 * np.linalg.norm(np.cross(T[:, 1] - T[:, 0], T[:, 2] - T[:, 0]),
                                      axis=1).sum())


def grown_region(points: np.ndarray, triangles: np.ndarray, nodes,
                 area_min: float) -> tuple[np.ndarray, int]:
    """(nodes, rings): surface ``nodes`` grown by rings of neighbours along ``triangles``
    until their region's area (:func:`region_area`) reaches ``area_min`` mm^2 (at most 50
    rings; with no node, from the first triangle's).
    """
    rings = 0
    nodes = np.unique(np.asarray(nodes, dtype=np.int64))
    while region_area(points, triangles, nodes) < area_min and rings < 50:
        touching = triangles[np.isin(triangles, nodes).any(axis=1)]
        if nodes.size == 0:
            touching = triangles[:1]
        nodes = np.union1d(nodes, touching.ravel())
        rings += 1
    return nodes, rings


def geometry_problems(g: Geometry) -> list[str]:
    """Everything wrong with a geometry's arrays (empty list if it is usable): shapes, ids,
    finite points, unused nodes, and cells that are not positively oriented (a tangled or
    inverted mesh; fem_sim orients every mesh before writing it).
    """
    p = []
    if g.points.ndim != 2 or g.points.shape[1] != 3 or g.points.shape[0] < 4:
        p.append(f"points: expected shape (n_nodes >= 4, 3), got {g.points.shape}")
    elif not np.all(np.isfinite(g.points)):
        p.append("points: contains NaN or inf")
    n = g.points.shape[0]
    for name, arr, width in (("cells", g.cells, 4), ("surface_triangles", g.surface_triangles, 3)):
        if arr.ndim != 2 or arr.shape[1] != width or arr.shape[0] == 0:
            p.append(f"{name}: expected shape (k >= 1, {width}), got {arr.shape}")
        elif arr.min() < 0 or arr.max() >= n:
            p.append(f"{name}: node ids outside [0, {n})")
    for name, ids in g.regions.items():
        if ids.ndim != 1 or (ids.size and (ids.min() < 0 or ids.max() >= n)):
            p.append(f"regions/{name}: expected node ids in [0, {n})")
    if not p:
        used = np.zeros(n, bool)
        used[g.cells.ravel()] = True
        if not used.all():
            p.append(f"cells: {int((~used).sum())} nodes belong to no cell")
        vol = signed_volumes(g.points, g.cells)
        bad = np.flatnonzero(vol <= 0)
        if bad.size:
            p.append(f"cells: {bad.size} of {vol.size} have a volume <= 0 (inverted or flat; "
                     f"first: cell {bad[0]}, {vol[bad[0]]:.3g} mm^3)")
    return p


def write_geometry(path: str | Path, g: Geometry) -> Path:
    """Write ``g`` atomically to ``path``. Raises ValueError listing problems of the arrays."""
    problems = geometry_problems(g)
    if problems:
        raise ValueError(f"{path}: invalid geometry: " + "; ".join(problems))
    path = Path(path)
    with atomic_path(path) as tmp, h5py.File(tmp, "w") as f:
        f.attrs["format"] = GEOMETRY_FORMAT
        f.attrs["schema_version"] = GEOMETRY_SCHEMA_VERSION
        f.attrs["geometry_id"] = g.geometry_id
        f.attrs["content_hash"] = g.content_hash
        f.attrs["units_length"] = "mm"
        f.attrs["description"] = g.description
        f["points"] = g.points
        f["cells"] = g.cells
        f["surface_triangles"] = g.surface_triangles
        f["surface_nodes"] = g.surface_nodes
        grp = f.create_group("regions")
        for name, ids in g.regions.items():
            grp[name] = ids
        if g.shape_coefficients is not None:
            f["shape_coefficients"] = g.shape_coefficients
    return path


def read_geometry(path: str | Path) -> Geometry:
    """Read a geometry file written by :func:`write_geometry`."""
    with h5py.File(path, "r") as f:
        if f.attrs.get("format") != GEOMETRY_FORMAT:
            raise ValueError(f"{path}: not a {GEOMETRY_FORMAT} file (format attribute "
                             f"{f.attrs.get('format')!r})")
        return Geometry(
            points=f["points"][...],
            cells=f["cells"][...],
            surface_triangles=f["surface_triangles"][...],
            regions={k: v[...] for k, v in f["regions"].items()},
            shape_coefficients=f["shape_coefficients"][...] if "shape_coefficients" in f
            else None,
            description=str(f.attrs.get("description", "")),
        )


def read_geometry_node_count(path: str | Path) -> int:
    with h5py.File(path, "r") as f:
        if f.attrs.get("format") != GEOMETRY_FORMAT:
            raise ValueError(f"not a {GEOMETRY_FORMAT} file")
        return int(f["points"].shape[0])


def boundary_triangles(cells: np.ndarray, points: np.ndarray | None = None) -> np.ndarray:
    """Faces of a tetrahedral mesh that belong to exactly one cell.

    With ``points`` given, each triangle is oriented so its normal points out of its cell.
    """
    cells = np.asarray(cells, dtype=np.int64)
    # Face k of a tet is the triangle opposite vertex k.
    local = np.array([[1, 2, 3], [0, 3, 2], [0, 1, 3], [0, 2, 1]])
    faces = cells[:, local].reshape(-1, 3)
    opposite = cells[:, [0, 1, 2, 3]].reshape(-1)
    key = np.sort(faces, axis=1)
    _, inverse, counts = np.unique(key, axis=0, return_inverse=True, return_counts=True)
    once = counts[inverse.ravel()] == 1
    tri = faces[once]
    if points is not None:
        opp = opposite[once]
        a, b, c = (points[tri[:, i]] for i in range(3))
        normal = np.cross(b - a, c - a)
        inward = np.einsum("ij,ij->i", normal, points[opp] - a) > 0
        tri[inward] = tri[inward][:, [0, 2, 1]]
    return tri


def box_mesh(n: int = 4, size: tuple[float, float, float] = (1.0, 1.0, 1.0)) -> Geometry:
    """A box [0, Lx] x [0, Ly] x [0, Lz] split into n^3 cubes of 6 tetrahedra each.

    Node (i, j, k) has id i + (n+1) j + (n+1)^2 k. The region ``x0`` holds the nodes on x = 0.
    """
    m = n + 1
    g = np.stack(np.meshgrid(*(np.linspace(0, s, m) for s in size), indexing="ij"), -1)
    points = g.transpose(2, 1, 0, 3).reshape(-1, 3)  # x fastest
    nid = np.arange(m ** 3).reshape(m, m, m)  # [k, j, i]
    cells = []
    # Kuhn split of each cube along its main diagonal: 6 tets, conforming across cubes.
    paths = [(0, 1, 2), (0, 2, 1), (1, 0, 2), (1, 2, 0), (2, 0, 1), (2, 1, 0)]
    for k in range(n):
        for j in range(n):
            for i in range(n):
                for path in paths:
                    c = [0, 0, 0]
                    tet = [nid[k, j, i]]
                    for axis in path:
                        c[axis] += 1
                        tet.append(nid[k + c[2], j + c[1], i + c[0]])
                    cells.append(tet)
    cells = np.array(cells, dtype=np.int64)
    e = points[cells[:, 1:]] - points[cells[:, :1]]
    negative = np.linalg.det(e) < 0
    cells[negative] = cells[negative][:, [0, 2, 1, 3]]  # positive orientation everywhere
    return Geometry(points=points, cells=cells,
                    surface_triangles=boundary_triangles(cells, points),
                    regions={"x0": np.flatnonzero(points[:, 0] == 0.0)},
                    description=f"box {size} mm, {n}^3 cubes of 6 tets")
