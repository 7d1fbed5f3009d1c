"""What a patient study reports of its curves (``bench/patient.py``, docs/patient.md): each
liver's curve is :func:`surrogate.patient.curve.evaluate_patient`'s answer plus the seconds
the study timed (``place_seconds``, ``fe_seconds`` per K, ``linear_seconds``); these
functions turn a list of them into the figures the report's template prints: the medians per
K, the least K within an MEE goal, the best K within a time goal, the rest's weights, the
fine-tuning's gain and the error against the size of the load's response.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np


def fe_seconds(data: str | Path, ranks: int, ks, first: int) -> dict:
    """For each K of ``ks``, the own solve seconds of the K training simulations of the
    dataset ``data`` (after the ``first`` held out) over ``ranks`` ranks, start-up aside; at
    K = 0 one simulation's.
    """
    from data_spec import list_shards, read_shard

    t = [float(read_shard(p).stats.info.get("total_wall_time", np.nan))
         for p in list_shards(data)][first:]
    return {str(k): sum(t[:max(k, 1)]) / ranks for k in ks}


def patient_mee(c: dict, k: int) -> float:
    """The patient model's MEE at K = ``k`` on curve ``c`` (at K = 0 without the small-strain
    responses there is none: the population model's).
    """
    p = c["points"][str(k)]
    return p.get("patient_model", p["population"])


def patient_minutes(c: dict, k: int, start: float) -> float:
    """Wall minutes from the liver file to the patient model at K = ``k`` on curve ``c``:
    placing, ``start`` s of FE start-up, the K solves over the ranks, ``fem_sim linear`` and
    the adaptation (K = 0 without the responses: placing only).
    """
    p = c["points"][str(k)]
    if "adapt_seconds" not in p:
        return c["place_seconds"] / 60
    return (c["place_seconds"] + start + c["fe_seconds"].get(str(k), 0.0)
            + c.get("linear_seconds", 0.0) + sum(p["adapt_seconds"].values())) / 60


def rest_weights(curves: list[dict]) -> list[dict]:
    """Per K where it was fitted, the rest's weight fitted on the K simulations: linear +
    weighted rest against linear + rest at weight 1 (K = 0's) on the same held-out
    simulations, median over the livers and how many livers each way.
    """
    ks = sorted({int(k) for c in curves for k, p in c["points"].items()
                 if isinstance(p, dict) and "linear_rest_weighted" in p})
    out = []
    for k in ks:
        have = [c for c in curves if "linear_rest_weighted" in c["points"].get(str(k), {})]
        w = [c["points"][str(k)]["linear_rest_weighted"] for c in have]
        one = [c["points"]["0"]["linear_rest"] for c in have]
        out.append({"k": k, "median": float(np.median(w)), "one": float(np.median(one)),
                    "lower": sum(x < y - 1e-9 for x, y in zip(w, one)),
                    "higher": sum(x > y + 1e-9 for x, y in zip(w, one)),
                    "livers": [(c["liver"], c["points"][str(k)]["rest_weight"]) for c in have]})
    return out


def load_size(curves: list[dict], big_peak_mm: float, goal_mm: float) -> dict | None:
    """The patient model's error on each held-out simulation against its FE peak
    displacement, at K = 0 and the largest K kept: Spearman's rank correlation at K = 0, the
    median MEE of the simulations whose peak passes ``big_peak_mm`` and of the others, and
    for each liver whose K = 0 error is near ``goal_mm`` or above, how many large ones it has
    and its mean MEE without them. None when no curve kept its simulations.
    """
    have = [c for c in curves if c.get("held_out_sims", {}).get("0")]
    if not have:
        return None
    from scipy.stats import spearmanr

    def pooled(k: str, key: str) -> np.ndarray:
        return np.concatenate([c["held_out_sims"][k][key] for c in have
                               if k in c["held_out_sims"]])

    err, peak = pooled("0", "mee_mm"), pooled("0", "peak_mm")
    big = peak > big_peak_mm
    kmax = max(int(k) for c in have for k in c["held_out_sims"])
    e_max, p_max = pooled(str(kmax), "mee_mm"), pooled(str(kmax), "peak_mm")
    per = [(c["liver"], int((np.array(h["peak_mm"]) > big_peak_mm).sum()),
            float(np.mean(np.array(h["mee_mm"])[np.array(h["peak_mm"]) <= big_peak_mm])))
           for c in have if (h := c["held_out_sims"]["0"]) and np.mean(h["mee_mm"]) > goal_mm - 0.1]
    return {"n": err.size, "livers": len(have), "rho": float(spearmanr(err, peak).statistic),
            "big": int(big.sum()), "big_mee": float(np.median(err[big])),
            "small_mee": float(np.median(err[~big])), "kmax": kmax,
            "livers_kmax": sum(str(kmax) in c["held_out_sims"] for c in have),
            "big_mee_kmax": float(np.median(e_max[p_max > big_peak_mm])),
            "small_mee_kmax": float(np.median(e_max[p_max <= big_peak_mm])), "per": per}


def _tuned(curves: list[dict], ks) -> dict:
    """Per K where every liver was fine-tuned: the median corrected / tuned / tuned +
    corrected MEE and on how many livers tuning + correcting beats correcting alone.
    """
    return {k: {"medians": [float(np.median([c["points"][str(k)][key] for c in curves]))
                            for key in ("corrected", "tuned", "tuned_corrected")],
                "lower": sum(c["points"][str(k)]["tuned_corrected"]
                             < c["points"][str(k)]["corrected"] for c in curves)}
            for k in ks if k and all("tuned" in c["points"].get(str(k), {}) for c in curves)}


def curve_figures(curves: list[dict], ks, start: float | None, goal_mm: float,
                  goal_minutes: float) -> dict:
    """The figures of the curves beyond their table: the median patient MEE per K (and over
    how many livers), the linear response against linear + rest at K = 0, the rest's weights,
    the fine-tuning, each liver's least K within ``goal_mm`` and, when the FE start-up
    ``start`` is known, its most accurate K within ``goal_minutes``.
    """
    ks_of = {c["liver"]: [k for k in ks if str(k) in c["points"]] for c in curves}
    p0 = [c["points"]["0"] for c in curves]
    rest = None if not all("linear_rest" in p for p in p0) else {
        "linear": [p["linear"] for p in p0], "rest": [p["linear_rest"] for p in p0],
        "lower": sum(p["linear_rest"] < p["linear"] for p in p0)}
    best = []
    for c in curves:
        within = [] if start is None else [k for k in ks_of[c["liver"]]
                                           if patient_minutes(c, k, start) <= goal_minutes]
        best.append(min(within, key=lambda k: patient_mee(c, k)) if within else None)
    return {"medians": [(k, float(np.median(m)), len(m)) for k in ks
                        for m in [[patient_mee(c, k) for c in curves if str(k) in c["points"]]]],
            "rest_vs": rest, "weights": rest_weights(curves) if rest else [],
            "tuned": _tuned(curves, ks),
            "reached": [next((k for k in ks_of[c["liver"]] if patient_mee(c, k) <= goal_mm),
                             None) for c in curves], "best_within": best}
