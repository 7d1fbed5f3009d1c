"""Where a scene's liver meshes come from: the embedded phantom, a population of phantoms, or a
file (a data_spec geometry ``.h5``, or a tetrahedral volume mesh readable by meshio).

Runs on one process (gmsh, meshio); the batch generator calls it on rank 0 before MPI work.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from data_spec import Geometry, Scene, read_geometry
from data_spec.geometry import boundary_triangles, geometry_problems
from data_spec.livers import members
from fem_sim.geometry.errors import GeometryError
from fem_sim.geometry.mesh_index import (
    indexed,
    phantom_code,
    phantom_key,
    read_index,
    write_index,
)
from fem_sim.geometry.quality import mesh_problems, orient
from fem_sim.geometry.regions import default_vena_cava


def n_geometries(scene: Scene) -> int:
    g = scene["geometry"]
    return len(members(g)) if g["source"] == "population" else 1


def scene_geometries(scene: Scene, cache=None, progress=None, dataset=None,
                     meshed=None) -> list[Geometry]:
    """Every geometry of a scene; for a population, with its PCA shape coefficients
    (:mod:`fem_sim.geometry.population`; ``cache``: an .npz file that keeps them between runs).

    ``dataset``: a dataset directory; its ``geometry/meshes.json`` indexes the phantoms meshed
    before: one with the same seed, variety, mesh size, phantom code and gmsh is read from its
    geometry file instead of being meshed again (the index is written here; the files are the
    caller's, so an entry whose file is missing or holds another mesh is meshed again).
    ``meshed(i)`` is called as each geometry is ready; ``progress`` during the registration.
    """
    g = scene["geometry"]
    if g["source"] == "population" and "livers" in g:
        from fem_sim.geometry.file_population import population_geometries

        return population_geometries(scene, cache, dataset, meshed, progress)
    index = read_index(dataset)
    livers, new = [], {}
    for i in range(n_geometries(scene)):
        key = _mesh_key(scene, i)
        liver = indexed(dataset, index.get(key)) if key else None
        if liver is None:
            liver = scene_geometry(scene, i)
            if key:
                new[key] = liver.geometry_id
        livers.append(liver)
        if meshed:
            meshed(i)
    if new and dataset is not None:
        write_index(dataset, {**index, **new})
    if g["source"] == "population" and len(livers) > 1:
        from fem_sim.geometry.population import attach_shape_coefficients

        attach_shape_coefficients(livers, g["pca_components"], cache=cache, progress=progress)
    return livers


def _mesh_key(scene: Scene, index: int) -> str | None:
    """What a phantom's or a liver file's mesh depends on (a file's bytes, its settings and
    the code that repairs and meshes it); None for a file that is a mesh already (read).
    """
    g = scene["geometry"]
    if g["source"] == "phantom":
        seed, variety = g["phantom_seed"], "narrow"
    elif g["source"] == "population":
        seed, variety = g["population_seed"] + index, g.get("variety", "anatomical")
    elif Path(g["path"]).suffix.lower() in SURFACES:
        import hashlib

        from fem_sim.geometry.file_population import _code_bytes

        h = hashlib.sha256(Path(g["path"]).read_bytes())
        h.update(_code_bytes())
        return (f"file {h.hexdigest()[:16]}, mesh size {float(g['mesh_size'])!r}, scale "
                f"{g['scale_to_mm']!r}, spacing {g.get('spacing')}, {phantom_code()}")
    else:
        return None
    return phantom_key(seed, variety, g["mesh_size"])


def scene_geometry(scene: Scene, index: int = 0) -> Geometry:
    """Geometry ``index`` of the scene (0 unless the scene is a population)."""
    g = scene["geometry"]
    if g["source"] == "phantom":
        from fem_sim.geometry.phantom import make_phantom

        return make_phantom(g["phantom_seed"], g["mesh_size"])
    if g["source"] == "population":
        from fem_sim.geometry.phantom import make_phantom

        member = members(g)[index]
        if member.path is not None:
            raise ValueError("a population's liver files are meshed with the population "
                             "(scene_geometries), not one by one")
        return make_phantom(member.seed, g["mesh_size"], g.get("variety", "anatomical"))
    return read_any(g["path"], g["mesh_size"], g["scale_to_mm"], g.get("spacing"))


SURFACES = (".vtk", ".vtp", ".stl", ".obj", ".ply")
MASKS = (".npy", ".npz", ".nii", ".nii.gz")


def read_any(path, mesh_size: float, scale_to_mm: float = 1.0, spacing=None) -> Geometry:
    """A liver from a file, by kind: a segmentation mask (meshed through
    :mod:`fem_sim.geometry.masks`), a closed surface (remeshed at ``mesh_size``), or a volume mesh /
    data_spec geometry (used as is, node order kept).
    """
    name = str(path).lower()
    if name.endswith(MASKS):
        from fem_sim.geometry.masks import mesh_mask_file

        return mesh_mask_file(path, mesh_size, spacing)
    if name.endswith(SURFACES) and not _is_volume_vtk(path):
        from fem_sim.geometry.repair import mesh_surface_file

        return mesh_surface_file(path, mesh_size, scale_to_mm)
    return read_mesh_file(path, scale_to_mm)


def _is_volume_vtk(path) -> bool:
    if not str(path).lower().endswith(".vtk") or not Path(path).exists():
        return False
    with open(path, "rb") as f:
        head = f.read(256)
    return b"UNSTRUCTURED_GRID" in head


def read_mesh_file(path: str | Path, scale_to_mm: float = 1.0) -> Geometry:
    """A data_spec geometry file, or a volume mesh with tetrahedra (meshio formats)."""
    path = Path(path)
    if path.suffix in (".h5", ".hdf5"):
        try:
            g = read_geometry(path)
        except (OSError, KeyError, ValueError) as exc:
            raise GeometryError(f"{path}: cannot read geometry: {exc}") from None
        problems = mesh_problems(g.points, g.cells)
        if problems:
            raise GeometryError(f"{path}: " + "; ".join(problems))
        return g
    import meshio

    try:
        m = meshio.read(path)
    except (Exception, SystemExit) as exc:  # meshio raises many types, even SystemExit
        raise GeometryError(f"{path}: meshio cannot read it: {exc}") from None
    tets = [c.data for c in m.cells if c.type == "tetra"]
    if not tets:
        kinds = sorted({c.type for c in m.cells})
        raise GeometryError(f"{path}: no tetrahedra (cell types {kinds}); surface meshes need "
                            "remeshing, which is not implemented yet")
    cells = np.concatenate(tets).astype(np.int64)
    points = np.asarray(m.points, dtype=np.float64)[:, :3] * scale_to_mm
    if not np.all(np.isfinite(points)):
        raise GeometryError(f"{path}: points contain NaN or inf")
    if cells.min() < 0 or cells.max() >= points.shape[0]:
        raise GeometryError(f"{path}: cells refer to node ids outside [0, {points.shape[0]})")
    cells = orient(points, cells, str(path))  # node-order conventions differ between files
    problems = mesh_problems(points, cells)
    if problems:
        raise GeometryError(f"{path}: " + "; ".join(problems))
    g = Geometry(points=points, cells=cells,
                 surface_triangles=boundary_triangles(cells, points),
                 description=f"from {path.name}")
    problems = geometry_problems(g)
    if problems:
        raise GeometryError(f"{path}: " + "; ".join(problems))

    g.regions["vena_cava"] = default_vena_cava(g)
    return g
