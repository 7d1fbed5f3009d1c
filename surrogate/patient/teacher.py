"""The teacher of a patient model (:mod:`surrogate.patient`): the population model placed on the
patient's liver, or the patient's own small-strain base (with the population's rest of it at a
weight fitted to the K simulations), plus the correction fitted on the K FE simulations.
"""

from __future__ import annotations

import warnings

import numpy as np

from surrogate.data import Dataset
from surrogate.linear_base import LinearBase
from surrogate.patient.correction import Correction, Sensors, fit_correction, spread_steps
from surrogate.tuning import fine_tuned, placed_cases, placed_modes

REST_MIN_SIMS = 2   # the rest's weight is fitted on at least this many simulations


class Teacher:
    """The population model placed on the patient's liver, at the nodes of the patient's
    mesh ``ds`` (its output nodes), plus the correction once fitted.
    """

    def __init__(self, pred, placement, ds: Dataset, shape: str | None = None,
                 linear: LinearBase | None = None, rest=None):
        """``rest``: a population model of what each liver's small-strain base misses (its
        ``base``, :mod:`surrogate.small_strain`), placed as ``pred`` and added to ``linear``,
        the patient's own base.
        """
        from surrogate.predict_liver import PlacedModel

        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            self.placed = PlacedModel(pred, nodes=ds.points[0], placement=placement,
                                      shape=shape)
            self.rest = None if rest is None else PlacedModel(
                rest, nodes=ds.points[0], placement=placement, shape=shape)
        if rest is not None and (linear is None or not rest.base.served_by(linear.order)):
            raise ValueError(f"the population model of the base's rest was trained over a "
                             f"small-strain base of order {rest.base.order}; the patient's "
                             f"is {'missing' if linear is None else f'of order {linear.order}'}"
                             f": run fem_sim linear --order {rest.base.order} on its scene")
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
                                                   cases.take(spread_steps(groups)))
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
    else:
        fit_rest_weight(teacher, ds, smp, fields)
    # the correction learns the residual of a load the network was not tuned on: out of fold
    u = teacher.out_of_fold if teacher.out_of_fold is not None else teacher.base(ds, smp)
    r = (fields - u).reshape(smp.size, -1)
    groups = ds.sample_sim[smp]
    sensors = Sensors.of(ds.points[0][teacher.out], x, f, fields, groups)
    teacher.correction = fit_correction(x, f, u, r, groups, sensors)
    return teacher
