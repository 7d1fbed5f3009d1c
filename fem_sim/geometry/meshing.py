"""Meshing helpers shared by the phantom and the surface importer (gmsh output, volumes)."""

from __future__ import annotations

import numpy as np

from data_spec.geometry import Geometry
from fem_sim.geometry.errors import GeometryError
from fem_sim.geometry.quality import orient, signed_volumes

# Above this the solver cannot run on a machine of this class (a P1 factorisation alone needs
# several GB), and gmsh would spend minutes and gigabytes before anyone is told.
MAX_NODES = 2_000_000
NODES_PER_VOLUME = 1.2  # nodes ~ 1.2 V / h^3 (gmsh, measured: phantom 3.1k at 8 mm, 19k at 4)


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
    return points, orient(points, cells, "gmsh")


def mesh_volume(g: Geometry) -> float:
    """Volume (mm^3) from the tetrahedra."""
    return float(np.abs(signed_volumes(g.points, g.cells)).sum())


def check_mesh_size(volume: float, mesh_size: float, where: str,
                    max_nodes: int = MAX_NODES) -> int:
    """Estimated node count of a tetrahedral mesh of ``volume`` mm^3 at ``mesh_size`` mm;
    GeometryError (before gmsh starts) when it exceeds ``max_nodes``.
    """
    estimate = NODES_PER_VOLUME * volume / mesh_size**3
    if estimate > max_nodes:
        h_min = (NODES_PER_VOLUME * volume / max_nodes) ** (1.0 / 3.0)
        raise GeometryError(f"{where}: mesh_size {mesh_size:g} mm would give about "
                            f"{estimate:.2g} nodes for {volume / 1e6:.2g} L (at most "
                            f"{max_nodes:,} here); use mesh_size >= {h_min:.2g} mm")
    return int(estimate)


# gmsh's 3D algorithm: Delaunay (1), which gives the same tetrahedra for the same surface
# every time. HXT (10) leaves fewer slivers along a kept surface but is not reproducible: gmsh
# hands it the surface's nodes in the order of their addresses in memory (a std::set of
# pointers), so one surface meshes differently from one call, or one process, to the next
# (docs/real_livers.md), and a dataset of real livers could not be made again.
ALGORITHM_3D = 1


def discrete_surface_solid(points, tris, mesh_size: float, description: str, *,
                           reparametrise: bool) -> Geometry:
    """Gmsh's tetrahedra inside a closed triangle surface: remeshed at the mesh size after
    reparametrising the surface (``reparametrise``: patches split at 45 degrees) or with the
    surface's triangles kept. The same surface gives the same mesh (:data:`ALGORITHM_3D`).
    """
    import gmsh

    from data_spec.geometry import boundary_triangles

    gmsh.initialize([], readConfigFiles=False)
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.option.setNumber("General.NumThreads", 1)
        gmsh.model.add("liver")
        s = gmsh.model.addDiscreteEntity(2)
        gmsh.model.mesh.addNodes(2, s, np.arange(1, len(points) + 1), points.ravel())
        gmsh.model.mesh.addElementsByType(s, 2, [], (tris + 1).ravel())
        surfaces = [s]
        if reparametrise:
            gmsh.model.mesh.classifySurfaces(np.pi / 4, True, True, np.pi)
            gmsh.model.mesh.createGeometry()
            surfaces = [t for _, t in gmsh.model.getEntities(2)]
        gmsh.model.geo.addVolume([gmsh.model.geo.addSurfaceLoop(surfaces)])
        gmsh.model.geo.synchronize()
        gmsh.option.setNumber("Mesh.MeshSizeMin", 0.5 * mesh_size)
        gmsh.option.setNumber("Mesh.MeshSizeMax", mesh_size)
        gmsh.option.setNumber("Mesh.MeshSizeFromCurvature", 0)
        gmsh.option.setNumber("Mesh.Algorithm3D", ALGORITHM_3D)
        gmsh.option.setNumber("Mesh.Optimize", 1)
        try:
            gmsh.model.mesh.generate(3)
            if not reparametrise:
                # a kept surface leaves slivers against it (an interior node close to a
                # boundary face): relocating the nodes takes them out (real livers at 8 mm:
                # smallest mean ratio 0.001 -> 0.05, docs/real_livers.md)
                gmsh.model.mesh.optimize("Relocate3D", niter=5)
        except Exception as exc:
            raise GeometryError(f"{description}: gmsh could not mesh the volume ({exc}); "
                                "self-intersecting surface?") from None
        pts, cells = gmsh_tetrahedra()
    finally:
        gmsh.finalize()
    if cells.size == 0:
        raise GeometryError(f"{description}: gmsh produced no tetrahedra")
    return Geometry(points=pts, cells=cells, surface_triangles=boundary_triangles(cells, pts),
                    description=description)
