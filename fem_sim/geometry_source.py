"""Where a scene's liver meshes come from: the embedded phantom, a population of phantoms, or a
file (a data_spec geometry ``.h5``, or a tetrahedral volume mesh readable by meshio).

Runs on one process (gmsh, meshio); the batch generator calls it on rank 0 before MPI work.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from data_spec import Geometry, Scene, read_geometry
from data_spec.geometry import boundary_triangles, geometry_problems


class GeometryError(ValueError):
    """A mesh file cannot be used; the message names the file and what is wrong."""


def n_geometries(scene: Scene) -> int:
    g = scene["geometry"]
    return g["population_size"] if g["source"] == "population" else 1


def scene_geometry(scene: Scene, index: int = 0) -> Geometry:
    """Geometry ``index`` of the scene (0 unless the scene is a population)."""
    g = scene["geometry"]
    if g["source"] == "phantom":
        from fem_sim.phantom import make_phantom

        return make_phantom(g["phantom_seed"], g["mesh_size"])
    if g["source"] == "population":
        from fem_sim.phantom import make_phantom

        return make_phantom(g["population_seed"] + index, g["mesh_size"])
    return read_mesh_file(g["path"], g["scale_to_mm"])


def read_mesh_file(path: str | Path, scale_to_mm: float = 1.0) -> Geometry:
    """A data_spec geometry file, or a volume mesh with tetrahedra (meshio formats)."""
    path = Path(path)
    if path.suffix in (".h5", ".hdf5"):
        try:
            return read_geometry(path)
        except (OSError, KeyError, ValueError) as exc:
            raise GeometryError(f"{path}: cannot read geometry: {exc}") from None
    import meshio

    try:
        m = meshio.read(path)
    except Exception as exc:  # meshio raises many types for unreadable files
        raise GeometryError(f"{path}: meshio cannot read it: {exc}") from None
    tets = [c.data for c in m.cells if c.type == "tetra"]
    if not tets:
        kinds = sorted({c.type for c in m.cells})
        raise GeometryError(f"{path}: no tetrahedra (cell types {kinds}); surface meshes need "
                            "remeshing, which is not implemented yet")
    cells = np.concatenate(tets).astype(np.int64)
    points = np.asarray(m.points, dtype=np.float64)[:, :3] * scale_to_mm
    e = points[cells[:, 1:]] - points[cells[:, :1]]
    det = np.linalg.det(e)
    if np.any(np.abs(det) < 1e-12 * np.abs(det).max()):
        raise GeometryError(f"{path}: {int(np.sum(np.abs(det) < 1e-12 * np.abs(det).max()))} "
                            "degenerate (zero-volume) tetrahedra")
    neg = det < 0
    cells[neg] = cells[neg][:, [0, 2, 1, 3]]
    g = Geometry(points=points, cells=cells,
                 surface_triangles=boundary_triangles(cells, points),
                 description=f"from {path.name}")
    problems = geometry_problems(g)
    if problems:
        raise GeometryError(f"{path}: " + "; ".join(problems))
    return g
