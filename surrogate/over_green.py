"""A new liver's whole field in seconds: the population model of what each liver's linear
response misses (config ``population_green``: the base ``linear`` of
:mod:`surrogate.small_strain`) placed on the liver, over
the liver's own small-strain Green's function.

``fem_sim linear SCENE --out DATA --green`` on the liver's scene (``surrogate truth-scene``:
the liver meshed as the population's livers were, fixed where the model's placement puts the
template's fixed region) factorises the tangent of the liver's own mesh at rest once and
back-solves a unit force at each surface node along each axis. Any nodal force's linear
response is then green[node] . force (exact in small strain, :class:`LinearPart`), and the
placed network adds what the Ogden law does beyond it. No FE simulation, no training: what
``make liver`` builds and ``predict-liver --base DATA`` calls.

A model over a second-order base (``population_linear``) cannot be used so: its base needs a
solve per load (the second-order term is not linear in the force); ``make patient`` distils
it instead. numpy and scipy; no dolfinx.
"""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np

from data_spec.eligible_loads import grasp_patch
from data_spec.green_grasp import GreenGrasp
from data_spec.scene import GRASP_RADIUS
from liverreg.morph import interpolation_matrix
from surrogate.grasp import GraspForce, fixed_distance, grasp_over_base
from surrogate.predictor import LinearPart


class OverGreen:
    """The rest model ``predictor`` placed by ``placement`` on the liver of ``data`` (a
    one-liver dataset directory holding its mesh, ``geometry/``, and ``linear.h5`` with the
    Green's function): displacements in mm at the mesh's output nodes, or at the points
    ``nodes`` (n, 3) mm inside the liver (a finer mesh to show: the linear part interpolated
    from the mesh's nodes), in the liver's frame, for nodal forces in N at mesh node ids.

        model = OverGreen(load_predictor("RUN/model"), "LIVER/data", placement)
        at = model.load_nodes([[120.0, 100.0, 190.0]])     # once per grasped point
        u = model([[0.0, 0.0, -0.4]], at)                   # (n_out, 3) mm, every frame
    """

    def __init__(self, predictor, data, placement, shape: str | None = None, nodes=None,
                 green=None, solver: str | None = None, patient=None):
        """``green``: :func:`green_of` ``(predictor, data)`` when the caller has read it;
        ``solver``: the solver environment's python, to solve the unit responses a load
        needs and the file lacks (:class:`~surrogate.green_rows.GrownGreen`); ``patient``:
        a patient's corrections of a model of grasps on this liver
        (:class:`~surrogate.patient.grasps.PatientGrasp`), at the mesh's nodes only.
        """
        from surrogate.predict_liver import PlacedModel

        if patient is not None and (nodes is not None or predictor.load != "grasp"):
            raise ValueError("a patient's model of grasps corrects a model of grasps at its "
                             "liver mesh's nodes")
        if patient is not None:
            patient.check_model(predictor.directory)
        self.patient = patient

        lf, g = green or green_of(predictor, data)
        self.geometry, self.data = g, Path(data)
        self.output_nodes = np.asarray(lf.output_nodes)
        self.fixed_nodes = lf.fixed(g.surface_nodes)
        self.free_nodes = np.setdiff1d(g.surface_nodes, self.fixed_nodes)
        self._lf, self._grow = lf, None
        if solver and lf.uncomputed(g.surface_nodes).size:
            from surrogate.green_rows import GrownGreen

            self._grow = GrownGreen(lf, g.surface_nodes, data, solver)
        at = g.points[self.output_nodes] if nodes is None else np.asarray(nodes, np.float64)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")   # the placement's warnings are said by place()
            self.placed = PlacedModel(predictor, nodes=at, placement=placement, shape=shape)
        self._index_responses()
        self._to_nodes = None if nodes is None else \
            interpolation_matrix(g.points[self.output_nodes], at).tocsr()
        self._template_of: dict[bytes, np.ndarray] = {}

    @property
    def points(self) -> np.ndarray:
        """(n, 3) mm: the liver's mesh nodes (its frame)."""
        return self.geometry.points

    def load_nodes(self, at) -> np.ndarray:
        """Mesh node ids under the points ``at`` (..., 3) mm: the nearest surface nodes off
        the fixed region (where loads act).
        """
        from scipy.spatial import cKDTree

        at = np.asarray(at, dtype=np.float64)
        ids = cKDTree(self.points[self.free_nodes]).query(at.reshape(-1, 3))[1]
        return self.free_nodes[ids].reshape(at.shape[:-1])

    def whole_surface_problem(self) -> str:
        """Why loads anywhere on the free surface cannot be answered (a Green's function
        near one load only), or "".
        """
        if self._grow is not None:
            return ""
        return self._lf.whole_surface_problem(self.geometry.surface_nodes, self.data)

    def _index_responses(self) -> None:
        """The linear part over the file's unit responses as they are (grown or not), and
        which mesh nodes have one (a frame's check is then a lookup).
        """
        self.green_nodes = np.asarray(self._lf.green_nodes)
        self.linear = LinearPart(self.green_nodes, self._lf.green, self.points,
                                 self.output_nodes)
        self._answered = np.zeros(self.points.shape[0], bool)
        self._answered[self.green_nodes] = True

    def check_responses(self, nodes) -> None:
        """ValueError when a load at the mesh ``nodes`` has no unit response to stand on
        (with a solver process, those it lacks are solved first).
        """
        nodes = np.asarray(nodes, np.int64).ravel()
        if self._answered[nodes].all():   # every frame of a load already answered
            return
        if self._grow is not None and self._grow(nodes):
            self._index_responses()
        why = self._lf.missing_response(nodes, self.geometry.surface_nodes)
        if why:
            raise ValueError(why)

    def close(self) -> None:
        """End the solver process of a grown Green's function (``solver``), if any."""
        if self._grow is not None:
            self._grow.close()

    def prefetch(self, near: int) -> None:
        """With a solver process: the free surface's unit responses solved in the
        background, nearest the mesh node ``near`` first (:meth:`GrownGreen.prefetch
        <surrogate.green_rows.GrownGreen.prefetch>`); a load there later finds them solved.
        """
        if self._grow is not None:
            self._grow.prefetch(nearest_first(self.points, self.free_nodes, near))

    def grasp(self, at, radius: float = GRASP_RADIUS):
        """Tools grasping the liver at the points ``at`` (T, 3) mm, each the patch of radius
        ``radius`` around the free surface node nearest to its point: ``grasp(d)`` with the
        tools' displacements d (T, 3) mm gives (the field at the output nodes, each tool's
        force in N). Over the small-strain base (a
        :class:`~data_spec.green_grasp.GreenGrasp`), a model of grasps adds the placed
        network's rest to the field and stiffens the force (:class:`GraspOverGreen`); a model
        of nodal forces adds nothing (docs/surgical_loads.md measures what the base misses).
        ValueError when a patch reaches the fixed region.
        """
        centres = np.atleast_1d(self.load_nodes(np.asarray(at, np.float64).reshape(-1, 3)))
        patches = [grasp_patch(self.points, self.geometry.surface_nodes, c, radius)
                   for c in centres]
        self.check_responses(np.concatenate(patches))
        base = GreenGrasp(self.linear.green, self.green_nodes, self.output_nodes, patches)
        if self.placed.predictor.load != "grasp":
            return base
        if centres.size != self.placed.predictor.spec.n_loads:
            raise ValueError(f"the model learned {self.placed.predictor.spec.n_loads} tool(s), "
                             f"got {centres.size}")
        return GraspOverGreen(base, self, centres)

    def _template_nodes(self, load_nodes: np.ndarray) -> np.ndarray:
        """The registered template's surface nodes under the mesh nodes ``load_nodes``, kept
        per node set (a pull at the same point every frame looks them up once).
        """
        key = load_nodes.tobytes() + str(load_nodes.shape).encode()
        if key not in self._template_of:
            self._template_of[key] = self.placed.load_nodes(self.points[load_nodes])
        return self._template_of[key]

    def __call__(self, forces, load_nodes) -> np.ndarray:
        """(n, 3), or (n_cases, n, 3) for forces (n_cases, n_loads, 3), mm at the output
        nodes (or the ``nodes`` given): the linear response of the liver's own mesh plus the
        placed network's rest.
        """
        forces = np.asarray(forces, dtype=np.float64)
        load_nodes = np.asarray(load_nodes, dtype=np.int64)
        single = forces.ndim == 2
        f, n = (forces[None], load_nodes.reshape(1, -1)) if single else \
            (forces, load_nodes.reshape(forces.shape[0], -1))
        if f.ndim != 3 or f.shape[2] != 3 or n.shape != f.shape[:2]:
            raise ValueError(f"forces (n_loads, 3) or (n_cases, n_loads, 3) with load_nodes of "
                             f"their first dimensions, got {forces.shape} and "
                             f"{load_nodes.shape}")
        if n.size and (n.min() < 0 or n.max() >= self.points.shape[0]):
            raise ValueError(f"load_nodes: expected mesh node ids in [0, {self.points.shape[0]})")
        self.check_responses(n)
        u = self.linear(f, n)
        if self._to_nodes is not None:   # all cases in one sparse product
            k = u.shape[0]
            u = (self._to_nodes @ u.transpose(1, 0, 2).reshape(u.shape[1], -1))
            u = u.reshape(-1, k, 3).transpose(1, 0, 2)
        u = u + self.placed(f, self._template_nodes(n), rest=True)
        return u[0] if single else u


class GraspOverGreen:
    """A grasp's field over a liver's Green's function with a model of grasps: ``(d)`` ->
    (the base's field plus the placed network's rest, each tool's force), ``d`` (T, 3) mm the
    tools' displacements; ``force(d)`` alone (a haptic loop's microseconds): the base's
    force stiffened as the model learned it (:class:`surrogate.grasp.GraspForce`; the base's
    own when the model has none). Built by :meth:`OverGreen.grasp`.
    """

    def __init__(self, base: GreenGrasp, over: OverGreen, centres: np.ndarray):
        self.base, self.over = base, over
        self.patches, self.stiffness = base.patches, base.stiffness
        self._at = over._template_nodes(np.asarray(centres, dtype=np.int64))
        self._centres = over.points[np.asarray(centres, dtype=np.int64)]
        # a patient's corrections hold near the grasps they were fitted on: said when not
        self.uncorrected = "" if over.patient is None else over.patient.beyond(self._centres)
        if self.uncorrected:
            warnings.warn(self.uncorrected, stacklevel=3)
        self._force = over.placed.predictor.grasp_force
        self._dist = fixed_distance(over.points, over.fixed_nodes, centres)   # mm, per tool
        # the grasped nodes move with their tool: the network's rest is not added there
        where = {int(n): i for i, n in enumerate(over.output_nodes)}
        self._held = np.array([where[int(n)] for p in base.patches for n in p if int(n) in where],
                              dtype=np.int64)

    def force(self, d) -> np.ndarray:
        f = self.base.force(d)
        return self._patient_force(d, f if self._force is None else
                                   self._force(d, f, self._dist))

    def pull_for(self, force) -> np.ndarray:
        """(1, 3) mm: the pull of the one tool whose force is ``force`` (1, 3) N, a force
        held by the tool (:meth:`surrogate.grasp.GraspForce.pull_for`; the small-strain
        K^-1 F for a model without a law); ``self(pull)`` then gives the field. ValueError
        for several tools or with a patient's corrections (their force is not inverted).
        """
        if len(self.patches) != 1:
            raise ValueError(f"a force held by {len(self.patches)} tools: one tool's only")
        if self.over.patient is not None and not self.uncorrected:
            raise ValueError("a force held by the tool with a patient's corrections: not "
                             "built (the population model's answers it without them)")
        force = np.asarray(force, np.float64).reshape(3)
        if not np.all(np.isfinite(force)):
            raise ValueError(f"the tool's force: expected finite N, got {force.tolist()}")
        law = self._force or GraspForce()
        return law.pull_for(self.stiffness, force, float(self._dist[0]))[None]

    def _patient_force(self, d, f) -> np.ndarray:
        """The model's force ``f`` plus the patient's correction of it, if any."""
        if self.over.patient is None or self.uncorrected:
            return f
        return f + self.over.patient.force_added(self._centres, d, f, near=True)

    def __call__(self, d) -> tuple[np.ndarray, np.ndarray]:
        u, force = self.base(d)
        if self.over._to_nodes is not None:   # at OverGreen's own points: interpolated
            return grasp_over_base(self.over.placed, self._at, d, self.over._to_nodes @ u,
                                   force, dist=self._dist)
        u, force = grasp_over_base(self.over.placed, self._at, d, u, force, self._held,
                                   self._dist)
        if self.over.patient is not None and not self.uncorrected:
            du = self.over.patient.field_added(self._centres, d, u, near=True)
            du[self._held] = 0.0   # the grasped nodes move with their tool
            u = u + du
        return u, self._patient_force(d, force)


def nearest_first(points: np.ndarray, nodes: np.ndarray, near: int) -> np.ndarray:
    """``nodes`` in order of distance from the node ``near``."""
    return nodes[np.argsort(np.linalg.norm(points[nodes] - points[near], axis=1))]


def green_of(predictor, data) -> tuple:
    """(the small-strain file of the directory ``data``, its liver's geometry): ValueError
    naming what to run when ``predictor`` is not a model over a liver's linear response, or
    the file is missing, of another scene or liver, or holds no Green's function.
    """
    from data_spec import read_geometry
    from data_spec.linear_fields import linear_fields_path, read_dataset_linear
    from data_spec.shards import geometry_path

    path = linear_fields_path(data)
    refusal = predictor.base.over_green_refusal()
    if refusal:
        raise ValueError(refusal)
    if not path.exists():
        raise ValueError(f"{path}: missing; run `"
                         f"{predictor.base.liver_command(Path(data) / 'scene.toml', data)}"
                         "` (make liver does)")
    lf = read_dataset_linear(data)   # of the directory's scene and liver
    if lf.green is None:
        raise ValueError(f"{path}: no Green's function; run fem_sim linear with --green")
    return lf, read_geometry(geometry_path(data, lf.geometry_id))


def predict_over_green(predictor, data, liver, forces, at, *, frame: str | None = None,
                       saved=None, shape: str | None = None, grasp: bool = False,
                       patient=None):
    """predict-liver over the liver's own Green's function: (the
    :class:`~surrogate.predict_liver.LiverPrediction` on the liver's own mesh, the model).
    ``forces`` (n_loads, 3) N act at the mesh's surface nodes nearest to ``at`` (n_loads, 3)
    mm, both in the liver file's frame; the placement is ``surrogate.evaluate.place``'s
    (``saved``: the file truth-scene --placement wrote, read when it holds this liver).
    ``grasp``: ``forces`` are the displacements (mm) of tools grasping the liver at ``at``
    (:meth:`OverGreen.grasp`); the prediction's forces are then each tool's force on it.
    ``patient``: a patient's corrections of a model of grasps on this liver
    (:class:`~surrogate.patient.grasps.PatientGrasp`, ``surrogate adapt``'s).
    """
    from surrogate.evaluate import place
    from surrogate.predict_liver import LiverPrediction

    green = green_of(predictor, data)   # read once, checked before the registration
    same_liver(data, green[1], liver)
    placement, found = place(predictor, liver, frame, saved)
    model = OverGreen(predictor, data, placement, shape, green=green, patient=patient)
    g = model.geometry
    if model.output_nodes.size != g.n_nodes:
        raise ValueError(f"{data}: its scene predicts {model.output_nodes.size} of the mesh's "
                         f"{g.n_nodes} nodes; predict-liver writes the whole liver (a scene "
                         "with [output] nodes = \"all\", as truth-scene writes it)")
    forces = np.asarray(forces, dtype=np.float64).reshape(-1, 3)
    nodes = model.load_nodes(np.asarray(at, dtype=np.float64).reshape(-1, 3))
    u = np.zeros_like(g.points)
    moved = None
    if grasp:
        moved = forces
        u[model.output_nodes], forces = model.grasp(at)(moved)
    else:
        u[model.output_nodes] = model(forces, nodes)
    return LiverPrediction(
        tool_displacements=moved,
        points=g.points, cells=g.cells, triangles=g.surface_triangles,
        fixed_nodes=model.fixed_nodes, displacement=u, load_nodes=nodes, forces=forces,
        coefficients=placement.coefficients, shape_told=model.placed.shape_told,
        shape_rule=model.placed.shape_rule, residual=placement.residual,
        offset=placement.offset, rotation=placement.rotation, frame=placement.frame,
        inverted=placement.inverted, warnings=found), model


# The liver file's surface against the mesh of a --base directory: the mesh's surface nodes lie
# on the file's surface (its repair and chords move them a millimetre or two; its vertices are a
# few mm apart), another liver's are centimetres away.
SAME_LIVER_MM = 5.0


def same_liver(data, g, liver) -> None:
    """ValueError naming both when ``g``, the liver mesh of the directory ``data``
    (``fem_sim linear`` of a truth scene), is not the liver of the file ``liver``: the median
    distance of its surface nodes to the file's surface vertices beyond :data:`SAME_LIVER_MM`.
    """
    from surrogate.predict_liver import read_liver_surface, surface_distances

    points, triangles = read_liver_surface(liver)
    d = float(np.median(surface_distances(points, triangles, g.points[g.surface_nodes])))
    if d > SAME_LIVER_MM:
        raise ValueError(f"{data} holds the mesh of another liver than {liver} ({g.description}"
                         f"): its surface lies {d:.1f} mm from the file's (median, at most "
                         f"{SAME_LIVER_MM:g} for the same liver); make liver builds the "
                         "directory of this one")


def _placed_on_mesh(predictor, points, triangles):
    """The model placed on a liver meshed and turned as its population's livers (points
    (n, 3) mm in the population's frame, surface ``triangles``): the template registered on
    them as on theirs, its field at the mesh's nodes.
    """
    from surrogate.predict_liver import PlacedModel, place_liver

    points = np.asarray(points, dtype=np.float64)
    return points, PlacedModel(predictor, nodes=points, placement=place_liver(
        predictor, points, triangles, center=False)[0])


def _case_row(u, truth, **more) -> dict:
    from surrogate.metrics import displacement_metrics

    m = displacement_metrics(u, np.asarray(truth, np.float64))
    return {"field": u, "mee": m["mee"], "p95": m["ee_p95"], "lt3": m["pct_ee_lt_3mm"], **more}


def grasps_on_mesh(predictor, points, triangles, grasps, fixed) -> list[list[dict]]:
    """A model of grasps on a liver meshed and turned as its population's livers
    (:func:`_placed_on_mesh`), fixed at the nodes ``fixed``, over FE truths of grasps: per
    grasp (a dict of ``centre`` node, ``pull`` (3,) mm at the last step, ``fractions`` of it,
    ``patch``, ``base`` and ``truth`` (steps, n, 3) mm, ``base_force`` and ``fe_force``
    (steps, 3) N) and step, the model's ``field`` and ``force`` (:func:`grasp_over_base`)
    with its MEE, 95th percentile and % of nodes under 3 mm against the truth and its
    force's error (%).
    """
    from surrogate.grasp import force_error_pct

    points, placed = _placed_on_mesh(predictor, points, triangles)
    out = []
    for g in grasps:
        at, rows = placed.load_nodes(points[[int(g["centre"])]]), []
        dist = fixed_distance(points, fixed, [g["centre"]])
        for s, fr in enumerate(g["fractions"][:len(g["truth"])]):
            u, f = grasp_over_base(placed, at, fr * np.asarray(g["pull"])[None],
                                   np.asarray(g["base"][s], np.float64),
                                   np.asarray(g["base_force"][s])[None], g["patch"], dist)
            rows.append(_case_row(u, g["truth"][s], force=f[0], force_error=float(
                force_error_pct(f[0], g["fe_force"][s]))))
        out.append(rows)
    return out


def forces_on_mesh(predictor, points, triangles, forces) -> list[list[dict]]:
    """A model of forces over each liver's small-strain base (a population model of its rest,
    ``make liver AT=...``'s) on a liver meshed as :func:`grasps_on_mesh`'s, over FE truths of
    pressed forces: per case (a dict of ``centre`` node, ``force`` (3,) N at the last step,
    ``fractions`` of it, ``unit``: the base's field (n, 3) mm at the last step, ``truth``
    (steps, n, 3) mm) and step, the base scaled plus the network's rest for the whole force
    at the centre node, with its MEE, 95th percentile and % of nodes under 3 mm.
    """
    points, placed = _placed_on_mesh(predictor, points, triangles)
    out = []
    for c in forces:
        if not len(c["truth"]):   # no converged step: nothing to answer
            out.append([])
            continue
        at, unit = placed.load_nodes(points[[int(c["centre"])]]), np.asarray(c["unit"], float)
        f = np.asarray(c["fractions"][:len(c["truth"])])[:, None, None] * np.asarray(
            c["force"], np.float64)[None, None]
        rest = placed(f, np.broadcast_to(at, f.shape[:2]), rest=True)
        out.append([_case_row(fr * unit + r, c["truth"][s]) for s, (fr, r) in enumerate(
            zip(c["fractions"], rest))])
    return out
