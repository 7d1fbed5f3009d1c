"""Figures of a run: error box plots (paper's Fig. 11) and sorted actual vs predicted Euclidean
displacement (Fig. 12); per-liver MEE histogram (Fig. 19) when several livers.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np


def error_plots(run: Path, pred: np.ndarray, true: np.ndarray, result: dict) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    err = pred - true
    data = [np.abs(err[:, 0]), np.abs(err[:, 1]), np.abs(err[:, 2]),
            np.linalg.norm(err, axis=1)]
    fig, ax = plt.subplots(figsize=(6, 4))
    ax.boxplot(data, tick_labels=["|e_x|", "|e_y|", "|e_z|", "Euclidean"], showfliers=False)
    ax.set_ylabel("error (mm)")
    ax.set_title(f"{result['scene']}: held-out errors (MEE {result['network']['mee']:.3f} mm)")
    fig.tight_layout()
    fig.savefig(run / "errors_boxplot.png", dpi=120)
    plt.close(fig)

    a, p = np.linalg.norm(true, axis=1), np.linalg.norm(pred, axis=1)
    order = np.argsort(a)
    step = max(1, order.size // 20000)
    fig, ax = plt.subplots(figsize=(6, 4))
    ax.plot(p[order][::step], ".", ms=1, alpha=0.3, label="predicted")
    ax.plot(a[order][::step], "k-", lw=1, label="actual (FEM)")
    ax.set_xlabel("node samples, sorted by actual displacement")
    ax.set_ylabel("Euclidean displacement (mm)")
    ax.legend()
    fig.tight_layout()
    fig.savefig(run / "actual_vs_predicted.png", dpi=120)
    plt.close(fig)

    if "per_liver_mee" in result:
        fig, ax = plt.subplots(figsize=(6, 4))
        ax.hist(result["per_liver_mee"]["values"], bins=20)
        ax.set_xlabel("MEE per liver (mm)")
        ax.set_ylabel("livers")
        fig.tight_layout()
        fig.savefig(run / "per_liver_mee.png", dpi=120)
        plt.close(fig)
