"""The node-wise design (``design = "nodewise"``, the paper's): one MLP maps each node's
features to its displacement; an example is one (sample, output node) pair.

Features are assembled inside jit from compact per-geometry and per-sample arrays
(:mod:`surrogate.features`), so no node-by-feature matrix is ever materialised.
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np

from surrogate.data import Dataset
from surrogate.engine import Problem
from surrogate.features import node_features
from surrogate.model import NodeMLP
from surrogate.normalise import Normaliser

EVAL_CHUNK = 65536
NORM_SAMPLE = 200_000  # examples the normalisation statistics and the validation loss use


def batch_features(data: dict, rows, samples, flip=None):
    """Raw features of examples (static row, sample) inside jit, through
    :func:`surrogate.features.node_features`. ``flip`` (B,) swaps the two force blocks (the
    paper's augmentation for two simultaneous forces).
    """
    f = data["forces"][samples]
    lp = data["load_points"][samples]
    if flip is not None:
        f = jnp.where(flip[:, None, None], f[:, ::-1], f)
        lp = jnp.where(flip[:, None, None], lp[:, ::-1], lp)
    return node_features(data["static"][rows], f, lp, data["extra"][samples], xp=jnp)


def example_index(ds: Dataset, samples: np.ndarray) -> tuple[np.ndarray, np.ndarray,
                                                              np.ndarray]:
    """(static rows, sample of each example, target rows) of all examples of ``samples``."""
    rows, smp, tgt = [], [], []
    for s in samples:
        g = ds.sample_geo[s]
        n = ds.geo_offset[g + 1] - ds.geo_offset[g]
        rows.append(np.arange(ds.geo_offset[g], ds.geo_offset[g + 1]))
        smp.append(np.full(n, s))
        tgt.append(np.arange(ds.sample_offset[s], ds.sample_offset[s] + n))
    return np.concatenate(rows), np.concatenate(smp), np.concatenate(tgt)


def device_data(ds: Dataset) -> dict:
    return {"static": jnp.asarray(ds.static), "forces": jnp.asarray(ds.forces),
            "load_points": jnp.asarray(ds.load_points), "extra": jnp.asarray(ds.extra)}


def normalisation(data: dict, targets: np.ndarray, rows, smp, tgt, rng,
                  n_max: int = NORM_SAMPLE) -> Normaliser:
    """Feature and target statistics from (a random subset of) the training examples."""
    pick = rng.choice(rows.size, size=min(n_max, rows.size), replace=False)
    x = np.asarray(batch_features(data, rows[pick], smp[pick]))
    return Normaliser.fit(x, targets[tgt[pick]])


class NodeWiseProblem(Problem):
    """Training examples of the training samples; the normaliser is fitted here and travels
    with the data (``data["norm"]``), so the loss and the exported model share it.
    """

    def __init__(self, ds: Dataset, train: np.ndarray, val: np.ndarray, cfg: dict, rng):
        self.ds, self.cfg = ds, cfg
        self.model = NodeMLP(hidden=tuple(cfg["hidden"]), dropout=cfg["dropout"])
        self.rows, self.smp, self.tgt = example_index(ds, train)
        data = device_data(ds)
        self.norm = normalisation(data, ds.targets, self.rows, self.smp, self.tgt, rng)
        self.data = {**data, "norm": self.norm}
        B = cfg["batch_size"]
        self.per_epoch = max(B, int(cfg["node_fraction"] * self.rows.size)) // B * B
        self.steps_per_epoch = self.per_epoch // B
        self.val = None
        if val.size:
            vr, vs, vt = example_index(ds, val)
            if vr.size > NORM_SAMPLE:
                pick = rng.choice(vr.size, NORM_SAMPLE, replace=False)
                vr, vs, vt = vr[pick], vs[pick], vt[pick]
            self.val = (jnp.asarray(vr), jnp.asarray(vs), jnp.asarray(ds.targets[vt]))

    def init(self, key):
        return self.model.init(key, jnp.zeros((1, self.ds.spec.dim)))["params"]

    def epoch(self, rng):
        n = self.rows.size
        order = rng.choice(n, size=self.per_epoch, replace=self.per_epoch > n)
        return np.split(order, self.steps_per_epoch)

    def batch(self, indices):
        return (jnp.asarray(self.rows[indices]), jnp.asarray(self.smp[indices]),
                jnp.asarray(self.ds.targets[self.tgt[indices]]))

    def validation(self):
        return self.val

    def loss(self, params, data, batch, key, train):
        return _loss(self.model, float(self.cfg["input_noise"]), self.ds.spec.n_loads,
                     params, data, batch, key, train)


def nodewise_loss(model, input_noise: float, n_loads: int):
    """The loss ``(params, data, batch, key, train) -> mse`` of normalised displacements;
    ``data["norm"]`` the normaliser, a batch (static rows, samples, targets in mm).
    """
    return functools.partial(_loss, model, input_noise, n_loads)


def _loss(model, input_noise, n_loads, params, data, batch, key, train):
    rows, samples, targets = batch
    norm = data["norm"]
    k_noise, k_drop, k_flip = jax.random.split(key, 3)
    flip = (jax.random.bernoulli(k_flip, 0.5, (rows.shape[0],))
            if (train and n_loads == 2) else None)
    x = norm.inputs(batch_features(data, rows, samples, flip))
    if train and input_noise > 0:
        x = x + input_noise * jax.random.normal(k_noise, x.shape)
    pred = model.apply({"params": params}, x, train=train, rngs={"dropout": k_drop})
    return jnp.mean((pred - norm.targets(targets)) ** 2)


@functools.lru_cache(maxsize=8)
def _predict_fn(hidden: tuple, dropout: float):
    model = NodeMLP(hidden=hidden, dropout=dropout)

    @jax.jit
    def predict(params, norm, data, rows, samples):
        x = norm.inputs(batch_features(data, rows, samples))
        return norm.outputs(model.apply({"params": params}, x, train=False))

    return predict


class NodeWise:
    """The design's entry in the registry (:data:`surrogate.designs.DESIGNS`)."""

    name = "nodewise"
    label = "node-wise"
    # the shape it is told for a liver outside its population (ShapeModel.shape_told): each
    # coefficient clipped to the population's range; it also sees the registered nodes, which
    # a shape far from its coefficients contradicts (chosen on phantoms drawn beyond the
    # population, docs/shape_rule.md)
    shape_rule = "range"
    needs_liver = False   # a model of a population has no liver of its own
    on_template = False
    node_sampled = True   # trains on a fraction of the nodes per epoch (node_fraction)
    takes = frozenset({"dropout"})  # the design-specific config keys it reads

    def check(self, ds: Dataset, cfg: dict | None = None) -> None:
        """Every dataset takes the node-wise design."""

    def scene_problem(self, varies_geometry: bool) -> str | None:
        """Every scene takes the node-wise design."""
        return None

    def problem(self, ds, train, val, cfg, rng) -> NodeWiseProblem:
        return NodeWiseProblem(ds, train, val, cfg, rng)

    def model(self, problem: NodeWiseProblem, params) -> tuple:
        """The trained model: (parameters, normaliser)."""
        return params, problem.norm

    def predict_samples(self, ds: Dataset, model, cfg: dict, samples: np.ndarray):
        """Predicted and true displacement (mm) of every output node of ``samples``."""
        params, norm = model
        predict = _predict_fn(tuple(cfg["hidden"]), float(cfg["dropout"]))
        data = device_data(ds)
        rows, smp, tgt = example_index(ds, samples)
        out = np.empty((rows.size, 3), dtype=np.float32)
        for i in range(0, rows.size, EVAL_CHUNK):
            r, s = rows[i:i + EVAL_CHUNK], smp[i:i + EVAL_CHUNK]
            n = r.size
            pad = EVAL_CHUNK - n  # one compiled shape for every chunk
            r = np.concatenate([r, np.repeat(r[:1], pad)])
            s = np.concatenate([s, np.repeat(s[:1], pad)])
            out[i:i + n] = np.asarray(predict(params, norm, data, jnp.asarray(r),
                                              jnp.asarray(s)))[:n]
        return out, ds.targets[tgt], smp

    def export_parts(self, model) -> tuple[dict, dict, dict]:
        """(parameters, statistics for model.json, extra arrays files) of the export."""
        params, norm = model
        return params, norm.to_dict(), {}

    def runtime(self, d, pred, hidden: tuple, dropout: float, dtype: str) -> NodeWiseRuntime:
        """The exported model in ``d`` at prediction time."""
        return NodeWiseRuntime(d, pred, hidden, dropout, dtype)


class NodeWiseRuntime:
    """An exported node-wise model at prediction time: its network over the selected nodes'
    static features (:class:`surrogate.predictor.Predictor` checks the inputs).
    """

    modes = None
    outputs_only = False  # predicts any node of the liver it is given

    def __init__(self, d, pred, hidden: tuple, dropout: float, dtype: str):
        from surrogate.model_files import read_params

        meta = pred.meta
        params = read_params(d / "params.npz", pred.spec.dim, hidden, version=meta["version"])
        # Reduced precision: the weights and the network's activations are cast; features,
        # normalisation and the returned millimetres stay float32.
        self.params = jax.tree_util.tree_map(lambda w: jnp.asarray(w, dtype=dtype), params)
        self.norm = Normaliser.from_dict(meta.get("stats"), pred.spec.dim,
                                         where=f"{d / 'model.json'}: stats")
        model = NodeMLP(hidden=hidden, dropout=dropout)

        def one_case(params, norm, static, forces, load_points, extra):
            x = norm.inputs(node_features(static, forces, load_points, extra, xp=jnp))
            y = model.apply({"params": params}, x.astype(dtype), train=False)
            return norm.outputs(y.astype(jnp.float32))

        self._batched = jax.jit(jax.vmap(one_case, in_axes=(None, None, None, 0, 0, 0)))

    def check_geometry(self, pred, geometry) -> None:
        """Any liver: its static features are computed from the points given."""

    def check_points(self, pred, n_nodes: int) -> None:
        """Any number of nodes."""

    def all_rows(self, static):
        return static

    def rows(self, pred, static, nodes):
        return static[jnp.asarray(nodes)]

    def apply(self, pred, rows, forces, load_points, extra, load_nodes, liver):
        return self._batched(self.params, self.norm, rows, forces, load_points, extra)

    def on_nodes(self, params, n_nodes: int, rng):
        """The trained model to export on another cloud of ``n_nodes`` nodes (timing): the
        same network and statistics (its features are computed at the nodes).
        """
        return params, self.norm
