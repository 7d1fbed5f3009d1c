"""The embedded liver phantom: a procedural, liver-shaped solid meshed by gmsh.

No file from outside the repository is needed. The shape is built from OpenCASCADE primitives:
a large right lobe (an ellipsoid), a thinner left lobe (a flatter ellipsoid, higher and to the
left), fused, with the visceral (inferior) side cut by a tilted plane, which gives the wedge-like
profile, and a groove carved on the posterior side by a vertical cylinder: the inferior vena
cava. The surface nodes lining that groove are the ``vena_cava`` region, the fixed boundary.

Axes: x to the patient's left... right (x > 0: right lobe), y anterior -> posterior, z up.
Shape parameters are drawn from a seeded distribution, so one seed gives one liver and a range
of seeds gives a population. Two distributions:

* ``narrow`` (:func:`phantom_parameters`, the embedded default liver and the first
  populations): the two ellipsoids vary by a few millimetres; ~200 x 150 x 120 mm, 1.3-1.8 L.
* ``anatomical`` (:func:`anatomical_parameters`, populations by default): the variety of real
  livers. Ranges and their sources:

  - volume 1.0-2.5 L, drawn around 1.55 +- 0.38 L: MRI volumetry of 2,773 adults (Kromrey
    et al., Eur J Radiol 2018, 1505 +- 385 cm^3) and CT volumetry of 369 adults (Feng et al.,
    World J Gastroenterol 2017, 594-2250 cm^3). The solid is scaled to the drawn volume.
  - right-lobe craniocaudal extent (dome above the equator plus the part below it to the
    visceral cut): 14.0 +- 1.7 cm at the midclavicular line, 9.4-21.3 cm, in 2,080 adults
    (Kratzer et al., J Ultrasound Med 2003); before the volume scaling the drawn extents span
    about 9-17 cm.
  - a Riedel's lobe (a tongue of the right lobe reaching down, anterior) in 15 % of livers:
    reported prevalences range from 3.3 % to 31 % (reviewed in Cureus 2024, PMC10867707).
  - left-lobe extent, right-lobe depth, dome curvature (the dome's height against the lobe's
    width, independent of the part below the equator), the sharpness of the inferior edge (an
    anterior-inferior bevel) and the position of the vena-cava groove: no single study gives
    their distributions; the ranges here (in :func:`anatomical_parameters`) are ours, wide
    enough to cover a small left lobe and one that reaches across to the spleen (the
    "beaver-tail" variant), flat and round domes, blunt and sharp edges. What the population
    then varies is measured in docs/population.md.
  - the groove is the fixed region: a drawn cava axis that only grazes the posterior surface
    leaves a sliver that holds the liver by a few nodes, so a groove under
    ``MIN_GROOVE_AREA`` gets its cava redrawn (:func:`with_groove`, the rest of the shape kept).
"""

from __future__ import annotations

import logging
from dataclasses import asdict, dataclass, replace

import numpy as np

from data_spec.geometry import Geometry, boundary_triangles
from fem_sim.geometry.errors import GeometryError
from fem_sim.geometry.meshing import (  # noqa: F401  (mesh_volume re-exported)
    check_mesh_size,
    gmsh_tetrahedra,
    mesh_volume,
)
from fem_sim.geometry.quality import flat_tetrahedra, mean_ratio

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
    # anatomical variety (None: the narrow phantom's shape)
    dome_height: float | None = None         # semi-axis of the right lobe above its equator
    bevel: tuple[float, float] | None = None  # anterior-inferior bevel: (tilt rad, y position)
    riedel: tuple | None = None              # Riedel's lobe: centre (3) and semi-axes (3)
    volume: float | None = None              # the solid is scaled to this volume, mm^3


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


RIEDEL_PREVALENCE = 0.15


def anatomical_parameters(seed: int, spread: float = 1.0) -> PhantomParameters:
    """Draw the shape of anatomical phantom ``seed`` (deterministic; ranges: module docstring).

    ``spread``: every uniform range widened (> 1) or narrowed about its centre by this factor,
    the volume's standard deviation and its clip too (the same random numbers drawn, so
    ``spread = 1`` is the population itself): livers beyond the population, drawn as far
    outside it as a real liver lies (docs/shape_rule.md).
    """
    if not (np.isfinite(spread) and spread > 0):
        raise ValueError(f"spread: expected a number > 0, got {spread!r}")
    rng = np.random.default_rng([20251, seed])
    u = lambda lo, hi: float(rng.uniform(*_widened(lo, hi, spread)))  # noqa: E731
    ra = (u(65, 95), u(55, 95), u(45, 80))      # right lobe: half width, depth, below-equator
    la = (u(45, 100), u(35, 62), u(18, 36))     # left lobe: extent, depth, thickness
    cut = u(0.5, 0.85) * ra[2]
    riedel = None
    if rng.uniform() < RIEDEL_PREVALENCE:
        riedel = (u(0.35, 0.65) * ra[0], u(-0.3, 0.1) * ra[1], -cut,
                  u(18, 30), u(15, 26), u(38, 60))
    # litres: 1.55 +- 0.38, clipped to 1.0 .. 2.5 (1.55 - 0.55, 1.55 + 0.95)
    sd, lo, hi = (0.38, 1.0, 2.5) if spread == 1.0 else \
        (0.38 * spread, 1.55 - 0.55 * spread, 1.55 + 0.95 * spread)
    volume = 1e6 * float(np.clip(rng.normal(1.55, sd), lo, hi))
    return PhantomParameters(
        right_axes=ra, left_axes=la,
        left_offset=(-(0.25 * ra[0] + 0.7 * la[0]), u(-14, 2), u(4, 24)),
        cut_height=cut, cut_tilt=u(0.02, 0.35), **_draw_cava(rng, ra, spread),
        dome_height=u(42, 88), bevel=(u(0.15, 0.65), u(0.1, 0.5) * ra[1]), riedel=riedel,
        volume=volume)


def _widened(lo: float, hi: float, spread: float) -> tuple[float, float]:
    """The range lo .. hi widened about its centre by ``spread`` (itself at 1)."""
    if spread == 1.0:
        return lo, hi
    mid, half = 0.5 * (lo + hi), 0.5 * spread * (hi - lo)
    return mid - half, mid + half


def _draw_cava(rng, ra, spread: float = 1.0) -> dict:
    """The vena cava of an anatomical phantom: axis (x, y) and radius, drawn from ``rng``."""
    u = lambda lo, hi: float(rng.uniform(*_widened(lo, hi, spread)))  # noqa: E731
    return dict(cava_x=u(-42, -10), cava_y=u(0.72, 0.9) * ra[1] + u(-6, 6),
                cava_radius=u(9, 14))


# The vena cava's groove is the fixed region. Where the drawn axis only grazes the posterior
# surface the groove is a sliver, and a few nodes hold the whole liver. A real retrohepatic
# vena cava runs 6-8 cm along the liver with about half its circumference embedded, at least
# 28 mm at the narrowest radius drawn (9 mm): 800 mm^2 is that half over 3 cm of its course.
MIN_GROOVE_AREA = 800.0  # mm^2
MAX_CAVA_DRAWS = 20


def with_groove(prm: PhantomParameters, seed: int, spread: float = 1.0) -> PhantomParameters:
    """``prm`` with its vena cava redrawn (seeded by ``seed`` and the attempt, the rest of the
    shape kept; ``spread`` as :func:`anatomical_parameters`'s) until its groove covers
    ``MIN_GROOVE_AREA``; ``prm`` itself when it does. Needs gmsh. :func:`make_phantom` draws
    the same cava, measuring each groove in the model it then meshes.
    """
    attempt, area = 0, groove_area(prm)
    while area < MIN_GROOVE_AREA:
        attempt, prm = _redrawn(prm, seed, attempt, area, spread)
        area = groove_area(prm)
    _log_redrawn(seed, attempt, area)
    return prm


def _redrawn(prm: PhantomParameters, seed: int, attempt: int, area: float,
             spread: float) -> tuple[int, PhantomParameters]:
    """The next draw of a cava whose groove (``area`` mm^2) is too small: (attempt, prm)."""
    attempt += 1
    if attempt > MAX_CAVA_DRAWS:
        raise GeometryError(f"phantom {seed}: no vena-cava groove of {MIN_GROOVE_AREA:.0f} "
                            f"mm^2 in {MAX_CAVA_DRAWS} draws (the last {area:.0f} mm^2)")
    return attempt, replace(prm, **_draw_cava(np.random.default_rng([20251, seed, attempt]),
                                              prm.right_axes, spread))


def _log_redrawn(seed: int, attempt: int, area: float) -> None:
    if attempt:
        log.info("phantom %d: vena cava redrawn %d time(s), groove %.0f mm^2", seed, attempt,
                 area)


class _SmallGroove(Exception):
    """The solid's groove is under MIN_GROOVE_AREA (its area, mm^2, in args[0])."""


def make_phantom(seed: int = 0, mesh_size: float = 8.0, variety: str = "narrow",
                 spread: float = 1.0) -> Geometry:
    """Mesh phantom ``seed`` of the ``variety`` ("narrow" or "anatomical") with target edge
    length ``mesh_size`` (mm); ``spread``: an anatomical phantom's ranges widened
    (:func:`anatomical_parameters`). Needs gmsh.
    """
    if variety not in ("narrow", "anatomical"):
        raise ValueError(f"variety: expected 'narrow' or 'anatomical', got {variety!r}")
    if variety == "narrow" and spread != 1.0:
        raise ValueError(f"spread: only anatomical phantoms are widened, got {spread!r} for a "
                         "narrow one")
    anatomical = variety == "anatomical"
    prm = anatomical_parameters(seed, spread) if anatomical else phantom_parameters(seed)
    widened = f", spread {spread:g}" if spread != 1.0 else ""
    lobes = (np.prod(prm.right_axes) + np.prod(prm.left_axes)) * 4.0 / 3.0 * np.pi
    if prm.volume is not None:
        lobes = prm.volume
    check_mesh_size(lobes, mesh_size, f"phantom {seed}")  # an upper bound of its volume
    # an anatomical phantom's groove is measured in the model that is then meshed (the solid
    # built once): too small, its cava is redrawn as with_groove redraws it
    failures, attempt, area = [], 0, None
    algorithms = iter(SURFACE_ALGORITHMS)
    algorithm = next(algorithms)
    while True:
        try:
            points, cells, scale, area = _mesh(prm, seed, mesh_size, algorithm,
                                               MIN_GROOVE_AREA if anatomical else None)
            problem = flat_tetrahedra(mean_ratio(points, cells))  # quality.py would refuse it
        except _SmallGroove as small:
            attempt, prm = _redrawn(prm, seed, attempt, small.args[0], spread)
            continue
        except Exception as exc:  # gmsh raises a bare Exception with its last error
            problem = str(exc) or type(exc).__name__  # never empty: not a mesh
        if not problem:
            break
        failures.append(f"surface algorithm {algorithm}: {problem}")
        algorithm = next(algorithms, None)
        if algorithm is None:
            raise GeometryError(f"phantom {seed} ({variety}{widened}), mesh size "
                                f"{mesh_size} mm: gmsh could not mesh it: "
                                + "; ".join(failures))
    if anatomical:
        _log_redrawn(seed, attempt, area)
    if failures:
        log.info("phantom %d (%s): meshed with surface algorithm %d after %s", seed, variety,
                 algorithm, "; ".join(failures))
    tri = boundary_triangles(cells, points)
    surf = np.unique(tri)
    axis_dist = np.hypot(points[surf, 0] - scale * prm.cava_x,
                         points[surf, 1] - scale * prm.cava_y)
    cava = surf[axis_dist <= scale * prm.cava_radius + 0.05 * mesh_size]
    return Geometry(points=points, cells=cells, surface_triangles=tri,
                    regions={"vena_cava": cava},
                    description=f"liver phantom seed {seed} ({variety}{widened}), mesh "
                                f"size {mesh_size} mm, parameters {asdict(prm)}")


# Surface algorithms tried in turn: Frontal-Delaunay first (every phantom that meshes with it
# keeps that mesh), then Delaunay and MeshAdapt. A thin wedge where two cuts meet can give the
# first a surface mesh that crosses itself (gmsh: "PLC Error: A segment and a facet
# intersect"); about 2 % of the anatomical population at 16 mm. Rarer, it gives a volume mesh
# with a flat tetrahedron (anatomical phantom 1150 at 16 mm, with the first two algorithms),
# which the solver would refuse: the next algorithm is tried then too.
SURFACE_ALGORITHMS = (6, 5, 1)


def _mesh(prm, seed: int, mesh_size: float, algorithm: int, min_groove: float | None = None):
    """Build phantom ``prm`` in a fresh gmsh model and mesh it with surface algorithm
    ``algorithm``: (points, cells, the scale applied to reach its volume, the groove's area in
    mm^2). ``min_groove``: :class:`_SmallGroove` before any meshing when the groove is
    smaller (None: not measured, area None).
    """
    import gmsh

    gmsh.initialize([], readConfigFiles=False)
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.option.setNumber("General.NumThreads", 1)  # reproducible meshes
        gmsh.model.add(f"phantom_{seed}")
        body, scale = _solid(prm)
        area = None
        if min_groove is not None:
            area = _groove(body) * scale ** 2
            if area < min_groove:
                raise _SmallGroove(area)
        if scale != 1.0:
            gmsh.model.occ.dilate(body, 0, 0, 0, scale, scale, scale)
            gmsh.model.occ.synchronize()
        vols = gmsh.model.getEntities(3)
        if len(vols) != 1:
            raise RuntimeError(f"phantom {seed}: expected one volume, got {len(vols)}")
        gmsh.option.setNumber("Mesh.MeshSizeMin", 0.5 * mesh_size)
        gmsh.option.setNumber("Mesh.MeshSizeMax", mesh_size)
        gmsh.option.setNumber("Mesh.MeshSizeFromCurvature", 0)
        gmsh.option.setNumber("Mesh.Algorithm3D", 1)
        gmsh.option.setNumber("Mesh.Optimize", 1)
        gmsh.option.setNumber("Mesh.Algorithm", algorithm)
        gmsh.model.mesh.generate(3)
        if 4 not in gmsh.model.mesh.getElements(3)[0]:  # no error, and no tetrahedron
            raise RuntimeError("no tetrahedra")
        points, cells = gmsh_tetrahedra()
        gmsh.model.remove()
    finally:
        gmsh.finalize()
    return points, cells, scale, area


def _solid(prm):
    """Build phantom ``prm``'s solid before its volume scaling (synchronised): (its volume
    entities, the scale that brings it to ``prm.volume``, 1 without one).
    """
    import gmsh

    occ = gmsh.model.occ
    if prm.dome_height is None:
        right = occ.addSphere(0, 0, 0, 1.0)
        occ.dilate([(3, right)], 0, 0, 0, *prm.right_axes)
    else:  # the dome above the equator, its own curvature; the same lobe below it
        right = _half_ellipsoids(occ, prm.right_axes, prm.dome_height)
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
    if prm.bevel is not None:
        # the sharp anterior-inferior edge: remove what lies below a plane rising toward
        # the front from the visceral cut's height at y = -bevel position
        tilt, y_edge = prm.bevel
        bev = occ.addBox(-L / 2, -L / 2, -L, L, L, L)
        occ.rotate([(3, bev)], 0, 0, 0, 1, 0, 0, -tilt)
        occ.translate([(3, bev)], 0, -y_edge, -prm.cut_height)
        body, _ = occ.cut(body, [(3, bev)])
    if prm.riedel is not None:
        cx, cy, cz, a, b, c = prm.riedel
        tongue = occ.addSphere(cx, cy, cz, 1.0)
        occ.dilate([(3, tongue)], cx, cy, cz, a, b, c)
        body, _ = occ.fuse(body, [(3, tongue)])
    cava = occ.addCylinder(prm.cava_x, prm.cava_y, -L / 2, 0, 0, L, prm.cava_radius)
    body, _ = occ.cut(body, [(3, cava)])
    occ.synchronize()
    scale = 1.0
    if prm.volume is not None:
        scale = (prm.volume / sum(occ.getMass(d, t) for d, t in body)) ** (1.0 / 3.0)
    return body, scale


def groove_area(prm: PhantomParameters) -> float:
    """Area (mm^2) of phantom ``prm``'s vena-cava groove, its fixed region: the faces the
    cava's cylinder leaves on the solid, at the solid's final size. Needs gmsh; no meshing.
    """
    import gmsh

    gmsh.initialize([], readConfigFiles=False)
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.model.add("groove")
        body, scale = _solid(prm)
        area = _groove(body)
    finally:
        gmsh.finalize()
    return area * scale ** 2


def _groove(body) -> float:
    """Area of the faces the cava's cylinder leaves on the solid ``body`` in the current gmsh
    model, before its volume scaling (the scaling turns every face into a B-spline).
    """
    import gmsh

    faces = gmsh.model.getBoundary(body, oriented=False)
    return sum(gmsh.model.occ.getMass(2, t) for _, t in faces
               if gmsh.model.getType(2, t) == "Cylinder")


def _half_ellipsoids(occ, axes, dome: float) -> int:
    """A lobe whose upper half has semi-axis ``dome`` in z and lower half ``axes[2]`` (both
    with the same equator, so the surface is smooth across it).
    """
    L = 400.0
    top = occ.addSphere(0, 0, 0, 1.0)
    occ.dilate([(3, top)], 0, 0, 0, axes[0], axes[1], dome)
    below = occ.addBox(-L / 2, -L / 2, -L, L, L, L)
    top_half, _ = occ.cut([(3, top)], [(3, below)])
    bottom = occ.addSphere(0, 0, 0, 1.0)
    occ.dilate([(3, bottom)], 0, 0, 0, *axes)
    above = occ.addBox(-L / 2, -L / 2, 0, L, L, L)
    bottom_half, _ = occ.cut([(3, bottom)], [(3, above)])
    lobe, _ = occ.fuse(top_half, bottom_half)
    return lobe[0][1]
