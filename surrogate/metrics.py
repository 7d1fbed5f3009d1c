"""The paper's metrics (Table 4): MAE per axis, mean Euclidean error, % of nodes with Euclidean
error < 1 mm and < 3 mm, Pearson correlation per axis; and the 95th percentile of the Euclidean
error (the tail that a mean hides). Pure numpy.
"""

from __future__ import annotations

import numpy as np


def displacement_metrics(pred: np.ndarray, true: np.ndarray) -> dict:
    """pred, true: (n, 3) displacements in mm."""
    pred = np.asarray(pred, dtype=np.float64)
    true = np.asarray(true, dtype=np.float64)
    err = pred - true
    ee = np.linalg.norm(err, axis=1)
    out = {f"mae_{a}": float(np.mean(np.abs(err[:, i]))) for i, a in enumerate("xyz")}
    out["mee"] = float(np.mean(ee))
    out["ee_p95"] = float(np.percentile(ee, 95))
    out["pct_ee_lt_1mm"] = float(100.0 * np.mean(ee < 1.0))
    out["pct_ee_lt_3mm"] = float(100.0 * np.mean(ee < 3.0))
    for i, a in enumerate("xyz"):
        sp, st = pred[:, i].std(), true[:, i].std()
        out[f"corr_{a}"] = float(np.mean((pred[:, i] - pred[:, i].mean()) *
                                         (true[:, i] - true[:, i].mean())) / (sp * st)) \
            if sp > 0 and st > 0 else 0.0
    return out


def metrics_table(rows: dict[str, dict]) -> str:
    """Markdown table, one row per model."""
    keys = ["mae_x", "mae_y", "mae_z", "mee", "pct_ee_lt_1mm", "pct_ee_lt_3mm", "corr_x",
            "corr_y", "corr_z"]
    head = ("| model | MAE x (mm) | MAE y (mm) | MAE z (mm) | MEE (mm) | % EE < 1 mm | "
            "% EE < 3 mm | corr x | corr y | corr z |")
    lines = [head, "|" + "---|" * (len(keys) + 1)]
    for name, m in rows.items():
        cells = []
        for k in keys:
            v = m[k]
            cells.append(f"{v:.1f}" if k.startswith("pct") else
                         f"{v:.3f}" if not k.startswith("corr") else f"{v:.4f}")
        lines.append(f"| {name} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def mee(pred, true=0.0) -> float:
    """Mean Euclidean error (mm): the mean over every node of every case of |pred - true|,
    fields whose consecutive triples are (x, y, z) ((..., 3), or rows of nodes x 3).
    """
    d = np.asarray(pred, dtype=np.float64) - np.asarray(true, dtype=np.float64)
    return float(np.linalg.norm(d.reshape(-1, 3), axis=1).mean())


def case_mee(pred, true) -> np.ndarray:
    """(cases,) the mean Euclidean error of each case of fields (cases, nodes, 3) mm."""
    d = np.asarray(pred, dtype=np.float64) - np.asarray(true, dtype=np.float64)
    return np.linalg.norm(d, axis=-1).mean(axis=1)
