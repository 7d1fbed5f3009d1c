"""The embedded liver phantom: a procedural, liver-shaped solid meshed by gmsh.

No file from outside the repository is needed. The shape is built from OpenCASCADE primitives:
a large right lobe (an ellipsoid), a thinner left lobe (a flatter ellipsoid, higher and to the
left), fused, with the visceral (inferior) side cut by a tilted plane, which gives the wedge-like
profile, and a groove carved on the posterior side by a vertical cylinder: the inferior vena
cava. The surface nodes lining that groove are the ``vena_cava`` region, the fixed boundary.

Axes: x to the patient's left... right (x > 0: right lobe), y anterior -> posterior, z up.
Shape parameters are drawn from a seeded distribution (:func:`phantom_parameters`), so one seed
gives one liver and a range of seeds gives a population. Nominal size ~200 x 150 x 120 mm and
~1.3-1.8 L.
"""

from __future__ import annotations

import logging
from dataclasses import asdict, dataclass

import numpy as np

from data_spec.geometry import Geometry, boundary_triangles
from fem_sim.geometry.meshing import (  # noqa: F401  (mesh_volume re-exported)
    check_mesh_size,
    gmsh_tetrahedra,
    mesh_volume,
)

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class PhantomParameters:
    """Shape of one phantom, all lengths in mm."""

    right_axes: tuple[float, float, float]   # semi-axes of the right lobe
    left_axes: tuple[float, float, float]    # semi-axes of the left lobe
    left_offset: tuple[float, float, float]  # left-lobe centre relative to the right lobe's
    cut_height: float                        # visceral cut plane height below the centre
    cut_tilt: float                          # its slope in z per mm of x (radians of tilt)
    cava_x: float                            # vena-cava axis position (x, y)
    cava_y: float
    cava_radius: float


def phantom_parameters(seed: int) -> PhantomParameters:
    """Draw the shape parameters of phantom ``seed`` (deterministic)."""
    rng = np.random.default_rng([20241, seed])
    u = lambda lo, hi: float(rng.uniform(lo, hi))  # noqa: E731
    ra = (u(76, 86), u(68, 78), u(56, 64))
    la = (u(62, 74), u(44, 52), u(26, 32))
    return PhantomParameters(
        right_axes=ra, left_axes=la,
        left_offset=(-u(62, 72), u(-12, -4), u(8, 16)),
        cut_height=u(0.45, 0.6) * ra[2], cut_tilt=u(0.12, 0.25),
        cava_x=u(-28, -18), cava_y=0.8 * ra[1] + u(-4, 4), cava_radius=u(10, 13))


def make_phantom(seed: int = 0, mesh_size: float = 8.0) -> Geometry:
    """Mesh phantom ``seed`` with target edge length ``mesh_size`` (mm). Needs gmsh."""
    import gmsh

    prm = phantom_parameters(seed)
    lobes = (np.prod(prm.right_axes) + np.prod(prm.left_axes)) * 4.0 / 3.0 * np.pi
    check_mesh_size(lobes, mesh_size, f"phantom {seed}")  # an upper bound of its volume
    gmsh.initialize([], readConfigFiles=False)
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.option.setNumber("General.NumThreads", 1)  # reproducible meshes
        gmsh.model.add(f"phantom_{seed}")
        occ = gmsh.model.occ
        right = occ.addSphere(0, 0, 0, 1.0)
        occ.dilate([(3, right)], 0, 0, 0, *prm.right_axes)
        ox, oy, oz = prm.left_offset
        left = occ.addSphere(ox, oy, oz, 1.0)
        occ.dilate([(3, left)], ox, oy, oz, *prm.left_axes)
        body, _ = occ.fuse([(3, right)], [(3, left)])
        # Visceral cut: remove everything below a plane tilted about the y axis.
        L = 400.0
        box = occ.addBox(-L / 2, -L / 2, -L, L, L, L)
        occ.rotate([(3, box)], 0, 0, 0, 0, 1, 0, prm.cut_tilt)
        occ.translate([(3, box)], 0, 0, -prm.cut_height)
        body, _ = occ.cut(body, [(3, box)])
        cava = occ.addCylinder(prm.cava_x, prm.cava_y, -L / 2, 0, 0, L, prm.cava_radius)
        body, _ = occ.cut(body, [(3, cava)])
        occ.synchronize()
        vols = gmsh.model.getEntities(3)
        if len(vols) != 1:
            raise RuntimeError(f"phantom {seed}: expected one volume, got {len(vols)}")
        gmsh.option.setNumber("Mesh.MeshSizeMin", 0.5 * mesh_size)
        gmsh.option.setNumber("Mesh.MeshSizeMax", mesh_size)
        gmsh.option.setNumber("Mesh.MeshSizeFromCurvature", 0)
        gmsh.option.setNumber("Mesh.Algorithm", 6)
        gmsh.option.setNumber("Mesh.Algorithm3D", 1)
        gmsh.option.setNumber("Mesh.Optimize", 1)
        gmsh.model.mesh.generate(3)
        points, cells = gmsh_tetrahedra()
        gmsh.model.remove()
    finally:
        gmsh.finalize()
    tri = boundary_triangles(cells, points)
    surf = np.unique(tri)
    axis_dist = np.hypot(points[surf, 0] - prm.cava_x, points[surf, 1] - prm.cava_y)
    cava = surf[axis_dist <= prm.cava_radius + 0.05 * mesh_size]
    return Geometry(points=points, cells=cells, surface_triangles=tri,
                    regions={"vena_cava": cava},
                    description=f"liver phantom seed {seed}, mesh size {mesh_size} mm, "
                                f"parameters {asdict(prm)}")
