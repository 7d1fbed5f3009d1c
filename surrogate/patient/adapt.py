"""``surrogate adapt`` (``make patient``'s last step, :mod:`surrogate.patient`): the patient
model of a liver from a population model, the patient's FE simulations and small-strain
responses, written to ``RUN/model`` with ``RUN/adaptation.json``.
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np

from surrogate.data import Dataset
from surrogate.linear_base import LinearBase
from surrogate.patient.distill import SYNTHETIC, distilled, student_config
from surrogate.patient.teacher import Teacher, fit_teacher


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
    from surrogate.predictor import load_predictor, model_load

    t = time.perf_counter()
    ds = load_dataset(data)
    kind = model_load(model_dir)
    pred = load_predictor(model_dir, load=kind)
    if pred.shape_model is None:
        raise ValueError(f"{model_dir}: not a population model (no shape model): a patient "
                         "model adapts a model trained on a population of livers")
    if "grasp" in (ds.load_kind, kind):
        return _grasps(pred, kind, model_dir, ds, data, liver, run, sims=sims, frame=frame,
                       saved=saved, tune=tune, rest=rest, log_fn=log_fn)
    linear = None if tune else LinearBase.of(ds)
    used = used_simulations(ds, sims, data, linear is not None)
    # a population model of the bases' rest is its own rest (and places the liver as well)
    rest_pred = pred if rest is None and not pred.base.whole else \
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


def _grasps(pred, kind, model_dir, ds, data, liver, run, *, sims, tune, rest, **kw) -> dict:
    """A patient's model of grasps (:mod:`surrogate.patient.grasps`); ValueError naming the
    mismatch when the model or the data is not of grasps, or for --tune or --rest.
    """
    from surrogate.patient.grasps import adapt_grasps

    if ds.load_kind != kind:
        raise ValueError(f"{data}: {ds.load_kind} loads, {model_dir}: a model of {kind} loads: a "
                         "patient's model of grasps adapts a model of grasps to the patient's "
                         "grasps (make patient LOAD=grasp)")
    if tune or rest is not None:
        raise ValueError("--tune and --rest adapt a model of forces; a model of grasps is "
                         "corrected over its own rest (make patient LOAD=grasp)")
    info = adapt_grasps(pred, model_dir, ds, data, liver, run,
                        used_simulations(ds, sims, data), **kw)
    (Path(run) / "adaptation.json").write_text(json.dumps(info, indent=1))
    return info


def _rest_model(rest, pred, model_dir):
    """The population model of the base's rest in ``rest``, checked against ``pred``'s
    template (it is placed by ``pred``'s placement).
    """
    from surrogate.evaluate import shape_model_digest
    from surrogate.predictor import load_predictor

    out = load_predictor(rest)
    if out.base.whole:
        raise ValueError(f"--rest {rest}: not a model of a small-strain base's rest (base "
                         f"{out.base.name!r}); train config population_linear")
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
