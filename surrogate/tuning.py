"""Fine-tuning a placed population model's network on a patient's own FE simulations.

The population basis (:mod:`surrogate.population_basis`) predicts the coefficients of modes on
the template; placed on a patient (:class:`surrogate.predict_liver.PlacedModel`) those modes
are interpolated to the patient's nodes. Here the network's weights (every member of the
ensemble, through their mean, as the model is called) are trained further by Adam on the
patient's simulations, the loss the population basis trains with (each field's RMS error) on
the patient's own nodes, in the population's frame. How far (the learning rate and the
number of steps, ``0`` keeping the population's weights) is chosen by cross-validation over
the patient's simulations, grouped by simulation (the caller passes at most a few load steps
of each); tuning is kept only when it lowers the held-out MEE by ``MIN_GAIN``.

The modes stay the population's: what the fields hold outside their span is left to the
correction of :mod:`surrogate.patient`, fitted on the tuned model's out-of-fold residuals
(each simulation's from the network tuned without it: on its own training cases the tuned
network's residuals are smaller than a new load's).
"""

from __future__ import annotations

import copy
import dataclasses
from collections.abc import Callable
from typing import NamedTuple

import numpy as np

from surrogate.metrics import mee as field_mee

RATES = (1e-4,)                           # Adam's learning rates tried
STEPS = (0, 10, 20, 40, 80, 160)          # steps tried (0: the population's weights)
FOLDS = 3                                 # folds of whole simulations for the choice
MIN_GAIN = 0.01                           # tuning kept when it lowers the held-out MEE
                                          # by at least this fraction


def simulation_folds(groups, n: int) -> list[np.ndarray]:
    """``n`` folds of the simulations in ``groups`` (fewer with fewer simulations), each a
    set of whole simulations, always the same for the same simulations.
    """
    sims = np.unique(groups)
    return np.array_split(np.random.default_rng(0).permutation(sims), min(n, sims.size))


@dataclasses.dataclass
class Cases:
    """A placed network's inputs for a patient's load cases and their FE fields, all in the
    population's frame: what fine-tuning feeds it.
    """

    forces: np.ndarray       # (n, 1, 3) N
    load_points: np.ndarray  # (n, 1, 3) mm, the registered template's load nodes
    extra: np.ndarray        # (n, e) shape coefficients told
    context: np.ndarray      # (n, 1, c) the loads' context on the registered template
    targets: np.ndarray      # (n, n_out * 3) mm
    groups: np.ndarray       # (n,) each case's simulation

    def take(self, idx) -> Cases:
        return Cases(*(np.asarray(v)[idx] for v in dataclasses.astuple(self)))


def placed_cases(placed, forces, points, fields, groups) -> Cases:
    """The network inputs of ``placed`` (a PlacedModel) for forces (n, 3) N at points (n, 3)
    mm of the liver's frame, with FE ``fields`` (n, n_out, 3) mm of that frame.
    """
    pred, pl = placed.predictor, placed.placement
    nodes = placed.load_nodes(np.asarray(points, float)[:, None])
    reg_points, fixed, _ = placed.geometry
    liver = (("tuning", pl.residual), reg_points, np.asarray(fixed))
    ctx = np.asarray(pred.runtime.context(pred, nodes, liver))
    n = len(nodes)
    return Cases(pl.vectors_to_population(np.asarray(forces, float)[:, None]).astype(np.float32),
                 reg_points[nodes].astype(np.float32),
                 pred.varied_inputs(n, None, placed.geometry).astype(np.float32),
                 ctx.astype(np.float32),
                 pl.vectors_to_population(fields).reshape(n, -1).astype(np.float32),
                 np.asarray(groups))


def placed_modes(placed, out_nodes) -> np.ndarray:
    """(k, 3 n_out): the population's modes at the output nodes ``out_nodes`` of the patient's
    mesh (placed.nodes), in the population's frame.
    """
    w = placed.interpolation[np.asarray(out_nodes)]
    modes = placed.predictor.runtime.modes                    # (k, n_template, 3)
    return np.stack([w @ m for m in modes]).reshape(len(modes), -1).astype(np.float32)


class Trainer(NamedTuple):
    """What tuning a placed network takes, built once per network and modes (:func:`_trainer`)."""

    init: Callable     # params -> Adam's state
    step: Callable     # (params, state, arrays, rate) -> (params, state), jitted
    mee: Callable      # (params, Cases) -> MEE mm of the cases
    arrays: Callable   # Cases -> what step takes
    fields: Callable   # (params, Cases) -> (n, 3 n_out) mm


def _trainer(runtime, rows) -> Trainer:
    """Adam on the RMS field loss of ``runtime``'s network, its step compiled once for every
    rate and set of cases of one shape. The loss is
    computed from the mode coefficients: with the modes' Gram matrix G = R R^T and a case's
    projections b = R t, its squared error is c G c - 2 c.b + t.t, whatever the nodes'
    count (``arrays(cases)``: what the step takes).
    """
    import jax
    import jax.numpy as jnp
    import optax

    adam = optax.scale_by_adam()
    rows = np.asarray(rows, dtype=np.float64)
    k, width = rows.shape
    gram = jnp.asarray(rows @ rows.T, dtype=jnp.float32)
    # the network's coefficients themselves: the call with unit modes, padded to whole nodes
    unit = jnp.asarray(np.eye(k, 3 * -(-k // 3)), dtype=jnp.float32)

    def coefficients(params, forces, load_points, extra, context):
        c = runtime.fields_with(params, unit, forces, load_points, extra, context)
        return c.reshape(len(forces), -1)[:, :k]

    def loss(params, c: tuple):
        forces, load_points, extra, context, b, tt = c
        a = coefficients(params, forces, load_points, extra, context)
        sq = jnp.einsum("ni,ij,nj->n", a, gram, a) - 2.0 * jnp.sum(a * b, axis=1) + tt
        return jnp.mean(jnp.sqrt(jnp.maximum(sq, 0.0) / (width / 3) + 1e-12))

    @jax.jit
    def step(params, state, c: tuple, rate):
        updates, state = adam.update(jax.grad(loss)(params, c), state, params)
        return jax.tree_util.tree_map(lambda p, u: p - rate * u, params, updates), state

    def fields(params, c: Cases) -> np.ndarray:
        return np.asarray(coefficients(params, c.forces, c.load_points, c.extra,
                                       c.context)) @ rows

    def mee(params, c: Cases) -> float:
        return field_mee(fields(params, c), c.targets)

    def arrays(c: Cases) -> tuple:
        t = np.asarray(c.targets, dtype=np.float64)
        return (c.forces, c.load_points, c.extra, c.context,
                (t @ rows.T).astype(np.float32), np.sum(t * t, axis=1).astype(np.float32))

    return Trainer(adam.init, step, mee, arrays, fields)


def _tuned(trainer: Trainer, params, c: Cases, rate: float, steps: int,
           held: Cases | None = None):
    """(``params`` after ``steps`` Adam steps on ``c``, {steps of STEPS: MEE on ``held``}:
    with ``held``, the steps run to the last of STEPS, scored at each of them).
    """
    last = max(STEPS) if held is not None else steps
    c, state, scores = trainer.arrays(c), trainer.init(params), {}
    for s in range(last + 1):
        if held is not None and s in STEPS:
            scores[s] = trainer.mee(params, held)
        if s < last:
            params, state = trainer.step(params, state, c, rate)
    return params, scores


def out_of_fold(trainer: Trainer, params, c: Cases, rate: float, steps: int) -> np.ndarray:
    """(n, 3 n_out) mm: each case's field from the network tuned (``rate``, ``steps``)
    without its simulation's fold: residuals as large as a new load's, for the correction
    fitted after tuning (on the tuned model's own training cases its residuals are too small).
    """
    out = np.zeros(c.targets.shape, dtype=np.float64)
    for held in simulation_folds(c.groups, FOLDS):
        te = np.isin(c.groups, held)
        tuned, _ = _tuned(trainer, params, c.take(~te), rate, steps)
        out[te] = trainer.fields(tuned, c.take(te))
    return out


def choose(runtime, rows, c: Cases, trainer=None) -> tuple[float, int, float]:
    """(rate, steps, cross-validated MEE mm) of least held-out MEE over folds of whole
    simulations; steps 0 (no tuning) unless tuning lowers it by ``MIN_GAIN``.
    """
    trainer = trainer or _trainer(runtime, rows)
    folds = simulation_folds(c.groups, FOLDS)
    total: dict = {}
    for held in folds:
        te = np.isin(c.groups, held)
        for rate in RATES:
            _, scores = _tuned(trainer, runtime.params, c.take(~te), rate, 0, c.take(te))
            for s, v in scores.items():
                total[(rate, s)] = total.get((rate, s), 0.0) + v / len(folds)
    best = min(total, key=lambda k: (total[k], k[1]))
    untuned = total[(RATES[0], 0)]
    if total[best] >= (1.0 - MIN_GAIN) * untuned:   # not clearly better on held-out ones
        return RATES[0], 0, untuned
    return best[0], best[1], total[best]


def fine_tuned(placed, rows, c: Cases, cv: Cases):
    """(a copy of ``placed`` whose network is tuned on the cases ``c`` as far as the
    cross-validation on ``cv`` says, {rate, steps, cv_mee_mm}, the cases' out-of-fold fields
    (:func:`out_of_fold`; the population frame) or None when not tuned); ``placed`` itself
    unchanged. Fewer than two simulations: no tuning.
    """
    if np.unique(c.groups).size < 2:
        return placed, {"rate": None, "steps": 0, "cv_mee_mm": None}, None
    runtime = placed.predictor.runtime
    trainer = _trainer(runtime, rows)
    rate, steps, cv_mee = choose(runtime, rows, cv, trainer)
    info = {"rate": rate, "steps": steps, "cv_mee_mm": cv_mee}
    if steps == 0:
        return placed, info, None
    oof = out_of_fold(trainer, runtime.params, c, rate, steps)
    params, _ = _tuned(trainer, runtime.params, c, rate, steps)
    tuned_runtime = copy.copy(runtime)
    tuned_runtime.params = params
    predictor = copy.copy(placed.predictor)
    predictor.runtime = tuned_runtime
    out = copy.copy(placed)
    out.predictor = predictor
    return out, info, oof
