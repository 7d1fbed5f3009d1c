"""The runtime predictor: an exported model directory (:mod:`surrogate.export`) loaded as a
jitted function of the loads that returns millimetres.

:class:`Predictor` checks the inputs every design takes (forces, load nodes, output nodes,
material, the liver) and hands the design's runtime (``DESIGNS[design].runtime``) the arrays
to evaluate; it never tests a design's name.
"""

from __future__ import annotations

import json
import logging
import warnings
from pathlib import Path

import numpy as np

from surrogate.features import FeatureSpec, static_node_features
from surrogate.model_files import check_fingerprint, read_meta
from surrogate.small_strain import base_of, green_product

# Inference precisions: float32 (as trained), or the weights and activations cast to 16 bits.
PRECISIONS = ("float32", "bfloat16", "float16")
log = logging.getLogger(__name__)


def _check_loads(forces, load_nodes, n_loads: int):
    """(forces (n_cases, L, 3), load node ids (n_cases, L), whether one case was given)."""
    forces = np.asarray(forces, dtype=np.float64)
    load_nodes = np.asarray(load_nodes)
    single = forces.ndim == 2
    if single:
        forces, load_nodes = forces[None], load_nodes[None]
    L = n_loads
    if forces.ndim != 3 or forces.shape[1:] != (L, 3):
        raise ValueError(f"forces: expected shape ({L}, 3) or (n_cases, {L}, 3), got "
                         f"{np.shape(forces) if not single else forces.shape[1:]}")
    if forces.shape[0] == 0:
        raise ValueError("forces: no case given (shape (0, n_loads, 3))")
    if load_nodes.shape != forces.shape[:2]:
        raise ValueError(f"load_nodes: expected shape {forces.shape[:2]} for forces of "
                         f"shape {forces.shape}, got {load_nodes.shape}")
    if not np.all(np.isfinite(forces)):
        raise ValueError("forces: contain NaN or inf")
    return forces, load_nodes, single


def _node_ids(ids: np.ndarray, n_nodes: int) -> bool:
    return (np.issubdtype(ids.dtype, np.integer)
            and (ids.size == 0 or (ids.min() >= 0 and ids.max() < n_nodes)))


def check_load_nodes(load_nodes, loadable) -> None:
    """Warn when a load acts on a node the scene never loads (interior, fixed, or closer to the
    fixed region than its minimum distance): no training example had a load there.
    """
    bad = np.setdiff1d(np.asarray(load_nodes).ravel(), loadable)
    if bad.size:
        warnings.warn(f"load node(s) {bad[:10].tolist()} never loaded in training (the scene "
                      "loads surface nodes away from the fixed region; these are interior, "
                      "fixed or too close to it): extrapolating", stacklevel=3)


class Predictor:
    """Jitted surrogate: forces (and load nodes, material) -> node displacements in mm.

    Call ``predict(forces, load_nodes, nodes=None, material=None, geometry=None)`` with
    forces (n_loads, 3) or (n_cases, n_loads, 3) in N, load_nodes (n_loads,) or
    (n_cases, n_loads) node ids; returns (n_nodes, 3) or (n_cases, n_nodes, 3).
    ``nodes`` selects output nodes (default: all), e.g. the surface. ``material`` (c..., m...,
    K) is required when the scene varied the material; ``geometry`` = (points, fixed_nodes,
    shape_coefficients) when it varied the liver (or to predict on another mesh).
    ``dtype``: the network's precision, one of :data:`PRECISIONS`.
    """

    def __init__(self, directory, dtype: str = "float32", load: str = "nodal"):
        from surrogate.designs import DESIGNS

        if dtype not in PRECISIONS:
            raise ValueError(f"dtype: expected one of {sorted(PRECISIONS)}, got {dtype!r}")
        if load not in LOADS:
            raise ValueError(f"load: expected one of {sorted(LOADS)}, got {load!r}")
        self.dtype = dtype
        self.directory = d = Path(directory)
        self.meta = meta = read_meta(d / "model.json", DESIGNS)
        check_fingerprint(d)   # a shipped model: its files as its card measured them
        self.load = meta.get("load", "nodal")   # "grasp": its loads are tools' pulls, mm
        # a model of grasps: its tools' force beyond the small-strain one (None: the base's)
        self.grasp_force = None
        if meta.get("grasp_force") is not None:
            from surrogate.grasp import GraspForce

            self.grasp_force = GraspForce(**meta["grasp_force"])
        if self.load not in LOADS:
            raise ValueError(f"{d / 'model.json'}: load {self.load!r}, expected one of "
                             f"{sorted(LOADS)}")
        if self.load != load:
            raise ValueError(f"{d}: a model of {LOADS[self.load]} (scene {meta.get('scene')!r}),"
                             f" asked for {LOADS[load]}: "
                             + ("give it a grasp (predict-liver --base DATA --grasp X Y Z DX DY "
                                "DZ, make liver GRASP=...)" if self.load == "grasp" else
                                "a grasp is answered by a model of grasps (scene4_grasp.toml); "
                                "without one, predict-liver --base DATA --grasp gives the "
                                "small-strain base alone"))
        try:
            self.spec = FeatureSpec(**meta["feature_spec"])
            cfg = meta["config"]
            hidden = tuple(int(w) for w in cfg["hidden"])
            dropout = float(cfg["dropout"])
            # a population model of what each liver's small-strain base misses
            # (surrogate/population_basis.py): its field is that rest, never a whole field
            self.base = base_of(int(cfg.get("linear_base", 0)))
            self.force_norm_max = float(meta["training_range"]["force_norm_max"])
        except (KeyError, TypeError, ValueError) as exc:
            raise ValueError(f"{d / 'model.json'}: incomplete or malformed ({exc!r})") from None
        self.design = meta["design"]
        self._read_liver(d / "geometry.npz",
                         meta.get("embedded_geometry") or DESIGNS[self.design].needs_liver)
        self._shape_model_path = d / meta["shape_model"] if meta.get("shape_model") else None
        self._shape_model = None
        self.runtime = DESIGNS[self.design].runtime(d, self, hidden, dropout, dtype)
        self._geo_key = self._sel_key = None
        self.linear_part = _read_linear_part(d, meta, self.points, self.output_nodes)

    def _read_liver(self, geo: Path, required: bool) -> None:
        """The liver the model was exported with (geometry.npz), if any."""
        import jax.numpy as jnp

        self.points = self.fixed = self.static = self.output_nodes = None
        self.triangles = self.loadable = None
        if not geo.exists():
            if required:
                raise ValueError(f"{geo}: missing (the model was exported with its liver)")
            return
        try:
            with np.load(geo, allow_pickle=False) as z:
                self.points, self.fixed = z["points"], z["fixed"]
                self.output_nodes = z["output_nodes"]
                self.triangles = z["triangles"] if "triangles" in z.files else None
                self.loadable = z["loadable"] if "loadable" in z.files else None
        except (OSError, KeyError, ValueError) as exc:
            raise ValueError(f"{geo}: cannot be read ({exc})") from None
        self.static = jnp.asarray(static_node_features(self.points, self.fixed),
                                  dtype=jnp.float32)

    @property
    def modes(self) -> np.ndarray | None:
        """(k, n_output_nodes, 3) the modes of a basis design, None for a node-wise one."""
        return self.runtime.modes

    def __call__(self, forces, load_nodes, nodes=None, material=None, geometry=None,
                 rest: bool = False):
        """The displacement field, mm; ``rest``: what the small-strain base misses, of a model
        trained on it (``self.base``, :mod:`surrogate.small_strain`), which gives nothing else,
        each load held at the training range's edge (its magnitude at most
        ``force_norm_max``: beyond it the base alone grows with the load).
        """
        if not (self.base.whole or rest):
            raise ValueError(self.base.rest_only())
        forces, load_nodes, single = _check_loads(forces, load_nodes, self.spec.n_loads)
        if self.linear_part is not None and geometry is not None:
            raise ValueError("geometry: this model's small-strain part is of its own liver's "
                             "mesh; it predicts on that mesh only")
        self.runtime.check_geometry(self, geometry)
        static, points = self._geometry(geometry)
        self.runtime.check_points(self, points.shape[0])
        if not _node_ids(load_nodes, points.shape[0]):
            raise ValueError(f"load_nodes: expected integer node ids in [0, {points.shape[0]})")
        rows = self._rows(nodes, static, geometry, points.shape[0])
        extra = self.varied_inputs(forces.shape[0], material, geometry)
        if geometry is None and self.loadable is not None:
            check_load_nodes(load_nodes, self.loadable)
        norms = np.linalg.norm(forces, axis=-1)
        fmax = norms.max()
        if fmax > 1.05 * self.force_norm_max:
            what, unit = ("pull", "mm") if self.load == "grasp" else ("force magnitude", "N")
            warnings.warn(f"{what} {fmax:.3g} {unit} exceeds the training range "
                          f"({self.force_norm_max:.3g} {unit}): " + (
                              "the network's rest is held at that range's edge, the "
                              "small-strain base carries the rest of the load" if rest else
                              "extrapolating"), stacklevel=2)
        if rest:   # an extrapolated rest is far worse than none (docs/surgical_loads.md)
            forces = forces * np.minimum(1.0, self.force_norm_max / np.maximum(
                norms, 1e-300))[..., None]
        # numpy in: the jitted call takes host arrays on its fast path (jnp.asarray here would
        # dispatch one eager conversion per argument, most of a small model's call)
        args = (np.asarray(forces, dtype=np.float32),
                np.asarray(points[load_nodes], dtype=np.float32),
                np.asarray(extra, dtype=np.float32))
        liver = None if geometry is None else (self._geo_key, points, np.asarray(geometry[1]))
        out = np.asarray(self.runtime.apply(self, rows, *args, load_nodes, liver))
        if self.linear_part is not None:
            out = out + self.linear_part(forces, load_nodes, nodes).astype(out.dtype)
        return out[0] if single else out

    def _rows(self, nodes, static, geometry, n_nodes: int):
        """What the runtime evaluates for the requested output nodes (all when None), kept
        once per (liver, node set): a caller that asks for the surface at every frame pays for
        the surface only.
        """
        if nodes is None:
            return self.runtime.all_rows(static)
        nodes = np.asarray(nodes)
        if nodes.ndim != 1 or not _node_ids(nodes, n_nodes):
            raise ValueError(f"nodes: expected a 1-D array of node ids in [0, {n_nodes})")
        key = (None if geometry is None else self._geo_key, nodes.dtype.str, nodes.shape,
               nodes.tobytes())
        if self._sel_key != key:
            self._sel_key = key
            self._sel = self.runtime.rows(self, static, nodes)
        return self._sel

    def varied_inputs(self, n_cases: int, material, geometry) -> np.ndarray:
        """(n_cases, e) the material and shape inputs the scene varied, checked."""
        blocks = []
        spec = self.spec
        if material is not None and not spec.material_dim:
            raise ValueError("material: this model was trained on one material and takes "
                             "none (its scene did not vary the material)")
        if spec.material_dim:
            if material is None:
                raise ValueError("material: this model needs (c, m, K) for each case")
            mat = np.asarray(material, dtype=np.float64).reshape(-1, spec.material_dim)
            if not np.all(np.isfinite(mat)):
                raise ValueError("material: contains NaN or inf")
            self._check_range("material", mat, 0, spec.material_dim)
            blocks.append(np.broadcast_to(mat, (n_cases, spec.material_dim)))
        if spec.geometry_dim:
            shape = np.asarray(geometry[2] if geometry is not None else [], dtype=np.float64)
            if shape.shape != (spec.geometry_dim,):
                raise ValueError(f"geometry: expected {spec.geometry_dim} shape "
                                 f"coefficients, got {shape.shape}")
            if not np.all(np.isfinite(shape)):
                raise ValueError("geometry: shape coefficients contain NaN or inf")
            m0 = spec.material_dim
            self._check_range("shape coefficients", shape[None], m0, m0 + spec.geometry_dim)
            blocks.append(np.broadcast_to(shape, (n_cases, shape.size)))
        return np.concatenate(blocks, axis=1) if blocks else np.zeros((n_cases, 0))

    def _check_range(self, what: str, values: np.ndarray, start: int, stop: int) -> None:
        """Warn when inputs leave the range seen in training (by more than 5 % of it):
        the network extrapolates there.
        """
        rng = self.meta["training_range"]
        lo = np.asarray(rng["extra_min"][start:stop])
        hi = np.asarray(rng["extra_max"][start:stop])
        span = np.maximum(hi - lo, 1e-12 * np.abs(hi))
        if np.any(values < lo - 0.05 * span) or np.any(values > hi + 0.05 * span):
            warnings.warn(f"{what} {values.tolist()} outside the training range "
                          f"[{lo.tolist()}, {hi.tolist()}]: extrapolating", stacklevel=4)

    @property
    def shape_model(self):
        """The population's :class:`liverreg.shape_model.ShapeModel` (None for a model of one
        liver, or exported without it).
        """
        if self._shape_model is None and self._shape_model_path is not None:
            from liverreg.shape_model import ShapeModel

            self._shape_model = ShapeModel.load(self._shape_model_path)
        return self._shape_model

    def _geometry(self, geometry):
        """(static node features, points) of the liver to predict on."""
        import jax.numpy as jnp

        if geometry is None:
            if self.static is None:
                raise ValueError("geometry: this model was trained on several livers; pass "
                                 "geometry=(points, fixed_nodes, shape_coefficients)")
            return self.static, self.points
        points, fixed = np.asarray(geometry[0], dtype=np.float64), np.asarray(geometry[1])
        if points.ndim != 2 or points.shape[1] != 3 or not np.all(np.isfinite(points)):
            raise ValueError("geometry: points must be a finite (n_nodes, 3) array in mm")
        if fixed.size == 0 or fixed.min() < 0 or fixed.max() >= points.shape[0]:
            raise ValueError("geometry: fixed_nodes must be node ids of the given points")
        key = (points.tobytes(), fixed.tobytes())
        if self._geo_key != key:  # static features once per liver
            self._geo_key = key
            self._geo_static = jnp.asarray(static_node_features(points, fixed),
                                           dtype=jnp.float32)
        return self._geo_static, points


class LinearPart:
    """The exact small-strain part of a patient model (``linear_part.npz``, see
    :mod:`surrogate.export`): the sum over the loads of green[load node] . force, a load at
    a node without a unit response taking the nearest one's (an interior or fixed node the
    predictor already warns of).
    """

    def __init__(self, nodes: np.ndarray, green: np.ndarray, points: np.ndarray,
                 output_nodes: np.ndarray):
        from scipy.spatial import cKDTree

        self.green = green
        self.row = cKDTree(points[nodes]).query(points)[1]   # each mesh node's nearest row
        self.output_nodes = output_nodes

    def __call__(self, forces: np.ndarray, load_nodes: np.ndarray, nodes=None) -> np.ndarray:
        """(n_cases, n_out or len(nodes), 3) mm for forces (n_cases, L, 3) N at load_nodes
        (n_cases, L).
        """
        columns = None if nodes is None else \
            np.searchsorted(self.output_nodes, np.asarray(nodes))
        return green_product(self.green, self.row[load_nodes], forces, columns)


def _read_linear_part(d: Path, meta: dict, points, output_nodes) -> LinearPart | None:
    if not meta.get("linear_part"):
        return None
    path = d / meta["linear_part"]
    try:
        with np.load(path, allow_pickle=False) as z:
            nodes, green = z["nodes"], z["green"]
    except (OSError, KeyError, ValueError) as exc:
        raise ValueError(f"{path}: cannot be read ({exc})") from None
    n_out = 0 if output_nodes is None else output_nodes.size
    if points is None or green.shape != (nodes.size, 3, n_out, 3):
        raise ValueError(f"{path}: expected unit responses ({nodes.size}, 3, {n_out}, 3) at "
                         f"the output nodes of the model's liver, got {green.shape}")
    return LinearPart(nodes, green, points, output_nodes)


# The loads a model may have learned: nodal forces (N), or tools grasping a patch and moving
# it (their displacements, mm: scene [loads] kind = "grasp").
LOADS = {"nodal": "forces", "grasp": "grasps"}


def model_load(directory) -> str:
    """The load the exported model in ``directory`` learned: "nodal" or "grasp"."""
    return json.loads((Path(directory) / "model.json").read_text()).get("load", "nodal")


def load_predictor(directory, dtype: str = "float32", load: str = "nodal") -> Predictor:
    """Load an exported model directory; see :class:`Predictor`. ``dtype`` "bfloat16" or
    "float16" runs the network in 16 bits (docs/tradeoff_surrogate.md gives what it costs).
    ``load``: what the caller gives it, "nodal" forces (N) or "grasp" (the tools' pulls, mm);
    ValueError when the model learned the other (its field would answer the wrong load).
    """
    return Predictor(directory, dtype, load)
