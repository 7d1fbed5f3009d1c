"""The one training loop: every design is a :class:`Problem` handed to :func:`fit`.

A design (node-wise MLP, reduced basis, ...) says what a batch is and what its loss is; the loop
owns everything else, once: the optimiser (Adam, with the learning-rate rule and weight decay as
optax transforms), epochs, validation on held-out simulations, early stopping with the best
parameters kept, per-epoch metrics, and a checkpoint after every epoch from which a killed
training resumes where it stopped (the same batches and random keys as an uninterrupted run).

Checkpoints are plain data: flax's msgpack serialisation of the parameters and optimiser state
plus a JSON record (epoch, history, numpy generator state); reading one executes no code.
"""

from __future__ import annotations

import abc
import hashlib
import json
import logging
import time
from pathlib import Path
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
import optax
from flax import serialization
from flax.training.early_stopping import EarlyStopping

from data_spec.atomic import atomic_path

log = logging.getLogger(__name__)

# The plateau rule: the learning rate x0.1 after ``lr_patience`` epochs without a relative
# improvement of the validation loss by this much.
PLATEAU_FACTOR = 0.1
PLATEAU_RTOL = 1e-4
DECAY_PER_EPOCH = 1.5  # the "decay" rule: the learning rate / 1.5 every epoch


class Problem(abc.ABC):
    """One design's training problem on fixed training and early-stopping samples.

    ``data`` is a pytree of device arrays passed to every jitted call (not captured, so large
    arrays are never baked into compiled code); a batch is a pytree built on the host.
    """

    data: Any = None

    @abc.abstractmethod
    def init(self, key) -> Any:
        """Initial network parameters."""

    @abc.abstractmethod
    def loss(self, params, data, batch, key, train: bool):
        """The mean squared error of a batch (pure, jittable; ``key`` for dropout/noise)."""

    steps_per_epoch: int = 0  # batches per epoch, the same every epoch

    @abc.abstractmethod
    def epoch(self, rng: np.random.Generator) -> list[np.ndarray]:
        """The example indices of each batch of one epoch, drawn with ``rng``."""

    @abc.abstractmethod
    def batch(self, indices: np.ndarray):
        """The batch (a pytree of arrays) of these example indices."""

    def validation(self):
        """The early-stopping batch, or None when nothing is held out."""
        return None

    def examples(self, indices: np.ndarray) -> int:
        """Examples in a batch, for the throughput figure."""
        return int(indices.size)


def kernel_mask(params):
    """True at the weight matrices (weight decay applies to them, not to biases)."""
    return jax.tree_util.tree_map_with_path(
        lambda path, _: getattr(path[-1], "key", None) == "kernel", params)


def optimizer(cfg: dict, steps_per_epoch: int) -> optax.GradientTransformationExtraArgs:
    """Adam with the config's learning-rate rule and weight decay, all as optax transforms.

    "decay": a staircase exponential schedule (/ 1.5 per epoch). "plateau": optax's
    ``reduce_on_plateau``, fed at every step with the latest validation loss and judging the
    mean over one epoch of steps: each epoch's validation loss is judged at the end of the next
    epoch. ``l2``: l2 w added to the gradient of every weight matrix before Adam, i.e. the
    penalty l2 |w|^2 / 2 in the loss (biases are not decayed).
    """
    lr = schedule(cfg, steps_per_epoch)
    parts = []
    if cfg["l2"] > 0:
        parts.append(optax.add_decayed_weights(cfg["l2"], mask=kernel_mask))
    parts += [optax.scale_by_adam(), optax.scale_by_learning_rate(lr)]
    if cfg["lr_rule"] == "plateau":
        parts.append(optax.contrib.reduce_on_plateau(
            factor=PLATEAU_FACTOR, patience=cfg["lr_patience"], rtol=PLATEAU_RTOL,
            accumulation_size=steps_per_epoch))
    return optax.chain(*parts)


def schedule(cfg: dict, steps_per_epoch: int):
    """The learning rate before the plateau rule: the config's rate, or for "decay" that rate
    / 1.5 per finished epoch, as a function of the step count (jax arrays inside the optimiser,
    plain integers for the report).
    """
    lr = cfg["learning_rate"]
    if cfg["lr_rule"] != "decay":
        return lr
    return lambda count: lr / DECAY_PER_EPOCH ** (count // steps_per_epoch)


def make_train_step(loss, tx):
    """The jitted step ``(params, opt_state, data, batch, key, value) -> (params, opt_state,
    loss)`` of a loss ``(params, data, batch, key, train) -> mse``; ``value`` feeds the
    plateau rule.
    """

    @jax.jit
    def train_step(params, opt_state, data, batch, key, value):
        mse, grads = jax.value_and_grad(loss)(params, data, batch, key, True)
        updates, opt_state = tx.update(grads, opt_state, params, value=value)
        return optax.apply_updates(params, updates), opt_state, mse

    return train_step


def config_hash(cfg: dict, extra: dict | None = None) -> str:
    text = json.dumps({"cfg": cfg, **(extra or {})}, sort_keys=True, default=str)
    return hashlib.sha256(text.encode()).hexdigest()[:16]


class Checkpoint:
    """The state of one fit after an epoch, in ``directory``.

    A kill at any moment leaves a loadable checkpoint: each save writes the state under a name
    of its own (``state-<sha256>.msgpack``), then replaces ``state.json``, which names it, and
    only then removes the states it no longer names. Until ``state.json`` is replaced it names
    the previous state, which is still on disk.
    """

    def __init__(self, directory: str | Path, identity: str):
        self.dir = Path(directory)
        self.identity = identity

    @property
    def meta_file(self) -> Path:
        return self.dir / "state.json"

    def save(self, tree: dict, meta: dict) -> None:
        self.dir.mkdir(parents=True, exist_ok=True)
        blob = serialization.to_bytes(tree)
        digest = hashlib.sha256(blob).hexdigest()
        name = f"state-{digest[:32]}.msgpack"
        self._write_state(name, blob)
        self._write_meta({**meta, "identity": self.identity, "sha256": digest, "state": name})
        for old in self.dir.glob("state-*.msgpack"):
            if old.name != name:
                old.unlink(missing_ok=True)

    def _write_state(self, name: str, blob: bytes) -> None:
        with atomic_path(self.dir / name) as tmp:
            Path(tmp).write_bytes(blob)

    def _write_meta(self, meta: dict) -> None:
        with atomic_path(self.meta_file) as tmp:
            Path(tmp).write_text(json.dumps(meta))

    def load(self, template: dict) -> tuple[dict, dict] | None:
        """(tree, meta) of the last epoch saved, or None: no checkpoint, one of another
        configuration or dataset (then it is ignored and overwritten), or an unreadable one.
        """
        try:
            meta = json.loads(self.meta_file.read_text())
            name = Path(str(meta.get("state", ""))).name  # a file of this directory only
            blob = (self.dir / name).read_bytes() if name.startswith("state-") else b""
        except (OSError, ValueError, AttributeError):
            return None
        if meta.get("identity") != self.identity:
            log.warning("%s: a checkpoint of another configuration or dataset; starting over",
                        self.dir)
            return None
        if hashlib.sha256(blob).hexdigest() != meta.get("sha256"):
            log.warning("%s: the state named by %s is missing or damaged; starting over",
                        self.dir, self.meta_file.name)
            return None
        return serialization.from_bytes(template, blob), meta


def _start(problem: Problem, cfg: dict, seed: int, rng, checkpoint, log_fn, label, eval_loss,
           validate):
    """(training state, history, first epoch, last validation loss): fresh from ``seed``, or
    resumed from the checkpoint's last epoch (``rng`` restored with it).
    """
    key = jax.random.PRNGKey(seed)
    key, k_init = jax.random.split(key)
    params = problem.init(k_init)
    tx = optimizer(cfg, problem.steps_per_epoch)
    state = {"params": params, "opt_state": tx.init(params), "best": params, "key": key,
             "stop": EarlyStopping(min_delta=0.0, patience=cfg["early_stopping"] - 1)}
    loaded = checkpoint.load(state) if checkpoint is not None else None
    if loaded is not None:
        state, meta = loaded
        rng.bit_generator.state = meta["rng"]
        log_fn(f"{label}resumed after epoch {meta['epoch']} from {checkpoint.dir}")
        # epochs another process trained: a run's cost counts them beside its own wall time
        history = [{**h, "earlier": True} for h in meta["history"]]
        return state, history, meta["epoch"], meta["last_val"]
    if problem.validation() is not None:
        return state, [], 0, validate(params)  # the plateau rule's first value
    # nothing held out: the first training batch's loss
    first = problem.batch(problem.epoch(np.random.default_rng(0))[0])
    return state, [], 0, float(eval_loss(params, problem.data, first))


def _epoch(problem: Problem, state: dict, train_step, rng, last_val) -> tuple[float, int]:
    """One epoch of steps on ``state`` (updated in place): (mean training loss, examples)."""
    order = problem.epoch(rng)
    if len(order) != problem.steps_per_epoch:
        raise RuntimeError(f"{type(problem).__name__}: {len(order)} batches in an epoch, "
                           f"declared {problem.steps_per_epoch}")
    losses, n = [], 0
    value = jnp.asarray(last_val, jnp.float32)
    params, opt_state, key = state["params"], state["opt_state"], state["key"]
    for indices in order:
        key, k = jax.random.split(key)
        params, opt_state, mse = train_step(params, opt_state, problem.data,
                                            problem.batch(indices), k, value)
        losses.append(mse)
        n += problem.examples(indices)
    state.update(params=params, opt_state=opt_state, key=key)
    return float(np.mean(jax.device_get(losses))), n


def fit(problem: Problem, cfg: dict, seed: int, rng: np.random.Generator, *,
        label: str = "", log_fn=print, log_every: int = 1,
        checkpoint: Checkpoint | None = None) -> tuple[Any, list[dict]]:
    """Train ``problem``; returns (best parameters by validation loss, per-epoch history).

    ``rng`` draws the batches (its state is checkpointed with the rest); ``checkpoint``: save
    after every epoch and resume from the last one saved. Without validation examples the
    plateau rule and early stopping watch the training loss.
    """
    steps = problem.steps_per_epoch
    train_step = make_train_step(problem.loss, optimizer(cfg, steps))
    eval_loss = jax.jit(lambda p, d, b: problem.loss(p, d, b, jax.random.PRNGKey(0), False))
    val = problem.validation()

    def validate(p):
        return float(eval_loss(p, problem.data, val))

    state, history, start, last_val = _start(problem, cfg, seed, rng, checkpoint, log_fn,
                                             label, eval_loss, validate)
    for epoch in range(start, cfg["epochs"]):
        if state["stop"].should_stop:
            break
        t0 = time.perf_counter()
        lr = learning_rate_now(cfg, state["opt_state"], epoch * steps, steps)  # this epoch's
        train_loss, n = _epoch(problem, state, train_step, rng, last_val)
        val_loss = last_val = train_loss if val is None else validate(state["params"])
        dt = time.perf_counter() - t0
        history.append({"epoch": epoch + 1, "train_loss": train_loss, "val_loss": val_loss,
                        "lr": lr, "seconds": dt, "examples_per_s": n / dt})
        if epoch % log_every == 0:
            log_fn(f"{label}epoch {epoch + 1:3d}  train {train_loss:.4e}  val {val_loss:.4e}  "
                   f"lr {lr:.1e}  {n / dt:,.0f} examples/s")
        state["stop"] = state["stop"].update(val_loss)
        if state["stop"].has_improved:
            state["best"] = state["params"]
        if checkpoint is not None:
            checkpoint.save(dict(state), {"epoch": epoch + 1, "history": history,
                                          "rng": rng.bit_generator.state, "last_val": last_val})
    return jax.device_get(state["best"]), history


def learning_rate_now(cfg: dict, opt_state, steps_done: int, steps_per_epoch: int) -> float:
    """The learning rate the next step uses (read from the schedule and the optimiser state)."""
    lr = schedule(cfg, steps_per_epoch)
    if callable(lr):
        return lr(steps_done)
    return lr * float(optax.tree_utils.tree_get(opt_state, "scale"))
