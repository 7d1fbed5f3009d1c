"""Exported models: plain files only (JSON + .npz read with allow_pickle=False), so loading a
model never executes code. ``load_predictor(path)`` returns a jitted predictor in millimetres.

    RUN/model/model.json     format, version, config, feature spec, normalisation statistics,
                             training ranges
    RUN/model/params.npz     network parameters, keys "hidden_0/kernel", ..., "output/bias"
                             (the reduced basis: "coefficients/..." for its last layer)
    RUN/model/geometry.npz   the liver (points, fixed nodes, output nodes, outward surface
                             triangles, the nodes the scene loads) when the scene has one
                             liver: enough to draw it
    RUN/model/shape_model.npz  when the scene varies the liver: the template, the PCA of the
                             population and the registration settings
                             (:class:`liverreg.shape_model.ShapeModel`): what a new liver
                             needs (``python -m surrogate predict-liver``)
"""

from __future__ import annotations

import json
import logging
import warnings
from pathlib import Path

import numpy as np
from flax import traverse_util

from surrogate.config import DESIGN_NAMES
from surrogate.features import FeatureSpec, node_features, static_node_features
from surrogate.normalise import Normaliser

MODEL_FORMAT = "liverfem-surrogate"
MODEL_VERSION = 3          # 3: explicit layer names; 2: the design is recorded
READABLE_VERSIONS = (1, 2, 3)  # 1-2: flax's automatic names Dense_i; version 1 is node-wise
# Inference precisions: float32 (as trained), or the weights and activations cast to 16 bits.
PRECISIONS = ("float32", "bfloat16", "float16")
# Designs whose field is a combination of stored modes (surrogate/basis.py,
# surrogate/population_basis.py); the population's modes live on the template's nodes.
BASIS_DESIGNS = ("basis", "population_basis")
log = logging.getLogger(__name__)


def export_model(directory, model, cfg, ds, unseen=()) -> Path:
    """Write a model directory from a trained model of the config's design (node-wise:
    (parameters, normaliser); basis: a :class:`surrogate.basis.BasisModel`) and its dataset.
    ``unseen``: the simulations the model never trained on (recorded for viewers).
    """
    from surrogate.designs import DESIGNS

    params, stats, files = DESIGNS[cfg["design"]].export_parts(model)
    d = _export(directory, params, {"design": cfg["design"], "stats": stats}, cfg, ds, unseen)
    for name, arrays in files.items():
        np.savez(d / name, **arrays)
    return d


def _export(directory, params, design: dict, cfg, ds, unseen=()) -> Path:
    d = Path(directory)
    d.mkdir(parents=True, exist_ok=True)
    flat = traverse_util.flatten_dict(params, sep="/")
    np.savez(d / "params.npz", **{k: np.asarray(v) for k, v in flat.items()})
    fnorm = np.linalg.norm(ds.forces, axis=-1)
    meta = {
        "format": MODEL_FORMAT, "version": MODEL_VERSION, "scene": ds.scene_name,
        "config": cfg, "feature_spec": ds.spec.to_dict(), "feature_names": ds.spec.names(),
        **design,
        "training_range": {
            "force_norm_max": float(fnorm.max()),
            "extra_min": ds.extra.min(axis=0).tolist() if ds.extra.size else [],
            "extra_max": ds.extra.max(axis=0).tolist() if ds.extra.size else []},
        "units": {"length": "mm", "force": "N", "stress": "MPa"},
        # Simulations held out of the exported model's training (its early-stopping slice):
        # the honest cases to compare it with the FE solution on (surrogate.viewer --compare).
        "unseen_simulations": sorted(int(i) for i in unseen),
    }
    meta["embedded_geometry"] = len(ds.points) == 1
    loadable = getattr(ds, "loadable", None)
    if meta["embedded_geometry"]:
        extra = {} if loadable is None else {"loadable": loadable[0]}
        np.savez(d / "geometry.npz", points=ds.points[0], fixed=ds.fixed[0],
                 output_nodes=ds.out_nodes[0], triangles=ds.triangles[0], **extra)
    if ds.spec.geometry_dim and getattr(ds, "directory", None) is not None:
        from surrogate.population import population_shape_model

        shape_model = population_shape_model(ds)
        if shape_model is not None:
            shape_model.save(d / "shape_model.npz")
            meta["shape_model"] = "shape_model.npz"
            if design["design"] == "population_basis":  # its modes live on the template
                np.savez(d / "geometry.npz", points=shape_model.template_points,
                         fixed=shape_model.fixed_nodes,
                         output_nodes=np.arange(shape_model.template_points.shape[0]),
                         triangles=shape_model.surface_triangles,
                         loadable=shape_model.loadable_nodes)
    (d / "model.json").write_text(json.dumps(meta, indent=1))
    return d


def _read_meta(path: Path) -> dict:
    try:
        meta = json.loads(path.read_text())
    except FileNotFoundError:
        raise ValueError(f"{path}: missing (not a model directory?)") from None
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise ValueError(f"{path}: not valid JSON ({exc})") from None
    if not isinstance(meta, dict):
        raise ValueError(f"{path}: expected a JSON object, got {type(meta).__name__}")
    if meta.get("format") != MODEL_FORMAT:
        raise ValueError(f"{path}: not a {MODEL_FORMAT} model")
    if meta.get("version") not in READABLE_VERSIONS:
        raise ValueError(f"{path}: version {meta.get('version')!r}, this code reads "
                         f"{', '.join(map(str, READABLE_VERSIONS))}")
    design = meta.setdefault("design", "nodewise")
    if design not in DESIGN_NAMES:
        raise ValueError(f"{path}: design {design!r}, expected one of "
                         f"{', '.join(DESIGN_NAMES)}")
    return meta


def layer_names(n_hidden: int, last: str) -> list[str]:
    return [f"hidden_{i}" for i in range(n_hidden)] + [last]


def _read_params(path: Path, dim: int, hidden: tuple[int, ...], out: int = 3,
                 version: int = MODEL_VERSION, last: str = "output", members: int = 1) -> dict:
    """The network's parameters, checked against the architecture in the config: every layer
    present with the right shapes, every value finite; an ensemble's arrays carry its
    ``members`` along a leading axis. Models before version 3 name their layers Dense_0,
    Dense_1, ... in order; they are read under the explicit names.
    """
    try:
        with np.load(path, allow_pickle=False) as z:
            flat = {k: z[k] for k in z.files}
    except FileNotFoundError:
        raise ValueError(f"{path}: missing") from None
    except (OSError, ValueError) as exc:  # truncated, not an npz, or a pickled array
        raise ValueError(f"{path}: cannot be read without executing code ({exc})") from None
    names = layer_names(len(hidden), last)
    if version < 3:
        old = {f"Dense_{i}": n for i, n in enumerate(names)}
        flat = {f"{old.get(k.split('/')[0], k.split('/')[0])}/{k.split('/', 1)[-1]}": v
                for k, v in flat.items()}
    widths = (dim, *hidden, out)
    want = {}
    lead = (members,) if members > 1 else ()
    for i, name in enumerate(names):
        want[f"{name}/kernel"] = (*lead, widths[i], widths[i + 1])
        want[f"{name}/bias"] = (*lead, widths[i + 1])
    problems = [f"'{k}' has shape {flat[k].shape}, the config says {shape}"
                for k, shape in want.items() if k in flat and flat[k].shape != shape]
    problems += [f"'{k}' is missing" for k in want if k not in flat]
    problems += [f"'{k}' is not part of the network" for k in flat if k not in want]
    problems += [f"'{k}' contains NaN or inf" for k in want
                 if k in flat and not np.all(np.isfinite(flat[k]))]
    if problems:
        raise ValueError(f"{path}: " + "; ".join(problems))
    return traverse_util.unflatten_dict(flat, sep="/")


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

    def __init__(self, directory, dtype: str = "float32"):
        import jax
        import jax.numpy as jnp

        from surrogate.model import NodeMLP

        if dtype not in PRECISIONS:
            raise ValueError(f"dtype: expected one of {sorted(PRECISIONS)}, got {dtype!r}")
        self.dtype = dtype
        d = Path(directory)
        meta = _read_meta(d / "model.json")
        self.meta = meta
        try:
            self.spec = FeatureSpec(**meta["feature_spec"])
            cfg = meta["config"]
            hidden = tuple(int(w) for w in cfg["hidden"])
            dropout = float(cfg["dropout"])
            self.force_norm_max = float(meta["training_range"]["force_norm_max"])
        except (KeyError, TypeError, ValueError) as exc:
            raise ValueError(f"{d / 'model.json'}: incomplete or malformed ({exc!r})") from None
        self.design = meta["design"]
        geo = d / "geometry.npz"
        if geo.exists():
            try:
                with np.load(geo, allow_pickle=False) as z:
                    self.points, self.fixed = z["points"], z["fixed"]
                    self.output_nodes = z["output_nodes"]
                    # Models exported before the triangles were stored have none.
                    self.triangles = z["triangles"] if "triangles" in z.files else None
                    self.loadable = z["loadable"] if "loadable" in z.files else None
            except (OSError, KeyError, ValueError) as exc:
                raise ValueError(f"{geo}: cannot be read ({exc})") from None
            self.static = jnp.asarray(static_node_features(self.points, self.fixed),
                                      dtype=jnp.float32)
        elif meta.get("embedded_geometry") or self.design in BASIS_DESIGNS:
            raise ValueError(f"{geo}: missing (the model was exported with its liver)")
        else:
            self.points = self.fixed = self.static = self.output_nodes = None
            self.triangles = self.loadable = None
        self._shape_model_path = d / meta["shape_model"] if meta.get("shape_model") else None
        self._shape_model = None
        if self.design in BASIS_DESIGNS:
            self._init_basis(d, meta, hidden, dtype)
            return
        params = _read_params(d / "params.npz", self.spec.dim, hidden,
                              version=meta["version"])
        # Reduced precision: the weights and the network's activations are cast; features,
        # normalisation and the returned millimetres stay float32.
        self.params = jax.tree_util.tree_map(lambda w: jnp.asarray(w, dtype=dtype), params)
        self.norm = Normaliser.from_dict(meta.get("stats"), self.spec.dim,
                                         where=f"{d / 'model.json'}: stats")
        model = NodeMLP(hidden=hidden, dropout=dropout)

        def one_case(params, norm, static, forces, load_points, extra):
            x = norm.inputs(node_features(static, forces, load_points, extra, xp=jnp))
            y = model.apply({"params": params}, x.astype(dtype), train=False)
            return norm.outputs(y.astype(jnp.float32))

        self._batched = jax.jit(jax.vmap(one_case, in_axes=(None, None, None, 0, 0, 0)))

    def __call__(self, forces, load_nodes, nodes=None, material=None, geometry=None):
        import jax.numpy as jnp

        forces = np.asarray(forces, dtype=np.float64)
        load_nodes = np.asarray(load_nodes)
        single = forces.ndim == 2
        if single:
            forces, load_nodes = forces[None], load_nodes[None]
        L = self.spec.n_loads
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
        if self.design == "basis" and geometry is not None:
            raise ValueError("geometry: a reduced-basis model predicts on the liver it was "
                             "trained on only (its modes live on those nodes)")
        static, points = self._geometry(geometry)
        n_nodes = points.shape[0]
        if self.design == "population_basis" and n_nodes != self.output_nodes.size:
            raise ValueError(f"geometry: a population-basis model predicts on the registered "
                             f"template ({self.output_nodes.size} nodes; "
                             "surrogate.predict_liver places a liver), got {n_nodes} points")
        if not np.issubdtype(load_nodes.dtype, np.integer) or load_nodes.min() < 0 or \
                load_nodes.max() >= n_nodes:
            raise ValueError(f"load_nodes: expected integer node ids in [0, {n_nodes})")
        if nodes is not None:
            nodes = np.asarray(nodes)
            if not np.issubdtype(nodes.dtype, np.integer) or nodes.ndim != 1 or (
                    nodes.size and (nodes.min() < 0 or nodes.max() >= n_nodes)):
                raise ValueError(f"nodes: expected a 1-D array of node ids in [0, {n_nodes})")
            # The rows of the selected nodes, gathered once per (liver, node set): a caller
            # that asks for the surface at every frame pays for the surface only.
            key = (None if geometry is None else self._geo_key, nodes.dtype.str, nodes.shape,
                   nodes.tobytes())
            if getattr(self, "_sel_key", None) != key:
                self._sel_key = key
                self._sel = (self._basis_rows(nodes) if self.design in BASIS_DESIGNS
                             else static[jnp.asarray(nodes)])
            static = self._sel
        elif self.design in BASIS_DESIGNS:
            static = self._modes
        blocks = []
        if material is not None and not self.spec.material_dim:
            raise ValueError("material: this model was trained on one material and takes "
                             "none (its scene did not vary the material)")
        if self.spec.material_dim:
            if material is None:
                raise ValueError("material: this model needs (c, m, K) for each case")
            mat = np.asarray(material, dtype=np.float64).reshape(-1, self.spec.material_dim)
            if not np.all(np.isfinite(mat)):
                raise ValueError("material: contains NaN or inf")
            self._check_range("material", mat, 0, self.spec.material_dim)
            blocks.append(np.broadcast_to(mat, (forces.shape[0], self.spec.material_dim)))
        if self.spec.geometry_dim:
            shape = np.asarray(geometry[2] if geometry is not None else [], dtype=np.float64)
            if shape.shape != (self.spec.geometry_dim,):
                raise ValueError(f"geometry: expected {self.spec.geometry_dim} shape "
                                 f"coefficients, got {shape.shape}")
            if not np.all(np.isfinite(shape)):
                raise ValueError("geometry: shape coefficients contain NaN or inf")
            m0 = self.spec.material_dim
            self._check_range("shape coefficients", shape[None], m0,
                              m0 + self.spec.geometry_dim)
            blocks.append(np.broadcast_to(shape, (forces.shape[0], shape.size)))
        extra = np.concatenate(blocks, axis=1) if blocks else np.zeros((forces.shape[0], 0))
        if geometry is None and self.loadable is not None:
            check_load_nodes(load_nodes, self.loadable)
        fmax = np.linalg.norm(forces, axis=-1).max()
        if fmax > 1.05 * self.force_norm_max:
            warnings.warn(f"force magnitude {fmax:.3g} N exceeds the training range "
                          f"({self.force_norm_max:.3g} N): "
                          "extrapolating", stacklevel=2)
        # numpy in: the jitted call takes host arrays on its fast path (jnp.asarray here would
        # dispatch one eager conversion per argument, most of a small model's call)
        args = (np.asarray(forces, dtype=np.float32),
                np.asarray(points[load_nodes], dtype=np.float32),
                np.asarray(extra, dtype=np.float32))
        if self.design in BASIS_DESIGNS:
            out = self._batched_basis(self.params, static, *args,
                                      self._load_context(points, load_nodes, geometry))
        else:
            out = self._batched(self.params, self.norm, static, *args)
        out = np.asarray(out)
        return out[0] if single else out


    # ------------------------------------------------------------------------------------------
    # The reduced-basis design (surrogate/basis.py)
    # ------------------------------------------------------------------------------------------
    def _init_basis(self, d: Path, meta: dict, hidden: tuple, dtype: str) -> None:
        import jax
        import jax.numpy as jnp

        from surrogate.basis import (
            LOAD_FEATURES,
            BasisModel,
            coefficients,
            input_width,
            member_mean,
            model_network,
        )
        from surrogate.population_basis import CONTEXT

        where = d / "basis.npz"
        try:
            with np.load(where, allow_pickle=False) as z:
                modes = np.asarray(z["modes"], dtype=np.float32)
        except FileNotFoundError:
            raise ValueError(f"{where}: missing (a reduced-basis model needs its modes)") \
                from None
        except (OSError, KeyError, ValueError) as exc:
            raise ValueError(f"{where}: cannot be read ({exc})") from None
        n_out = self.output_nodes.size
        if modes.ndim != 2 or modes.shape[1] != 3 * n_out or not np.all(np.isfinite(modes)):
            raise ValueError(f"{where}: modes must be a finite (k, {3 * n_out}) array for the "
                             f"{n_out} output nodes, got shape {modes.shape}")
        L, e = self.spec.n_loads, self.spec.material_dim + self.spec.geometry_dim
        st = meta.get("stats")
        try:
            x_mean = np.asarray(st["x_mean"], dtype=np.float32)
            x_std = np.asarray(st["x_std"], dtype=np.float32)
            c_scale, f_scale = float(st["c_scale"]), float(st["f_scale"])
            n_extra = st.get("n_extra", e)  # models written before shape_inputs: all
            context = st.get("context", 0)  # and before load_context: none
            members = st.get("members", 1)  # and before ensembles: one network
            shared = st.get("shared_loads", False)  # and before shared loads: one per load
        except (KeyError, TypeError, ValueError, AttributeError):
            raise ValueError(f"{d / 'model.json'}: stats: expected x_mean, x_std, c_scale, "
                             "f_scale") from None
        if not (isinstance(members, int) and members >= 1):
            raise ValueError(f"{d / 'model.json'}: stats: members: expected an integer >= 1, "
                             f"got {members!r}")
        if not isinstance(shared, bool):
            raise ValueError(f"{d / 'model.json'}: stats: shared_loads: expected true or "
                             f"false, got {shared!r}")
        if not (isinstance(n_extra, int) and self.spec.material_dim <= n_extra <= e):
            raise ValueError(f"{d / 'model.json'}: stats: n_extra: expected an integer from "
                             f"{self.spec.material_dim} to {e}, got {n_extra!r}")
        if context not in (0, CONTEXT) or (context and self.design != "population_basis"):
            raise ValueError(f"{d / 'model.json'}: stats: context: expected 0"
                             + (f" or {CONTEXT}" if self.design == "population_basis" else "")
                             + f", got {context!r}")
        self._context = context
        dim = (LOAD_FEATURES + context) * L + n_extra
        k = modes.shape[0]
        params = _read_params(d / "params.npz",
                              input_width(L, LOAD_FEATURES + context, n_extra, shared), hidden,
                              out=3 * k * (1 if shared else L),
                              version=meta["version"], last="coefficients", members=members)
        if x_mean.shape != (dim,) or x_std.shape != (dim,) or not (
                np.all(np.isfinite(x_mean)) and np.all(x_std > 0) and c_scale > 0
                and f_scale > 0 and np.isfinite(c_scale) and np.isfinite(f_scale)):
            raise ValueError(f"{d / 'model.json'}: stats: {dim} finite means, positive scales "
                             "and positive finite c_scale, f_scale expected")
        # The modes are stored per output node; a node set picks its 3 rows.
        self._out_row = {int(n): i for i, n in enumerate(self.output_nodes.tolist())}
        self._modes_np = modes.reshape(k, n_out, 3)
        self._modes = jnp.asarray(modes, dtype=dtype)
        self.params = jax.tree_util.tree_map(lambda w: jnp.asarray(w, dtype=dtype), params)
        self.norm = None
        stats = BasisModel(params=None, modes=None, x_mean=x_mean, x_std=x_std,
                           c_scale=c_scale, f_scale=f_scale, hidden=hidden, n_loads=L,
                           n_extra=n_extra, context=context, members=members,
                           shared_loads=shared)
        self._basis_stats = stats  # the model without its parameters and modes
        net = model_network(stats, k)

        def one_case(params, modes, forces, load_points, extra, ctx):
            apply = member_mean(net, params, members, cast=lambda a: a.astype(dtype))
            c = coefficients(stats, forces, load_points, extra, xp=jnp, apply=apply,
                             context=ctx if context else None)
            return (c.astype(dtype) @ modes).astype(jnp.float32).reshape(-1, 3)

        self._batched_basis = jax.jit(jax.vmap(one_case, in_axes=(None, None, 0, 0, 0, 0)))

    def _load_context(self, points, load_nodes, geometry):
        """(n_cases, n_loads, c) the loads' context on the liver predicted on (the population
        basis's, c = 0 for a model without it): a load node of the registered template is the
        template's node of the same id.
        """
        import jax.numpy as jnp

        if not self._context:
            return np.zeros(load_nodes.shape + (0,), dtype=np.float32)
        from surrogate.population_basis import load_context

        # once per (liver, load nodes): a manipulator drags one node with changing forces
        key = (None if geometry is None else self._geo_key, load_nodes.dtype.str,
               load_nodes.shape, load_nodes.tobytes())
        if getattr(self, "_ctx_key", None) != key:
            fixed = self.fixed if geometry is None else np.asarray(geometry[1])
            self._ctx_key = key
            self._ctx = jnp.asarray(load_context(points[load_nodes], self.points[load_nodes],
                                                 points[fixed]), dtype=jnp.float32)
        return self._ctx

    def _basis_rows(self, nodes: np.ndarray):
        import jax.numpy as jnp

        rows = [self._out_row.get(int(n)) for n in nodes.tolist()]
        if any(r is None for r in rows):
            raise ValueError("nodes: a reduced-basis model predicts its scene's output nodes "
                             f"only ({self.output_nodes.size} of {self.points.shape[0]})")
        k = self._modes_np.shape[0]
        return jnp.asarray(self._modes_np[:, rows].reshape(k, -1), dtype=self._modes.dtype)

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
                          f"[{lo.tolist()}, {hi.tolist()}]: extrapolating", stacklevel=3)

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
        if getattr(self, "_geo_key", None) != key:  # static features once per liver
            self._geo_key = key
            self._geo_static = jnp.asarray(static_node_features(points, fixed),
                                           dtype=jnp.float32)
        return self._geo_static, points


def check_load_nodes(load_nodes, loadable) -> None:
    """Warn when a load acts on a node the scene never loads (interior, fixed, or closer to the
    fixed region than its minimum distance): no training example had a load there.
    """
    bad = np.setdiff1d(np.asarray(load_nodes).ravel(), loadable)
    if bad.size:
        warnings.warn(f"load node(s) {bad[:10].tolist()} never loaded in training (the scene "
                      "loads surface nodes away from the fixed region; these are interior, "
                      "fixed or too close to it): extrapolating", stacklevel=3)


def load_predictor(directory, dtype: str = "float32") -> Predictor:
    """Load an exported model directory; see :class:`Predictor`. ``dtype`` "bfloat16" or
    "float16" runs the network in 16 bits (docs/tradeoff_surrogate.md gives what it costs).
    """
    return Predictor(directory, dtype)
