"""Where a patient model's error is: what bounds the corrected population model
(:mod:`surrogate.patient`) on a patient's held-out simulations.

- the projection floor: the held-out FE fields' distance to the span of the K training FE
  fields (every load step). The correction's output (the load's population field plus a
  combination of the training residuals) lies in a span that contains this one (the
  training FE fields, their population fields and the load's), so a floor far below the
  corrected error says the fields are there to be combined and what is missing is how to
  combine them for a new load;
- the error relative to the displacement at the first and the last load step of each held-out
  simulation: alike, the error is not the loads' nonlinearity (the first step is nearly
  linear, the last is not);
- what each held-out simulation's error follows (Spearman's rank correlation over the
  held-out simulations): its mean displacement, or the distance from its load point to the
  nearest of the K training loads;
- how many held-out simulations the correction makes worse than the population model alone.

:func:`error_sources` takes arrays only; ``bench/patient.py`` feeds it a validation liver's.
"""

from __future__ import annotations

import numpy as np

from surrogate.metrics import case_mee


def projection_floor(train: np.ndarray, held: np.ndarray) -> float:
    """MEE (mm) of the fields ``held`` (h, nodes, 3) projected orthogonally on the span of
    ``train`` (t, nodes, 3): the least any combination of the training fields can miss by
    (least squares per field, so an upper bound of the least MEE).
    """
    basis, _ = np.linalg.qr(train.reshape(len(train), -1).T)
    flat = held.reshape(len(held), -1)
    projected = (flat @ basis) @ basis.T
    return float(case_mee(projected.reshape(held.shape), held).mean())


def error_sources(train_true, train_points, held_true, held_points, held_population,
                  held_corrected, held_sims) -> dict:
    """The figures of the module's docstring for one patient and one K.

    train_true (t, nodes, 3) mm: the K training simulations' FE fields (every load step);
    train_points (t, 3) mm: their load points; held_true, held_population, held_corrected
    (h, nodes, 3) mm: the held-out cases' FE fields, the population model's and the corrected
    one's; held_points (h, 3) mm; held_sims (h,): each held-out case's simulation, its load
    steps in order.
    """
    from scipy.stats import spearmanr

    held_sims = np.asarray(held_sims)
    pop, cor = case_mee(held_population, held_true), case_mee(held_corrected, held_true)
    size = np.linalg.norm(held_true, axis=-1).mean(axis=1)
    sims = np.unique(held_sims)
    per_sim = np.array([cor[held_sims == s].mean() for s in sims])
    per_pop = np.array([pop[held_sims == s].mean() for s in sims])
    first = np.array([np.flatnonzero(held_sims == s)[0] for s in sims])
    last = np.array([np.flatnonzero(held_sims == s)[-1] for s in sims])
    near = np.array([np.linalg.norm(np.asarray(train_points) - held_points[i], axis=1).min()
                     for i in last])
    return {
        "population_mm": float(pop.mean()), "corrected_mm": float(cor.mean()),
        "projection_floor_mm": projection_floor(np.asarray(train_true), np.asarray(held_true)),
        "relative_first_step": float(np.median(cor[first] / np.maximum(size[first], 1e-12))),
        "relative_last_step": float(np.median(cor[last] / np.maximum(size[last], 1e-12))),
        "spearman_displacement": float(spearmanr(per_sim, [size[held_sims == s].mean()
                                                           for s in sims]).statistic),
        "spearman_nearest_load": float(spearmanr(per_sim, near).statistic),
        "nearest_load_mm": float(np.median(near)),
        "worse_than_population": int((per_sim > per_pop).sum()), "simulations": int(sims.size),
    }


def per_simulation(pred: np.ndarray, true: np.ndarray, sims: np.ndarray) -> dict:
    """Each simulation's error and size: ``pred`` and ``true`` (cases, nodes, 3) mm, the
    cases' simulations ``sims`` (cases,), each simulation's load steps in order. Returns lists
    over the simulations (ascending): ``sim``, ``mee_mm`` (the node MEE averaged over its load
    steps), ``peak_mm`` (the largest node displacement of its last load step) and
    ``mean_mm`` (its mean node displacement over its load steps).
    """
    sims = np.asarray(sims)
    err = case_mee(np.asarray(pred), np.asarray(true))
    size = np.linalg.norm(np.asarray(true), axis=-1)
    order = np.unique(sims)
    last = [np.flatnonzero(sims == s)[-1] for s in order]
    return {"sim": order.tolist(),
            "mee_mm": [float(err[sims == s].mean()) for s in order],
            "peak_mm": [float(size[i].max()) for i in last],
            "mean_mm": [float(size[sims == s].mean()) for s in order]}
