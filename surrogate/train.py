"""Training: pure ``train_step``; side effects (files, printing) only in ``train_and_evaluate``.

k-fold cross-validation split by simulation (by liver when the geometry varies); inside each
fold a fraction of the training simulations is held out for early stopping and the learning-rate
rule, so the reported metrics come from folds the model never saw in any way.
"""

from __future__ import annotations

import functools
import json
import logging
import shutil
import sys
import time
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import optax
from flax import traverse_util
from flax.training import train_state
from flax.training.early_stopping import EarlyStopping

from data_spec.atomic import check_writable
from surrogate import basis
from surrogate.data import Dataset, kfold_groups, load_dataset
from surrogate.features import node_features
from surrogate.metrics import displacement_metrics, metrics_table
from surrogate.model import NodeMLP
from surrogate.normalise import Normaliser

log = logging.getLogger(__name__)

EVAL_CHUNK = 65536


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


def make_fns(cfg: dict, n_loads: int):
    """Pure jitted functions ``train_step(state, norm, data, rows, samples, targets, key)``,
    ``eval_loss(params, norm, data, rows, samples, targets)`` and
    ``predict(params, norm, data, rows, samples) -> mm``, built (and compiled) once per
    network and loss settings, not once per fold.
    """
    return _fns(tuple(cfg["hidden"]), float(cfg["dropout"]), float(cfg["input_noise"]),
                float(cfg["l2"]), int(n_loads))


@functools.lru_cache(maxsize=8)
def _fns(hidden: tuple, dropout: float, input_noise: float, l2: float, n_loads: int):
    model = NodeMLP(hidden=hidden, dropout=dropout)

    def loss_fn(params, norm, data, rows, samples, targets, key, train):
        k_noise, k_drop, k_flip = jax.random.split(key, 3)
        flip = (jax.random.bernoulli(k_flip, 0.5, (rows.shape[0],))
                if (train and n_loads == 2) else None)
        x = norm.inputs(batch_features(data, rows, samples, flip))
        if train and input_noise > 0:
            x = x + input_noise * jax.random.normal(k_noise, x.shape)
        pred = model.apply({"params": params}, x, train=train, rngs={"dropout": k_drop})
        mse = jnp.mean((pred - norm.targets(targets)) ** 2)
        if l2 > 0:
            flat = traverse_util.flatten_dict(params)
            penalty = sum(jnp.sum(w**2) for k, w in flat.items() if k[-1] == "kernel")
            return mse + 0.5 * l2 * penalty, mse
        return mse, mse

    @jax.jit
    def train_step(state, norm, data, rows, samples, targets, key):
        grad_fn = jax.value_and_grad(loss_fn, has_aux=True)
        (_, mse), grads = grad_fn(state.params, norm, data, rows, samples, targets, key, True)
        return state.apply_gradients(grads=grads), mse

    @jax.jit
    def eval_loss(params, norm, data, rows, samples, targets):
        return loss_fn(params, norm, data, rows, samples, targets, jax.random.PRNGKey(0),
                       False)[1]

    @jax.jit
    def predict(params, norm, data, rows, samples):
        x = norm.inputs(batch_features(data, rows, samples))
        return norm.outputs(model.apply({"params": params}, x, train=False))

    return train_step, eval_loss, predict


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


def normalisation(ds: Dataset, data: dict, rows, smp, tgt, rng,
                  n_max: int = 200_000) -> Normaliser:
    """Feature and target statistics from (a random subset of) the training examples;
    ``data`` is :func:`device_data` of ``ds``.
    """
    pick = rng.choice(rows.size, size=min(n_max, rows.size), replace=False)
    x = np.asarray(batch_features(data, rows[pick], smp[pick]))
    return Normaliser.fit(x, ds.targets[tgt[pick]])


def device_data(ds: Dataset) -> dict:
    return {"static": jnp.asarray(ds.static), "forces": jnp.asarray(ds.forces),
            "load_points": jnp.asarray(ds.load_points), "extra": jnp.asarray(ds.extra)}


def inner_split(ds: Dataset, train_samples: np.ndarray, cfg: dict, rng):
    """(training, early-stopping) samples: ``inner_val_fraction`` of the simulations (of the
    livers when the geometry varies) of ``train_samples`` held out.
    """
    unit = ds.sample_geo if ds.spec.geometry_dim else ds.sample_sim
    units = np.unique(unit[train_samples])
    n_val = max(1, int(round(cfg["inner_val_fraction"] * units.size))) if units.size > 1 else 0
    val_units = rng.choice(units, size=n_val, replace=False) if n_val else np.array([])
    is_val = np.isin(unit[train_samples], val_units)
    return train_samples[~is_val], train_samples[is_val]


def early_stopping_split(ds: Dataset, train_samples: np.ndarray, cfg: dict, seed: int):
    """(training samples, early-stopping samples, rng) of a fit with this seed: every design's
    fit starts here, so the exported model's unseen simulations are known without training.
    """
    rng = np.random.default_rng(seed)
    tr, va = inner_split(ds, train_samples, cfg, rng)
    return tr, va, rng


def fit(ds: Dataset, train_samples: np.ndarray, cfg: dict, seed: int, label: str = "",
        log_fn=print) -> tuple[dict, dict, list[dict]]:
    """Train on ``train_samples`` (a slice held out for early stopping). Returns
    (params, normaliser, per-epoch history).
    """
    tr, va, rng = early_stopping_split(ds, train_samples, cfg, seed)
    rows, smp, tgt = example_index(ds, tr)
    data = device_data(ds)
    norm = normalisation(ds, data, rows, smp, tgt, rng)
    model = NodeMLP(hidden=tuple(cfg["hidden"]), dropout=cfg["dropout"])
    key = jax.random.PRNGKey(seed)
    key, k_init = jax.random.split(key)
    params = model.init(k_init, jnp.zeros((1, ds.spec.dim)))["params"]
    tx = optax.inject_hyperparams(optax.adam)(learning_rate=cfg["learning_rate"])
    state = train_state.TrainState.create(apply_fn=model.apply, params=params, tx=tx)
    train_step, eval_loss, _ = make_fns(cfg, ds.spec.n_loads)
    if va.size:
        vrows, vsmp, vtgt = example_index(ds, va)
        if vrows.size > 200_000:
            pick = rng.choice(vrows.size, 200_000, replace=False)
            vrows, vsmp, vtgt = vrows[pick], vsmp[pick], vtgt[pick]
        vtargets = jnp.asarray(ds.targets[vtgt])
    B = cfg["batch_size"]
    n_per_epoch = max(B, int(cfg["node_fraction"] * rows.size)) // B * B
    lr_rule = LearningRateRule(cfg, params)
    stop = EarlyStopping(min_delta=0.0, patience=cfg["early_stopping"] - 1)
    best_params, history = state.params, []
    for epoch in range(cfg["epochs"]):
        t0 = time.perf_counter()
        order = rng.choice(rows.size, size=n_per_epoch, replace=n_per_epoch > rows.size)
        losses = []
        for i in range(0, n_per_epoch, B):
            b = order[i:i + B]
            key, k = jax.random.split(key)
            state, mse = train_step(state, norm, data, jnp.asarray(rows[b]),
                                    jnp.asarray(smp[b]), jnp.asarray(ds.targets[tgt[b]]), k)
            losses.append(mse)
        train_loss = float(np.mean(jax.device_get(losses)))
        val_loss = float(eval_loss(state.params, norm, data, jnp.asarray(vrows),
                                   jnp.asarray(vsmp), vtargets)) if va.size else train_loss
        dt = time.perf_counter() - t0
        lr = lr_rule.value
        history.append({"epoch": epoch + 1, "train_loss": train_loss, "val_loss": val_loss,
                        "lr": lr, "seconds": dt, "examples_per_s": n_per_epoch / dt})
        log_fn(f"{label}epoch {epoch + 1:3d}  train {train_loss:.4e}  val {val_loss:.4e}  "
               f"lr {lr:.1e}  {n_per_epoch / dt:,.0f} examples/s")
        state, stop, best_params = end_of_epoch(state, stop, lr_rule, best_params, val_loss)
        if stop.should_stop:
            break
    return jax.device_get(best_params), norm, history


def end_of_epoch(state, stop, lr_rule, best, val_loss: float):
    """Early stopping and the learning-rate rule after one epoch: (state with the next
    learning rate, stopping state, best parameters so far).
    """
    stop = stop.update(val_loss)
    if stop.has_improved:
        best = state.params
    state = state.replace(opt_state=with_learning_rate(state.opt_state,
                                                       lr_rule.update(val_loss)))
    return state, stop, best


class LearningRateRule:
    """The learning rate per epoch. "plateau": optax's ``reduce_on_plateau`` fed once per epoch
    with the validation loss (x0.1 after ``lr_patience`` epochs without a relative improvement
    of 1e-4); "decay": divided by 1.5 every epoch.
    """

    def __init__(self, cfg: dict, params):
        self.base, self.rule = cfg["learning_rate"], cfg["lr_rule"]
        self.epochs = 0
        self.plateau = optax.contrib.reduce_on_plateau(factor=0.1, patience=cfg["lr_patience"],
                                                       rtol=1e-4)
        self.state = self.plateau.init(params)
        self.value = self.base

    def update(self, val_loss: float) -> float:
        self.epochs += 1
        if self.rule == "decay":
            self.value = self.base / 1.5**self.epochs
        else:
            _, self.state = self.plateau.update({}, self.state, value=jnp.asarray(val_loss))
            self.value = self.base * float(self.state.scale)
        return self.value


def with_learning_rate(opt_state, lr: float):
    """The optimiser state of ``optax.inject_hyperparams(optax.adam)`` with a new learning
    rate (a new state; nothing is edited in place).
    """
    return opt_state._replace(hyperparams={**opt_state.hyperparams,
                                           "learning_rate": jnp.asarray(lr)})


def predict_samples(ds: Dataset, params, norm: Normaliser, cfg: dict, samples: np.ndarray):
    """Predicted and true displacement (mm) of every output node of ``samples``."""
    _, _, predict = make_fns(cfg, ds.spec.n_loads)
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


def fit_design(ds: Dataset, train_samples: np.ndarray, cfg: dict, seed: int, label: str,
               log_fn) -> tuple:
    """(model, history) of the config's design: (params, normaliser) for the node-wise MLP,
    a :class:`surrogate.basis.BasisModel` for the reduced basis.
    """
    if cfg["design"] == "basis":
        return basis.fit(ds, train_samples, cfg, seed, label, log_fn)
    params, norm, hist = fit(ds, train_samples, cfg, seed, label, log_fn)
    return (params, norm), hist


def predict_design(ds: Dataset, model, cfg: dict, samples: np.ndarray):
    if cfg["design"] == "basis":
        return basis.predict_samples(ds, model, samples)
    return predict_samples(ds, *model, cfg, samples)


def train_and_evaluate(data_dir: str | Path, run_dir: str | Path, cfg: dict,
                       log_fn=None) -> dict:
    """k-fold CV + metrics + plots + (optionally) a final model exported to RUN/model."""
    from surrogate.export import export_basis, export_model
    from surrogate.plots import error_plots

    run = Path(run_dir)
    created = not run.exists()
    check_writable(run)  # a read-only run directory fails now, not after the training
    lines = []

    def say(msg):
        lines.append(msg)
        (log_fn or (lambda m: print(m, file=sys.stderr, flush=True)))(msg)

    t0 = time.perf_counter()
    try:
        ds = load_dataset(data_dir, stream=cfg.get("stream", "auto"), spill_dir=run)
    except Exception:
        if created:  # leave no empty run directory behind a dataset that cannot be read
            shutil.rmtree(run, ignore_errors=True)
        raise
    say(f"dataset {data_dir}: {ds.n_samples} samples ({np.unique(ds.sample_sim).size} "
        f"simulations, {ds.failed_sims} failed), {ds.targets.shape[0]:,} node examples, "
        f"{ds.spec.dim} features: {', '.join(ds.spec.names())}"
        + ("; targets streamed from disk" if isinstance(ds.targets, np.memmap) else ""))
    if cfg["design"] == "basis":
        basis.check_dataset(ds)
    (run / "config.json").write_text(json.dumps(cfg, indent=1))
    folds = kfold_groups(ds, cfg["folds"], cfg["seed"])
    preds, trues, smps, naive, history = [], [], [], [], {}
    train_time, examples = 0.0, 0
    for k, held in enumerate(folds):
        train_samples = np.setdiff1d(np.arange(ds.n_samples), held)
        t = time.perf_counter()
        model, hist = fit_design(ds, train_samples, cfg, cfg["seed"] + 1 + k,
                                 f"fold {k + 1}/{len(folds)} ", say)
        train_time += time.perf_counter() - t
        examples += sum(h["examples_per_s"] * h["seconds"] for h in hist)
        history[f"fold{k}"] = hist
        p, y, s = predict_design(ds, model, cfg, held)
        _, _, tr_tgt = example_index(ds, train_samples)
        mean_disp = ds.targets[tr_tgt].mean(axis=0)
        preds.append(p)
        trues.append(y)
        smps.append(s)
        naive.append(np.broadcast_to(mean_disp, y.shape))
    pred, true, smp, nv = (np.concatenate(a) for a in (preds, trues, smps, naive))
    m_nn, m_naive = displacement_metrics(pred, true), displacement_metrics(nv, true)
    result = {"scene": ds.scene_name, "folds": cfg["folds"], "network": m_nn,
              "naive": m_naive, "skill": m_nn["mee"] / m_naive["mee"],
              "n_simulations": int(np.unique(ds.sample_sim).size),
              "n_samples": int(ds.n_samples), "n_examples": int(ds.targets.shape[0]),
              "training_seconds": train_time,
              "training_examples_per_s": examples / train_time if train_time else 0.0}
    if ds.spec.geometry_dim or len(ds.geo_ids) > 1:
        geo = ds.sample_geo[smp]
        ee = np.linalg.norm(pred - true, axis=1)
        per = [float(ee[geo == g].mean()) for g in np.unique(geo)]
        result["per_liver_mee"] = {"mean": float(np.mean(per)), "median": float(np.median(per)),
                                   "values": per}
    table = metrics_table({"network": m_nn, "naive (mean displacement)": m_naive})
    md = (f"# {ds.scene_name}: {cfg['folds']}-fold cross-validation\n\n{table}\n\n"
          f"skill = MEE_NN / MEE_naive = {result['skill']:.4f} (paper, scene 1: 0.078)\n")
    say("\n" + table + f"\nskill = MEE_NN / MEE_naive = {result['skill']:.4f}")
    error_plots(run, pred, true, result)
    if cfg["final_fit"]:
        model, hist = fit_design(ds, np.arange(ds.n_samples), cfg, cfg["seed"], "final ", say)
        history["final"] = hist
        _, held, _ = early_stopping_split(ds, np.arange(ds.n_samples), cfg, cfg["seed"])
        unseen = np.unique(ds.sample_sim[held])
        if cfg["design"] == "basis":
            export_basis(run / "model", model, cfg, ds, unseen)
        else:
            export_model(run / "model", *model, cfg, ds, unseen)
        say(f"model exported to {run / 'model'}")
    result["total_seconds"] = time.perf_counter() - t0
    (run / "metrics.json").write_text(json.dumps(result, indent=1))
    (run / "metrics.md").write_text(md)
    (run / "history.json").write_text(json.dumps(history, indent=1))
    (run / "log.txt").write_text("\n".join(lines) + "\n")
    if isinstance(ds.targets, np.memmap):
        Path(ds.targets.filename).unlink(missing_ok=True)  # a cache, not a result
    return result
