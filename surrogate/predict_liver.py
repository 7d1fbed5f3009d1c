"""A liver the model has never seen: place it in the training population and predict on it.

    python -m surrogate predict-liver RUN LIVER --force X Y Z FX FY FZ [--out DIR]
    python -m surrogate predict-liver RUN LIVER          # the manipulator opens on it

A model trained on a population of livers (a scene that varies the geometry) carries its
shape model (``RUN/model/shape_model.npz``: template mesh, PCA basis, registration settings;
:mod:`liverreg.shape_model`). Here the liver is mapped into the population's frame (its frame
named by ``--frame``, LPS by default, or the best rigid fit, turns and mirror images included:
:mod:`liverreg.rigid`), the template is registered onto it with the same staged CPD as in
training (:mod:`liverreg.cpd`, the code the solver used), its shape
coefficients come from the same PCA, and the network predicts on the registered template: the
new liver's shape with the template's mesh, nodes and fixed region. A force is placed at the
surface node of the registered template nearest to the point given.

Warnings, with their numbers, when the liver lies outside the population (registration
residual, shape coefficients outside the population's range) or a load acts where the scene
never loaded (interior, fixed, or too near the fixed region). Output: the deformed liver as a
``.vtu`` (ParaView: the point data ``displacement``; "Warp By Vector" shows the deformed
shape), a JSON with the placement and warnings, and a picture.

The same as a Python API: :func:`read_liver_surface`, :func:`place_liver`,
:func:`predict_liver`, :func:`predict_at_points` (at the nodes of the liver's own mesh) and
:class:`PlacedModel` (the same, placed once for repeated calls: real time on the liver's mesh).
numpy, scipy and pyvista (to read surfaces); no dolfinx.
"""

from __future__ import annotations

import json
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from liverreg.morph import interpolation_matrix
from surrogate.predictor import check_load_nodes

SURFACE_SUFFIXES = (".vtk", ".vtp", ".vtu", ".stl", ".obj", ".ply", ".h5")


class LiverFileError(ValueError):
    """A liver file that cannot be used; the message names the file and what was expected."""


def read_liver_surface(path, scale_to_mm: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """(points (p, 3) mm, triangles (t, 3)): the boundary of a liver file.

    Surfaces (``.vtk``/``.vtp``/``.stl``/``.obj``/``.ply``) and volume meshes (``.vtu``, a
    legacy ``.vtk`` unstructured grid, a data_spec geometry ``.h5``). Polygons are split into
    triangles, duplicate points merged, and only the largest connected piece is kept (small
    loose specks are common in exported surfaces).
    """
    path = Path(path)
    if not path.exists():
        raise LiverFileError(f"{path}: no such file")
    suffix = path.suffix.lower()
    if suffix not in SURFACE_SUFFIXES:
        raise LiverFileError(f"{path}: unknown liver file type {suffix!r}; expected one of "
                             f"{', '.join(SURFACE_SUFFIXES)}")
    if not np.isfinite(scale_to_mm) or scale_to_mm <= 0:
        raise LiverFileError(f"scale_to_mm: expected a number > 0, got {scale_to_mm}")
    if suffix == ".h5":
        from data_spec import read_geometry

        try:
            g = read_geometry(path)
        except (OSError, KeyError, ValueError) as exc:
            raise LiverFileError(f"{path}: not a data_spec geometry ({exc})") from None
        return _checked(path, g.points * scale_to_mm, g.surface_triangles)
    from liverviz.pictures import pyvista

    pv = pyvista()
    try:
        mesh = pv.read(str(path))
    except Exception as exc:  # VTK's readers raise many kinds
        raise LiverFileError(f"{path}: cannot be read ({type(exc).__name__}: {exc})") from None
    if mesh.n_points == 0 or mesh.n_cells == 0:
        raise LiverFileError(f"{path}: no points or cells")
    surf = mesh.extract_surface(algorithm="dataset_surface").triangulate().clean()
    if surf.n_cells == 0:
        raise LiverFileError(f"{path}: no surface triangles")
    surf = _largest_body(path, surf, scale_to_mm).extract_surface(algorithm="dataset_surface")
    surf = surf.triangulate().clean()
    faces = np.asarray(surf.faces).reshape(-1, 4)
    if faces.size == 0 or not np.all(faces[:, 0] == 3):
        raise LiverFileError(f"{path}: expected a triangulated surface")
    return _checked(path, np.asarray(surf.points, dtype=np.float64) * scale_to_mm, faces[:, 1:])


def _largest_body(path, surf, scale_to_mm: float):
    """The connected body of ``surf`` enclosing the most volume; LiverFileError naming both
    volumes when another is more than a speck, as fem_sim mesh refuses it
    (:func:`data_spec.liver_shape.pieces_problem`).
    """
    from data_spec.liver_shape import pieces_problem

    bodies = [b.extract_surface(algorithm="dataset_surface") for b in surf.split_bodies()]
    ml = [abs(b.volume) * scale_to_mm**3 / 1e3 for b in bodies]
    order = np.argsort(ml)[::-1]
    why = pieces_problem(str(path), [ml[i] for i in order], "fem_sim mesh FILE --mesh-size "
                         "16 --keep-largest --out LIVER.h5, then predict-liver on LIVER.h5")
    if why:
        raise LiverFileError(why)
    return bodies[order[0]]


def _checked(path, points, triangles):
    if not np.all(np.isfinite(points)):
        raise LiverFileError(f"{path}: points contain NaN or inf")
    if triangles.shape[0] < 100:
        raise LiverFileError(f"{path}: {triangles.shape[0]} surface triangles; a liver "
                             "surface needs many more (at least 100)")
    from data_spec.units import span_problem

    why = span_problem(float(np.ptp(points, axis=0).max()), str(path))
    if why:
        raise LiverFileError(why)
    return points, np.asarray(triangles, dtype=np.int64)


@dataclass
class LiverPrediction:
    """A prediction on a new liver: the registered template and its displacement."""

    points: np.ndarray          # (n, 3) registered template nodes, mm, in the liver's frame
    cells: np.ndarray           # (c, 4) template tetrahedra
    triangles: np.ndarray       # (t, 3) boundary
    fixed_nodes: np.ndarray
    displacement: np.ndarray    # (n, 3) mm
    load_nodes: np.ndarray      # (n_loads,)
    forces: np.ndarray          # (n_loads, 3) N
    coefficients: np.ndarray    # the liver's shape coefficients
    shape_told: np.ndarray      # the shape the network was told (ShapeModel.shape_told)
    shape_rule: str
    residual: float
    offset: np.ndarray          # (3,) and rotation (3, 3): the liver's map into the
    rotation: np.ndarray        # population's frame, x_population = rotation @ x + offset
    frame: str = "as given"     # how the liver was turned into the population's frame
    inverted: int = 0           # template tetrahedra the placement turned inside out
    warnings: list = field(default_factory=list)
    # a grasp (predict-liver --grasp): each tool's displacement, mm; forces are then its force
    tool_displacements: np.ndarray | None = None

    def write_vtu(self, path) -> Path:
        """The liver as a ParaView file: tetrahedra, point data displacement and |u|."""
        from liverviz.pictures import pyvista

        pv = pyvista()
        cells = np.hstack([np.full((self.cells.shape[0], 1), 4), self.cells]).ravel()
        grid = pv.UnstructuredGrid(cells, np.full(self.cells.shape[0], 10, np.uint8),
                                   self.points)
        grid.point_data["displacement"] = self.displacement
        grid.point_data["displacement_magnitude"] = np.linalg.norm(self.displacement, axis=1)
        fixed = np.zeros(self.points.shape[0], np.uint8)
        fixed[self.fixed_nodes] = 1
        grid.point_data["fixed"] = fixed
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        grid.save(str(path))
        return path

    def draw(self, png, title: str = "") -> Path:
        from liverviz.pictures import Panel, Surface, render_panels

        s = Surface.from_mesh(self.points, self.triangles, self.fixed_nodes)
        umax = np.linalg.norm(self.displacement, axis=1).max()
        panel = Panel(surface=s, u=self.displacement[s.nodes], forces=self.forces,
                      load_nodes=self.load_nodes, f_ref=float(np.linalg.norm(
                          self.forces, axis=1).max() or 1.0),
                      label=f"predicted, max displacement {umax:.1f} mm")
        return render_panels([panel], png, title=title)


def place_liver(predictor, points, triangles, center: bool = True,
                frame: str | None = None):
    """(placement, warnings): the template registered onto the liver surface, with the
    reasons (numbers included) it lies outside the training population. The liver is first
    mapped into the population's frame: ``frame`` names its frame (``LPS``, the default:
    DICOM, ITK; ``RAS``: NIfTI, Slicer; ``population``: x toward the right lobe, y posterior,
    z up), or ``auto`` takes the best rigid fit (turns and mirror images) onto the
    population's mean liver, which may turn a liver unlike the population's away from its
    anatomy.
    ``center=False``: as given, for a liver already in the population's frame and place (one
    the solver's population pipeline made).
    """
    sm = predictor.shape_model
    if sm is None:
        raise ValueError(_no_population(predictor))
    placement = sm.place(points, triangles, center=center, frame=frame)
    return placement, sm.warnings(placement)


def shape_rule(predictor) -> str:
    """The rule that tells the predictor's design a shape for a liver outside its population
    (the design's ``shape_rule``, :data:`surrogate.designs.DESIGNS`).
    """
    from surrogate.designs import DESIGNS

    return getattr(DESIGNS.get(predictor.design), "shape_rule", "own")


def told_shape(predictor, coefficients, shape: str | None = None) -> tuple[np.ndarray, str]:
    """(coefficients, rule applied): the shape the predictor's network is told for a liver
    with these shape coefficients, by the rule ``shape`` or (None) the design's
    (:meth:`liverreg.shape_model.ShapeModel.shape_told`, :func:`shape_rule`).
    """
    return predictor.shape_model.shape_told(coefficients, shape or shape_rule(predictor))


def told_note(rule: str) -> str:
    """What the command and the manipulator say when a liver is told a shape not its own."""
    return (f"the liver lies beyond the population: the network is told a shape inside it "
            f"(--shape {rule}, docs/shape_rule.md; --shape own: its own)")


def _no_population(predictor) -> str:
    if not predictor.spec.geometry_dim:
        return ("this model was trained on one liver (its scene does not vary the geometry): "
                "it cannot place a new liver; train on a population scene (scene 4)")
    return ("this model carries no shape model (RUN/model/shape_model.npz): it was exported "
            "without its population; train it again on a dataset with geometry/population.npz")


def nearest_surface_nodes(points, triangles, at) -> np.ndarray:
    """For each point of ``at`` (k, 3), the nearest node of the surface."""
    from scipy.spatial import cKDTree

    surf = np.unique(triangles)
    return surf[cKDTree(points[surf]).query(np.asarray(at, dtype=np.float64))[1]]


def predict_liver(predictor, points, triangles, forces, at=None, load_nodes=None,
                  placement=None, center: bool = True, frame: str | None = None,
                  shape: str | None = None) -> LiverPrediction:
    """Place the liver (points, triangles: its surface; :func:`place_liver`) and predict the
    displacement under ``forces`` (n_loads, 3) N acting at the template nodes nearest to
    ``at`` (n_loads, 3) mm, or at template node ids ``load_nodes``. Points, forces and the
    result are in the liver's frame (the file's). ``shape``: the shape the network is told for
    a liver outside the population (:meth:`liverreg.shape_model.ShapeModel.shape_told`:
    ``own``, ``range``, ``radius``, ``hull`` or ``outside``; None: the design's,
    :func:`shape_rule`).
    """
    sm = predictor.shape_model
    if sm is None:
        raise ValueError(_no_population(predictor))
    found = []
    if placement is None:
        placement, found = place_liver(predictor, points, triangles, center, frame)
    forces = np.asarray(forces, dtype=np.float64).reshape(-1, 3)
    if (at is None) == (load_nodes is None):
        raise ValueError("give either at (points, mm) or load_nodes (template node ids)")
    if at is not None:  # points in the liver's frame; the placement is in the population's
        at = placement.to_population(np.asarray(at, dtype=np.float64).reshape(-1, 3))
        load_nodes = nearest_surface_nodes(placement.points, sm.surface_triangles, at)
    load_nodes = np.asarray(load_nodes, dtype=np.int64).ravel()
    if load_nodes.size != forces.shape[0]:
        raise ValueError(f"{forces.shape[0]} force(s) for {load_nodes.size} load node(s)")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        if sm.loadable_nodes.size:  # the exported model's own check, on the template's nodes
            check_load_nodes(load_nodes, sm.loadable_nodes)
        told, rule = told_shape(predictor, placement.coefficients, shape)
        u = predictor(placement.vectors_to_population(forces), load_nodes,
                      geometry=(placement.points, sm.fixed_nodes, told))
    found += [str(w.message) for w in caught if "shape coefficients" not in str(w.message)]
    for msg in found:
        warnings.warn(msg, stacklevel=2)
    return LiverPrediction(points=placement.to_liver(placement.points),
                           cells=placement.oriented(sm.template_cells),
                           triangles=placement.oriented(sm.surface_triangles),
                           fixed_nodes=sm.fixed_nodes,
                           displacement=placement.vectors_to_liver(u), load_nodes=load_nodes,
                           forces=forces, coefficients=placement.coefficients,
                           shape_told=told, shape_rule=rule, residual=placement.residual,
                           offset=placement.offset,
                           rotation=placement.rotation, frame=placement.frame,
                           inverted=placement.inverted, warnings=found)


class PlacedModel:
    """A population model placed on one liver, for repeated calls at the nodes of the liver's
    own mesh: the real-time form of :func:`predict_at_points`.

    Built once per liver: the placement (:func:`place_liver`, or one given), the shape the
    network is told (:func:`told_shape`) and the sparse interpolation from the registered
    template to ``nodes`` (the liver's mesh nodes, its frame; default: the surface points).
    A call then costs the network on the template, one sparse product and a turn into the
    liver's frame, whatever the number of nodes.

        placed = PlacedModel(load_predictor("RUN/model"), points, triangles, nodes=mesh_nodes)
        at = placed.load_nodes([[120.0, 100.0, 190.0]])      # once per grasped point
        u = placed([[0.0, 0.0, -0.4]], at)                    # (n_nodes, 3) mm, every frame
    """

    def __init__(self, predictor, points=None, triangles=None, nodes=None, *,
                 placement=None, center: bool = True, frame: str | None = None,
                 shape: str | None = None):
        sm = predictor.shape_model
        if sm is None:
            raise ValueError(_no_population(predictor))
        self.warnings: list[str] = []
        if placement is None:
            if points is None or triangles is None:
                raise ValueError("give the liver's surface (points, triangles) or a placement")
            placement, self.warnings = place_liver(predictor, points, triangles, center, frame)
        if nodes is None:
            if points is None:
                raise ValueError("nodes: give the points to predict at (a placement alone "
                                 "does not carry the liver's mesh)")
            nodes = points
        nodes = np.asarray(nodes, dtype=np.float64)
        if nodes.ndim != 2 or nodes.shape[1] != 3 or not np.all(np.isfinite(nodes)):
            raise ValueError(f"nodes: expected a finite (n, 3) array in mm, got shape "
                             f"{nodes.shape}")
        self.predictor, self.placement, self.nodes = predictor, placement, nodes
        self.shape_told, self.shape_rule = told_shape(predictor, placement.coefficients, shape)
        self.geometry = (placement.points, sm.fixed_nodes, self.shape_told)
        self.interpolation = interpolation_matrix(placement.points,
                                                  placement.to_population(nodes)).tocsr()

    def load_nodes(self, at) -> np.ndarray:
        """Template node ids under the points ``at`` (..., 3) mm of the liver's frame: the
        registered template's surface nodes nearest to them (what a call takes).
        """
        at = np.asarray(at, dtype=np.float64)
        flat = self.placement.to_population(at.reshape(-1, 3))
        ids = nearest_surface_nodes(self.placement.points,
                                    self.predictor.shape_model.surface_triangles, flat)
        return ids.reshape(at.shape[:-1])

    def __call__(self, forces, load_nodes, rest: bool = False) -> np.ndarray:
        """Displacements (n_nodes, 3), or (n_cases, n_nodes, 3) for forces (n_cases, n_loads,
        3), mm in the liver's frame, for ``forces`` N (the liver's frame) at the template node
        ids ``load_nodes`` (:meth:`load_nodes`); ``rest``: of a model of what the liver's
        small-strain base misses (the predictor's ``rest``).
        """
        f = self.placement.vectors_to_population(forces)
        u = np.asarray(self.predictor(f, np.asarray(load_nodes), geometry=self.geometry,
                                      rest=rest), dtype=np.float64)
        single = u.ndim == 2
        u = u[None] if single else u
        n_cases, n_t = u.shape[:2]
        out = self.interpolation @ u.transpose(1, 0, 2).reshape(n_t, -1)  # all cases at once
        out = self.placement.vectors_to_liver(
            out.reshape(-1, n_cases, 3).transpose(1, 0, 2))
        return out[0] if single else out


def predict_at_points(predictor, placement, points, forces, at,
                      shape: str | None = None) -> np.ndarray:
    """Displacements (n_cases, len(points), 3) mm at ``points`` of the placed liver (e.g. the
    nodes of its own mesh; the liver's frame) for ``forces`` (n_cases, n_loads, 3) N acting at
    the template surface nodes nearest to ``at`` (n_cases, n_loads, 3) mm, all in the liver's
    frame: the registered template's prediction, interpolated (:class:`PlacedModel`, which
    keeps the interpolation for repeated calls). ``shape`` as :func:`predict_liver`'s.
    """
    placed = PlacedModel(predictor, nodes=points, placement=placement, shape=shape)
    forces = np.asarray(forces, dtype=np.float64)
    return placed(forces, placed.load_nodes(np.broadcast_to(at, forces.shape)))


# A force's point farther than this from the liver's surface is said (the force acts at the
# nearest surface node); farther than REFUSE_MM it is refused: not a point on this liver.
WARN_MM = 5.0
REFUSE_MM = 30.0


def surface_distances(points, triangles, at) -> np.ndarray:
    """(k,) mm from each point of ``at`` to the nearest vertex of the surface."""
    from scipy.spatial import cKDTree

    surf = np.unique(triangles)
    return cKDTree(points[surf]).query(np.asarray(at, dtype=np.float64))[0]


def _force_points(spec: np.ndarray, points, triangles, file,
                  flag: str = "--force") -> tuple[list[str], str | None]:
    """(warnings, the reason to refuse or None) for the load points (``flag``'s: --force or
    --grasp) against the liver's own surface, before any registration.
    """
    d = surface_distances(points, triangles, spec[:, :3])

    def said(i: int) -> str:
        return (f"{flag} {i + 1}: the point {spec[i, :3].tolist()} is {d[i]:.1f} mm from the "
                f"surface of {file}")

    if np.any(d > REFUSE_MM):
        i = int(np.argmax(d))
        return [], (f"{said(i)}: more than {REFUSE_MM:g} mm, not a point of this liver (give a "
                    "point on its surface, in mm in the file's frame)")
    acts = "the tool grasps around" if flag == "--grasp" else "the force acts at"
    return [f"{said(i)} (more than {WARN_MM:g} mm): {acts} the nearest surface node"
            for i in np.flatnonzero(d > WARN_MM)], None


def _summary(args, predictor, pred, asked) -> dict:
    """prediction.json's content."""
    sm = predictor.shape_model
    used = pred.points[pred.load_nodes]
    return {"liver": str(args.liver), "model": str(args.run),
            "registration_residual_mm": pred.residual,
            "inverted_template_tetrahedra": pred.inverted,
            "into_population_frame": {"rotation": pred.rotation.tolist(),
                                      "offset_mm": pred.offset.tolist(),
                                      "mirrored": bool(np.linalg.det(pred.rotation) < 0),
                                      "how": pred.frame},
            "population_residual_mm": {"median": float(np.median(sm.residuals)),
                                       "max": float(sm.residuals.max())},
            "shape_coefficients": pred.coefficients.tolist(),
            "shape_rule": pred.shape_rule, "shape_told": pred.shape_told.tolist(),
            "load_nodes": pred.load_nodes.tolist(), "forces_N": pred.forces.tolist(),
            # where each force was asked for and where it acts (liver frame, mm)
            "force_points_asked_mm": asked.tolist(), "force_points_used_mm": used.tolist(),
            "force_point_moved_mm": np.linalg.norm(used - asked, axis=1).tolist(),
            "max_displacement_mm": float(np.linalg.norm(pred.displacement, axis=1).max()),
            "warnings": pred.warnings} | ({} if pred.tool_displacements is None else {
                # a grasp: forces_N are each tool's force on the liver
                "grasp_displacements_mm": pred.tool_displacements.tolist(),
                "grasp": "the small-strain base over the liver's Green's function " + (
                    "alone" if predictor.load != "grasp" else "and the network's rest (the "
                    "force the base's" + ("" if predictor.grasp_force is None else
                                          " stiffened as the model learned it") + ")")})


def _checked_request(args, fail):
    """(predictor, forces spec (L, 6), surface points, triangles, warnings) or an exit code:
    every argument checked before the registration runs.
    """
    import sys

    from data_spec.atomic import out_problem
    from data_spec.scene import GRASP_TOOLS
    from surrogate.predictor import load_predictor, model_load

    why = out_problem(args.out, "--out", directory=True)   # nothing created for --out
    if why:
        return fail(why)
    grasp = getattr(args, "grasp", None)
    try:   # a grasp: a model of grasps adds its rest, a model of forces gives the base alone
        model = Path(args.run) / "model"
        predictor = load_predictor(model, load=model_load(model) if grasp else "nodal")
    except (OSError, ValueError) as exc:
        return fail(exc)
    if predictor.shape_model is None:
        return fail(f"{args.run}: {_no_population(predictor)}")
    if not (predictor.base.whole or args.base):
        return fail(f"{args.run}: {predictor.base.rest_only()}")
    L = predictor.spec.n_loads
    if grasp and (args.force or not args.base or len(grasp) > GRASP_TOOLS):
        return fail(f"--grasp: 1 to {GRASP_TOOLS} tools, with --base (the liver's Green's "
                    "function, make liver) and no --force")
    if grasp and predictor.load == "grasp" and len(grasp) != L:
        return fail(f"--grasp: the model learned {L} tool(s), got {len(grasp)}")
    if not grasp and len(args.force) != L:
        return fail(f"--force: the model takes {L} force(s), got {len(args.force)} (each "
                    "--force X Y Z FX FY FZ: a point near the liver surface in mm and a force "
                    "in N)")
    spec, flag = np.asarray(grasp or args.force, dtype=np.float64), \
        "--grasp" if grasp else "--force"
    if not np.all(np.isfinite(spec)):
        return fail(f"{flag}: contains NaN or inf")
    try:
        points, triangles = read_liver_surface(args.liver, args.scale_to_mm)
    except LiverFileError as exc:
        return fail(exc)
    said, refused = _force_points(spec, points, triangles, args.liver, flag)
    if refused:
        return fail(refused)
    from data_spec.liver_shape import surface_volume_ml, unlike_a_liver

    unlike = unlike_a_liver(points, surface_volume_ml(points, triangles), str(args.liver))
    said += [unlike] if unlike else []
    for msg in said:
        print(f"warning: {msg}", file=sys.stderr)
    return predictor, spec, points, triangles, said


def _say_grasp(predictor, pred) -> None:
    """Each tool's pull and force, and what part of them is the small-strain base alone."""
    import sys

    from surrogate import grasp

    base_field = predictor.load != "grasp"   # a model of forces: the base alone
    base_force = base_field or predictor.grasp_force is None
    for d, f in zip(pred.tool_displacements, pred.forces):
        print(f"grasp moved {np.linalg.norm(d):.1f} mm: the tool's force on the liver "
              f"{np.round(f, 3).tolist()} N ({np.linalg.norm(f):.3f} N; "
              + ("the small-strain base alone" if base_force else
                 "the base's stiffened as the model learned it")
              + ", docs/surgical_loads.md)")
        off = ([] if not base_force else ["its force is too low"]) + \
            ([] if not base_field else ["its field off by millimetres (a model of grasps "
                                        "corrects the field)"])
        if np.linalg.norm(d) > grasp.SMALL_PULL_MM and off:
            print(f"warning: a {np.linalg.norm(d):.0f} mm pull is beyond the small-strain "
                  "base's range: the Ogden liver stiffens, so " + " and ".join(off)
                  + " (docs/surgical_loads.md measures by how much)", file=sys.stderr)


def main(args, over=None) -> int:
    """The ``predict-liver`` subcommand (arguments parsed by surrogate.__main__); ``over``:
    the prediction over the liver's own base, ``over(predictor, forces, at)`` -> its
    :class:`LiverPrediction` (``--base``: :func:`surrogate.over_green.predict_over_green`).
    """
    import sys

    def fail(msg):
        print(f"liverfem-surrogate predict-liver: {msg}", file=sys.stderr)
        return 2

    checked = _checked_request(args, fail)
    if isinstance(checked, int):
        return checked
    predictor, spec, points, triangles, said = checked
    asked = spec[:, :3]
    if over is None or not args.placement:   # make liver's steps placed it already
        print(f"registering the template onto {args.liver} ({points.shape[0]:,} surface "
              "points)", file=sys.stderr, flush=True)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # reported below, once
        if over is not None:   # the liver's own mesh and Green's function (make liver)
            try:
                pred = over(predictor, spec[:, 3:], asked)
            except (OSError, ValueError) as exc:
                return fail(f"--base {args.base}: {exc}")
        else:
            pred = predict_liver(predictor, points, triangles, spec[:, 3:], at=asked,
                                 center=not args.no_center, frame=args.frame, shape=args.shape)
    pred.warnings = said + pred.warnings
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    vtu = pred.write_vtu(out / "liver_deformed.vtu")
    summary = _summary(args, predictor, pred, asked)
    (out / "prediction.json").write_text(json.dumps(summary, indent=1))
    for msg in pred.warnings[len(said):]:
        print(f"warning: {msg}", file=sys.stderr)
    if pred.shape_rule != "own":
        print(told_note(pred.shape_rule), file=sys.stderr)
    if not args.no_picture:
        png = pred.draw(out / "liver_deformed.png", title=Path(args.liver).name)
        print(f"picture: {png}", file=sys.stderr)
    if pred.tool_displacements is not None:
        _say_grasp(predictor, pred)
    print(f"placed as {pred.frame}; registration residual {pred.residual:.2f} mm, "
          f"{pred.inverted} of {pred.cells.shape[0]} template tetrahedra inverted; max "
          f"displacement {summary['max_displacement_mm']:.2f} mm; written {vtu} and "
          f"{out / 'prediction.json'}")
    return 0
