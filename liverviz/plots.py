"""The reports' charts (matplotlib, off-screen): each function draws one figure of a report
from the plain records its bench keeps and writes it as a PNG. The benches decide what to
measure; how a learning curve, a price list or an error budget is drawn lives here, once.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")   # no display: every chart is a file
    import matplotlib.pyplot as plt

    return plt


def _save(fig, png: str | Path, dpi: int = 110) -> Path:
    fig.tight_layout()
    fig.savefig(png, dpi=dpi)
    _pyplot().close(fig)
    return Path(png)


def learning_curves(rows: dict, paper: dict, paper_folds: int, png: str | Path) -> Path:
    """Skill against training simulations per fold, one line a scene (``rows``: table4's
    rows by scene), the points past the budget as open circles, the paper's as stars.
    """
    fig, ax = _pyplot().subplots(figsize=(6.0, 4.0))
    for k, r in sorted(rows.items()):
        n = [c["train_sims"] for c in r["curve"]]
        line, = ax.loglog(n, [c["skill"] for c in r["curve"]], "o-", label=f"scene {k}")
        for b in r.get("beyond", []):   # past the budget: measured, not in the fit
            f = b["overrides"]["folds"]
            ax.loglog([b["metrics"]["n_simulations"] * (f - 1) / f], [b["metrics"]["skill"]],
                      "o", mfc="none", ms=8, color=line.get_color())
        ps = paper[k]
        ax.loglog([ps["sims"] * (paper_folds - 1) / paper_folds],
                  [float(ps["skill"].split("/")[-1])], "*", ms=10, color=line.get_color())
    ax.set(xlabel="training simulations per fold", ylabel="skill = MEE_NN / MEE_naive")
    ax.set_title("learning curves; stars: the paper; open circles: past the budget",
                 fontsize=9)
    ax.grid(alpha=0.3, which="both")
    ax.legend()
    return _save(fig, png, 120)


def _price_curve(ax, lc) -> None:
    n = [r["spec"]["n_train"] for r in lc]
    ax.plot(n, [r["all"]["mee"] for r in lc], "o-", label="MEE")
    ax.plot(n, [r["all"]["ee_p95"] for r in lc], "s--", label="95th percentile")
    ax.set(xscale="log", yscale="log", xlabel="training simulations",
           ylabel="error on held-out simulations (mm)", title="learning curve (paper scene-1 net)")
    ax.set_xticks(n, [str(v) for v in n])
    ax.xaxis.set_minor_formatter(_pyplot().NullFormatter())
    ax.legend()


def _price_networks(ax, nets, lat, name_of, n_knob: int) -> None:
    for r in nets:
        t = lat.get(r["id"], {}).get("all_float32")
        if t is None:
            continue
        ax.scatter(1e3 * t, r["all"]["mee"], color="C0")
        ax.annotate(name_of.get(tuple(r["spec"]["hidden"]), ""), (1e3 * t, r["all"]["mee"]),
                    textcoords="offset points", xytext=(4, 3), fontsize=8)
        ax.scatter(1e3 * lat[r["id"]].get("surface_float32"), r["surface"]["mee"], color="C1",
                   marker="^")
    ax.scatter([], [], color="C0", label="all nodes")
    ax.scatter([], [], color="C1", marker="^", label="surface nodes")
    for hz in (300, 1000):
        ax.axvline(1e3 / hz, color="grey", ls=":", lw=1)
        ax.text(1e3 / hz, ax.get_ylim()[1] if nets else 1, f" {hz} Hz", fontsize=7, va="top")
    ax.set(xscale="log", xlabel="latency per load case (ms, float32)", ylabel="MEE (mm)",
           title=f"network size ({n_knob} training sims)")
    ax.legend(fontsize=8)


def surrogate_price_list(lc, nets, fractions, lat, name_of: dict, n_knob: int,
                         png: str | Path) -> Path:
    """The surrogate's price list in three panels: the learning curve (``lc``), error against
    latency per network size (``nets``, latencies ``lat`` by run id) and error against
    training seconds per sampled node fraction (``fractions``).
    """
    fig, ax = _pyplot().subplots(1, 3, figsize=(17, 5))
    if lc:
        _price_curve(ax[0], lc)
    _price_networks(ax[1], nets, lat, name_of, n_knob)
    for r in fractions:
        ax[2].scatter(r["training_seconds"], r["all"]["mee"], color="C2")
        ax[2].annotate(f"{r['spec']['node_fraction']:g}", (r["training_seconds"],
                       r["all"]["mee"]), textcoords="offset points", xytext=(4, 3), fontsize=8)
    ax[2].set(xlabel="training seconds", ylabel="MEE (mm)",
              title="sampled node fraction per epoch")
    for a in ax:
        a.grid(True, which="both", alpha=0.3)
    return _save(fig, png)


def pareto_front(points) -> list[tuple[float, float]]:
    """The (seconds, error) points no other beats on both, by seconds; a point that differs
    from a faster one by round-off only is no gain.
    """
    front, best = [], np.inf
    for x, y in sorted(points):
        if y < best * (1 - 1e-6):
            front.append((x, y))
            best = y
    return front


def fem_price_list(livers: dict, title: str, png: str | Path) -> Path:
    """Error against seconds, a panel a liver (``livers``: name -> [(label, marker, colour,
    note, seconds, error)]), each panel's Pareto front dashed.
    """
    fig, axes = _pyplot().subplots(1, max(1, len(livers)), squeeze=False,
                                   figsize=(7 * max(1, len(livers)), 5.5))
    for ax, (liver, pts) in zip(axes[0], sorted(livers.items())):
        for label, marker, colour, note, x, y in pts:
            ax.scatter(x, y, marker=marker, label=label, color=colour)
            if note:
                ax.annotate(note, (x, y), textcoords="offset points", xytext=(4, 3), fontsize=7)
        front = pareto_front([(x, y) for *_, x, y in pts])
        if front:
            ax.plot(*zip(*front), "k--", lw=1, label="Pareto front")
        handles, labels = ax.get_legend_handles_labels()
        uniq = dict(zip(labels, handles))
        ax.legend(uniq.values(), uniq.keys(), fontsize=7)
        ax.set(xscale="log", yscale="log", xlabel="seconds per simulation (1 rank)",
               ylabel="mean displacement error / max |u_ref|", title=f"{liver}: {title}")
        ax.grid(True, which="both", alpha=0.3)
    return _save(fig, png)


def error_budget(b: list[dict], exclude_mm: float, png: str | Path) -> Path:
    """The error budget per mesh (``b``: budget rows): the FE error, the surrogate's, the
    total and their sum as its upper bound, each mesh's cost under it.
    """
    fig, ax = _pyplot().subplots(figsize=(9, 5))
    if b:
        x, w = np.arange(len(b)), 0.27
        ax.bar(x - w, [r["fe"] for r in b], w, label="FE error (mesh vs reference)")
        ax.bar(x, [r["surrogate"] for r in b], w, label="surrogate error (vs its own FE data)")
        ax.bar(x + w, [r["total"] for r in b], w, label="total (surrogate vs reference)")
        ax.scatter(x + w, [r["fe"] + r["surrogate"] for r in b], marker="_", s=400,
                   color="k", label="FE + surrogate (upper bound)", zorder=3)
        ax.set_xticks(x, [f"P{r['degree']} {r['h']:g} mm\n{r['vertices']} nodes\n"
                          f"{r['sim_hours'] + r['train_hours']:.2f} h" for r in b])
        ax.set(yscale="log", ylabel=f"mean error, mm (outside {exclude_mm:g} mm of the load)")
        ax.set_title("error budget, scene 1 on the phantom; under each mesh: cost "
                     "(simulation CPU-h + training h)", fontsize=10)
        ax.legend(fontsize=8)
        ax.grid(True, axis="y", which="both", alpha=0.3)
    return _save(fig, png)


def shape_model(results: dict, iou_target: float, png: str | Path) -> Path:
    """The shape model against its components, a line a population variety: explained
    variance, and the reconstruction's IoU (mean, worst) with its target.
    """
    fig, ax = _pyplot().subplots(1, 2, figsize=(10, 4))
    for (variety, rows), c in zip(results.items(), ("C0", "C1", "C2")):
        n = [r["n"] for r in rows]
        ax[0].plot(n, [r["explained_variance"] for r in rows], "-o", ms=3, color=c,
                   label=variety)
        ax[1].plot(n, [r["iou_mean"] for r in rows], "-s", ms=3, color=c,
                   label=f"{variety} (mean)")
        ax[1].plot(n, [r["iou_min"] for r in rows], ":", color=c, label=f"{variety} (worst)")
    ax[0].set_ylabel("cumulative explained variance")
    ax[1].set_ylabel("IoU of the reconstruction")
    ax[1].axhline(iou_target, color="gray", lw=0.8)
    for a in ax:
        a.set_xlabel("PCA components")
        a.grid(alpha=0.3)
        a.legend(fontsize=8)
    return _save(fig, png, 120)


def error_against_peak(curves: list[dict], kmax: int, goal_mm: float, big_peak_mm: float,
                       png: str | Path) -> Path:
    """Each held-out simulation's patient-model MEE against its FE peak displacement, at
    K = 0 and K = ``kmax``, one colour a liver (``curves``: the patient study's).
    """
    from matplotlib.ticker import NullFormatter, ScalarFormatter

    plt = _pyplot()
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.4), sharey=True)
    colours = plt.get_cmap("tab20")
    for ax, k in zip(axes, ("0", str(kmax))):
        for i, c in enumerate(curves):   # one colour per liver in both panels
            h = c["held_out_sims"].get(k)
            if h:
                ax.scatter(h["peak_mm"], h["mee_mm"], s=14, color=colours(i % 20),
                           label=c["liver"])
        ax.axhline(goal_mm, color="k", lw=0.8, ls="--")
        ax.axvline(big_peak_mm, color="grey", lw=0.8, ls=":")
        ax.set(xscale="log", yscale="log", xlabel="FE peak displacement, last load step (mm)",
               title=f"K = {k}: each held-out simulation")
        ax.set_xticks([5, 10, 20, 30, 50, 100])
        ax.xaxis.set_major_formatter(ScalarFormatter())
        ax.xaxis.set_minor_formatter(NullFormatter())
    axes[0].set_ylabel("patient model MEE on the simulation (mm)")
    axes[0].legend(fontsize=6, ncol=2, loc="upper left")
    return _save(fig, png, 120)


def surgical_curves(grasp: list[dict], force: list[dict], goal: dict, png: str | Path) -> Path:
    """MEE against the grasp's pull and against the pressed force (median and worst liver,
    the model where the rows have one, the small-strain base and the naive model) and the
    reaction-force error against the pull (model, base), with the goals (``grasp``,
    ``force``: bench/surgical_loads.py's curves).
    """
    fig, ax = _pyplot().subplots(1, 3, figsize=(13, 3.8))
    for rows, key, a, unit in ((grasp, "pull", ax[0], "grasp pull (mm)"),
                               (force, "force", ax[2], "force on the patch (N)")):
        x = [r[key] for r in rows]
        for m, colour in (("model", "C2"), ("base", "C0"), ("naive", "C3")):
            if rows and m not in rows[0]:
                continue
            a.plot(x, [r[m]["mee_median"] for r in rows], "o-", color=colour,
                   label=f"{m}, median liver")
            a.plot(x, [r[m]["mee_worst"] for r in rows], "--", color=colour,
                   label=f"{m}, worst liver")
        a.axhline(goal["median"], color="k", lw=0.8, ls=":", label="goal, median liver")
        a.set(xlabel=unit, ylabel="MEE (mm)", yscale="log")
        a.legend(fontsize=7)
    for k, style in (("median", "o-"), ("worst", "--")):
        ax[1].plot([r["pull"] for r in grasp], [r[f"force_error_{k}"] for r in grasp], style,
                   color="C0", label=f"base, {k} liver")
        if grasp and "model" in grasp[0]:
            ax[1].plot([r["pull"] for r in grasp], [r["model"][f"force_{k}"] for r in grasp],
                       style, color="C2", label=f"model, {k} liver")
    ax[1].axhline(goal["force"], color="k", lw=0.8, ls=":", label="goal")
    ax[1].set(xlabel="grasp pull (mm)", ylabel="reaction force error (%)")
    ax[1].legend(fontsize=7)
    return _save(fig, png)
