"""What a liver the population never contained needs to be placed in it: the template mesh,
the PCA of the population's template-surface displacements, the registration settings, and
the population's ranges (to say when a liver lies outside them).

``ShapeModel.place(points, triangles)`` maps the liver into the population's frame
(:mod:`liverreg.rigid`), registers the template onto its surface with the same staged CPD
and the same samples as the population was built with, moves every template node (the
interior by harmonic extension, :mod:`liverreg.morph`) and projects the template surface's
displacement on the components: the liver's shape coefficients. Stored as a plain
``.npz`` (no pickle) next to an exported model.
"""

from __future__ import annotations

from dataclasses import dataclass, fields
from pathlib import Path

import numpy as np

from data_spec.geometry import region_area
from liverreg.cpd import STAGED, dense_surface, farthest_points, project, register
from liverreg.morph import SurfaceMorph
from liverreg.rigid import RigidFit, orient

FORMAT = 1
INVERTED_FLOOR = 0.01  # fraction of inverted template tetrahedra never worth a warning
AREA_MARGIN = 1.25  # a fixed region this many times beyond the population's range is warned
DEFAULT_FRAME = "LPS"  # the frame of DICOM and ITK, hence of most segmented livers


SHAPE_RULES = ("own", "range", "radius", "hull", "outside")


def template_fit(points, triangles, template_surface, frame: str) -> RigidFit:
    """The rigid map of a liver surface (points (p, 3) mm, triangles (t, 3)) into the
    population's frame, as a population of liver files turns each of its livers
    (:class:`fem_sim.geometry.file_population.Registrar`): every vertex of the surface fitted
    onto the template's surface nodes ``template_surface`` (:func:`liverreg.rigid.orient`
    from ``frame``, refined by rigid ICP; ``auto``: the best of every start).
    """
    verts = np.asarray(points, dtype=np.float64)[np.unique(triangles)]
    return orient(verts, np.asarray(template_surface, dtype=np.float64), frame, refine=True)


def landed_region(moved: np.ndarray, template_surface: np.ndarray, region: np.ndarray,
                  points: np.ndarray, surface: np.ndarray) -> np.ndarray:
    """The liver's ``surface`` nodes (ids into ``points``) whose nearest node of the moved
    template's ``template_surface`` (ids into ``moved``, the same frame) is in the template's
    ``region``: where a template region lands on a liver, as a file population fixes its
    livers and a liver it never saw is fixed for its truth and its base.
    """
    from scipy.spatial import cKDTree

    template_surface, surface = np.asarray(template_surface), np.asarray(surface)
    near = cKDTree(moved[template_surface]).query(points[surface])[1]
    return surface[np.isin(template_surface[near], region)]


def nearest_convex_combination(points: np.ndarray, x: np.ndarray) -> np.ndarray:
    """The point of the convex hull of ``points`` (R, K) nearest to ``x`` (K,): min |P^T w - x|
    over w >= 0, sum w = 1, solved as a non-negative least-squares problem whose extra row,
    weighted far above the data's scale, holds the sum to 1 (to about 1e-8 relative).
    """
    from scipy.optimize import nnls

    P = np.asarray(points, dtype=np.float64)
    x = np.asarray(x, dtype=np.float64)
    heavy = 1e4 * max(1.0, float(np.abs(P).max()), float(np.abs(x).max()))
    A = np.vstack([P.T, np.full((1, P.shape[0]), heavy)])
    w, _ = nnls(A, np.concatenate([x, [heavy]]), maxiter=50 * P.shape[0])
    return P.T @ (w / w.sum())


@dataclass
class Placement:
    """A liver placed in the population: the template moved onto it and its coefficients."""

    points: np.ndarray        # (n_template_nodes, 3) moved template, mm
    coefficients: np.ndarray  # (K,)
    residual: float           # symmetric mean distance, moved template surface <-> liver, mm
    iterations: list          # CPD iterations per stage
    offset: np.ndarray        # (3,) translation of the liver into the population's frame, mm
    inverted: int = 0         # template tetrahedra turned inside out by the placement
    rotation: np.ndarray = None  # (3, 3) orthogonal map into the population's frame (det -1:
    #                              a mirror image); x_population = rotation @ x + offset
    frame: str = "as given"   # how the liver was turned (liverreg.rigid.RigidFit.describe)
    surface: str | None = None  # the meshed liver it was registered on, as its placing
    #                             recorded it (None: the liver file's own surface)

    def __post_init__(self):
        if self.rotation is None:
            self.rotation = np.eye(3)

    @property
    def mirrored(self) -> bool:
        return bool(np.linalg.det(self.rotation) < 0)

    def to_population(self, x) -> np.ndarray:
        """Points (..., 3) of the liver's frame in the population's."""
        return np.asarray(x, dtype=np.float64) @ self.rotation.T + self.offset

    def to_liver(self, x) -> np.ndarray:
        """Points (..., 3) of the population's frame in the liver's."""
        return (np.asarray(x, dtype=np.float64) - self.offset) @ self.rotation

    def vectors_to_population(self, v) -> np.ndarray:
        """Forces or displacements (..., 3) of the liver's frame in the population's."""
        return np.asarray(v, dtype=np.float64) @ self.rotation.T

    def vectors_to_liver(self, v) -> np.ndarray:
        return np.asarray(v, dtype=np.float64) @ self.rotation

    def oriented(self, simplices) -> np.ndarray:
        """Template cells (c, 4) or boundary triangles (t, 3) as seen in the liver's frame: a
        mirror image turns them inside out, so two of their nodes swap.
        """
        simplices = np.asarray(simplices)
        return simplices[:, [0, 2, 1, *range(3, simplices.shape[1])]] if self.mirrored \
            else simplices


@dataclass
class ShapeModel:
    """A population's shape model: template, PCA, registration settings and ranges."""

    template_points: np.ndarray     # (n, 3) mm
    template_cells: np.ndarray      # (c, 4) tetrahedra
    surface_triangles: np.ndarray   # (t, 3) template boundary, node ids
    fixed_nodes: np.ndarray         # the template's fixed region, node ids
    mean: np.ndarray                # (3 s,) mean displacement of the surface nodes
    components: np.ndarray          # (K, 3 s) orthonormal rows
    coefficient_min: np.ndarray     # (K,) over the population
    coefficient_max: np.ndarray
    residuals: np.ndarray           # (R,) the population's registration residuals, mm
    n_points: int = 600             # CPD samples per surface
    schedule: np.ndarray = None     # (stages, 3): beta, lambda, tolerance
    loadable_nodes: np.ndarray = None  # template nodes the scene's loads act on (empty: any)
    population_inverted: np.ndarray = None  # (R,) template tetrahedra each liver inverted
    population_coefficients: np.ndarray = None  # (R, K) each liver's shape coefficients
    population_fixed_area: np.ndarray = None  # (R,) mm^2, the fixed region on each liver
    frame: str = ""  # the population's liver files' frame: a new liver's default ("": LPS)

    def __post_init__(self):
        if self.loadable_nodes is None:
            self.loadable_nodes = np.zeros(0, dtype=np.int64)
        if self.population_inverted is None:
            self.population_inverted = np.zeros(0, dtype=np.int64)
        if self.population_coefficients is None:  # a model exported before they were kept
            self.population_coefficients = np.zeros((0, self.components.shape[0]))
        if self.population_fixed_area is None:
            self.population_fixed_area = np.zeros(0)
        if self.schedule is None:
            self.schedule = np.asarray(STAGED, dtype=np.float64)
        self.schedule = np.asarray(self.schedule, dtype=np.float64).reshape(-1, 3)
        self.n_points = int(self.n_points)
        self.frame = str(self.frame)

    @property
    def surface_nodes(self) -> np.ndarray:
        return np.unique(self.surface_triangles)

    @property
    def n_components(self) -> int:
        return int(self.components.shape[0])

    def place(self, points: np.ndarray, triangles: np.ndarray, center: bool = True,
              frame: str | None = None) -> Placement:
        """Register the template onto the liver surface (points (p, 3) mm, triangles (t, 3)).

        The placement is in the population's frame: the liver is first mapped into it
        (:func:`liverreg.rigid.orient`; ``frame``: the liver's frame, ``LPS`` (DICOM, ITK),
        ``RAS`` or ``population``, refined by a rigid fit; None: the frame of the
        population's own liver files, LPS for a population of phantoms; or ``auto``: the best
        rigid fit onto the population's mean surface, which may turn a liver unlike the
        population's away from its anatomy). A liver of the population's own, meshed as the
        population meshed it (``liverfem-sim mesh``) and in its frame, is told its own
        coefficients: the same rigid fit (:func:`template_fit`), samples and registration.
        ``center=False``: as given, for livers already in that frame and place (those the
        solver's population pipeline made).
        """
        triangles = np.asarray(triangles, dtype=np.int64)
        points = np.asarray(points, dtype=np.float64)
        surf = self.surface_nodes
        S = self.template_points[surf]
        # Livers come in any scanner frame; the population's lie around one place, in one
        # orientation, and the PCA (of displacements) and the network's node coordinates both
        # see position: the liver is mapped onto the template first, as the population's were.
        if center:
            fit = self.rigid_fit(points, triangles, frame)
            rotation, offset, how = fit.Q, fit.t, fit.describe()
        else:
            rotation, offset, how = np.eye(3), np.zeros(3), "as given"
        points = points @ rotation.T + offset
        verts = points[np.unique(triangles)]
        # the samples of liverreg.cpd.surface_samples (farthest points, seed 0) and the
        # registration of liverreg.cpd.build_population
        reg = register(SurfaceMorph(self.template_points, self.template_cells, surf),
                       S[farthest_points(S, self.n_points)], self.surface_triangles,
                       verts[farthest_points(verts, self.n_points)],
                       dense_surface(points, triangles), [tuple(r) for r in self.schedule])
        coeff = project((reg.points[surf] - S).ravel(), self.mean, self.components)
        return Placement(points=reg.points, coefficients=coeff, residual=reg.residual,
                         iterations=reg.iterations, offset=offset, inverted=reg.inverted,
                         rotation=rotation, frame=how)

    def fixed_area(self, points) -> float:
        """Area (mm^2) of the template's fixed region with the template's nodes at ``points``
        ((n, 3): the template moved onto a liver, :attr:`Placement.points`).
        """
        return region_area(np.asarray(points, dtype=np.float64), self.surface_triangles,
                           self.fixed_nodes)

    def fixed_areas(self, surface_displacements) -> np.ndarray:
        """(R,) the fixed region's area on each liver whose template-surface displacement
        (3 s,) is a row of ``surface_displacements`` (the population's registration: mean +
        every component's coefficient).
        """
        surf, P = self.surface_nodes, self.template_points.copy()
        out = []
        for d in np.atleast_2d(surface_displacements):
            P[surf] = self.template_points[surf] + d.reshape(-1, 3)
            out.append(self.fixed_area(P))
        return np.asarray(out)

    def rigid_fit(self, points, triangles, frame: str | None = None) -> RigidFit:
        """The map of a liver surface into the population's frame: from a known frame, the
        population's own fit onto the template (:func:`template_fit`); ``auto`` (a frame not
        known), the best of every start onto the population's mean surface, the likeliest
        shape, whose single best fit does not depend on the file's frame (onto the template, a
        phantom, a liver turned in its file found another of the fits nearly as good).
        """
        frame = frame or self.frame or DEFAULT_FRAME
        if frame != "auto":
            return template_fit(points, triangles, self.template_points[self.surface_nodes],
                                frame)
        verts = np.asarray(points, dtype=np.float64)[np.unique(triangles)]
        mean_surface = self.template_points[self.surface_nodes] + self.mean.reshape(-1, 3)
        return orient(verts[farthest_points(verts, self.n_points)],
                      mean_surface[farthest_points(mean_surface, self.n_points)], "auto")

    def outside_range(self, coefficients) -> np.ndarray:
        """Indices of shape coefficients outside the population's range (by more than 5 % of
        it, as the predictor's other inputs).
        """
        c, lo, hi = np.asarray(coefficients), self.coefficient_min, self.coefficient_max
        margin = 0.05 * (hi - lo)
        return np.flatnonzero((c < lo - margin) | (c > hi + margin))

    def shape_told(self, coefficients, rule: str = "hull") -> tuple[np.ndarray, str]:
        """(coefficients, rule applied): the shape a network is told for a liver with these
        coefficients. A network answers shapes unlike its training livers' by extrapolating;
        for a liver outside the population each rule but ``own`` tells it a shape inside
        instead (the template is still registered onto the liver itself: only the network's
        shape input changes). A liver inside is told its own shape by every rule.

        * ``own``: the liver's coefficients;
        * ``range``: each coefficient clipped to the population's range;
        * ``radius``: beyond the population's largest Mahalanobis radius (coefficients over
          the population's standard deviations), scaled toward the mean shape onto it;
        * ``hull``: beyond that radius, the nearest convex combination of the population's
          livers (nearest in the same whitened metric): a shape between livers it saw;
        * ``outside``: the nearest convex combination for a liver beyond that radius *or* with
          a coefficient beyond the population's range (:meth:`outside_range`, the warning's
          margin): every liver the coefficient warnings name.

        The rule applied is ``own`` when the rule changed nothing. A model exported without
        its population's coefficients (older files) knows only the ranges: ``radius`` and
        ``hull`` (and ``outside``) fall back to ``range``.
        """
        c = np.asarray(coefficients, dtype=np.float64)
        if rule not in SHAPE_RULES:
            raise ValueError(f"shape rule {rule!r}: expected one of {', '.join(SHAPE_RULES)}")
        C = self.population_coefficients
        if rule in ("radius", "hull", "outside") and C.shape[0] < 2:
            rule = "range"
        if rule == "range":
            told = np.clip(c, self.coefficient_min, self.coefficient_max)
            return (told, "range") if np.any(told != c) else (c, "own")
        if rule == "own":
            return c, rule
        std = self._spread()
        r, r_max = np.linalg.norm(c / std), np.linalg.norm(C / std, axis=1).max()
        if rule == "outside":
            beyond = r > r_max or self.outside_range(c).size > 0
            return (self.nearest_mix(c), rule) if beyond else (c, "own")
        if r <= r_max:
            return c, "own"
        if rule == "radius":
            return c * (r_max / r), rule
        return self.nearest_mix(c), rule

    def nearest_mix(self, coefficients) -> np.ndarray:
        """The nearest convex combination of the population's livers' coefficients, nearest in
        the whitened metric (coefficients over the population's standard deviations).
        """
        std = self._spread()
        C = self.population_coefficients
        return nearest_convex_combination(C / std, np.asarray(coefficients, float) / std) * std

    def _spread(self) -> np.ndarray:
        """The population's standard deviation per coefficient (1 where it does not vary)."""
        std = self.population_coefficients.std(axis=0)
        return np.where(std > 0, std, 1.0)

    def warnings(self, placement: Placement) -> list[str]:
        """Ways the liver lies outside the population, with the numbers (empty: inside)."""
        out = []
        worst = float(self.residuals.max()) if self.residuals.size else np.inf
        if placement.residual > 1.5 * worst:
            out.append(f"registration residual {placement.residual:.2f} mm, the population's "
                       f"livers {np.median(self.residuals):.2f} mm median, {worst:.2f} mm at "
                       "worst: the template does not fit this liver's shape well")
        n_cells = self.template_cells.shape[0]
        # A surface registration flips some flat tetrahedra along the surface of any liver
        # unlike the template, the population's own included; more than the population's
        # worst means a placement folded further than any training liver's.
        worst_inverted = max(INVERTED_FLOOR * n_cells, 1.5 * self.population_inverted.max(
            initial=0))
        if placement.inverted > worst_inverted:
            out.append(f"{placement.inverted} of {n_cells} template tetrahedra "
                       f"({100 * placement.inverted / n_cells:.0f} %) turned inside out by the "
                       "registration: the liver is far from the population's shapes and the "
                       "prediction inside it is unreliable")
        c, lo, hi = placement.coefficients, self.coefficient_min, self.coefficient_max
        bad = self.outside_range(c)
        if bad.size:
            listed = ", ".join(f"shape{i} = {c[i]:.3g} (population {lo[i]:.3g} .. {hi[i]:.3g})"
                               for i in bad[:5])
            out.append(f"{bad.size} of {c.size} shape coefficients outside the population's "
                       f"range: {listed}{' ...' if bad.size > 5 else ''}")
        # The fixed region is where the template's lands on the liver; a patch wider than any
        # training liver's holds the liver stiffer than the network ever saw (and a narrower one
        # softer): the prediction's size is then extrapolated, however good its shape.
        A = self.population_fixed_area
        if A.size:
            a = self.fixed_area(placement.points)
            if not A.min() / AREA_MARGIN <= a <= AREA_MARGIN * A.max():
                out.append(f"the fixed region covers {a:.0f} mm^2 of this liver, "
                           f"{self.fixed_area(self.template_points):.0f} mm^2 of the template "
                           f"and {A.min():.0f} .. {A.max():.0f} mm^2 of the population's "
                           "livers: the liver is held over a patch no training liver had, and "
                           "the size of its predicted displacement is extrapolated")
        return out

    def save(self, path) -> None:
        arrays = {f.name: np.asarray(getattr(self, f.name)) for f in fields(self)}
        with open(path, "wb") as fh:  # a file object: np.savez appends no ".npz"
            np.savez(fh, format=np.asarray(FORMAT), **arrays)

    @classmethod
    def load(cls, path) -> ShapeModel:
        path = Path(path)
        try:
            with np.load(path, allow_pickle=False) as z:
                if int(z["format"]) != FORMAT:
                    raise ValueError(f"format {int(z['format'])}, this code reads {FORMAT}")
                # fields a newer code added (defaults None) may be absent from older files
                kw = {f.name: z[f.name] for f in fields(cls)
                      if f.name in z.files or f.default is not None}
        except (OSError, KeyError, ValueError) as exc:
            raise ValueError(f"{path}: not a readable shape model ({exc})") from None
        kw["n_points"] = int(kw["n_points"])
        if "frame" in kw:
            kw["frame"] = str(kw["frame"])
        return cls(**kw)

