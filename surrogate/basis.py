"""The reduced-basis design (``design = "basis"``): the whole field from one small network.

A node-wise MLP repeats the whole network once per node, so its cost grows with the mesh. Here
the displacement field of a load case is a combination of ``modes`` fixed fields,

    u(loads) = sum_i c_i(loads) phi_i,      c = M(x) f / f_scale,

with phi_i the leading right singular vectors of the training displacement fields (orthonormal,
so the loss on c is the loss on u in mm^2, and the basis error is known before any training:
``projection_mee``), x the global load features (per load: the load node's coordinates, the
force direction and magnitude; then the material and shape inputs when the scene varies them),
and M(x) a (modes x 3 n_loads) matrix from a small MLP: the field is linear in the force at a
fixed direction and magnitude, and zero without load. A call costs one small network plus one
(3N x modes) product, for any number of nodes (docs/realtime.md).

It needs one liver (the basis lives on its nodes): a scene that varies the geometry keeps the
node-wise design. Pure functions of arrays, and one training loop like the node-wise one
(early stopping on held-out simulations, the same learning-rate rule).
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from surrogate.data import Dataset

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

    def stats(self) -> dict:
        return {"x_mean": self.x_mean.tolist(), "x_std": self.x_std.tolist(),
                "c_scale": self.c_scale, "f_scale": self.f_scale}


def load_features(forces, load_points, extra, xp=np):
    """(..., 7 n_loads + e) global features of load cases: per load its point, force
    direction and magnitude; then ``extra``.
    """
    mag = xp.sqrt(xp.sum(forces * forces, axis=-1, keepdims=True))
    direction = forces / xp.maximum(mag, 1e-12)
    per = xp.concatenate([load_points, direction, mag], axis=-1)  # (..., L, 7)
    flat = per.reshape(per.shape[:-2] + (per.shape[-2] * LOAD_FEATURES,))
    return xp.concatenate([flat, extra], axis=-1)


def network(hidden, modes: int, n_loads: int):
    """The flax module: (features, forces / f_scale) -> coefficients (modes,)."""
    import flax.linen as nn
    import jax.numpy as jnp

    class BasisMLP(nn.Module):
        @nn.compact
        def __call__(self, x, f):
            for width in hidden:
                x = nn.gelu(nn.Dense(width)(x))
            M = nn.Dense(modes * 3 * n_loads)(x).reshape(x.shape[:-1] + (modes, 3 * n_loads))
            return jnp.einsum("...kj,...j->...k", M, f.reshape(f.shape[:-2] + (-1,)))

    return BasisMLP()


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
    R = U @ modes.T @ modes - U
    return float(np.linalg.norm(R.reshape(U.shape[0], -1, 3), axis=2).mean())


def fit(ds: Dataset, train_samples: np.ndarray, cfg: dict, seed: int, label: str = "",
        log_fn=print) -> tuple[BasisModel, list[dict]]:
    """Modes and network from ``train_samples`` (a slice of simulations held out for early
    stopping, as for the node-wise design).
    """
    import jax
    import jax.numpy as jnp
    import optax
    from flax.training import train_state
    from flax.training.early_stopping import EarlyStopping

    from surrogate.train import LearningRateRule, early_stopping_split, end_of_epoch

    check_dataset(ds)
    tr, va, rng = early_stopping_split(ds, train_samples, cfg, seed)
    U = fields(ds, tr)
    modes = compute_modes(U, cfg["modes"], seed).astype(np.float32)
    X = load_features(ds.forces, ds.load_points, ds.extra)
    x_mean = X[tr].mean(axis=0)
    std = X[tr].std(axis=0)
    x_std = np.where(std > 1e-8 * (np.abs(X[tr]).max(axis=0) + 1e-30), std, 1.0)
    C = U @ modes.T.astype(np.float64)
    c_scale = float(np.sqrt(np.mean(C**2))) or 1.0
    f_scale = float(np.linalg.norm(ds.forces[tr], axis=-1).mean()) or 1.0
    Xn = jnp.asarray((X - x_mean) / x_std, dtype=jnp.float32)
    Fn = jnp.asarray(ds.forces / f_scale, dtype=jnp.float32)
    target = np.zeros((ds.n_samples, modes.shape[0]), dtype=np.float32)
    target[tr] = C / c_scale
    if va.size:
        target[va] = fields(ds, va) @ modes.T.astype(np.float64) / c_scale
    target = jnp.asarray(target)
    n_loads = ds.spec.n_loads
    net = network(tuple(cfg["hidden"]), modes.shape[0], n_loads)
    key = jax.random.PRNGKey(seed)
    params = net.init(key, Xn[:1], Fn[:1])["params"]
    tx = optax.inject_hyperparams(optax.adam)(learning_rate=cfg["learning_rate"])
    state = train_state.TrainState.create(apply_fn=net.apply, params=params, tx=tx)

    def loss_fn(params, idx):
        pred = net.apply({"params": params}, Xn[idx], Fn[idx])
        return jnp.mean(jnp.sum((pred - target[idx]) ** 2, axis=-1))

    @jax.jit
    def step(state, idx):
        loss, grads = jax.value_and_grad(loss_fn)(state.params, idx)
        return state.apply_gradients(grads=grads), loss

    val_loss_fn = jax.jit(loss_fn)
    lr_rule = LearningRateRule(cfg, params)
    stop = EarlyStopping(min_delta=0.0, patience=cfg["early_stopping"] - 1)
    B = min(cfg["batch_size"], tr.size)
    best, history = state.params, []
    for epoch in range(cfg["epochs"]):
        t0 = time.perf_counter()
        order = rng.permutation(tr)
        losses = []
        for i in range(0, order.size - B + 1, B):
            state, loss = step(state, jnp.asarray(order[i:i + B]))
            losses.append(loss)
        train_loss = float(np.mean(jax.device_get(losses)))
        val_loss = float(val_loss_fn(state.params, jnp.asarray(va))) if va.size else train_loss
        dt = time.perf_counter() - t0
        history.append({"epoch": epoch + 1, "train_loss": train_loss, "val_loss": val_loss,
                        "lr": lr_rule.value, "seconds": dt,
                        "examples_per_s": order.size / dt})
        if epoch % 10 == 0:
            # coefficient loss x c_scale^2 = mean squared field error summed over dofs, mm^2
            log_fn(f"{label}epoch {epoch + 1:3d}  train {train_loss:.4e}  val {val_loss:.4e}  "
                   f"lr {lr_rule.value:.1e}")
        state, stop, best = end_of_epoch(state, stop, lr_rule, best, val_loss)
        if stop.should_stop:
            break
    log_fn(f"{label}stopped after {len(history)} epochs; {modes.shape[0]} modes, projection "
           f"MEE of the training fields {projection_mee(U, modes.astype(np.float64)):.4f} mm")
    model = BasisModel(params=jax.device_get(best), modes=modes,
                       x_mean=x_mean.astype(np.float32), x_std=x_std.astype(np.float32),
                       c_scale=c_scale, f_scale=f_scale, hidden=tuple(cfg["hidden"]),
                       n_loads=n_loads)
    return model, history


def coefficients(model: BasisModel, forces, load_points, extra, *, apply, xp=np):
    """Mode coefficients (..., k) in mm of load cases: the one definition of training,
    evaluation and the exported predictor (pure; ``apply(x, f)`` is the network, only the
    model's statistics are read here).
    """
    x = (load_features(forces, load_points, extra, xp) - model.x_mean) / model.x_std
    return apply(x, forces / model.f_scale) * model.c_scale


def predict_samples(ds: Dataset, model: BasisModel, samples: np.ndarray):
    """Predicted and true displacement (mm) of every output node of ``samples``, laid out
    as :func:`surrogate.train.predict_samples` (sample by sample, output nodes in order).
    """
    import jax.numpy as jnp

    net = network(model.hidden, model.modes.shape[0], model.n_loads)

    def apply(x, f):
        return np.asarray(net.apply({"params": model.params}, jnp.asarray(x, jnp.float32),
                                    jnp.asarray(f, jnp.float32)))

    c = coefficients(model, ds.forces[samples], ds.load_points[samples], ds.extra[samples],
                     apply=apply)
    pred = (c @ model.modes).reshape(-1, 3).astype(np.float32)
    true = fields(ds, samples).reshape(-1, 3)
    n = int(ds.sample_offset[1] - ds.sample_offset[0])
    return pred, true, np.repeat(samples, n)
