"""Real liver surfaces in: read what segmentations come as, repair, mesh with gmsh.

A surface segmented from CT has holes (a few to a hundred open edges), staircases, separate
specks and self-intersections. The route, each step reported (:class:`RepairReport`):

1. read: OBJ (with normals or texture coordinates, polygons fanned into triangles), STL,
   PLY, VTK/VTP; the largest piece is kept and the others reported;
2. a clean surface (closed, manifold, not crossing itself) is meshed as it is: gmsh remeshes
   it at the mesh size (its reparametrisation);
3. a surface with defects, or one gmsh cannot reparametrise, takes the segmentation route it
   came from, as the paper's livers did: the solid it encloses at 1 mm voxels (ray parity
   along three axes, two of three deciding, so that a hole cannot leak), an opening and a
   closing by one voxel, marching cubes, Taubin smoothing; then decimated to the mesh size
   (``fast-simplification``), repaired by MeshFix (``pymeshfix``: a decimation may fold a
   triangle over another) and meshed inside by gmsh, which keeps that surface;
4. measured: the volume before (the input with its holes closed by flat patches) and after
   (the tetrahedra), the largest and mean distance from the input's vertices to the meshed
   surface, the mesh's smallest dihedral angle and mean ratio. A liver moved beyond
   :data:`BOUNDS` is refused, naming the file, the defect and the bound. The distance bound
   holds the repair proper (the enclosed solid at 1 mm voxels); the opening then takes off
   parts thinner than its ball (3 voxels across: a segmentation's strands and fins), which
   can reach farther. Those are reported (vertices, farthest distance, volume) and bounded
   by the volume bound only: a 2 mm fin is no liver tissue a 16 mm mesh could hold.

MeshFix alone is not the repair of record: its removal of self-intersections deletes whole
sheets of a staircase segmentation (docs/real_livers.md).
"""

from __future__ import annotations

import logging
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from data_spec.geometry import Geometry, signed_volumes
from data_spec.liver_shape import pieces_problem
from data_spec.units import span_problem
from fem_sim.geometry.errors import GeometryError
from fem_sim.geometry.regions import default_vena_cava
from fem_sim.geometry.surfaces import read_obj

log = logging.getLogger(__name__)

# A liver is refused where the repair moved it beyond these (before meshing: what the mesh
# size then changes is the user's choice, reported beside): the repaired surface encloses a
# volume more than ``volume`` (relative) off the input's with its holes closed, or a vertex of
# the input lies farther than ``distance_mm`` from it.
BOUNDS = {"volume": 0.02, "distance_mm": 10.0}
# The meshed liver against its input, after gmsh, with room for what a coarse mesh cannot
# hold: its chords cut volume (the 161 shared CT livers lose at most 2.2 % at 16 mm,
# docs/real_livers.md; a sphere of radius 40 mm 3.6 %, inscribed chords) and a thin sharp
# margin (the SOFA liver's: 44 of its 4,996 vertices beyond 10 mm, at most 12.9 mm, at 16 mm;
# the CT livers at most 9.3 mm). So the input's vertices lie within ``max_mm`` of the mesh
# (twice the repair's bound; thin parts the repair took off aside), and the mesh has at least
# ``nodes`` nodes (elements across the liver's thickness). A bound on the mean distance was
# tried and dropped: a coarse input's few vertices sit on corners the repair rounds (a 60 mm
# box: 3 mm on average), and a thin part taken off weighs on a mean over the area.
MESH_BOUNDS = {"volume": 0.05, "max_mm": 20.0, "nodes": 100}
DECIMATE_EDGE = 0.6  # the decimated surface's target edge, in mesh sizes


@dataclass
class RepairReport:
    """What was done to one liver surface, and what it cost in geometry."""

    file: str
    mesh_size: float
    input_vertices: int = 0
    input_triangles: int = 0
    pieces_dropped: list = field(default_factory=list)   # triangles of each dropped piece
    pieces_dropped_ml: list = field(default_factory=list)  # and the volume it encloses
    flipped_triangles: int = 0     # turned to face as their neighbours
    boundary_edges: int = 0
    holes: int = 0
    nonmanifold_edges: int = 0
    self_intersecting_triangles: int = 0
    area_added_mm2: float = 0.0    # the flat patches that close the holes
    route: str = ""                # "remeshed surface" or "segmentation route"
    volume_before_ml: float = 0.0  # the input with its holes closed
    volume_repaired_ml: float = 0.0  # the repaired surface, before meshing
    volume_after_ml: float = 0.0   # the tetrahedral mesh
    repair_distance_mm: float = 0.0  # the largest, input vertices to the repaired surface
    #                                   (to the solid before the opening where the opening
    #                                   took off a thin part: the three below)
    thin_vertices: int = 0          # input vertices on thin parts the opening took off
    thin_distance_mm: float = 0.0   # the farthest of them from the repaired surface
    thin_volume_ml: float = 0.0     # what the opening took off in all
    thin_vertex_ids: list = field(default_factory=list)   # those vertices (of the piece)
    max_distance_mm: float = 0.0   # input vertices to the meshed surface
    mesh_distance_mm: float = 0.0  # the same, of the vertices not on thin parts (bounded)
    mean_distance_mm: float = 0.0
    nodes: int = 0
    tetrahedra: int = 0
    min_dihedral_deg: float = 0.0
    min_mean_ratio: float = 0.0
    seconds: float = 0.0
    warnings: list = field(default_factory=list)   # e.g. a surface unlike any liver

    @property
    def volume_change(self) -> float:
        return self.volume_after_ml / self.volume_before_ml - 1.0

    @property
    def repair_volume_change(self) -> float:
        return self.volume_repaired_ml / self.volume_before_ml - 1.0

    def summary(self) -> str:
        """One line: what was repaired, how, and what it cost in volume and distance."""
        flipped = (f"{self.flipped_triangles} triangles turned to face as their neighbours, "
                   if self.flipped_triangles else "")
        return (f"{Path(self.file).name}: {self.holes} holes closed ({self.area_added_mm2:.0f} "
                f"mm^2), {self.self_intersecting_triangles} crossing triangles, {flipped}pieces "
                f"dropped {self.pieces_dropped[:3]}; {self._thin()}{self.route}; volume "
                f"{self.volume_before_ml:.0f} -> "
                f"{self.volume_after_ml:.0f} mL ({self.volume_change:+.2%}); input within "
                f"{self.max_distance_mm:.1f} mm; {self.nodes:,} nodes, smallest dihedral "
                f"{self.min_dihedral_deg:.1f} deg; {self.seconds:.1f} s")

    def _thin(self) -> str:
        return "" if not self.thin_vertices else (
            f"thin parts taken off by the opening ({self.thin_vertices} "
            f"vert{'ex' if self.thin_vertices == 1 else 'ices'}, up to "
            f"{self.thin_distance_mm:.1f} mm, {self.thin_volume_ml:.2f} mL); ")

    def to_dict(self) -> dict:
        return {**asdict(self), "volume_change": self.volume_change,
                "repair_volume_change": self.repair_volume_change}


# ----------------------------------------------------------------------------------------------
# Reading
# ----------------------------------------------------------------------------------------------




def read_any_surface(path: str | Path) -> tuple[np.ndarray, np.ndarray]:
    """(points, triangles) of a surface file: .obj, .stl, .ply, .vtk (POLYDATA), .vtp."""
    from fem_sim.geometry.surfaces import read_surface

    path = Path(path)
    if not path.exists():
        raise GeometryError(f"{path}: no such file")
    if path.suffix.lower() == ".obj":
        return read_obj(path)
    if path.suffix.lower() not in (".stl", ".ply", ".vtk", ".vtp"):
        raise GeometryError(f"{path}: unknown surface type {path.suffix!r} (expected .obj, "
                            ".stl, .ply, .vtk, .vtp)")
    return read_surface(path)


# ----------------------------------------------------------------------------------------------
# Measuring
# ----------------------------------------------------------------------------------------------


def edges_of(tris: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(unique undirected edges, how many triangles share each)."""
    e = np.sort(np.concatenate([tris[:, [0, 1]], tris[:, [1, 2]], tris[:, [2, 0]]]), axis=1)
    return np.unique(e, axis=0, return_counts=True)




def area(points, tris) -> float:
    x = points[tris]
    return float(0.5 * np.linalg.norm(np.cross(x[:, 1] - x[:, 0], x[:, 2] - x[:, 0]),
                                      axis=1).sum())


def distances(from_points, points, tris) -> np.ndarray:
    """(n,) mm from each point to the nearest point of the surface (points, tris), exact: VTK's
    distance to a triangle mesh (a cell locator, then each candidate triangle's closest point).
    """
    from vtkmodules.util.numpy_support import numpy_to_vtk, numpy_to_vtkIdTypeArray
    from vtkmodules.vtkCommonCore import vtkDoubleArray, vtkPoints
    from vtkmodules.vtkCommonDataModel import vtkCellArray, vtkPolyData
    from vtkmodules.vtkFiltersCore import vtkImplicitPolyDataDistance

    def vtk_points(x):
        out = vtkPoints()
        out.SetData(numpy_to_vtk(np.ascontiguousarray(x, dtype=np.float64), deep=True))
        return out

    t = np.asarray(tris, dtype=np.int64)
    cells = vtkCellArray()
    cells.SetData(numpy_to_vtkIdTypeArray(np.arange(0, 3 * len(t) + 1, 3), deep=True),
                  numpy_to_vtkIdTypeArray(t.ravel(), deep=True))
    surface = vtkPolyData()
    surface.SetPoints(vtk_points(points))
    surface.SetPolys(cells)
    implicit = vtkImplicitPolyDataDistance()
    implicit.SetInput(surface)
    out = vtkDoubleArray()
    implicit.FunctionValue(vtk_points(from_points).GetData(), out)
    return np.abs(np.frombuffer(out, dtype=np.float64, count=len(from_points)).copy())


def hole_patches(points, tris) -> tuple[np.ndarray, np.ndarray]:
    """(points, patch triangles) that close every hole by a fan from its boundary loop's
    centroid (the centroids appended to the points), facing as the surface around it.
    """
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    directed = np.concatenate([tris[:, [0, 1]], tris[:, [1, 2]], tris[:, [2, 0]]])
    key = np.sort(directed, axis=1)
    _, first, counts = np.unique(key, axis=0, return_index=True, return_counts=True)
    boundary = directed[first[counts == 1]]  # each open edge as its triangle runs it
    if boundary.size == 0:
        return points, np.zeros((0, 3), dtype=np.int64)
    nodes, inv = np.unique(boundary, return_inverse=True)
    inv = inv.reshape(-1, 2)
    g = coo_matrix((np.ones(len(inv)), (inv[:, 0], inv[:, 1])), shape=(nodes.size,) * 2)
    label = connected_components(g, directed=False)[1][inv[:, 0]]
    centres = np.array([points[np.unique(boundary[label == k])].mean(axis=0)
                        for k in range(label.max() + 1)])
    patch = np.column_stack([boundary[:, 1], boundary[:, 0], len(points) + label])
    return np.concatenate([points, centres]), patch.astype(np.int64)


# ----------------------------------------------------------------------------------------------
# Repairing and meshing
# ----------------------------------------------------------------------------------------------




def meshfix(points, tris) -> tuple[np.ndarray, np.ndarray]:
    """MeshFix's repair of a surface (holes and crossings at once, the smallest pieces
    dropped): what the decimated surface is mended with, and the alternative to the
    segmentation route that docs/real_livers.md measures.
    """
    import pymeshfix

    mf = pymeshfix.MeshFix(np.asarray(points, dtype=np.float64),
                           np.asarray(tris, dtype=np.int64))
    mf.repair(joincomp=False, remove_smallest_components=True)
    return np.asarray(mf.points, dtype=np.float64), np.asarray(mf.faces, dtype=np.int64)


def measure_defects(points, tris, report: RepairReport) -> np.ndarray:
    """Open and non-manifold edges, holes, triangles that cross another (MeshFix's test),
    and the volume and patch area of the surface with its holes closed; the triangles, turned
    to face as their neighbours where the surface is closed, manifold and not crossing itself
    (there the turn is unambiguous; a defective surface takes the segmentation route, which
    does not depend on the triangles' facing).
    """
    import pymeshfix

    from fem_sim.geometry.surfaces import enclosed_volume, orient_consistently

    _, counts = edges_of(tris)
    report.boundary_edges = int(np.sum(counts == 1))
    report.nonmanifold_edges = int(np.sum(counts > 2))
    t = pymeshfix.PyTMesh()
    t.set_quiet(True)
    t.load_array(np.asarray(points, dtype=np.float64), np.asarray(tris, dtype=np.int64))
    report.self_intersecting_triangles = len(t.select_intersecting_triangles(justproper=True))
    if not (report.boundary_edges or report.nonmanifold_edges
            or report.self_intersecting_triangles):
        tris, report.flipped_triangles = orient_consistently(tris)
    closed, patch = hole_patches(points, tris)
    report.holes = len(closed) - len(points)  # a patch centre per boundary loop
    report.area_added_mm2 = area(closed, patch) if len(patch) else 0.0
    report.volume_before_ml = abs(enclosed_volume(closed, np.concatenate([tris, patch]))) / 1e3
    return tris


def decimated(points, tris, mesh_size: float) -> tuple[np.ndarray, np.ndarray]:
    """The surface decimated to triangles of about DECIMATE_EDGE mesh sizes (quadric error),
    repaired again (decimation may fold a triangle over another).
    """
    import fast_simplification

    from fem_sim.geometry.surfaces import clean_surface

    target = area(points, tris) / (0.433 * (DECIMATE_EDGE * mesh_size) ** 2)
    reduction = float(np.clip(1.0 - target / len(tris), 0.0, 0.99))
    p, t = fast_simplification.simplify(points.astype(np.float32), tris.astype(np.int32),
                                        target_reduction=reduction)
    p, t = meshfix(np.asarray(p, dtype=np.float64), np.asarray(t, dtype=np.int64))
    return clean_surface(p, t, "decimated surface")


OPENING = 1   # voxels: the radius of the opening and closing of the segmentation route


def segmentation_surface(points, tris, voxel: float = 1.0,
                         radius: int = OPENING) -> tuple[np.ndarray, np.ndarray]:
    """The surface of the solid a segmentation surface encloses, at ``voxel`` mm, opened and
    closed by a ball of ``radius`` voxels (the module docstring's step 3): closed, manifold,
    outward and smooth.
    """
    from fem_sim.geometry.masks import mask_surface
    from fem_sim.geometry.voxels import voxelize_majority

    mask, origin = voxelize_majority(points, tris, voxel)
    return mask_surface(mask, np.full(3, voxel), origin, voxel=voxel, radius=radius)


def _thin_parts(points, tris, far: np.ndarray, surface, report: RepairReport) -> np.ndarray:
    """The input vertices' distances ``far`` to the opened ``surface``, with those beyond the
    distance bound measured to the solid before the opening instead where they are within
    the bound of it: parts the opening took off (reported in ``report.thin_*``), not moved
    by the repair.
    """
    from fem_sim.geometry.surfaces import enclosed_volume

    solid = segmentation_surface(points, tris, radius=0)
    near = distances(points, *solid)
    thin = (far > BOUNDS["distance_mm"]) & (near <= BOUNDS["distance_mm"])
    report.thin_vertices = int(thin.sum())
    report.thin_vertex_ids = np.flatnonzero(thin).tolist()
    report.thin_distance_mm = float(far[thin].max()) if thin.any() else 0.0
    report.thin_volume_ml = max(abs(enclosed_volume(*solid)) - abs(enclosed_volume(*surface)),
                                0.0) / 1e3
    return np.where(thin, near, far)


def _repaired(points, tris, report: RepairReport) -> tuple[np.ndarray, np.ndarray]:
    """The surface gmsh meshes: a clean input as it is, else its segmentation surface;
    refused (GeometryError) where the repair moved it beyond :data:`BOUNDS`.
    """
    from fem_sim.geometry.surfaces import clean_surface, enclosed_volume

    segmented = bool(report.boundary_edges or report.nonmanifold_edges
                     or report.self_intersecting_triangles)
    surface = segmentation_surface(points, tris) if segmented else \
        clean_surface(points, tris, report.file)
    report.volume_repaired_ml = abs(enclosed_volume(*surface)) / 1e3
    d = distances(points, *surface)
    if segmented and d.max() > BOUNDS["distance_mm"]:
        d = _thin_parts(points, tris, d, surface, report)
    report.repair_distance_mm = float(d.max())
    why = refusal(report)
    if why:
        exc = GeometryError(why)
        exc.report = report  # what was measured, for a study of the refusals
        raise exc
    return surface


def mesh_inside(points, tris, mesh_size: float, description: str) -> Geometry:
    """Tetrahedra of the solid inside a closed surface whose triangles gmsh keeps as they are
    (no reparametrisation): the last step of the decimated routes.
    """
    from fem_sim.geometry.meshing import discrete_surface_solid

    return discrete_surface_solid(points, tris, mesh_size, description, reparametrise=False)


def _mesh(points, tris, mesh_size: float, report: RepairReport) -> Geometry:
    """The repaired surface remeshed by gmsh at the mesh size (a clean input's route); a
    segmentation surface, or one gmsh cannot reparametrise, decimated to the mesh size and
    meshed inside.
    """
    from fem_sim.geometry.quality import mesh_problems
    from fem_sim.geometry.surfaces import mesh_closed_surface

    description = f"{Path(report.file).name}, mesh size {mesh_size:g}"
    clean = not (report.boundary_edges or report.nonmanifold_edges
                 or report.self_intersecting_triangles)
    surface = _repaired(points, tris, report)
    if clean:
        try:
            g = mesh_closed_surface(*surface, mesh_size, description)
            if not mesh_problems(g.points, g.cells):
                report.route = "remeshed surface"
                return g
        except Exception as exc:  # gmsh raises plain Exceptions
            log.info("%s: gmsh could not remesh the surface (%s)", description, exc)
    report.route = "decimated surface" if clean else "segmentation route"
    g = mesh_inside(*decimated(*surface, mesh_size), mesh_size, description)
    bad = mesh_problems(g.points, g.cells)
    if bad:
        raise GeometryError(f"{report.file}: the meshed liver is unusable: {'; '.join(bad)}")
    return g


def _measure(g: Geometry, input_points, report: RepairReport) -> None:
    from fem_sim.geometry.quality import dihedral_angles, mean_ratio

    report.nodes, report.tetrahedra = g.n_nodes, int(g.cells.shape[0])
    report.volume_after_ml = float(np.abs(signed_volumes(g.points, g.cells)).sum()) / 1e3
    # to the nearest of the meshed surface and the mesh's nodes: an input vertex inside the
    # solid (a crease the coarse mesh fills) is measured to the nearest node
    from scipy.spatial import cKDTree

    d = np.minimum(distances(input_points, g.points, g.surface_triangles),
                   cKDTree(g.points).query(input_points)[0])
    report.max_distance_mm, report.mean_distance_mm = float(d.max()), float(d.mean())
    report.mesh_distance_mm = float(np.delete(d, report.thin_vertex_ids).max())
    report.min_dihedral_deg = float(dihedral_angles(g.points, g.cells).min())
    report.min_mean_ratio = float(mean_ratio(g.points, g.cells).min())


def refusal(report: RepairReport) -> str | None:
    """Why the repair moved the liver too far from its input (None when within
    :data:`BOUNDS`): the message names the file, the defects and the bound.
    """
    defects = (f"{report.holes} holes, {report.self_intersecting_triangles} self-intersecting "
               f"triangles, {report.nonmanifold_edges} non-manifold edges")
    if abs(report.repair_volume_change) > BOUNDS["volume"]:
        return (f"{report.file}: repairing it ({defects}) changes its volume by "
                f"{report.repair_volume_change:+.1%} from {report.volume_before_ml:.0f} mL, "
                f"beyond the bound of {BOUNDS['volume']:.0%}")
    if report.repair_distance_mm > BOUNDS["distance_mm"]:
        return (f"{report.file}: repairing it ({defects}) moves a vertex by "
                f"{report.repair_distance_mm:.1f} mm, beyond the bound of "
                f"{BOUNDS['distance_mm']:g} mm")
    return None


def _option(flag: str, name: str) -> str:
    """The command-line flag or the scene key a message names (``flag``: the scale's)."""
    cli = flag.startswith("--")
    return {"mesh": "--mesh-size" if cli else "geometry.mesh_size",
            "keep": "--keep-largest" if cli else
            "fem_sim mesh FILE --mesh-size H --keep-largest --out LIVER.h5, then "
            "geometry.path = LIVER.h5"}[name]


def _checked_input(points, mesh_size, scale_to_mm, file: str, flag: str) -> np.ndarray:
    """The file's points in mm; GeometryError naming the file, the value and the fix for a
    non-finite or non-positive mesh size or scale, or a coordinate that is NaN or inf.
    """
    for value, name in ((mesh_size, _option(flag, "mesh")), (scale_to_mm, flag)):
        if not (np.isfinite(value) and value > 0):
            raise GeometryError(f"{file}: {name} {value!r}: expected a finite number > 0"
                                + (" (a negative scale would mirror the liver)"
                                   if name == flag and np.isfinite(value) and value < 0 else ""))
    points = np.asarray(points, dtype=np.float64)
    bad = np.flatnonzero(~np.all(np.isfinite(points), axis=1))
    if bad.size:
        raise GeometryError(f"{file}: {bad.size} vertices have NaN or inf coordinates (the "
                            f"first: vertex {bad[0] + 1}, {points[bad[0]].tolist()}); a "
                            "surface needs finite coordinates")
    points = points * scale_to_mm
    why = span_problem(float(np.ptp(points, axis=0).max()), str(file), flag)
    if why:
        raise GeometryError(why)
    return points


def _largest_piece(points, tris, report: RepairReport, flag: str,
                   keep_largest: bool) -> tuple[np.ndarray, np.ndarray]:
    """The piece enclosing the most volume (each measured with its triangles facing as their
    neighbours), as it is in the file; the others reported, and refused (GeometryError naming
    both volumes and the option that keeps the largest) when one is more than a speck
    (:func:`data_spec.liver_shape.pieces_problem`).
    """
    from fem_sim.geometry.surfaces import enclosed_volume, orient_consistently, split_pieces

    parts = []
    for p, t in split_pieces(points, np.asarray(tris, dtype=np.int64), source=report.file):
        turned = orient_consistently(t)[0]
        closed, patch = hole_patches(p, turned)
        ml = abs(enclosed_volume(closed, np.concatenate([turned, patch])))
        parts.append((ml / 1e3, p, t))
    parts.sort(key=lambda x: -x[0])
    (_, p, t), rest = parts[0], parts[1:]
    report.pieces_dropped = [len(x[2]) for x in rest]
    report.pieces_dropped_ml = [x[0] for x in rest]
    why = pieces_problem(report.file, [x[0] for x in parts], _option(flag, "keep"))
    if why and not keep_largest:
        raise GeometryError(why)
    return p, t


def _pass_size(report: RepairReport, span: float) -> float:
    """About the mesh size at which the meshed liver keeps within :data:`MESH_BOUNDS`: a
    chord's loss of volume and distance grows as the square of the mesh size, the node count
    as its inverse cube; at most a tenth of the liver's span.
    """
    h, b = report.mesh_size, MESH_BOUNDS
    sizes = [span / 10.0, h * (report.nodes / (1.5 * b["nodes"])) ** (1 / 3)]
    if report.volume_change:
        sizes.append(h * np.sqrt(0.5 * b["volume"] / abs(report.volume_change)))
    if report.mesh_distance_mm:
        sizes.append(h * np.sqrt(0.5 * b["max_mm"] / report.mesh_distance_mm))
    best = min(sizes)
    return float(np.floor(best)) if best >= 2 else float(f"{best:.1g}")


def mesh_refusal(report: RepairReport, span: float, flag: str = "--scale-to-mm") -> str | None:
    """Why the meshed liver is too far from its input (None when within
    :data:`MESH_BOUNDS`): the message names the file, the bound and a mesh size that keeps it.
    """
    b = MESH_BOUNDS
    what = []
    if report.nodes < b["nodes"]:
        what.append(f"has {report.nodes} nodes, fewer than {b['nodes']}")
    if abs(report.volume_change) > b["volume"]:
        what.append(f"changes the volume by {report.volume_change:+.1%} ("
                    f"{report.volume_before_ml:.0f} -> {report.volume_after_ml:.0f} mL), beyond "
                    f"the bound of {b['volume']:.0%}")
    if report.mesh_distance_mm > b["max_mm"]:
        what.append(f"lies {report.mesh_distance_mm:.1f} mm from a vertex of the input (not "
                    f"on a thin part the repair took off), beyond the bound of "
                    f"{b['max_mm']:g} mm")
    if not what:
        return None
    return (f"{report.file}: meshed at {report.mesh_size:g} mm the liver {'; '.join(what)}; "
            f"{_option(flag, 'mesh')} {_pass_size(report, span):g} or less keeps it")


def mesh_liver_surface(points, tris, mesh_size: float, file: str = "surface",
                       scale_to_mm: float = 1.0, flag: str = "--scale-to-mm",
                       keep_largest: bool = False) -> tuple[Geometry, RepairReport]:
    """(tetrahedral mesh, repair report) of a liver surface (points in the file's unit times
    ``scale_to_mm``); GeometryError naming the file, the defect and the bound when the repair
    (:data:`BOUNDS`) or the mesh (:data:`MESH_BOUNDS`) would change the liver too much, or a
    second piece is large (``keep_largest``: mesh the largest anyway). A surface unlike any
    liver is meshed with a warning (``report.warnings``). The default fixed region
    (``vena_cava``): the surface nodes within 25 mm of the most posterior surface point.
    """
    from data_spec.liver_shape import unlike_a_liver
    from fem_sim.geometry.meshing import check_mesh_size

    t0 = time.perf_counter()
    report = RepairReport(file=str(file), mesh_size=float(mesh_size))
    points = _checked_input(points, mesh_size, scale_to_mm, str(file), flag)
    report.input_vertices, report.input_triangles = len(points), len(tris)
    piece, ptris = _largest_piece(points, tris, report, flag, keep_largest)
    ptris = measure_defects(piece, ptris, report)
    report.warnings = [w for w in [unlike_a_liver(piece, report.volume_before_ml, str(file))]
                       if w]
    check_mesh_size(report.volume_before_ml * 1e3, mesh_size, str(file))
    g = _mesh(piece, ptris, mesh_size, report)
    _measure(g, piece, report)
    why = mesh_refusal(report, float(np.ptp(piece, axis=0).max()), flag)
    if why:
        exc = GeometryError(why)
        exc.report = report
        raise exc
    report.seconds = time.perf_counter() - t0
    g.regions["vena_cava"] = default_vena_cava(g)
    return g, report


def mesh_liver_file(path: str | Path, mesh_size: float, scale_to_mm: float = 1.0,
                    flag: str = "--scale-to-mm") -> tuple[Geometry, RepairReport]:
    """:func:`mesh_liver_surface` of a surface file."""
    points, tris = read_any_surface(path)
    return mesh_liver_surface(points, tris, mesh_size, str(path), scale_to_mm, flag)


def mesh_surface_file(path: str | Path, mesh_size: float, scale_to_mm: float = 1.0,
                      fixed_radius: float = 25.0) -> Geometry:
    """Read, repair and mesh a surface file as a scene's file route does (this module's
    route: every repair logged; a liver the repair would move beyond its bounds refused). As
    a default fixed region (``vena_cava``) it marks the surface nodes within
    ``fixed_radius`` mm of the most posterior (max y) surface point; scenes can select any
    other region.
    """
    g, report = mesh_liver_file(path, mesh_size, scale_to_mm, flag="geometry.scale_to_mm")
    if report.route != "remeshed surface" or report.pieces_dropped:
        log.warning("%s", report.summary())
    for msg in report.warnings:
        log.warning("%s", msg)
    g.regions["vena_cava"] = default_vena_cava(g, fixed_radius)
    return g
