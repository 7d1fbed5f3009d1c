"""The reduced-basis design (``design = "basis"``): the whole field from one small network.

A node-wise MLP repeats the whole network once per node, so its cost grows with the mesh. Here
the displacement field of a load case is a combination of ``modes`` fixed fields,

    u(loads) = sum_i c_i(loads) phi_i,      c = M(x) f / f_scale,

with phi_i the leading right singular vectors of the training displacement fields (orthonormal,
so the loss on c is the loss on u in mm^2, and the basis error is known before any training:
``projection_mee``), x the global load features (per load: the load node's coordinates, the
force direction and magnitude; then the material and shape inputs when the scene varies them;
``shape_inputs`` tells the population design only the leading shape coefficients), and M(x) a
(modes x 3 n_loads) matrix from a small MLP: the field is linear in the force at a fixed
direction and magnitude, and zero without load. A call costs one small network plus one (3N x
modes) product, for any number of nodes (docs/realtime.md).

With several loads and ``shared_loads``, one network serves every load: load l's (modes x 3)
block is M(x_l, mean of the other loads' x, extra), and c = sum_l M_l f_l / f_scale. The
prediction then does not depend on the order in which the loads are listed, and each training
case teaches the one map once per load (a sum of one-load responses, corrected by what the
other loads are doing). With one load it is the same network as without.

It needs one liver (the basis lives on its nodes); a scene that varies the geometry takes the
population basis (:mod:`surrogate.population_basis`) or the node-wise design. Pure functions of
arrays; trained by the one loop of :mod:`surrogate.engine`.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import flax.linen as nn
import jax
import jax.numpy as jnp
import numpy as np

from surrogate.data import Dataset
from surrogate.engine import Problem
from surrogate.metrics import mee

LOAD_FEATURES = 7  # per load: point (3), force direction (3), force magnitude (1)


class BasisDesignError(ValueError):
    """The dataset cannot take the reduced-basis design."""


@dataclass
class BasisModel:
    """A trained reduced-basis surrogate (numpy arrays; the network's parameters as a dict)."""

    params: dict
    modes: np.ndarray       # (k, 3 n_out) orthonormal rows, float32
    x_mean: np.ndarray      # (dim,) feature statistics
    x_std: np.ndarray
    c_scale: float          # coefficient scale the network is trained in, mm
    f_scale: float          # force scale, N
    hidden: tuple
    n_loads: int
    n_extra: int            # leading columns of the extra inputs the network is told
    context: int = 0        # per-load context features (the population design's), or 0
    members: int = 1        # networks of an ensemble (their arrays: a leading axis), or 1
    shared_loads: bool = False  # one network for every load (module docstring)

    def stats(self) -> dict:
        return {"x_mean": self.x_mean.tolist(), "x_std": self.x_std.tolist(),
                "c_scale": self.c_scale, "f_scale": self.f_scale, "n_extra": self.n_extra,
                "context": self.context, "members": self.members,
                "shared_loads": self.shared_loads}


def load_features(forces, load_points, extra, xp=np, context=None):
    """(..., (7 + c) n_loads + e) global features of load cases: per load its point, force
    direction and magnitude, then its ``context`` (..., n_loads, c) if given; then ``extra``.
    """
    mag = xp.sqrt(xp.sum(forces * forces, axis=-1, keepdims=True))
    direction = forces / xp.maximum(mag, 1e-12)
    per = [load_points, direction, mag] + ([] if context is None else [context])
    per = xp.concatenate(per, axis=-1)  # (..., L, 7 + c)
    flat = per.reshape(per.shape[:-2] + (per.shape[-2] * per.shape[-1],))
    return xp.concatenate([flat, extra], axis=-1)


def per_load_inputs(x, n_loads: int, per: int):
    """(..., n_loads, in) the shared network's input of each load from the global features
    (..., per n_loads + e): the load's own ``per`` features, the mean of the other loads'
    (with two or more loads), then the extra inputs.
    """
    own = x[..., :n_loads * per].reshape(x.shape[:-1] + (n_loads, per))
    extra = jnp.broadcast_to(x[..., None, n_loads * per:],
                             x.shape[:-1] + (n_loads, x.shape[-1] - n_loads * per))
    parts = [own]
    if n_loads > 1:
        parts.append((own.sum(axis=-2, keepdims=True) - own) / (n_loads - 1))
    return jnp.concatenate(parts + [extra], axis=-1)


def input_width(n_loads: int, per: int, n_extra: int, shared: bool) -> int:
    """The first layer's input width."""
    if shared:
        return per * (2 if n_loads > 1 else 1) + n_extra
    return per * n_loads + n_extra


class BasisMLP(nn.Module):
    """(features, forces / f_scale) -> mode coefficients (modes,): hidden GELU layers
    ``hidden_i``, then ``coefficients``, the (modes x 3 n_loads) matrix applied to the forces;
    ``shared``: one network per load (inputs :func:`per_load_inputs`, ``per`` features per
    load), its (modes x 3) blocks applied to each load's force and summed.
    """

    hidden: tuple
    modes: int
    n_loads: int
    shared: bool = False
    per: int = LOAD_FEATURES

    @nn.compact
    def __call__(self, x, f):
        if self.shared:
            x = per_load_inputs(x, self.n_loads, self.per)
        for i, width in enumerate(self.hidden):
            x = nn.gelu(nn.Dense(width, name=f"hidden_{i}")(x))
        if self.shared:
            M = nn.Dense(self.modes * 3, name="coefficients")(x)
            M = M.reshape(x.shape[:-1] + (self.modes, 3))  # (..., n_loads, modes, 3)
            return jnp.einsum("...lkj,...lj->...k", M, f)
        M = nn.Dense(self.modes * 3 * self.n_loads, name="coefficients")(x)
        M = M.reshape(x.shape[:-1] + (self.modes, 3 * self.n_loads))
        return jnp.einsum("...kj,...j->...k", M, f.reshape(f.shape[:-2] + (-1,)))


def network(hidden, modes: int, n_loads: int, shared: bool = False,
            per: int = LOAD_FEATURES) -> BasisMLP:
    return BasisMLP(hidden=tuple(hidden), modes=int(modes), n_loads=int(n_loads),
                    shared=bool(shared), per=int(per))


def model_network(model: BasisModel, modes: int) -> BasisMLP:
    """The network of a trained or exported model with ``modes`` modes (its statistics say
    which network).
    """
    return network(model.hidden, modes, model.n_loads, model.shared_loads,
                   LOAD_FEATURES + model.context)


def member_mean(net: BasisMLP, params, members: int = 1, cast=lambda a: a):
    """``apply(x, f)``: the network's coefficients, or for an ensemble (parameters with a
    leading member axis) the mean of its members' (``cast``: the inputs' precision).
    """
    def one(p, x, f):
        return net.apply({"params": p}, cast(x), cast(f))

    if members == 1:
        return lambda x, f: one(params, x, f)
    return lambda x, f: jnp.mean(jax.vmap(one, in_axes=(0, None, None))(params, x, f), axis=0)


def fields(ds: Dataset, samples: np.ndarray) -> np.ndarray:
    """(len(samples), 3 n_out) displacement fields of samples, float64."""
    n = int(ds.sample_offset[1] - ds.sample_offset[0])
    return np.stack([np.asarray(ds.targets[ds.sample_offset[s]:ds.sample_offset[s] + n],
                                dtype=np.float64).ravel() for s in samples])


def check_dataset(ds: Dataset) -> None:
    if len(ds.points) != 1 or ds.spec.geometry_dim:
        raise BasisDesignError("design 'basis' needs a scene with one liver (the basis lives "
                               f"on its nodes); this dataset has {len(ds.points)} livers: use "
                               "design 'nodewise'")


def extra_inputs(spec, cfg: dict) -> int:
    """How many leading columns of the extra inputs (material, then shape coefficients in
    order of explained variance) the network is told: all of them, or the material and the
    first ``cfg["shape_inputs"]`` shape coefficients.
    """
    k = cfg.get("shape_inputs", "all")
    shapes = spec.geometry_dim if k == "all" else min(int(k), spec.geometry_dim)
    return spec.material_dim + shapes


def compute_modes(U: np.ndarray, k: int, seed: int = 0) -> np.ndarray:
    """The ``k`` leading right singular vectors of the fields ``U`` (S, 3n), as rows.

    Exact SVD when the fields are few or short; otherwise a randomised range finder with two
    power iterations (Halko, Martinsson and Tropp 2011), accurate for the leading modes.
    """
    k = min(k, *U.shape)
    if min(U.shape) <= 3000:
        return np.linalg.svd(U, full_matrices=False)[2][:k]
    rng = np.random.default_rng(seed)
    Y = U.T @ (U @ rng.standard_normal((U.shape[1], k + 16)))
    for _ in range(2):
        Y = np.linalg.qr(U.T @ (U @ np.linalg.qr(Y)[0]))[0]
    Q = np.linalg.qr(Y)[0]                      # (3n, k + 16) basis of the row space
    _, _, Wt = np.linalg.svd(U @ Q, full_matrices=False)
    return (Q @ Wt.T).T[:k]


def projection_mee(U: np.ndarray, modes: np.ndarray) -> float:
    """Mean Euclidean node error (mm) of the fields U projected on the modes: the floor the
    network cannot beat.
    """
    return mee(U @ modes.T @ modes, U)


class BasisProblem(Problem):
    """Modes of the training fields, then a network from the loads to their coefficients;
    an example is one sample (a whole field).
    """

    def __init__(self, ds: Dataset, tr: np.ndarray, va: np.ndarray, cfg: dict, seed: int,
                 fields_of=None, context=None):
        """``fields_of(samples)``: the samples' fields in the basis' node order (default: the
        one liver's output nodes, :func:`fields`); ``context``: (n_samples, n_loads, c)
        per-load features beside the load's own (default: none).
        """
        if fields_of is None:
            check_dataset(ds)
            fields_of = lambda s: fields(ds, s)  # noqa: E731
        U = fields_of(tr)
        self.modes = compute_modes(U, cfg["modes"], seed).astype(np.float32)
        self.projection_mee = projection_mee(U, self.modes.astype(np.float64))
        self.n_extra = extra_inputs(ds.spec, cfg)
        self.context = 0 if context is None else int(context.shape[-1])
        X = load_features(ds.forces, ds.load_points, ds.extra[:, :self.n_extra],
                          context=context)
        L, per = ds.spec.n_loads, LOAD_FEATURES + self.context
        self.shared = bool(cfg.get("shared_loads", False))
        Xs = X[tr]
        if self.shared:  # one network reads every load: the loads share their statistics
            pooled = Xs[:, :L * per].reshape(-1, per)
            mean = np.concatenate([np.tile(pooled.mean(axis=0), L), Xs[:, L * per:].mean(0)])
            std = np.concatenate([np.tile(pooled.std(axis=0), L), Xs[:, L * per:].std(0)])
            big = np.concatenate([np.tile(np.abs(pooled).max(axis=0), L),
                                  np.abs(Xs[:, L * per:]).max(axis=0, initial=0.0)])
        else:
            mean, std, big = Xs.mean(axis=0), Xs.std(axis=0), np.abs(Xs).max(axis=0)
        self.x_mean = mean.astype(np.float32)
        self.x_std = np.where(std > 1e-8 * (big + 1e-30), std, 1.0).astype(np.float32)
        C = U @ self.modes.T.astype(np.float64)
        self.c_scale = float(np.sqrt(np.mean(C**2))) or 1.0
        self.f_scale = float(np.linalg.norm(ds.forces[tr], axis=-1).mean()) or 1.0
        target = np.zeros((ds.n_samples, self.modes.shape[0]), dtype=np.float32)
        target[tr] = C / self.c_scale
        if va.size:
            target[va] = fields_of(va) @ self.modes.T.astype(np.float64) / self.c_scale
        self.data = {"x": jnp.asarray((X - self.x_mean) / self.x_std, dtype=jnp.float32),
                     "f": jnp.asarray(ds.forces / self.f_scale, dtype=jnp.float32),
                     "target": jnp.asarray(target)}
        self.net = network(tuple(cfg["hidden"]), self.modes.shape[0], L, self.shared, per)
        # training noise per normalised feature: input_noise, and shape_noise on the shape
        # coefficients (the last columns) when given
        noise = np.full(X.shape[1], float(cfg["input_noise"]), dtype=np.float32)
        shapes = self.n_extra - ds.spec.material_dim
        if cfg.get("shape_noise") is not None and shapes:
            noise[-shapes:] = float(cfg["shape_noise"])
        self.noise = jnp.asarray(noise) if noise.any() else None
        self.loss_kind = cfg.get("loss", "mse")
        if self.loss_kind == "mee":  # the modes as (k, n, 3), to decode the error per node
            k = self.modes.shape[0]
            self.node_modes = jnp.asarray(self.modes.reshape(k, -1, 3))
        self.tr, self.va = tr, va
        self.B = min(cfg["batch_size"], tr.size)
        self.steps_per_epoch = tr.size // self.B

    def init(self, key):
        return self.net.init(key, self.data["x"][:1], self.data["f"][:1])["params"]

    def epoch(self, rng):
        order = rng.permutation(self.tr)
        return [order[i * self.B:(i + 1) * self.B] for i in range(self.steps_per_epoch)]

    def batch(self, indices):
        return jnp.asarray(indices)

    def validation(self):
        return jnp.asarray(self.va) if self.va.size else None

    def loss(self, params, data, idx, key, train):
        # coefficient loss x c_scale^2 = mean squared field error summed over dofs, mm^2
        x = data["x"][idx]
        if train and self.noise is not None:  # on the normalised features, not the forces
            x = x + self.noise * jax.random.normal(key, x.shape)
        pred = self.net.apply({"params": params}, x, data["f"][idx])
        err = pred - data["target"][idx]
        if self.loss_kind == "mee":  # the metric itself on the basis' nodes, x sqrt(n) so
            # that it weighs against the weight decay as the rms loss does
            node = jnp.einsum("bk,knj->bnj", err, self.node_modes)
            per = jnp.sqrt(jnp.sum(node ** 2, axis=-1) + 1e-12)
            return jnp.mean(per) * np.sqrt(per.shape[-1])
        sq = jnp.sum(err ** 2, axis=-1)
        # rms: each field's root-mean-square error, so the largest displacements do not
        # outweigh the rest as their squares do (the metric, MEE, is linear in the error)
        return jnp.mean(jnp.sqrt(sq + 1e-12) if self.loss_kind == "rms" else sq)


def coefficients(model: BasisModel, forces, load_points, extra, *, apply, xp=np,
                 context=None):
    """Mode coefficients (..., k) in mm of load cases: the one definition of training,
    evaluation and the exported predictor (pure; ``apply(x, f)`` is the network, only the
    model's statistics are read here). ``context``: the loads' context features, as the model
    was trained with (``model.context`` per load).
    """
    x = load_features(forces, load_points, extra[..., :model.n_extra], xp, context)
    x = (x - model.x_mean) / model.x_std
    return apply(x, forces / model.f_scale) * model.c_scale


def predict_fields(ds: Dataset, model: BasisModel, samples: np.ndarray,
                   context=None) -> np.ndarray:
    """(len(samples), 3 n) predicted fields (mm) in the basis' node order; ``context``: the
    dataset's (n_samples, n_loads, c) load context when the model takes one.
    """
    net = model_network(model, model.modes.shape[0])
    mean = member_mean(net, model.params, model.members,
                       cast=lambda a: jnp.asarray(a, jnp.float32))

    def apply(x, f):
        return np.asarray(mean(x, f))

    c = coefficients(model, ds.forces[samples], ds.load_points[samples], ds.extra[samples],
                     apply=apply, context=None if context is None else context[samples])
    return c @ model.modes


def predict_samples(ds: Dataset, model: BasisModel, samples: np.ndarray):
    """Predicted and true displacement (mm) of every output node of ``samples``, laid out
    as the node-wise design's (sample by sample, output nodes in order).
    """
    pred = predict_fields(ds, model, samples).reshape(-1, 3).astype(np.float32)
    true = fields(ds, samples).reshape(-1, 3)
    n = int(ds.sample_offset[1] - ds.sample_offset[0])
    return pred, true, np.repeat(samples, n)


class Basis:
    """The design's entry in the registry (:data:`surrogate.designs.DESIGNS`)."""

    name = "basis"
    label = "reduced basis"
    log_every = 10
    shape_rule = "own"  # predicts on its own liver only
    needs_liver = True  # its modes live on the liver it is exported with
    on_template = False
    node_sampled = False  # trains on whole fields
    takes = frozenset({"modes", "ensemble", "shared_loads", "loss"})

    def scene_problem(self, varies_geometry: bool) -> str | None:
        """Why a scene cannot take the design (None when it can)."""
        if varies_geometry:
            return (f"design {self.name!r} needs a scene with one liver (its modes live on "
                    "its nodes); the scene varies the geometry: use config "
                    "'population_basis' or a node-wise config")
        return None

    def check(self, ds: Dataset, cfg: dict | None = None) -> None:
        check_dataset(ds)

    def problem(self, ds, train, val, cfg, rng) -> BasisProblem:
        return BasisProblem(ds, train, val, cfg, int(rng.integers(2**31)))

    def model(self, problem: BasisProblem, params, members: int = 1) -> BasisModel:
        return BasisModel(params=params, modes=problem.modes, x_mean=problem.x_mean,
                          x_std=problem.x_std, c_scale=problem.c_scale,
                          f_scale=problem.f_scale, hidden=problem.net.hidden,
                          n_loads=problem.net.n_loads, n_extra=problem.n_extra,
                          context=problem.context, members=members,
                          shared_loads=problem.shared)

    def summary(self, problem: BasisProblem) -> str:
        return (f"{problem.modes.shape[0]} modes, projection MEE of the training fields "
                f"{problem.projection_mee:.4f} mm")

    def predict_samples(self, ds: Dataset, model: BasisModel, cfg: dict, samples: np.ndarray):
        return predict_samples(ds, model, samples)

    def export_parts(self, model: BasisModel) -> tuple[dict, dict, dict]:
        return model.params, model.stats(), {"basis.npz": {"modes": model.modes}}

    def runtime(self, d, pred, hidden: tuple, dropout: float, dtype: str) -> BasisRuntime:
        """The exported model in ``d`` at prediction time."""
        return BasisRuntime(d, pred, hidden, dropout, dtype)


def _read_modes(where, n_out: int) -> np.ndarray:
    """(k, 3 n_out) float32 modes of an exported basis model, checked."""
    try:
        with np.load(where, allow_pickle=False) as z:
            modes = np.asarray(z["modes"], dtype=np.float32)
    except FileNotFoundError:
        raise ValueError(f"{where}: missing (a reduced-basis model needs its modes)") from None
    except (OSError, KeyError, ValueError) as exc:
        raise ValueError(f"{where}: cannot be read ({exc})") from None
    if modes.ndim != 2 or modes.shape[1] != 3 * n_out or not np.all(np.isfinite(modes)):
        raise ValueError(f"{where}: modes must be a finite (k, {3 * n_out}) array for the "
                         f"{n_out} output nodes, got shape {modes.shape}")
    return modes


def read_stats(where, stats, spec, contexts: tuple[int, ...]) -> BasisModel:
    """The exported statistics (model.json's ``stats``) as a :class:`BasisModel` without its
    parameters and modes; ``contexts``: the load-context widths the design reads.
    """
    L, e = spec.n_loads, spec.material_dim + spec.geometry_dim
    try:
        x_mean = np.asarray(stats["x_mean"], dtype=np.float32)
        x_std = np.asarray(stats["x_std"], dtype=np.float32)
        c_scale, f_scale = float(stats["c_scale"]), float(stats["f_scale"])
        n_extra = stats.get("n_extra", e)  # models written before shape_inputs: all
        context = stats.get("context", 0)  # and before load_context: none
        members = stats.get("members", 1)  # and before ensembles: one network
        shared = stats.get("shared_loads", False)  # and before shared loads: one per load
    except (KeyError, TypeError, ValueError, AttributeError):
        raise ValueError(f"{where}: stats: expected x_mean, x_std, c_scale, f_scale") from None
    problems = []
    if not (isinstance(members, int) and members >= 1):
        problems.append(f"members: expected an integer >= 1, got {members!r}")
    if not isinstance(shared, bool):
        problems.append(f"shared_loads: expected true or false, got {shared!r}")
    if not (isinstance(n_extra, int) and spec.material_dim <= n_extra <= e):
        problems.append(f"n_extra: expected an integer from {spec.material_dim} to {e}, got "
                        f"{n_extra!r}")
    if context not in contexts:
        problems.append(f"context: expected {' or '.join(map(str, contexts))}, got "
                        f"{context!r}")
    dim = (LOAD_FEATURES + (context if context in contexts else 0)) * L + \
        (n_extra if isinstance(n_extra, int) else 0)
    if not problems and (x_mean.shape != (dim,) or x_std.shape != (dim,) or not (
            np.all(np.isfinite(x_mean)) and np.all(x_std > 0) and c_scale > 0
            and f_scale > 0 and np.isfinite(c_scale) and np.isfinite(f_scale))):
        problems.append(f"{dim} finite means, positive scales and positive finite c_scale, "
                        "f_scale expected")
    if problems:
        raise ValueError(f"{where}: stats: " + "; ".join(problems))
    return BasisModel(params=None, modes=None, x_mean=x_mean, x_std=x_std, c_scale=c_scale,
                      f_scale=f_scale, hidden=(), n_loads=L, n_extra=n_extra, context=context,
                      members=members, shared_loads=shared)


class BasisRuntime:
    """An exported reduced-basis model at prediction time: the network's coefficients times
    the modes of the requested output nodes. It predicts on the liver it was trained on.
    """

    outputs_only = True   # its modes live on the scene's output nodes only
    contexts = (0,)       # the load-context widths this design reads

    def __init__(self, d, pred, hidden: tuple, dropout: float, dtype: str):
        from surrogate.model_files import read_params

        meta, spec = pred.meta, pred.spec
        n_out = pred.output_nodes.size
        modes = _read_modes(d / "basis.npz", n_out)
        stats = read_stats(d / "model.json", meta.get("stats"), spec, self.contexts)
        self.stats = dataclasses.replace(stats, hidden=hidden)  # without parameters, modes
        k, s = modes.shape[0], self.stats
        params = read_params(d / "params.npz",
                             input_width(spec.n_loads, LOAD_FEATURES + s.context, s.n_extra,
                                         s.shared_loads), hidden,
                             out=3 * k * (1 if s.shared_loads else spec.n_loads),
                             version=meta["version"], last="coefficients", members=s.members)
        self._out_row = {int(n): i for i, n in enumerate(pred.output_nodes.tolist())}
        self.modes = modes.reshape(k, n_out, 3)
        self._modes = jnp.asarray(modes, dtype=dtype)
        self.params = jax.tree_util.tree_map(lambda w: jnp.asarray(w, dtype=dtype), params)
        self._batched = self._compile(k, dtype)

    def _compile(self, k: int, dtype: str):
        s, net = self.stats, model_network(self.stats, k)

        def one_case(params, modes, forces, load_points, extra, ctx):
            apply = member_mean(net, params, s.members, cast=lambda a: a.astype(dtype))
            c = coefficients(s, forces, load_points, extra, xp=jnp, apply=apply,
                             context=ctx if s.context else None)
            return (c.astype(dtype) @ modes).astype(jnp.float32).reshape(-1, 3)

        return jax.jit(jax.vmap(one_case, in_axes=(None, None, 0, 0, 0, 0)))

    def check_geometry(self, pred, geometry) -> None:
        if geometry is not None:
            raise ValueError("geometry: a reduced-basis model predicts on the liver it was "
                             "trained on only (its modes live on those nodes)")

    def check_points(self, pred, n_nodes: int) -> None:
        """Its own liver (check_geometry refuses another)."""

    def all_rows(self, static):
        return self._modes

    def rows(self, pred, static, nodes):
        rows = [self._out_row.get(int(n)) for n in nodes.tolist()]
        if any(r is None for r in rows):
            raise ValueError("nodes: a reduced-basis model predicts its scene's output nodes "
                             f"only ({pred.output_nodes.size} of {pred.points.shape[0]})")
        k = self.modes.shape[0]
        return jnp.asarray(self.modes[:, rows].reshape(k, -1), dtype=self._modes.dtype)

    def context(self, pred, load_nodes, liver):
        """(n_cases, n_loads, 0): this design reads no load context."""
        return np.zeros(load_nodes.shape + (0,), dtype=np.float32)

    def apply(self, pred, rows, forces, load_points, extra, load_nodes, liver):
        return self._batched(self.params, rows, forces, load_points, extra,
                             self.context(pred, load_nodes, liver))

    def fields_with(self, params, rows, forces, load_points, extra, context):
        """(n_cases, nodes, 3) the fields of cases whose network inputs are given (``extra``:
        the predictor's ``varied_inputs``, ``context``: this runtime's ``context``), with the
        network weights ``params``: what fine-tuning differentiates (:mod:`surrogate.tuning`).
        """
        return self._batched(params, rows, forces, load_points, extra, context)

    def on_nodes(self, params, n_nodes: int, rng) -> BasisModel:
        """The trained model to export on another cloud of ``n_nodes`` nodes (timing):
        the same network with orthonormal random modes of that size.
        """
        k = self.modes.shape[0]
        modes = np.linalg.qr(rng.standard_normal((3 * n_nodes, k)))[0].T.astype(np.float32)
        return dataclasses.replace(self.stats, params=params, modes=modes)
