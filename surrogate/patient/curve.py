"""A patient model against K, the FE simulations of the patient's own liver it is made from:
``surrogate evaluate-patient``. The first ``held`` simulations of the patient's truth are held
out (the same for every K) and the next K train, so a larger K only adds simulations; each
K's errors (:func:`surrogate.patient.held_out_errors`) are kept in ``RESULTS/k.json`` under
the fingerprint of the simulations they used and a digest of everything else they depend on,
so a second call computes only what is new.

    python -m surrogate evaluate-patient MODEL DATA --liver FILE --results DIR
        [--ks 0 5 10 20 40] [--held 10] [--rest RUN] [--tune] [--out K.json]
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

import numpy as np

PACKAGE = Path(__file__).resolve().parent


def held_out_split(ds, k: int, held: int) -> tuple[np.ndarray, np.ndarray]:
    """(the K = ``k`` training simulations, the ``held`` held-out ones) of a patient's truth
    ``ds``: the first ``held`` are held out, the next ``k`` train.
    """
    sims = np.unique(ds.sample_sim)
    return sims[held:held + k], sims[:held]


def made_by(model: Path, data: Path, rest: Path | None = None) -> str:
    """A digest of what every K's errors depend on but the simulations: the population
    model's files (and the rest model's), the adaptation's code and the truth's small-strain
    responses (their order, whether with a Green's function).
    """
    from data_spec.linear_fields import linear_fields_path, read_linear_fields

    h = hashlib.sha256()
    if linear_fields_path(data).exists():
        lf = read_linear_fields(linear_fields_path(data))
        h.update(f"order {lf.order} green {lf.green is not None}".encode())
    code = [*(f for f in sorted(PACKAGE.glob("*.py")) if f.name != "study.py"),   # reporting
            *(PACKAGE.parent / n for n in ("tuning.py", "linear_base.py"))]
    for f in [*sorted(Path(model).glob("*")), *(sorted(Path(rest).glob("*")) if rest else []),
              *code]:
        h.update(f.read_bytes())
    return h.hexdigest()[:16]


def evaluate_patient(model: str | Path, data: str | Path, liver: str | Path, results: str | Path,
                     *, ks=(0, 5, 10, 20, 40), held: int = 10, frame: str | None = None,
                     rest: str | Path | None = None, tune: bool = False, placement=None,
                     log_fn=print) -> dict:
    """Every K's held-out errors of the patient model made from the population model
    ``model`` (its model directory) and the first K training simulations of ``data`` (the
    patient's truth: truth-scene, fem_sim generate, fem_sim linear), each exported under
    ``results/run_K<K>``; K beyond the simulations there are left out (named). Returns
    ``{"nodes", "ks", "points": {K: errors}, "held_out_sims": {K: per simulation}}`` for the
    smallest and largest K.
    """
    from data_spec.views import dataset_fingerprint
    from surrogate.data import load_dataset
    from surrogate.evaluate import place
    from surrogate.patient.evaluation import held_out_errors
    from surrogate.predictor import load_predictor

    model, data, results = Path(model), Path(data), Path(results)
    pred = load_predictor(model)
    rest_pred = load_predictor(rest) if rest else None
    placement = placement or place(pred, liver, frame)[0]
    ds = load_dataset(data)
    n = np.unique(ds.sample_sim).size
    done_ks = [k for k in ks if held + k <= n]
    if len(done_ks) < len(ks):
        log_fn(f"K = {[k for k in ks if k not in done_ks]} left out: {n} simulations, "
               f"{held} of them held out")
    path, key = results / "k.json", made_by(model, data, rest)
    done = json.loads(path.read_text()) if path.exists() else {}
    if done.get("made_by") != key:   # another population model, adaptation or truth
        done = {"made_by": key}
    results.mkdir(parents=True, exist_ok=True)
    for k in done_ks:
        train, out = held_out_split(ds, k, held)
        used = dataset_fingerprint(data, np.concatenate([out, train]))
        if done.get(str(k), {}).get("shards") != used:
            done[str(k)] = {**held_out_errors(pred, placement, ds, train, out,
                                              run=results / f"run_K{k}", tune=tune,
                                              rest=rest_pred, log_fn=lambda m: None),
                            "shards": used}
            path.write_text(json.dumps(done, indent=1))
        log_fn(f"K={k}: " + ", ".join(f"{name} {v:.3f} mm" for name, v in done[str(k)].items()
                                      if isinstance(v, float) and name != "rest_weight"))
    return {"nodes": int(ds.points[0].shape[0]), "ks": done_ks, "points": done,
            "held_out_sims": held_out_sims(ds, results, (done_ks[0], done_ks[-1]), held)
            if done_ks else {}}


def held_out_sims(ds, results: Path, ks, held: int) -> dict:
    """For each K of ``ks``, the exported patient model's error and the FE field's size on
    each held-out simulation (:func:`surrogate.patient_errors.per_simulation`).
    """
    from surrogate.patient.evaluation import load_predictor_of, predictor_fields
    from surrogate.patient.teacher import sample_fields, sims_samples
    from surrogate.patient_errors import per_simulation

    smp = sims_samples(ds, held_out_split(ds, 0, held)[1])
    true = sample_fields(ds, smp)
    return {str(k): per_simulation(predictor_fields(load_predictor_of(results / f"run_K{k}"),
                                                    ds, smp), true, ds.sample_sim[smp])
            for k in dict.fromkeys(ks) if (results / f"run_K{k}" / "model").is_dir()}
