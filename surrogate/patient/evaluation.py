"""A patient model against the patient's held-out FE simulations (:mod:`surrogate.patient`): the
population model, the corrected teacher, the small-strain base, the distilled patient model
and the baselines it must beat, each as its mean Euclidean error.
"""

from __future__ import annotations

import time
import warnings
from pathlib import Path

import numpy as np

from surrogate.data import Dataset
from surrogate.linear_base import LinearBase
from surrogate.metrics import mee
from surrogate.patient.adapt import adapted
from surrogate.patient.distill import SYNTHETIC, student_config, with_cases
from surrogate.patient.teacher import Teacher, fit_teacher, sample_fields, sims_samples


def predictor_fields(pred, ds: Dataset, samples: np.ndarray) -> np.ndarray:
    """(samples, n_out, 3) mm: a one-liver model's prediction of the samples' loads."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        u = pred(ds.forces[samples], ds.load_nodes[samples], nodes=np.asarray(ds.out_nodes[0]))
    return np.asarray(u, dtype=np.float64)



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
           "population": mee(teacher.base(ds, smp), true)}
    linear = LinearBase.of(ds)
    if linear is not None:
        out["linear"] = mee(linear.samples(ds, smp), true)
    if len(train_sims) == 0 and linear is None:
        return out
    start, fitted = time.perf_counter(), 0.0
    if len(train_sims):
        fit_teacher(teacher, ds, train_sims)
        out["corrected"] = mee(teacher(f, x, teacher.base(ds, smp)), true)
        fitted = time.perf_counter() - start
    if linear is not None:   # K = 0: the small-strain responses alone, distilled
        start = time.perf_counter()
        teacher = Teacher(pred, placement, ds, linear=linear, rest=rest)
        if rest is not None:
            out["linear_rest"] = mee(teacher.base(ds, smp), true)
        if len(train_sims):
            fit_teacher(teacher, ds, train_sims)
            base = teacher.base(ds, smp)
            if rest is not None:   # the rest at its weight fitted on the K simulations
                out["rest_weight"] = teacher.rest_weight
                out["linear_rest_weighted"] = mee(base, true)
            out["linear_corrected"] = mee(teacher(f, x, base), true)
        fitted = time.perf_counter() - start
    info = adapted(teacher, ds, train_sims, run, synthetic=synthetic, log_fn=log_fn)
    out["patient_model"] = mee(predictor_fields(load_predictor_of(run), ds, smp), true)
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
        out = {"tuned": mee(tuned.population(f, x), true),
               "tuned_corrected": mee(tuned(f, x), true),
               "tuning": {**tuned.tuning, "seconds": time.perf_counter() - start}}
    model, cfg = scratch_model(ds, train_sims, student_config(), log_fn=log_fn)
    p, t, _ = DESIGNS["basis"].predict_samples(ds, model, cfg, smp)
    out["scratch"] = mee(p, t)
    return out
