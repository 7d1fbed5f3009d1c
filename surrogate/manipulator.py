"""The liver manipulator's logic, without a window: which node a click picks, which force a
drag sets (clamped to the training range), which inputs the model takes, and the prediction.

:mod:`surrogate.viewer` draws it (pyvista); the tests drive it directly. A *handle* is one force
of the model (two for a two-force model): a surface node and a force vector in N. Dragging a
handle's sphere to ``tip`` sets the force ``f_max * (tip - x_node) / drag_length`` (mode
"pull": the sphere is where the surface is pulled toward) or its opposite (mode "push": the
sphere stands where the push comes from, outside the liver, so it stays visible and grabbable),
so a drag of ``drag_length`` mm (a quarter of the liver's size by default) asks for the
largest force seen in training; longer drags are clamped to it.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from liverviz.pictures import Surface
from surrogate.grasp import SMALL_PULL_MM


@dataclass
class Handle:
    """One force of the model: where it acts and what it is."""

    node: int                                  # mesh node id of the load
    force: np.ndarray = field(default_factory=lambda: np.zeros(3))  # N


@dataclass
class Input:
    """One scalar model input a slider sets: a material parameter or a shape coefficient."""

    name: str
    lo: float
    hi: float
    value: float


@dataclass
class Frame:
    """One prediction: displacement of the surface vertices (mm), of all predicted nodes, and
    the seconds the surrogate took.
    """

    surface_u: np.ndarray
    u: np.ndarray
    seconds: float


def clamped(v, top: float, what: str) -> np.ndarray:
    """``v`` as a finite 3-vector, its length clamped to ``top``; ValueError naming ``what``."""
    v = np.asarray(v, dtype=float).reshape(3)
    if not np.all(np.isfinite(v)):
        raise ValueError(f"{what}: expected finite components, got {v.tolist()}")
    n = float(np.linalg.norm(v))
    return v * (top / n) if n > top else v


def material_names(material_dim: int) -> list[str]:
    """Names of the material vector (c_1..c_n, m_1..m_n, K), as features.material_vector."""
    n = (material_dim - 1) // 2
    return ([f"c{k + 1} (MPa)" for k in range(n)] + [f"m{k + 1}" for k in range(n)]
            + ["K (MPa)"])


class Manipulator:
    """State of the manipulator around a loaded :class:`surrogate.predictor.Predictor`.

    ``nodes``: "surface" predicts the surface vertices only (what is drawn); "all" predicts
    every node of the liver (the whole field, as a simulator would use it) and draws the
    surface. ``geometry``: (points, fixed nodes, surface triangles, shape coefficients) for a
    model trained on several livers (it has no liver of its own).
    """

    def __init__(self, predictor, *, nodes: str = "surface", geometry=None,
                 drag_length: float | None = None):
        if nodes not in ("surface", "all"):
            raise ValueError(f"nodes: expected 'surface' or 'all', got {nodes!r}")
        self.pred = predictor
        spec = predictor.spec
        if geometry is None:
            if predictor.points is None:
                raise ValueError("this model was trained on several livers: give the liver to "
                                 "show (the viewer's --data DIR [--liver ID])")
            if predictor.triangles is None:
                raise ValueError("the model directory has no surface triangles (exported "
                                 "before they were stored): retrain, or give --data DIR")
            points, fixed, triangles = predictor.points, predictor.fixed, predictor.triangles
            shape = np.zeros(0)
            self._geometry = None
        else:
            points, fixed, triangles, shape = (np.asarray(a) for a in geometry)
            self._geometry = (points, fixed)
        self.points = np.asarray(points, dtype=np.float64)
        self.fixed = np.asarray(fixed)
        self.surface = Surface.from_mesh(self.points, triangles, self.fixed)
        self.f_max = float(predictor.force_norm_max)
        self.drag_length = float(drag_length or 0.25 * self.surface.size)
        self.nodes_mode = nodes
        self._predict_nodes, self._rows = self._node_plan(nodes)
        rng = predictor.meta["training_range"]
        lo, hi = np.asarray(rng["extra_min"], float), np.asarray(rng["extra_max"], float)
        names = material_names(spec.material_dim) if spec.material_dim else []
        names += [f"shape {k + 1}" for k in range(spec.geometry_dim)]
        start = np.concatenate([0.5 * (lo + hi)[: spec.material_dim],
                                np.asarray(shape, float).reshape(-1)[: spec.geometry_dim]])
        if start.size != len(names):
            start = 0.5 * (lo + hi)
        self.inputs = [Input(n, float(a), float(b), float(v))
                       for n, a, b, v in zip(names, lo, hi, start)]
        self.handles = [Handle(node=n) for n in self.default_nodes(spec.n_loads)]
        self.active = 0
        self.mode = "pull"

    magnitude_title = "force of the active handle (N)"

    @property
    def magnitude_max(self) -> float:
        """The slider's end: the largest force seen in training (N)."""
        return self.f_max

    def magnitude(self, handle: int | None = None) -> float:
        """The slider's value: the handle's force (N)."""
        return float(np.linalg.norm(self.handles[self._handle(handle)].force))

    def describe(self, j: int) -> str:
        """The status line of handle ``j``."""
        h, mark = self.handles[j], "*" if j == self.active and len(self.handles) > 1 else ""
        return (f"F{j + 1}{mark} = {np.linalg.norm(h.force):.3f} N (max {self.f_max:.2f}) "
                f"at node {h.node}")

    def prefetch(self) -> None:
        """Work to do while a window waits for people: none for a model of its own."""

    # -- picking and dragging ------------------------------------------------------------------
    def default_nodes(self, n: int) -> list[int]:
        """Surface nodes farthest from the fixed region (and from each other): where a user
        pulls first.
        """
        x = self.surface.points
        d = np.full(x.shape[0], np.inf)
        for a in self.points[self.fixed]:  # distance to the nearest fixed node
            d = np.minimum(d, np.linalg.norm(x - a, axis=1))
        out = []
        for _ in range(n):
            i = int(np.argmax(d))
            out.append(int(self.surface.nodes[i]))
            d = np.minimum(d, np.linalg.norm(x - x[i], axis=1))
        return out

    def nearest_surface_node(self, xyz) -> int:
        """The surface node closest to a point (mm) in the undeformed liver."""
        xyz = np.asarray(xyz, dtype=float).reshape(3)
        if not np.all(np.isfinite(xyz)):
            raise ValueError(f"pick: expected a finite point, got {xyz.tolist()}")
        i = int(np.argmin(np.linalg.norm(self.surface.points - xyz, axis=1)))
        return int(self.surface.nodes[i])

    def pick(self, xyz, handle: int | None = None, deformed: np.ndarray | None = None) -> int:
        """Move a handle (default: the active one) to the surface node nearest ``xyz``; its
        force is kept. ``deformed``: the surface vertices as drawn, when the click was on the
        deformed liver.
        """
        h = self._handle(handle)
        node = self.clicked_node(xyz, deformed)
        if int(node) in self.fixed.tolist():
            return self.handles[h].node  # the fixed region cannot be loaded: keep the node
        self.handles[h].node = node
        return node

    def clicked_node(self, xyz, deformed: np.ndarray | None = None) -> int:
        """The surface node a click at ``xyz`` (mm) picks: the nearest vertex of ``deformed``
        (the surface vertices as drawn) when given, else of the undeformed surface.
        """
        if deformed is None:
            return self.nearest_surface_node(xyz)
        i = int(np.argmin(np.linalg.norm(np.asarray(deformed) - np.asarray(xyz), axis=1)))
        return int(self.surface.nodes[i])

    def outward_normal(self, node: int) -> np.ndarray:
        """The outward unit normal of the surface at the mesh node ``node``."""
        return self.surface.normals()[self.surface.local([node])[0]]

    def drag(self, tip, handle: int | None = None) -> np.ndarray:
        """Set a handle's force from its sphere's position ``tip`` (mm); returns it (N)."""
        h = self._handle(handle)
        tip = np.asarray(tip, dtype=float).reshape(3)
        f = self._sign * self.f_max * (tip - self.points[self.handles[h].node]) / \
            self.drag_length
        return self.set_force(f, h)

    def handle_position(self, handle: int | None = None) -> np.ndarray:
        """Where a handle's sphere sits for its current force (the inverse of ``drag``)."""
        h = self.handles[self._handle(handle)]
        return self.points[h.node] + self._sign * h.force / self.f_max * self.drag_length

    def toggle_mode(self) -> str:
        """Switch between pulling and pushing with the spheres; the forces stay."""
        self.mode = "push" if self.mode == "pull" else "pull"
        return self.mode

    @property
    def _sign(self) -> float:
        return 1.0 if self.mode == "pull" else -1.0

    def set_force(self, force, handle: int | None = None) -> np.ndarray:
        """Set a force (N), its magnitude clamped to the training range; returns it."""
        h = self._handle(handle)
        self.handles[h].force = f = clamped(force, self.f_max, "force")
        return f

    def set_magnitude(self, magnitude: float, handle: int | None = None) -> np.ndarray:
        """Scale a force to ``magnitude`` N (clamped), keeping its direction (default
        direction for a zero force: along the outward normal when pulling, the inward one when
        pushing, so the sphere stays outside the liver).
        """
        h = self._handle(handle)
        f = self.handles[h].force
        n = float(np.linalg.norm(f))
        direction = f / n if n > 0 else self._sign * self.outward_normal(self.handles[h].node)
        return self.set_force(direction * max(float(magnitude), 0.0), h)

    def set_input(self, index: int, value: float) -> float:
        """Set a material / shape input, clamped to the training range; returns it."""
        inp = self.inputs[index]
        inp.value = float(np.clip(value, inp.lo, inp.hi))
        return inp.value

    def _handle(self, handle: int | None) -> int:
        h = self.active if handle is None else int(handle)
        if not 0 <= h < len(self.handles):
            raise ValueError(f"handle: this model has {len(self.handles)} force(s), got {h}")
        return h

    # -- prediction -----------------------------------------------------------------------------
    def colour_range(self) -> float:
        """A fixed colour range (mm) for a live view: the largest |u| of the surface under the
        largest training force along +-x, +-y, +-z at each handle's node, rounded up.
        """
        saved = [h.force.copy() for h in self.handles]
        top = 0.0
        for j in range(len(self.handles)):
            for axis in np.vstack([np.eye(3), -np.eye(3)]):
                for k, h in enumerate(self.handles):
                    h.force = axis * self.f_max if k == j else np.zeros(3)
                top = max(top, float(np.linalg.norm(self.predict().surface_u, axis=1).max()))
        for h, f in zip(self.handles, saved):
            h.force = f
        return float(np.ceil(max(top, 1e-3) * 1.1))

    def _node_plan(self, nodes: str):
        """(node ids to predict or None for all, rows of the prediction for the surface
        vertices). A reduced-basis model predicts its output nodes only.
        """
        surf = self.surface.nodes
        if nodes == "surface":
            return surf, np.arange(surf.size)
        n_all = self.points.shape[0]
        if self.pred.runtime.outputs_only and self.pred.output_nodes.size != n_all:
            raise ValueError(f"nodes='all': this reduced-basis model predicts its "
                             f"{self.pred.output_nodes.size} output nodes, not all {n_all}")
        return None, surf

    @property
    def n_predicted(self) -> int:
        """How many nodes each prediction computes (the surface, or the whole liver)."""
        return int(self._rows.size if self._predict_nodes is not None else self.points.shape[0])

    def predict(self) -> Frame:
        """The surrogate's displacement for the current handles and inputs."""
        spec = self.pred.spec
        forces = np.stack([h.force for h in self.handles])
        nodes = np.array([h.node for h in self.handles])
        values = np.array([i.value for i in self.inputs])
        material = values[: spec.material_dim] if spec.material_dim else None
        geometry = None
        if self._geometry is not None:
            geometry = (*self._geometry, values[spec.material_dim:])
        t = time.perf_counter()
        u = self.pred(forces, nodes, nodes=self._predict_nodes, material=material,
                      geometry=geometry)
        seconds = time.perf_counter() - t
        return Frame(surface_u=u[self._rows], u=u, seconds=seconds)


class GreenManipulator(Manipulator):
    """Forces on a liver's own mesh over its small-strain Green's function with a model of
    the rest placed on the liver (an :class:`~surrogate.over_green.OverGreen`: ``make
    liver``'s data directory and a ``population_green`` model): the handles, drag, slider and
    push / pull of :class:`Manipulator`, the whole field at every node of the mesh from
    ``over(forces, nodes)`` (the linear response plus the network's rest). The liver's shape
    is its own and the material the population's: no input sliders.
    """

    def __init__(self, over, drag_length: float | None = None):
        g = over.geometry
        why = over.whole_surface_problem()
        if why:
            raise ValueError(why)
        if over.output_nodes.size != g.n_nodes:
            raise ValueError(f"the liver's Green's function reaches {over.output_nodes.size} "
                             f"of its {g.n_nodes} nodes; make liver writes the whole liver")
        super().__init__(over.placed.predictor, geometry=(
            g.points, over.fixed_nodes, g.surface_triangles, np.zeros(0)),
            drag_length=drag_length)
        self.over, self.inputs, self.nodes_mode = over, [], "all"
        self._rows = np.searchsorted(over.output_nodes, self.surface.nodes)

    @property
    def n_predicted(self) -> int:
        return int(self.over.output_nodes.size)

    def prefetch(self) -> None:
        """:meth:`OverGreen.prefetch <surrogate.over_green.OverGreen.prefetch>` from the
        first handle.
        """
        self.over.prefetch(self.handles[0].node)

    def set_input(self, index: int, value: float) -> float:
        raise ValueError("a model over a liver's Green's function takes no material or "
                         "shape input: the liver is its own")

    def predict(self) -> Frame:
        """The whole liver's field for the present handles (mm, every mesh node)."""
        forces = np.stack([h.force for h in self.handles])
        nodes = np.array([h.node for h in self.handles])
        t = time.perf_counter()
        u = self.over(forces, nodes)
        return Frame(surface_u=u[self._rows], u=u, seconds=time.perf_counter() - t)


class GraspManipulator:
    """A grasping tool on a liver's own mesh over its small-strain Green's function (the data
    directory of ``make liver``, ``fem_sim linear --green``): a click picks the patch the tool
    holds (:func:`data_spec.eligible_loads.grasp_patch`), a drag moves it to the pointer
    (clamped to ``max_pull`` mm), and the field and the tool's force on the liver come from
    :class:`data_spec.green_grasp.GreenGrasp`, the small-strain base, or with ``over`` (an
    :class:`~surrogate.over_green.OverGreen` of a model of grasps placed on this liver) from
    its :meth:`~surrogate.over_green.OverGreen.grasp`: the base plus the network's rest, the
    force stiffened (docs/surgical_loads.md measures both). ``solver`` (the solver
    environment's python): a patch the file has no unit responses for (``make liver``
    solves its load's only) has them solved on the spot (:mod:`surrogate.green_rows`). It
    offers what the viewer draws,
    as :class:`Manipulator` does; a handle's ``force`` is the tool's force (N) and the load a
    script or the slider sets is the pull (mm).
    """

    magnitude_title = "pull of the grasp (mm)"
    nodes_mode = "all"
    mode = "pull"

    def __init__(self, data, max_pull: float = 40.0, radius: float | None = None, over=None,
                 solver: str | None = None):
        from data_spec import read_geometry
        from data_spec.linear_fields import read_dataset_linear
        from data_spec.scene import GRASP_RADIUS
        from data_spec.shards import geometry_path

        lf = read_dataset_linear(data)
        if lf.green is None:
            raise ValueError(f"{data}: its small-strain file holds no Green's function; run "
                             "fem_sim linear with --green (make liver does)")
        g = read_geometry(geometry_path(data, lf.geometry_id))
        self._grow = None
        if over is not None and over.placed.predictor.load == "grasp":   # the model's file
            why = over.whole_surface_problem()
        elif solver and lf.uncomputed(g.surface_nodes).size:
            from surrogate.green_rows import GrownGreen

            self._grow, why = GrownGreen(lf, g.surface_nodes, data, solver), ""
        else:
            why = lf.whole_surface_problem(g.surface_nodes, data)
        if why:
            raise ValueError(why)
        if lf.output_nodes.size != g.n_nodes:
            raise ValueError(f"{data}: its Green's function reaches {lf.output_nodes.size} of "
                             f"the mesh's {g.n_nodes} nodes; the grasp draws the whole liver "
                             "(a scene with [output] nodes = \"all\", as make liver writes it)")
        self.points, self.radius = g.points, float(radius or GRASP_RADIUS)
        self.fixed = lf.fixed(g.surface_nodes)
        self.surface = Surface.from_mesh(g.points, g.surface_triangles, self.fixed)
        self._lf, self._surface_nodes = lf, g.surface_nodes
        # a model of forces over the Green's function grasps with the base alone
        self._over = over if over is not None and over.placed.predictor.load == "grasp" else None
        self._rows = np.searchsorted(lf.output_nodes, self.surface.nodes)
        self.max_pull = self.magnitude_max = self.drag_length = float(max_pull)
        self.inputs: list[Input] = []
        self.active, self.pull = 0, np.zeros(3)
        self.handles = [Handle(node=self.default_nodes(1)[0])]
        self._grasp = self._grasp_at(self.handles[0].node)
        # the arrows' scale: the force of the largest pull along the stiffest axis
        self.f_max = float(np.linalg.norm(self._grasp.stiffness, 2)) * self.max_pull

    def close(self) -> None:
        """End the solver process of its own grown Green's function (``solver``), if any."""
        if self._grow is not None:
            self._grow.close()

    def prefetch(self) -> None:
        """With a solver process: every free patch's unit responses solved in the
        background, nearest the tool first (a patch grasped later finds them solved).
        """
        from surrogate.over_green import nearest_first

        if self.grown is not None:
            self.grown.prefetch(nearest_first(self.points, self.grown.free,
                                              self.handles[0].node))

    @property
    def grown(self):
        """The :class:`~surrogate.green_rows.GrownGreen` that solves new patches (its own,
        or its model's), or None.
        """
        return self._grow if self._grow is not None else getattr(self._over, "_grow", None)

    @property
    def solved_seconds(self) -> list[float]:
        """Each request for a new patch's unit responses (:mod:`surrogate.green_rows`)."""
        return [] if self.grown is None else list(self.grown.seconds)

    def _grasp_at(self, node: int):
        from data_spec.eligible_loads import grasp_patch
        from data_spec.green_grasp import GreenGrasp

        if self._over is not None:   # the model of grasps: its network's rest and force
            return self._over.grasp(self.points[node][None], self.radius)
        lf, patch = self._lf, grasp_patch(self.points, self._surface_nodes, node, self.radius)
        if self._grow is not None:
            self._grow(patch)
        why = lf.missing_response(patch, self._surface_nodes)
        if why:
            raise ValueError(why)
        return GreenGrasp(lf.green, lf.green_nodes, lf.output_nodes, [patch])

    nearest_surface_node = Manipulator.nearest_surface_node
    default_nodes = Manipulator.default_nodes
    clicked_node = Manipulator.clicked_node
    outward_normal = Manipulator.outward_normal

    def pick(self, xyz, handle: int | None = None, deformed: np.ndarray | None = None) -> int:
        """Grasp the patch around the surface node nearest ``xyz`` (on the ``deformed``
        surface when given), the pull kept; a patch that reaches the fixed region is not
        taken (the tool stays where it was).
        """
        node = self.clicked_node(xyz, deformed)
        try:
            self._grasp = self._grasp_at(node)
        except ValueError:   # the patch holds a fixed node
            return self.handles[0].node
        self.handles[0].node = node
        return node

    def set_force(self, pull, handle: int | None = None) -> np.ndarray:
        """Set the tool's pull (mm; its length clamped to ``max_pull``); returns it."""
        self.pull = clamped(pull, self.max_pull, "pull")
        return self.pull

    def drag(self, tip, handle: int | None = None) -> np.ndarray:
        """Move the patch to ``tip`` (mm): the pull is tip less the grasped node, clamped."""
        return self.set_force(np.asarray(tip, float).reshape(3)
                              - self.points[self.handles[0].node])

    def handle_position(self, handle: int | None = None) -> np.ndarray:
        """Where the tool holds the patch's centre: the node moved by the pull."""
        return self.points[self.handles[0].node] + self.pull

    def set_magnitude(self, magnitude: float, handle: int | None = None) -> np.ndarray:
        """Pull by ``magnitude`` mm along the present pull (along the outward normal at first)."""
        n = float(np.linalg.norm(self.pull))
        direction = self.pull / n if n > 0 else self.outward_normal(self.handles[0].node)
        return self.set_force(direction * max(float(magnitude), 0.0))

    def magnitude(self, handle: int | None = None) -> float:
        return float(np.linalg.norm(self.pull))

    def toggle_mode(self) -> str:
        return self.mode   # a grasp pulls where the pointer is: nothing to switch

    def set_input(self, index: int, value: float) -> float:
        raise ValueError("a grasp over a Green's function takes no material or shape input")

    @property
    def n_predicted(self) -> int:
        return int(self._lf.output_nodes.size)

    def colour_range(self) -> float:
        """A fixed colour range (mm) for a live view: the largest pull (no node moves more
        than the held patch).
        """
        return float(np.ceil(self.max_pull))

    def describe(self, handle: int = 0) -> str:
        """The status line of the tool: its pull and its force."""
        f = self.handles[0].force
        said = "model of grasps: base + network)" if self._over is not None else \
            "small-strain base" + ("; too low at this pull)"
                                   if np.linalg.norm(self.pull) > SMALL_PULL_MM else ")")
        return (f"grasp at node {self.handles[0].node}: {np.linalg.norm(self.pull):.1f} mm "
                f"(max {self.max_pull:g})\nforce {np.linalg.norm(f):.3f} N ({said}")

    def predict(self) -> Frame:
        """The field of the whole liver and the tool's force for the present pull."""
        t = time.perf_counter()
        u, force = self._grasp(self.pull[None])
        seconds = time.perf_counter() - t
        self.handles[0].force = force[0]
        return Frame(surface_u=u[self._rows], u=u, seconds=seconds)
