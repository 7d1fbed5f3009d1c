"""A new patient's model: the population model placed on the patient's liver (its boundary
condition), the liver's small-strain responses on its own mesh corrected with a few FE
simulations there, and distilled into a model of that one liver (the reduced basis,
:mod:`surrogate.basis`) that ``load_predictor``, the viewer and the manipulator use as any
other one-liver model.

    python -m surrogate adapt MODEL DATA --liver FILE --run OUT [--sims K] [--frame F] [--tune]

``DATA``: the patient's FE simulations with the model's boundary condition (``truth-scene``
then ``fem_sim generate``), and their small-strain responses with those of the drawn loads
(``fem_sim linear``, ``DATA/linear.h5``, :mod:`surrogate.linear_base`); ``make patient``
runs the four steps. The teacher's base is those responses (the exact linear elasticity of
the patient's mesh, with their second-order terms when ``fem_sim linear --order 2`` gave
them: :mod:`surrogate.linear_base`); a dataset without them falls back on the placed
population model.

With the population model of the base's rest (``--rest``), the rest's weight over the
base is first fitted to the K simulations (least squares, within [0, 1]: a liver whose own
base is already close takes less of it; :func:`fit_rest_weight`).

The correction (:class:`Correction`) is the residual of the FE fields against the base,
regressed on the load by kernel ridge regression (with ``tune``: against
that model with its network first fine-tuned on the K simulations, :mod:`surrogate.tuning`,
on the tuned network's out-of-fold residuals; docs/patient.md measures both). The kernel is a
Gaussian of the distance between the load points times a polynomial of the forces with no
constant term, ``g(x, x') (f.f' + beta (f.f')^2)``: a residual that vanishes with the force
and is nearly linear in it, as a hyperelastic liver's against a population model is for
small loads (against its own small-strain response, nearly quadratic), and that spreads
from a loaded point to its neighbours (a Gaussian, or an exponential with its heavier tail).
Two terms are added to it: the product of the base's fields for the two loads,
and that of what the K FE simulations say of each load by reciprocity (:class:`Sensors`:
by Maxwell-Betti, simulation k's first, nearly linear, load step gives the displacement at
its load point along its force that any other load causes there; so a load reads its
residual at the K load points, and the regression learns how the whole residual field
follows those K readings). The decay, length scale, ridge, beta and the weights of the two
added terms are chosen by cross-validation over the K simulations, grouped by simulation (a
held-out simulation's readings come from the others only); with fewer than
two, or when no setting beats the base on the held-out simulations, the base is kept
unchanged. The distillation takes loads drawn as the scene draws them (its eligible nodes,
uniform directions, its magnitude and load steps: ``fem_sim linear``'s drawn cases, or drawn
here without them), their fields from the corrected base, and trains the reduced basis on
them with the K FE fields.
"""

from __future__ import annotations

import dataclasses
import json
import time
import warnings
from pathlib import Path

import numpy as np

from surrogate.data import Dataset
from surrogate.linear_base import LinearBase
from surrogate.tuning import fine_tuned, placed_cases, placed_modes, simulation_folds

LENGTHS = (10.0, 20.0, 40.0, 80.0, 160.0)   # mm: the kernel's length scales tried
DECAYS = ("gauss", "exp")                    # how it falls with the load points' distance d:
                                             # exp(-d^2 / 2 l^2), or exp(-d / l)
RIDGES = (1e-3, 1e-2, 0.1, 0.3, 1.0, 3.0, 10.0)   # relative to the kernel's mean diagonal
BETAS = (0.0, 1.0)                           # weight of the quadratic force term
# the distilled model's config (its RMS loss as the population basis's: docs/real_knobs.md),
# and the drawn loads it learns the corrected model from beside the K FE simulations
# (docs/patient.md: the student's settings, measured on training livers)
STUDENT = {"design": "basis", "ensemble": 1, "folds": 2, "loss": "rms"}
SYNTHETIC = 600


def _products(a: tuple, b: tuple) -> tuple:
    """What the kernel needs of cases a, b = (load points (n, 3) mm, forces (n, 3) N,
    population fields (n, m) mm, reciprocity readings (n, K) mm): squared distances, force,
    field and readings inner products.
    """
    (xa, fa, ua, sa), (xb, fb, ub, sb) = a, b
    return ((xa[:, None, :] - xb[None, :, :]) ** 2).sum(-1), fa @ fb.T, ua @ ub.T, sa @ sb.T


def _combined(p: tuple, length: float, beta: float, mix: float, decay: str, gamma: float,
              scales: tuple) -> np.ndarray:
    """(na, nb): (1 - mix) x a decay in the load points' distance (``DECAYS``) times
    f.f' + beta (f.f')^2, plus mix x the population fields' inner product, plus gamma x the
    reciprocity readings' (``scales``: the force's, the fields' and the readings' scales).
    """
    d2, ff = p[0], p[1] / scales[0] ** 2
    uu, ss = p[2] / scales[1] ** 2, p[3] / scales[2] ** 2
    near = np.exp(-d2 / (2.0 * length ** 2)) if decay == "gauss" else \
        np.exp(-np.sqrt(np.maximum(d2, 0.0)) / length)
    return (1.0 - mix) * near * (ff + beta * ff ** 2) + mix * uu + gamma * ss


def _kernel(a: tuple, b: tuple, length: float, beta: float, mix: float, decay: str,
            gamma: float, scales: tuple) -> np.ndarray:
    return _combined(_products(a, b), length, beta, mix, decay, gamma, scales)


@dataclasses.dataclass
class Sensors:
    """What the patient's K FE simulations say of any load by reciprocity (Maxwell-Betti: in
    the linear range, the displacement at point a along d caused by a force f at b is f . the
    displacement at b caused by a unit force at a along d). Simulation k's first load step
    (the smallest force, nearly linear) divided by its force gives that unit field; a load
    (b, f) then reads f . it at b, the displacement it causes at simulation k's load point
    along its force, less what the population model's field for the load puts there: a
    reading of the load's residual at the K load points, known for a new load without its
    FE simulation. A load not at an output node reads the fields at the nearest one.
    """

    nodes: np.ndarray        # (n_out, 3) mm: the output nodes
    at: np.ndarray           # (K,) the output node of each simulation's load point
    along: np.ndarray        # (K, 3) its force's direction
    unit: np.ndarray         # (K, n_out, 3) mm/N: its first load step's field per newton
    sims: np.ndarray         # (K,) their simulations
    tree: object = dataclasses.field(repr=False, compare=False)  # KD-tree of the nodes

    @classmethod
    def of(cls, nodes, x, f, fields, groups) -> Sensors:
        """From the cases of the FE simulations: load points ``x`` (n, 3) mm, forces ``f``
        (n, 3) N, ``fields`` (n, n_out, 3) mm at the output ``nodes``, each case's
        simulation ``groups``.
        """
        from scipy.spatial import cKDTree

        nodes, f, groups = np.asarray(nodes, float), np.asarray(f, float), np.asarray(groups)
        sims = np.unique(groups)
        norms = np.linalg.norm(f, axis=1)
        first = np.array([np.flatnonzero(groups == s)[np.argmin(norms[groups == s])]
                          for s in sims])
        tree = cKDTree(nodes)
        at = tree.query(np.asarray(x, float)[first])[1]
        size = np.maximum(norms[first], 1e-30)[:, None]
        unit = np.asarray(fields, float)[first] / size[:, :, None]
        return cls(nodes, at, f[first] / size, unit, sims, tree)

    def __call__(self, x, f, fields, groups=None) -> np.ndarray:
        """(n, K) mm: the readings of loads at ``x`` (n, 3) mm with forces ``f`` (n, 3) N whose
        population fields are ``fields`` (n, m); ``groups``: the cases' own simulations, which
        read nothing of themselves (zero), as a new load has no simulation of its own.
        """
        b = self.tree.query(np.asarray(x, float).reshape(-1, 3))[1]
        f = np.asarray(f, float).reshape(-1, 3)
        said = np.einsum("knc,nc->nk", self.unit[:, b], f)
        put = np.einsum("nkc,kc->nk", np.asarray(fields, float).reshape(
            len(f), len(self.nodes), 3)[:, self.at], self.along)
        out = said - put
        if groups is not None:
            out[np.asarray(groups)[:, None] == self.sims[None, :]] = 0.0
        return out


MIXES = (0.0, 0.5, 1.0)                      # weight of the population fields' product
GAMMAS = (0.0, 0.3, 1.0, 3.0)                # weight of the reciprocity readings' product
MIN_GAIN = 0.01                              # a kept correction lowers the held-out
                                             # MEE by at least this fraction (a heavily
                                             # ridged fit of noise scrapes a few 1e-4)
CV_STEPS = 4                                 # load steps per simulation the setting is
                                             # chosen on
REST_WEIGHT = True                           # fit the rest's weight on the K simulations
REST_MIN_SIMS = 2                            # with at least this many


def _take(cases: tuple, idx) -> tuple:
    return tuple(c[idx] for c in cases)


@dataclasses.dataclass
class Correction:
    """Kernel ridge regression of residual fields on the load (one load per case), the
    population model's field for it and its reciprocity readings.
    """

    cases: tuple            # the training cases: load points, forces, population fields,
    #                         readings
    weights: np.ndarray     # (n, m): dual coefficients, m = output nodes x 3
    setting: tuple          # (length mm, beta, mix, decay, gamma, ridge)
    scales: tuple           # the force's scale (N), the fields' and the readings' (mm)
    sensors: Sensors | None = None   # what gives a load its readings (None: no readings)
    cv_mee: float = float("nan")   # mm: the chosen setting's cross-validated residual MEE

    def __call__(self, points, forces, fields) -> np.ndarray:
        """(cases, m) residual at load points (cases, 3) mm with forces (cases, 3) N and the
        population model's fields (cases, m) mm for them.
        """
        b = _cases(points, forces, fields, self.sensors)
        return _kernel(b, self.cases, *self.setting[:-1], self.scales) @ self.weights


def _cases(x, f, u, sensors: Sensors | None, groups=None) -> tuple:
    """The kernel's cases: load points, forces, population fields, reciprocity readings
    (none without ``sensors``), each (n, ...) float64.
    """
    x, f, u = (np.asarray(a, dtype=np.float64).reshape(len(a), -1) for a in (x, f, u))
    s = np.zeros((len(x), 0)) if sensors is None else sensors(x, f, u, groups)
    return x, f, u, s


def _mee(residual: np.ndarray) -> float:
    return float(np.linalg.norm(residual.reshape(residual.shape[0], -1, 3), axis=-1).mean())


def _sq(pred, true) -> float:
    return float(np.mean(np.sum((pred - true) ** 2, axis=1)))


def _cv_scores(cases: tuple, r, groups, scales: tuple, score=_sq, grid=None,
               columns=None) -> dict:
    """{(length, beta, mix, decay, gamma, ridge): mean held-out ``score``} over folds of
    whole simulations; ``grid``: the (length, beta, mix, decay, gamma) tried (default: every
    one, gamma 0 only without readings) with every ridge; ``columns``: the simulation each
    reading comes from (a fold's held-out simulations read nothing).
    """
    folds = simulation_folds(groups, 5)
    gammas = GAMMAS if cases[3].shape[1] else (0.0,)
    grid = grid or [(ln, b, m, d, g) for ln in LENGTHS for b in BETAS for m in MIXES
                    for d in DECAYS for g in gammas]
    products = _products(cases, cases)  # once: every fold's kernels are slices of it
    scores: dict = {}
    for held in folds:
        te = np.isin(groups, held)
        if cases[3].shape[1]:
            s = cases[3][:, ~np.isin(columns, held)]
            products = (*products[:3], s @ s.T)
        for kernel in grid:
            full = _combined(products, *kernel, scales)
            k = full[np.ix_(~te, ~te)]
            lam, q = np.linalg.eigh(k)
            qr = q.T @ r[~te]
            kt = full[np.ix_(te, ~te)] @ q
            diag = max(float(np.mean(np.diag(k))), 1e-30)
            for ridge in RIDGES:
                pred = kt @ (qr / (np.maximum(lam, 0.0) + ridge * diag)[:, None])
                key = (*kernel, ridge)
                scores[key] = scores.get(key, 0.0) + score(pred, r[te]) / len(folds)
    return scores


def _spread_steps(groups: np.ndarray) -> np.ndarray:
    """The cases the cross-validation uses: at most CV_STEPS of each simulation's, spread
    over its steps and ending at its last.
    """
    out = []
    for g in np.unique(groups):
        idx = np.flatnonzero(groups == g)
        out.append(idx[np.unique(np.linspace(idx.size - 1, 0, CV_STEPS).round().astype(int))])
    return np.sort(np.concatenate(out))


def fit_correction(x, f, u, r, groups, sensors: Sensors | None = None) -> Correction | None:
    """The correction of residuals ``r`` (n, m) for loads at ``x`` (n, 3) mm with forces ``f``
    (n, 3) N whose population fields are ``u`` (n, m); ``groups``: each case's simulation (the
    cross-validation holds out whole ones); ``sensors``: the loads' reciprocity readings
    (:class:`Sensors` of these simulations; None: none). The setting is the one of least
    cross-validated squared error, computed on at most CV_STEPS load steps of each simulation
    (the steps of one load are nearly proportional) and on the residuals' singular
    coordinates (the same sums, far fewer columns). None (no correction) with fewer than two
    simulations, or when the nested cross-validated MEE of the whole fit (:func:`_nested_mee`)
    is not MIN_GAIN below the residual's own.
    """
    groups = np.asarray(groups)
    if np.unique(groups).size < 2:
        return None   # nothing to check a setting on
    cases = _cases(x, f, u, sensors, groups)
    r = np.asarray(r, dtype=np.float64)
    scales = tuple(float(np.linalg.norm(c, axis=1).max(initial=0.0)) or 1.0
                   for c in cases[1:])
    columns = None if sensors is None else sensors.sims
    sub = _spread_steps(groups)
    cs, rs, gs = _take(cases, sub), r[sub], groups[sub]
    cv = _nested_mee(cs, rs, gs, scales, columns)
    if cv >= (1.0 - MIN_GAIN) * _mee(rs):   # no better than the base on held-out
        #                                     simulations
        return None
    setting = _selected(cs, rs, gs, scales, columns)
    return Correction(cases, _weights(cases, r, setting, scales), setting, scales, sensors, cv)


def _selected(cs: tuple, rs, gs, scales: tuple, columns) -> tuple:
    """The setting of least cross-validated squared error (on the residuals' singular
    coordinates: the same sums, far fewer columns).
    """
    left, sv, _ = np.linalg.svd(rs, full_matrices=False)
    scores = _cv_scores(cs, left * sv, gs, scales, columns=columns)
    return min(scores, key=scores.get)


def _weights(cases: tuple, r, setting: tuple, scales: tuple) -> np.ndarray:
    k = _kernel(cases, cases, *setting[:-1], scales)
    diag = max(float(np.mean(np.diag(k))), 1e-30)
    return np.linalg.solve(k + setting[-1] * diag * np.eye(k.shape[0]), r)


def _nested_mee(cs: tuple, rs, gs, scales: tuple, columns) -> float:
    """The cross-validated MEE of the whole fit, its choice of setting included: each
    fold's simulations predicted by a correction whose setting was selected (and fitted) on
    the other simulations alone, reading none of the fold's. Scoring the setting chosen on
    all folds on those same folds instead is biased low (the least of 1,680 noisy scores):
    it kept corrections that made held-out simulations worse. Infinite when a fold leaves
    fewer than two simulations to select on.
    """
    folds = simulation_folds(gs, 5)
    total = 0.0
    for held in folds:
        te = np.isin(gs, held)
        if np.unique(gs[~te]).size < 2:
            return float("inf")
        inner, cols = cs, columns
        if columns is not None:
            keep = ~np.isin(columns, held)
            inner, cols = (*cs[:3], cs[3][:, keep]), columns[keep]
        train = _take(inner, ~te)
        setting = _selected(train, rs[~te], gs[~te], scales, cols)
        w = _weights(train, rs[~te], setting, scales)
        pred = _kernel(_take(inner, te), train, *setting[:-1], scales) @ w
        total += _mee(pred - rs[te]) / len(folds)
    return total


class Teacher:
    """The population model placed on the patient's liver, at the nodes of the patient's
    mesh ``ds`` (its output nodes), plus the correction once fitted.
    """

    def __init__(self, pred, placement, ds: Dataset, shape: str | None = None,
                 linear: LinearBase | None = None, rest=None):
        """``rest``: a population model of what each liver's small-strain base misses (config
        ``linear_base``), placed as ``pred`` and added to ``linear``, the patient's own base.
        """
        from surrogate.predict_liver import PlacedModel

        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            self.placed = PlacedModel(pred, nodes=ds.points[0], placement=placement,
                                      shape=shape)
            self.rest = None if rest is None else PlacedModel(
                rest, nodes=ds.points[0], placement=placement, shape=shape)
        if rest is not None and (linear is None or linear.order < rest.linear_base):
            raise ValueError(f"the population model of the base's rest was trained over a "
                             f"small-strain base of order {rest.linear_base}; the patient's "
                             f"is {'missing' if linear is None else f'of order {linear.order}'}"
                             f": run fem_sim linear --order {rest.linear_base} on its scene")
        self.out = np.asarray(ds.out_nodes[0])
        self.linear = linear   # the patient's small-strain responses: the base when given
        self.rest_weight = 1.0   # of the rest over the base (fit_rest_weight)
        self.correction: Correction | None = None
        self.tuning: dict | None = None
        self.out_of_fold: np.ndarray | None = None   # (samples, n_out, 3) mm, once tuned

    def tune(self, ds: Dataset, samples: np.ndarray, fields: np.ndarray) -> None:
        """The placed network fine-tuned on the FE ``fields`` of the patient's ``samples``
        (:mod:`surrogate.tuning`; how far chosen by cross-validation over simulations).
        """
        if self.linear is not None:
            raise ValueError("fine-tuning adapts the population network; with the patient's "
                             "small-strain responses as the base there is none to tune")
        groups = ds.sample_sim[samples]
        cases = placed_cases(self.placed, ds.forces[samples, 0], ds.load_points[samples, 0],
                             fields, groups)
        rows = placed_modes(self.placed, self.out)
        placement = self.placed.placement
        self.placed, self.tuning, oof = fine_tuned(self.placed, rows, cases,
                                                   cases.take(_spread_steps(groups)))
        self.out_of_fold = None if oof is None else \
            placement.vectors_to_liver(oof.reshape(fields.shape))

    def population(self, forces, points, chunk: int = 256, placed=None) -> np.ndarray:
        """(cases, n_out, 3) mm: the placed population model (``placed``: another one, of
        the base's rest) for one load per case, forces (cases, 3) N at the load points
        (cases, 3) mm (the patient's frame).
        """
        forces, points = np.asarray(forces, float), np.asarray(points, float)
        placed, out = placed or self.placed, []
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            for s in range(0, forces.shape[0], chunk):
                f, p = forces[s:s + chunk, None], points[s:s + chunk, None]
                out.append(placed(f, placed.load_nodes(p), rest=placed is self.rest)[:, self.out])
        return np.concatenate(out) if out else np.zeros((0, self.out.size, 3))

    def over_base(self, base: np.ndarray, forces, points) -> np.ndarray:
        """The small-strain ``base`` of the cases plus the population's rest (times its
        weight), when given.
        """
        if self.rest is None or self.rest_weight == 0.0:
            return base
        return base + self.rest_weight * self.population(forces, points, placed=self.rest)

    def base(self, ds: Dataset, samples: np.ndarray) -> np.ndarray:
        """(samples, n_out, 3) mm: what the correction corrects for the samples of ``ds``:
        the small-strain responses when the teacher has them (plus the population's rest of
        them when given), else the population model.
        """
        f, x = ds.forces[samples, 0], ds.load_points[samples, 0]
        if self.linear is not None:
            return self.over_base(self.linear.samples(ds, samples), f, x)
        return self.population(f, x)

    def __call__(self, forces, points, base: np.ndarray | None = None) -> np.ndarray:
        """(cases, n_out, 3) mm: the base (``base``; default the population model) plus
        the correction.
        """
        u = self.population(forces, points) if base is None else base
        if self.correction is not None and len(u):
            u = u + self.correction(points, forces, u).reshape(u.shape)
        return u


def sample_fields(ds: Dataset, samples: np.ndarray) -> np.ndarray:
    """(samples, n_out, 3) mm: the FE fields of the samples of a one-liver dataset."""
    n_out = ds.out_nodes[0].size
    return np.stack([np.asarray(ds.targets[ds.sample_offset[s]:ds.sample_offset[s] + n_out])
                     for s in samples]).astype(np.float64)


def sims_samples(ds: Dataset, sims) -> np.ndarray:
    """The samples (converged load steps) of the simulations ``sims``."""
    return np.flatnonzero(np.isin(ds.sample_sim, np.asarray(sims)))


def fit_rest_weight(teacher: Teacher, ds: Dataset, smp: np.ndarray, fields) -> float:
    """The weight of the population's rest over the patient's small-strain base that fits
    the FE ``fields`` of the samples ``smp`` best (least squares over every node, clipped to
    [0, 1]: the rest, or less of it where the liver's base needs less), kept in the teacher;
    1 with fewer than REST_MIN_SIMS simulations or without a rest.
    """
    if teacher.rest is None or np.unique(ds.sample_sim[smp]).size < REST_MIN_SIMS:
        return teacher.rest_weight
    rest = teacher.population(ds.forces[smp, 0], ds.load_points[smp, 0], placed=teacher.rest)
    miss = np.asarray(fields, np.float64) - teacher.linear.samples(ds, smp)
    fit = float(np.sum(miss * rest) / max(float(np.sum(rest * rest)), 1e-300))
    teacher.rest_weight = float(np.clip(fit, 0.0, 1.0))
    return teacher.rest_weight


def fit_teacher(teacher: Teacher, ds: Dataset, sims, tune: bool = False) -> Teacher:
    """The teacher fitted on the FE simulations ``sims`` of the patient: its network
    fine-tuned on them (``tune``), or the weight of the population's rest over its base
    (:func:`fit_rest_weight`), then the correction of what is left, fitted on the tuned
    network's out-of-fold residuals.
    """
    smp = sims_samples(ds, sims)
    f, x = ds.forces[smp, 0], ds.load_points[smp, 0]
    fields = sample_fields(ds, smp)
    if tune:
        teacher.tune(ds, smp, fields)
    elif REST_WEIGHT:
        fit_rest_weight(teacher, ds, smp, fields)
    # the correction learns the residual of a load the network was not tuned on: out of fold
    u = teacher.out_of_fold if teacher.out_of_fold is not None else teacher.base(ds, smp)
    r = (fields - u).reshape(smp.size, -1)
    groups = ds.sample_sim[smp]
    sensors = Sensors.of(ds.points[0][teacher.out], x, f, fields, groups)
    teacher.correction = fit_correction(x, f, u, r, groups, sensors)
    return teacher


def drawn_loads(ds: Dataset, n_sims: int, seed: int):
    """(forces (S, 3) N, load nodes (S,), fractions (S,), simulation (S,)): ``n_sims`` loads
    drawn as the patient's scene draws them (a node it may load, a uniform direction, its
    magnitude), each at every load fraction of the FE simulations.
    """
    rng = np.random.default_rng(seed)
    fractions = np.unique(np.round(ds.sample_fraction, 9))
    magnitude = float(np.max(np.linalg.norm(ds.forces[:, 0], axis=-1)
                             / np.maximum(ds.sample_fraction, 1e-12)))
    nodes = rng.choice(np.asarray(ds.loadable[0]), size=n_sims)
    d = rng.normal(size=(n_sims, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    rep = fractions.size
    forces = np.repeat(magnitude * d, rep, axis=0) * np.tile(fractions, n_sims)[:, None]
    return (forces, np.repeat(nodes, rep), np.tile(fractions, n_sims),
            np.repeat(np.arange(n_sims), rep))


def with_cases(ds: Dataset, keep: np.ndarray, forces, nodes, fractions, sims,
               fields) -> Dataset:
    """A one-liver dataset of the samples ``keep`` of ``ds`` and new cases (one load each;
    ``fields`` (S, n_out, 3) mm) numbered after its simulations.
    """
    if ds.extra.shape[1]:
        raise ValueError(f"{ds.directory}: the patient's scene varies its material or shape "
                         "(extra inputs); a patient model is of one liver and one material")
    n_out = ds.out_nodes[0].size
    first = int(ds.sample_sim.max()) + 1
    rows = np.concatenate([np.arange(ds.sample_offset[s], ds.sample_offset[s] + n_out)
                           for s in keep]) if keep.size else np.zeros(0, int)
    targets = np.concatenate([np.asarray(ds.targets[rows], np.float32),
                              np.asarray(fields, np.float32).reshape(-1, 3)])
    n = keep.size + len(sims)
    return dataclasses.replace(
        ds, sample_geo=np.zeros(n, ds.sample_geo.dtype),
        sample_sim=np.concatenate([ds.sample_sim[keep], first + np.asarray(sims)]),
        sample_fraction=np.concatenate([ds.sample_fraction[keep], fractions]),
        forces=np.concatenate([ds.forces[keep], np.asarray(forces)[:, None]]),
        load_points=np.concatenate([ds.load_points[keep],
                                    ds.points[0][np.asarray(nodes)][:, None]]),
        load_nodes=np.concatenate([ds.load_nodes[keep], np.asarray(nodes)[:, None]]),
        extra=np.zeros((n, 0), ds.extra.dtype), targets=targets,
        sample_offset=np.arange(n + 1) * n_out)


def distilled(teacher: Teacher, ds: Dataset, sims, n_synthetic: int, cfg: dict,
              seed: int = 0, log_fn=print):
    """(model, dataset, linear part): the reduced basis trained on the FE simulations
    ``sims`` and ``n_synthetic`` drawn loads with the teacher's fields; with the small-strain
    Green's function (``fem_sim linear --green``), trained on what the fields hold beyond
    its exact small-strain part, which the exported model adds back at run time (the linear
    part: (nodes, unit responses), else None).
    """
    from surrogate.train import fit_design

    if teacher.linear is not None:   # the drawn cases of fem_sim linear, with their responses
        forces, nodes, fractions, sim, base = teacher.linear.drawn(n_synthetic)
        base = teacher.over_base(base, forces, ds.points[0][nodes])
        fields = teacher(forces, ds.points[0][nodes], base)
    else:
        forces, nodes, fractions, sim = drawn_loads(ds, n_synthetic, seed)
        fields = teacher(forces, ds.points[0][nodes])
    aug = with_cases(ds, sims_samples(ds, sims), forces, nodes, fractions, sim, fields)
    part = None if teacher.linear is None else teacher.linear.green
    if part is not None:
        exact = teacher.linear.green_part(aug.load_nodes[:, 0], aug.forces[:, 0])
        aug = dataclasses.replace(aug, targets=(np.asarray(aug.targets, np.float64)
                                                - exact.reshape(-1, 3)).astype(np.float32))
    model, _ = fit_design(aug, np.arange(aug.n_samples), cfg, seed, "patient ", log_fn)
    return model, aug, part


def student_config(**overrides) -> dict:
    """The distilled model's config: the reduced basis, one network, no cross-validation."""
    from surrogate.config import get_config

    return get_config("basis", **{**STUDENT, **overrides})


def adapt(model_dir, data, liver, run, *, sims: int | None = None, frame: str | None = None,
          synthetic: int = SYNTHETIC, seed: int = 0, saved=None, tune: bool = False,
          rest=None, log_fn=print, **overrides) -> dict:
    """The patient model of ``liver`` in ``run/model``: the population model ``model_dir``
    placed on it (as predict-liver places it; ``saved``: a placement file truth-scene wrote),
    corrected (its network first fine-tuned with ``tune``) with the first ``sims`` FE
    simulations of ``data`` (None: all; 0 with the patient's small-strain responses: those
    alone) and distilled; ``rest``: the model directory of a population model of the
    base's rest (:class:`Teacher`), ``model_dir`` itself when it is one.
    Writes and returns ``run/adaptation.json`` (what was used, the correction's setting,
    seconds per step).
    """
    from surrogate.data import load_dataset
    from surrogate.evaluate import place
    from surrogate.predictor import load_predictor

    t = time.perf_counter()
    ds = load_dataset(data)
    linear = None if tune else LinearBase.of(ds)
    used = used_simulations(ds, sims, data, linear is not None)
    pred = load_predictor(model_dir)
    if pred.shape_model is None:
        raise ValueError(f"{model_dir}: not a population model (no shape model): a patient "
                         "model adapts a model trained on a population of livers")
    # a population model of the bases' rest is its own rest (and places the liver as well)
    rest_pred = pred if rest is None and pred.linear_base else \
        None if rest is None else _rest_model(rest, pred, model_dir)
    placement, found = place(pred, liver, frame, saved)
    # --tune adapts the population network, so it keeps the population model as the base
    teacher = Teacher(pred, placement, ds, linear=linear, rest=rest_pred)
    placed = time.perf_counter()
    if len(used):
        fit_teacher(teacher, ds, used, tune)
    corrected = time.perf_counter()
    info = {"population_model": str(Path(model_dir).resolve()),
            "liver": str(Path(liver).resolve()), "data": str(Path(data).resolve()),
            "placement_residual_mm": placement.residual, "warnings": list(found),
            "base": "population model" if teacher.linear is None else
                    f"small-strain responses ({teacher.linear.path})"
                    + ("" if rest_pred is None else " and the population's rest of them"),
            "tuning": teacher.tuning,
            "rest_weight": None if rest_pred is None else teacher.rest_weight,
            **adapted(teacher, ds, used, run, synthetic=synthetic, seed=seed, log_fn=log_fn,
                      **overrides)}
    fitting = "tuning_and_correction" if tune else "correction"
    info["seconds"] = {"place": placed - t, fitting: corrected - placed,
                       **info["seconds"], "total": time.perf_counter() - t}
    (Path(run) / "adaptation.json").write_text(json.dumps(info, indent=1))
    return info


def _rest_model(rest, pred, model_dir):
    """The population model of the base's rest in ``rest``, checked against ``pred``'s
    template (it is placed by ``pred``'s placement).
    """
    from surrogate.evaluate import shape_model_digest
    from surrogate.predictor import load_predictor

    out = load_predictor(rest)
    if not out.linear_base:
        raise ValueError(f"--rest {rest}: not a model of a small-strain base's rest (config "
                         "linear_base = 0); train config population_linear")
    if out.shape_model is None or \
            shape_model_digest(out.shape_model) != shape_model_digest(pred.shape_model):
        raise ValueError(f"--rest {rest}: another template or shape model than {model_dir}'s: "
                         "both must be trained on the same population dataset")
    return out


def used_simulations(ds: Dataset, sims: int | None, data, linear: bool = False) -> np.ndarray:
    """The first ``sims`` simulations of the patient's dataset ``ds`` (read from ``data``)
    with converged load steps (None: all of them; 0 only with the patient's small-strain
    responses, ``linear``); ValueError, before any work, for none, or fewer than asked (a
    model fitted on fewer simulations than the user counted on).
    """
    done = np.unique(ds.sample_sim)
    if sims == 0 and linear:
        return done[:0]
    if sims == 0 or not done.size:
        raise ValueError(f"{data}: adapting needs at least one FE simulation of the patient "
                         f"(--sims {sims}; the data has {done.size} with converged load "
                         "steps), or at --sims 0 its small-strain responses (fem_sim linear, "
                         "as make patient runs it); predict-liver gives the population model "
                         "on this liver")
    if sims is not None and sims > done.size:
        raise ValueError(f"{data}: {done.size} simulations with converged load steps, fewer "
                         f"than the {sims} asked (--sims): ask for at most {done.size}, or "
                         "run more (fem_sim generate keeps the done ones of a scene grown "
                         "by raising its n_simulations, as make patient with a larger K)")
    return done[:sims]


def adapted(teacher: Teacher, ds: Dataset, used, run, *, synthetic: int = SYNTHETIC,
            seed: int = 0, log_fn=print, **overrides) -> dict:
    """The fitted ``teacher`` distilled on the FE simulations ``used`` of ``ds`` and ``synthetic``
    drawn loads, exported to ``run/model``; what was used and the seconds it took.
    """
    from surrogate.export import export_model

    t = time.perf_counter()
    cfg = student_config(**overrides)
    model, aug, part = distilled(teacher, ds, used, synthetic, cfg, seed, log_fn)
    export_model(Path(run) / "model", model, cfg, aug, linear_part=part)
    c = teacher.correction
    return {"fe_simulations": np.asarray(used).tolist(), "synthetic_simulations": synthetic,
            "correction": None if c is None else {
                **dict(zip(("length_mm", "beta", "mix", "decay", "reciprocity", "ridge"),
                           c.setting)),
                "cv_mee_mm": c.cv_mee},
            "seconds": {"distillation": time.perf_counter() - t}}


def predictor_fields(pred, ds: Dataset, samples: np.ndarray) -> np.ndarray:
    """(samples, n_out, 3) mm: a one-liver model's prediction of the samples' loads."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        u = pred(ds.forces[samples], ds.load_nodes[samples], nodes=np.asarray(ds.out_nodes[0]))
    return np.asarray(u, dtype=np.float64)


def field_mee(pred: np.ndarray, true: np.ndarray) -> float:
    """Mean Euclidean error (mm) over every node of every case."""
    return float(np.linalg.norm(pred - true, axis=-1).mean())


def scratch_model(ds: Dataset, sims, cfg: dict, seed: int = 0, log_fn=print):
    """The reduced basis trained on the patient's FE simulations ``sims`` alone, without the
    population model (the baseline a patient model must beat); its modes at most the samples'
    count.
    """
    from surrogate.train import fit_design

    n_out = ds.out_nodes[0].size
    one = with_cases(ds, sims_samples(ds, sims), np.zeros((0, 3)), np.zeros(0, int),
                     np.zeros(0), np.zeros(0, int), np.zeros((0, n_out, 3)))
    cfg = {**cfg, "modes": min(cfg["modes"], one.n_samples - 1)}
    model, _ = fit_design(one, np.arange(one.n_samples), cfg, seed, "scratch ", log_fn)
    return model, cfg


def held_out_errors(pred, placement, ds: Dataset, train_sims, held_sims, *, run: Path,
                    synthetic: int = SYNTHETIC, tune: bool = True, rest=None,
                    log_fn=print) -> dict:
    """MEE (mm) on the patient's simulations ``held_sims`` of: the population model ``pred``
    placed by ``placement``; it corrected with ``train_sims`` (``corrected``); with the
    dataset's small-strain responses (``linear.h5``), those alone (``linear``) and corrected
    (``linear_corrected``); the patient model distilled from the teacher ``adapt``
    uses (the responses' when there are any), exported to ``run``; the population network fine-tuned
    on ``train_sims`` (``tuned``), and that corrected (``tuned_corrected``; not with
    ``tune`` False); the reduced basis trained on ``train_sims`` alone. With ``rest`` (a
    loaded population model of the base's rest), the responses plus it (``linear_rest``)
    are the teacher's base, the rest at the weight fitted on ``train_sims``
    (``linear_rest_weighted``, the weight ``rest_weight``). With the seconds of each step.
    """
    smp = sims_samples(ds, held_sims)
    true = sample_fields(ds, smp)
    f, x = ds.forces[smp, 0], ds.load_points[smp, 0]
    teacher = Teacher(pred, placement, ds)
    out = {"fe_simulations": len(train_sims), "held_out": len(held_sims),
           "population": field_mee(teacher.base(ds, smp), true)}
    linear = LinearBase.of(ds)
    if linear is not None:
        out["linear"] = field_mee(linear.samples(ds, smp), true)
    if len(train_sims) == 0 and linear is None:
        return out
    start, fitted = time.perf_counter(), 0.0
    if len(train_sims):
        fit_teacher(teacher, ds, train_sims)
        out["corrected"] = field_mee(teacher(f, x, teacher.base(ds, smp)), true)
        fitted = time.perf_counter() - start
    if linear is not None:   # K = 0: the small-strain responses alone, distilled
        start = time.perf_counter()
        teacher = Teacher(pred, placement, ds, linear=linear, rest=rest)
        if rest is not None:
            out["linear_rest"] = field_mee(teacher.base(ds, smp), true)
        if len(train_sims):
            fit_teacher(teacher, ds, train_sims)
            base = teacher.base(ds, smp)
            if rest is not None:   # the rest at its weight fitted on the K simulations
                out["rest_weight"] = teacher.rest_weight
                out["linear_rest_weighted"] = field_mee(base, true)
            out["linear_corrected"] = field_mee(teacher(f, x, base), true)
        fitted = time.perf_counter() - start
    info = adapted(teacher, ds, train_sims, run, synthetic=synthetic, log_fn=log_fn)
    out["patient_model"] = field_mee(predictor_fields(load_predictor_of(run), ds, smp), true)
    out["adapt_seconds"] = {"correction": fitted, **info["seconds"]}
    out["correction"] = info["correction"]
    if len(train_sims):
        out.update(_baselines(pred, placement, ds, train_sims, smp, true, tune, log_fn))
    return out


def load_predictor_of(run: Path):
    from surrogate.predictor import load_predictor

    return load_predictor(Path(run) / "model")


def _baselines(pred, placement, ds: Dataset, train_sims, smp, true, tune: bool,
               log_fn) -> dict:
    """The population network fine-tuned on ``train_sims`` (alone and corrected; with
    ``tune``) and the reduced basis trained on them alone, on the held-out samples ``smp``.
    """
    from surrogate.designs import DESIGNS

    out = {}
    if tune:
        start = time.perf_counter()
        tuned = fit_teacher(Teacher(pred, placement, ds), ds, train_sims, tune=True)
        f, x = ds.forces[smp, 0], ds.load_points[smp, 0]
        out = {"tuned": field_mee(tuned.population(f, x), true),
               "tuned_corrected": field_mee(tuned(f, x), true),
               "tuning": {**tuned.tuning, "seconds": time.perf_counter() - start}}
    model, cfg = scratch_model(ds, train_sims, student_config(), log_fn=log_fn)
    p, t, _ = DESIGNS["basis"].predict_samples(ds, model, cfg, smp)
    out["scratch"] = float(np.linalg.norm(np.asarray(p) - np.asarray(t), axis=-1).mean())
    return out
