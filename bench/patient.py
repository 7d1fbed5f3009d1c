"""A new patient's model against K, the FE simulations on the patient's own mesh: docs/patient.md.

    .venv-train/bin/python bench/patient.py [--model RUN] [--livers Amos-054 LiTS-100 LiTS-67]
        [--ks 0 5 10 20 40 80] [--design] [--order 1] [--no-green] [--no-tune]

For each validation liver (never seen by the population model, its PCA or any design choice):
its FE truth with the population model's boundary condition, HELD + K_MAX simulations
(resumable, under bench/results/patient/: a larger K only adds simulations); then for every
K the MEE on the first HELD simulations (the same for every K) of the placed population
model alone, the corrected one, the liver's small-strain responses (``fem_sim linear``)
alone and corrected, the exported patient model (``surrogate adapt`` on the K training
simulations, :mod:`surrogate.patient`), the reduced basis trained on the same K simulations
from scratch, with the adaptation's seconds, and the population network fine-tuned on them
(``--tune``), alone and corrected; and the wall time of ``make patient`` end to end at K = 40
on the first liver, on two cores.

``--design``: the same on training livers (default Amos-005, LiTS-12, LiTS-16), with a
population model trained as the shipped one on scene 4's dataset less their simulations
(under bench/results/patient_design/): docs/patient_design.md, where the adaptation's settings
are chosen, so that the validation livers stay out of every choice.
"""

from __future__ import annotations

import argparse
import json
import shutil
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from fem_sim.batch.chunked import generate_chunks, liver_truth
from liverviz.report import ROOT, SOFA, SOFA_FRAME, write_report
from surrogate.patient import SYNTHETIC

SCENE = ROOT / "data_spec" / "scenes" / "scene4_livers.toml"
RESULTS = ROOT / "bench" / "results" / "patient"
MODEL = ROOT / "bench" / "results" / "scene4_real" / "run_population_basis"
DATA = ROOT / "runs" / "data" / "scene4_livers"   # scene 4's dataset (bench/scene4_real.py)
DESIGN_OVERRIDES = {"folds": 10, "evaluate_folds": 1}   # as bench/scene4_real.py trains it
DESIGN_LIVERS = ["Amos-005", "LiTS-12", "LiTS-16"]
KS = (0, 5, 10, 20, 40, 80)
HELD = 10
TRUTH_SIMS = HELD + max(KS)   # the truth scene's simulations, solved up to HELD + the K asked
SOURCES_K = 40  # the K at which the error's sources are measured (the largest K if less)
GOAL_MM = 0.5   # the goal: this MEE within GOAL_MINUTES on two cores
GOAL_MINUTES = 5.0
FRAMES = {SOFA.stem: SOFA_FRAME}   # a liver file not in the scene's frame: predict-liver's --frame
BIG_PEAK_MM = 30.0   # a held-out simulation's FE peak displacement counted as a large one


def truth(pred, liver: Path, a, frame: str | None = None) -> Path:
    """The liver's FE truth with the model's boundary condition (the liver file in
    ``frame``, predict-liver's --frame): a scene of TRUTH_SIMS simulations, the first HELD +
    the largest K solved.
    """
    from surrogate.evaluate import truth_scene

    d, n = a.results / liver.stem, HELD + max(a.ks)
    data = liver_truth(d, truth_scene(pred, SCENE, liver, TRUTH_SIMS, frame), n,
                       generate=False)   # the scene; another one's truth emptied
    if not (a.no_new_fe and (data / "sims").is_dir()):
        generate_chunks(d / "scene.toml", data, n, ranks=a.np, chunk=n)
    linear(d / "scene.toml", data, d / "linear.json", a.order, a.green)
    return data


def linear(scene: Path, data: Path, record: Path, order: int = 1, green: bool = False) -> dict:
    """``fem_sim linear`` on the truth's scene (SYNTHETIC drawn loads, ``order``, with the
    Green's function if ``green``), as make patient runs it, once per setting: its wall
    seconds in ``record``.
    """
    from data_spec import load_scene
    from data_spec.linear_fields import linear_fields_path, read_linear_fields

    path = linear_fields_path(data)
    done = json.loads(record.read_text()) if record.exists() else {}
    if path.exists() and done.get("seconds") and done.get("order", 1) == order:
        lf = read_linear_fields(path)
        if lf.scene_hash == load_scene(scene).hash and lf.order == order \
                and (lf.green is not None) == green:
            return done
    t = time.perf_counter()
    subprocess.run([str(ROOT / ".venv-solver" / "bin" / "python"), "-m", "fem_sim", "linear",
                    str(scene), "--out", str(data), "--synthetic", str(SYNTHETIC), "--order",
                    str(order), *(["--green"] if green else [])], cwd=ROOT, check=True)
    done = {"seconds": time.perf_counter() - t, "order": order,
            "solves_seconds": read_linear_fields(path).seconds}
    record.write_text(json.dumps(done))
    return done


def curve(liver: Path, a) -> tuple[dict, dict]:
    """Every K's errors on the liver's held-out simulations (``surrogate evaluate-patient``'s,
    kept under <results>/<liver>), and where the corrected model's error is at SOURCES_K or
    the largest K below (:func:`sources`).
    """
    from surrogate.data import load_dataset
    from surrogate.evaluate import place
    from surrogate.patient.curve import evaluate_patient
    from surrogate.predictor import load_predictor

    model = Path(a.model) / "model"
    pred = load_predictor(model)
    t = time.perf_counter()
    frame = FRAMES.get(liver.stem)
    placement, _ = place(pred, liver, frame)
    placing = time.perf_counter() - t
    data = truth(pred, liver, a, frame)
    found = evaluate_patient(model, data, liver, a.results / liver.stem, ks=a.ks, held=HELD,
                             rest=Path(a.rest) / "model" if a.rest else None, tune=a.tune,
                             placement=placement,
                             log_fn=lambda m: print(f"[{liver.stem}] {m}", flush=True))
    ks, ds = found["ks"], load_dataset(data)
    return ({"liver": liver.stem, "nodes": found["nodes"], "points": found["points"],
             "held_out_sims": found["held_out_sims"],
             "fe_seconds": fe_seconds(data, a.np, ks), "place_seconds": placing,
             "linear_seconds": json.loads((data.parent / "linear.json").read_text())["seconds"]},
            {"liver": liver.stem, "k": min(a.sources_k, ks[-1]),
             **sources(pred, placement, ds, min(a.sources_k, ks[-1]))})


def sources(pred, placement, ds, k: int) -> dict:
    """Where the corrected model's error is on the held-out simulations of the liver's truth
    ``ds`` at K = ``k`` (:func:`surrogate.patient_errors.error_sources`; recomputed each run:
    seconds).
    """
    from surrogate.patient import Teacher, fit_teacher, sample_fields, sims_samples
    from surrogate.patient.curve import held_out_split
    from surrogate.patient_errors import error_sources

    train_sims, held_sims = held_out_split(ds, k, HELD)
    train, held = sims_samples(ds, train_sims), sims_samples(ds, held_sims)
    teacher = fit_teacher(Teacher(pred, placement, ds), ds, train_sims)
    f, x = ds.forces[held, 0], ds.load_points[held, 0]
    return error_sources(
        sample_fields(ds, train), ds.load_points[train, 0], sample_fields(ds, held), x,
        teacher.population(f, x), teacher(f, x), ds.sample_sim[held])


def fe_seconds(data: Path, ranks: int, ks=KS, first: int = HELD) -> dict:
    """For each K, the own solve seconds (the shards' records) of the K training simulations
    (those after the ``first`` held out) over ``ranks`` ranks: what make patient's FE takes at
    that K, meshing and start-up aside; at K = 0 one simulation's (make patient solves one: a
    patient dataset is made of simulations).
    """
    from data_spec import list_shards, read_shard

    t = [float(read_shard(p).stats.info.get("total_wall_time", np.nan))
         for p in list_shards(data)][first:]
    return {str(k): sum(t[:max(k, 1)]) / ranks for k in ks}


def minutes(c: dict, k: int, start: float) -> float:
    """Wall minutes from the liver file to the patient model at K = ``k`` on two cores, by
    parts: placing, ``start`` seconds of FE start-up (meshing, MPI, the forms), the first
    ``k`` simulations' solves over the ranks, the small-strain responses (``fem_sim
    linear``, a process of its own) and the adaptation (K = 0 without the responses:
    placing only, the population model's predictor).
    """
    p = c["points"][str(k)]
    if "adapt_seconds" not in p:
        return c["place_seconds"] / 60
    return (c["place_seconds"] + start + c["fe_seconds"].get(str(k), 0.0)
            + c.get("linear_seconds", 0.0) + sum(p["adapt_seconds"].values())) / 60


def end_to_end(liver: Path, a, k: int = 40) -> dict:
    """Wall seconds of ``make patient`` (K simulations, two ranks), run once: in all, and of
    its steps (placing and writing the truth scene, meshing and FE, adapting), read from when
    each step's last output was written.
    """
    out = RESULTS / "make_patient"
    shutil.rmtree(out, ignore_errors=True)
    t = time.time()
    subprocess.run(["make", "--no-print-directory", "patient", f"LIVER={liver}",
                    f"MODEL={a.model}", f"K={k}", f"PATIENT={out}", f"ORDER={a.order}",
                    f"GREEN={int(a.green)}", *([f"REST={a.rest}"] if a.rest else []),
                    *([f"FRAME={FRAMES[liver.stem]}"] if liver.stem in FRAMES else [])],
                   cwd=ROOT, check=True,
                   stdout=subprocess.DEVNULL)
    end = time.time()
    placed = (out / "scene.toml").stat().st_mtime
    solved = max(f.stat().st_mtime for f in (out / "data").rglob("*") if f.is_file())
    return {"total": end - t, "place": placed - t, "fe": solved - placed,
            "solves": fe_seconds(out / "data", a.np, [k], first=0)[str(k)],
            "adapt": end - solved, "k": k, "liver": liver.stem}


def sources_lines(found: list[dict]) -> list[str]:
    """The table and the sentence of where the corrected model's error is."""
    rows = [f"| {s['liver']} | {s['population_mm']:.3f} | {s['corrected_mm']:.3f} | "
            f"{s['projection_floor_mm']:.3f} | {s['relative_first_step']:.2f} | "
            f"{s['relative_last_step']:.2f} | {s['spearman_displacement']:+.2f} | "
            f"{s['spearman_nearest_load']:+.2f} | {s['nearest_load_mm']:.0f} | "
            f"{s['worse_than_population']} of {s['simulations']} |" for s in found]
    ratio = [s["corrected_mm"] / s["projection_floor_mm"] for s in found]
    gap = [abs(s["relative_first_step"] - s["relative_last_step"]) for s in found]
    return [
        f"Where the corrected model's error is, at K = {found[0]['k']} "
        "(`surrogate.patient_errors`, recomputed by each run): the projection floor is the "
        "held-out FE fields' distance to the span of the K training FE fields (within the span the "
        "correction combines); the error relative to the mean displacement, median over the "
        "held-out simulations, at their first (nearly linear) and last load step; Spearman's "
        "rank correlation over the held-out simulations of their error with their mean "
        "displacement and with the distance from their load point to the nearest training "
        "load.", "",
        "| liver | population MEE mm | corrected MEE mm | projection floor mm | error / "
        "displacement, first step | last step | rank correlation with displacement | with "
        "nearest training load | nearest training load mm | held-out simulations made worse "
        "by the correction |", "|---|---|---|---|---|---|---|---|---|---|", *rows, "",
        f"The corrected error is {min(ratio):.1f} to {max(ratio):.1f} times its projection "
        "floor (where it is several times, the fields a new load needs are in the span of "
        "the K simulations and what is missing is how to combine them for a load not among "
        "them); the first and last load steps' relative errors differ by at most "
        f"{max(gap):.2f} on any liver (alike: the loads' nonlinearity is not what the "
        "correction misses).", ""]


def _size_lines(curves: list[dict], md: Path) -> list[str]:
    """The sentence and the picture (``md`` with .png) of the patient model's error on each
    held-out simulation against the size of its FE field, at K = 0 and the largest K."""
    have = [c for c in curves if c.get("held_out_sims", {}).get("0")]
    if not have:
        return []
    from scipy.stats import spearmanr

    def pooled(k: str, key: str) -> np.ndarray:
        return np.concatenate([c["held_out_sims"][k][key] for c in have
                               if k in c["held_out_sims"]])

    err, peak = pooled("0", "mee_mm"), pooled("0", "peak_mm")
    big = peak > BIG_PEAK_MM
    kmax = max(int(k) for c in have for k in c["held_out_sims"])
    at_max = [c for c in have if str(kmax) in c["held_out_sims"]]
    e_max, p_max = pooled(str(kmax), "mee_mm"), pooled(str(kmax), "peak_mm")
    _size_picture(have, md.with_suffix(".png").with_stem(md.stem + "_loads"), kmax)
    per = [f"{c['liver']} {int((np.array(h['peak_mm']) > BIG_PEAK_MM).sum())} "
           f"({np.mean(np.array(h['mee_mm'])[np.array(h['peak_mm']) <= BIG_PEAK_MM]):.3f} mm "
           "without them)" for c in have if (h := c["held_out_sims"]["0"])
           and np.mean(h["mee_mm"]) > GOAL_MM - 0.1]
    return [f"The patient model's error follows the size of the load's response. Over the "
            f"{err.size} held-out simulations of {len(have)} livers at K = 0, Spearman's rank "
            f"correlation of a simulation's MEE with its FE field's peak displacement (last "
            f"load step) is {spearmanr(err, peak).statistic:.2f}; the {int(big.sum())} whose "
            f"peak passes {BIG_PEAK_MM:.0f} mm (a 0.4 N force on a thin part of the liver) have "
            f"median MEE {np.median(err[big]):.3f} mm, the others {np.median(err[~big]):.3f} "
            f"mm. At K = {kmax} ({len(at_max)} livers) the same split gives "
            f"{np.median(e_max[p_max > BIG_PEAK_MM]):.3f} and "
            f"{np.median(e_max[p_max <= BIG_PEAK_MM]):.3f} mm: more FE simulations of the "
            "patient do not reach the large deflections of loads they did not hold."
            + (" Such simulations among the 10 held out of the livers nearest the goal: "
               + ", ".join(per) + "." if per else ""), "",
            f"![error against displacement]({md.stem}_loads.png)", ""]


def _size_picture(curves: list[dict], png: Path, kmax: int) -> None:
    """Each held-out simulation's patient-model MEE against its FE peak displacement."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.ticker import NullFormatter, ScalarFormatter

    fig, axes = plt.subplots(1, 2, figsize=(11, 4.4), sharey=True)
    colours = plt.get_cmap("tab20")
    for ax, k in zip(axes, ("0", str(kmax))):
        for i, c in enumerate(curves):   # one colour per liver in both panels
            h = c["held_out_sims"].get(k)
            if h:
                ax.scatter(h["peak_mm"], h["mee_mm"], s=14, color=colours(i % 20),
                           label=c["liver"])
        ax.axhline(GOAL_MM, color="k", lw=0.8, ls="--")
        ax.axvline(BIG_PEAK_MM, color="grey", lw=0.8, ls=":")
        ax.set(xscale="log", yscale="log", xlabel="FE peak displacement, last load step (mm)",
               title=f"K = {k}: each held-out simulation")
        ax.set_xticks([5, 10, 20, 30, 50, 100])
        ax.xaxis.set_major_formatter(ScalarFormatter())
        ax.xaxis.set_minor_formatter(NullFormatter())
    axes[0].set_ylabel("patient model MEE on the simulation (mm)")
    axes[0].legend(fontsize=6, ncol=2, loc="upper left")
    fig.tight_layout()
    fig.savefig(png, dpi=120)
    plt.close(fig)


def _rest_lines(curves: list[dict]) -> list[str]:
    """The sentence on what the population's rest adds to each liver's small-strain base."""
    p0 = [c["points"]["0"] for c in curves]
    if not all("linear_rest" in p for p in p0):
        return []
    lin, rest = [p["linear"] for p in p0], [p["linear_rest"] for p in p0]
    lower = sum(r < x for r, x in zip(rest, lin))
    return [f"The population's rest over each liver's small-strain base (linear + rest against "
            f"linear, no FE simulation of the liver used): median {np.median(rest):.3f} against "
            f"{np.median(lin):.3f} mm over the livers, lower on {lower} of {len(curves)}; "
            + ", ".join(f"{c['liver']} {r:.3f} / {x:.3f}" for c, r, x in zip(curves, rest, lin))
            + " mm.", "", *_weight_lines(curves)]


def _weight_lines(curves: list[dict]) -> list[str]:
    """The sentence on the rest's weight fitted on the K simulations (linear + rest at it
    against at weight 1, the same held-out simulations)."""
    ks = sorted({int(k) for c in curves for k, p in c["points"].items()
                 if isinstance(p, dict) and "linear_rest_weighted" in p})
    if not ks:
        return []
    parts = []
    for k in ks:
        have = [c for c in curves if "linear_rest_weighted" in c["points"].get(str(k), {})]
        w = [c["points"][str(k)]["linear_rest_weighted"] for c in have]
        one = [c["points"]["0"]["linear_rest"] for c in have]
        weights = [c["points"][str(k)]["rest_weight"] for c in have]
        parts.append(f"K = {k}: median {np.median(w):.3f} against {np.median(one):.3f} mm, "
                     f"lower on {sum(x < y - 1e-9 for x, y in zip(w, one))}, higher on "
                     f"{sum(x > y + 1e-9 for x, y in zip(w, one))} of {len(have)} (weights "
                     + ", ".join(f"{c['liver']} {v:.2f}" for c, v in zip(have, weights)) + ")")
    return ["The rest's weight fitted on the K simulations (least squares, clipped to [0, 1]; "
            "the linear + corrected and patient model columns use it), linear + rest at that "
            "weight against at weight 1 on the held-out simulations: " + "; ".join(parts)
            + ".", ""]


def _mee(c: dict, k: int) -> float:
    """The patient model's MEE at K = k (none at K = 0 without the small-strain responses:
    the population model's)."""
    return c["points"][str(k)].get("patient_model", c["points"][str(k)]["population"])


def _ks_of(c: dict, ks) -> list[int]:
    """The K values of ``ks`` the liver has."""
    return [k for k in ks if str(k) in c["points"]]


def _table_rows(curves: list[dict], a, start: float | None) -> tuple[list[str], list[str]]:
    """The table's header and rows, one per liver and K."""
    keys = ["population", "corrected", "linear", *(["linear_rest"] if a.rest else []),
            "linear_corrected", "patient_model", "scratch", "tuned", "tuned_corrected"]
    n_main = len(keys) - 2
    rows = []
    for k in a.ks:
        for c in (c for c in curves if str(k) in c["points"]):
            p = c["points"][str(k)]
            cells = [f"{p.get(key, float('nan')):.3f}" if key in p else "" for key in keys]
            adapt = f"{sum(p['adapt_seconds'].values()):.0f}" if "adapt_seconds" in p else ""
            tuning = p.get("tuning") or {}
            if tuning.get("steps"):
                cells[n_main] += f" ({tuning['steps']} steps)"
            cells.append(f"{tuning['seconds']:.0f}" if "seconds" in tuning else "")
            wall = "" if start is None else f"{minutes(c, k, start):.1f}"
            rows.append(f"| {k} | {c['liver']} | {' | '.join(cells[:n_main])} | {adapt} | "
                        f"{wall} | {' | '.join(cells[n_main:])} |")
    head = ["| K | liver | population MEE mm | corrected MEE mm | linear MEE mm | "
            + ("linear + rest MEE mm | " if a.rest else "") + "linear + "
            "corrected MEE mm | patient model MEE mm | scratch MEE mm | adaptation s | minutes | "
            "tuned MEE mm | tuned + corrected MEE mm | tuning s |",
            "|---|---|---|---|---|---|---|---|---|---|---|---|---|" + ("---|" if a.rest else "")]
    return head, rows


def _intro(curves: list[dict], a) -> str:
    """The paragraph naming the livers and every column."""
    order_note = ("; at `--order 2`, as here, plus its second-order term, damped and gated: "
                  "docs/load_expansion.md" if a.order == 2 else "")
    names = ", ".join(c["liver"] for c in curves if c["liver"] not in FRAMES)
    other = [c["liver"] for c in curves if c["liver"] in FRAMES]
    model = Path(a.model).resolve().relative_to(ROOT)
    return (
        (f"Design livers {names}: training livers of the scene whose simulations the "
         f"population model `{model}` was not trained on (trained "
         "as the shipped one on the scene's dataset less them; the PCA is the scene's, which "
         "has their shapes), to choose the adaptation's settings on" if a.design else
         _named(names, other) + f", none seen by the population model `{model}`, its PCA "
         "or any design choice")
        + "; FE truth on each liver's own mesh with the model's boundary condition "
        f"(scene 4's settings: P2 at 16 mm, one random 0.4 N force, 10 load steps); MEE on "
        f"its first {HELD} simulations, never used to adapt (the K training simulations are the "
        "next K). Population: the model placed as "
        "predict-liver places it. Corrected: plus the kernel ridge correction fitted on the "
        "K training simulations. Linear: the liver's small-strain response on its own mesh "
        "(`fem_sim linear`: the body linearised at u = 0, one factorisation, a back-solve "
        f"per load, scaled by the load fraction{order_note}), no nonlinear simulation "
        "needed; linear + corrected: plus the same correction fitted on its residuals (the liver's "
        "stiffening)."
        + (f" Linear + rest: plus the population model of what each liver's small-strain "
           f"base misses (`{Path(a.rest).resolve().relative_to(ROOT)}`, config "
           "population_linear, "
           "docs/scene4_real.md), placed as the population model; it is the base the "
           "correction corrects and the teacher distils." if a.rest else "")
        + " Patient model: the linear + corrected teacher (at K = 0 the linear "
        f"responses{' and the rest' if a.rest else ''} alone) on {SYNTHETIC} drawn loads "
        "and the K simulations, distilled into "
        "the exported one-liver model (`make patient`). Scratch: the reduced basis trained on "
        "the same K simulations alone. Adaptation: the seconds of correcting and distilling "
        "(placing the liver and the FE simulations not included). Minutes: from the liver "
        "file to the patient model on two cores, by parts: placing the liver (this run's), the FE "
        "start-up as `make patient` spent it (below), the K simulations' own solve "
        "seconds over the two ranks (the shards' records; at K = 0 one simulation's, which "
        "make patient solves as well), the small-strain responses "
        "(`fem_sim linear` with its start-up and meshing, this run's) and the adaptation. "
        "Tuned "
        "(`surrogate adapt --tune`, not the default): the population network fine-tuned "
        "on the K simulations "
        "(surrogate.tuning; how many Adam steps, chosen by cross-validation over them, in "
        "brackets); tuned + corrected: the correction fitted on the tuned network's "
        "out-of-fold residuals; tuning s: the seconds of both.")


def _named(names: str, other: list[str]) -> str:
    """The validation livers ``names`` and the other livers ``other``, as the report names
    them."""
    who = [f"validation livers {names}"] if names else []
    if other:
        who.append(f"the liver{'s' if len(other) > 1 else ''} {', '.join(other)}, of another "
                   "source and frame, placed by the best rigid fit (predict-liver's --frame "
                   "auto, make patient's FRAME=auto)")
    text = " and ".join(who)
    return text[:1].upper() + text[1:]


def _median_line(curves: list[dict], a) -> str:
    """The patient model's median MEE over the livers at each K."""
    med = {k: [_mee(c, k) for c in curves if str(k) in c["points"]] for k in a.ks}
    return ("Median over the livers (patient model; at K = 0 the small-strain responses"
            + (" and the population's rest" if a.rest else "") + " alone, distilled): "
            + ", ".join(f"K = {k}: {np.median(m):.3f} mm" + ("" if len(m) == len(curves) else
                                                               f" ({len(m)} livers)")
                        for k, m in med.items()) + ".")


def _tuned_lines(curves: list[dict], ks) -> list[str]:
    """The sentence on fine-tuning the population network, when it was measured."""
    tuned = {k: [np.median([c["points"][str(k)][key] for c in curves])
                 for key in ("corrected", "tuned", "tuned_corrected")] for k in ks
             if k and all("tuned" in c["points"].get(str(k), {}) for c in curves)}
    if not tuned:
        return []
    lower = {k: sum(c["points"][str(k)]["tuned_corrected"] < c["points"][str(k)]["corrected"]
                    for c in curves) for k in tuned}
    return ["Fine-tuning the population network (`--tune`), median over the livers, "
            "corrected / tuned / tuned + corrected: "
            + "; ".join(f"K = {k}: {a:.3f} / {b:.3f} / {c:.3f} mm" for k, (a, b, c)
                        in tuned.items())
            + ". Tuned + corrected below corrected on "
            + ", ".join(f"{n} of {len(curves)} livers at K = {k}" for k, n in lower.items())
            + f" ({sum(lower.values())} of {len(curves) * len(lower)} points).", ""]


def _reached_lines(curves: list[dict], ks, start: float | None) -> list[str]:
    """The least K within the goal per liver, and the FE seconds against K."""
    def reached(c) -> str:   # the least K within GOAL_MM, its FE seconds (and minutes)
        k = next((k for k in _ks_of(c, ks) if _mee(c, k) <= GOAL_MM), None)
        if k is None:
            return f"{c['liver']}: not reached"
        wall = "" if start is None else f", {minutes(c, k, start):.1f} min"
        return f"{c['liver']}: {k} ({c['fe_seconds'].get(str(k), 0.0):.0f} s{wall})"

    return ["Least K at which the patient model is within the goal's "
            f"{GOAL_MM} mm, with the FE seconds of those K simulations on two ranks (their "
            "own solve seconds over the ranks; meshing, start-up and adapting aside)"
            + ("" if start is None else " and the minutes from the liver file")
            + ": " + ", ".join(map(reached, curves))
            + ".", "", "FE seconds on two ranks against K (the same records): "
            + "; ".join(f"{c['liver']}: " + ", ".join(f"{v:.0f}" for v in
                                                       c["fe_seconds"].values())
                        for c in curves)
            + f" (K = {', '.join(map(str, ks))}, as far as each liver has; at K = 0 one "
            "simulation).", ""]


def _within_lines(curves: list[dict], ks, start: float | None) -> list[str]:
    """The least MEE each liver's patient model reaches within the goal's minutes."""
    if start is None:
        return []
    best = []
    for c in curves:
        within = [k for k in _ks_of(c, ks) if minutes(c, k, start) <= GOAL_MINUTES]
        k = min(within, key=lambda k: _mee(c, k)) if within else None
        best.append(f"{c['liver']}: none" if k is None else
                    f"{c['liver']}: {_mee(c, k):.3f} mm (K = {k}, "
                    f"{minutes(c, k, start):.1f} min)")
    return [f"Within the goal's {GOAL_MINUTES:.0f} minutes on two cores (the minutes "
            "column), the least MEE each liver's patient model reaches: "
            + ", ".join(best) + ".", ""]


def _e2e_lines(curves: list[dict], e2e: dict | None, start: float | None) -> list[str]:
    """The sentence on make patient run end to end, checked against the minutes column."""
    if e2e is None:
        return []
    first = curves[0]
    check = ("" if start is None or first["liver"] != e2e.get("liver", first["liver"])
             or str(e2e["k"]) not in first["points"] else
             f" The minutes column puts the same liver at K = {e2e['k']} at "
             f"{minutes(first, e2e['k'], start):.1f} min (its start-up is this run's, "
             f"{start:.0f} s: meshing the liver, MPI and the forms on each rank, and the "
             "ranks' uneven end).")
    return [f"`make patient` run end to end at K = {e2e['k']} on {first['liver']}, "
            f"each step a process of its own: {e2e['total'] / 60:.1f} min wall time on "
            f"two cores: placing the liver and writing its scene {e2e['place']:.0f} s, "
            f"meshing and {e2e['k']} FE simulations on two ranks {e2e['fe']:.0f} s, "
            f"adapting {e2e['adapt']:.0f} s." + check, ""]


def report(curves: list[dict], e2e: dict | None, a, found: list[dict], md: Path) -> str:
    """docs/patient.md's body after the header."""
    # the FE start-up (meshing, MPI, the forms, the ranks' uneven end) as make patient spent
    # it: its FE step's wall seconds less its simulations' own solves over the ranks
    start = max(0.0, e2e["fe"] - e2e["solves"]) if e2e and "solves" in e2e else None
    head, rows = _table_rows(curves, a, start)
    lines = [_intro(curves, a), "", *head, *rows, "", _median_line(curves, a), "",
             *_rest_lines(curves), *_tuned_lines(curves, a.ks),
             *_reached_lines(curves, a.ks, start), *_within_lines(curves, a.ks, start),
             *_e2e_lines(curves, e2e, start)]
    lines += _size_lines(curves, md) + sources_lines(found)
    return "\n".join(lines)


def design_model(names: list[str], a) -> Path:
    """The population model for the design livers ``names``: the shipped one's config
    trained on scene 4's dataset less their simulations (reused when done); with ``a.rest``
    (main points it there), the population model of the small-strain base's rest trained so
    too.
    """
    from data_spec import read_geometry
    from data_spec.shards import geometry_path
    from data_spec.views import without
    from surrogate.evaluate import shards_by_liver
    from surrogate.train import train_or_reuse

    ids = {read_geometry(geometry_path(DATA, gid)).description.split(".")[0]: gid
           for gid in shards_by_liver(DATA)}
    view = without(DATA, [ids[n] for n in names], a.results / "data")
    run = a.results / "run_population_basis"
    train_or_reuse(view, run, "population_basis", DESIGN_OVERRIDES)
    if a.rest:
        train_or_reuse(view, Path(a.rest), "population_linear", DESIGN_OVERRIDES)
    return run


def _parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--model", default=str(MODEL), help="the population model's run")
    ap.add_argument("--livers", nargs="+", default=None,
                    help="validation livers of the scene (default: Amos-054 LiTS-100 LiTS-67) "
                    f"or {SOFA.stem} (placed by the best rigid fit); with --design, training "
                    f"livers (default: {' '.join(DESIGN_LIVERS)})")
    ap.add_argument("--design", action="store_true",
                    help="training livers, with a population model trained without their "
                    "simulations: docs/patient_design.md, the settings' playground")
    ap.add_argument("--np", type=int, default=2, help="MPI ranks")
    ap.add_argument("--ks", nargs="+", type=int, default=list(KS),
                    help=f"the K values (the truth holds the largest plus {HELD} held out; "
                    "include 0)")
    ap.add_argument("--no-tune", dest="tune", action="store_false",
                    help="leave out the fine-tuned population network (ADAPT=--tune)")
    ap.add_argument("--order", type=int, default=2, choices=(1, 2),
                    help="the small-strain responses' order (make patient's ORDER, default 2)")
    ap.add_argument("--no-green", dest="green", action="store_false",
                    help="no Green's function in the patient model (make patient's GREEN=0)")
    ap.add_argument("--rest", default=None, metavar="RUN",
                    help="a population model of the small-strain base's rest (config "
                    "population_linear) added to each patient's base (make patient's REST; "
                    "with --design, any value: the design livers' own is trained)")
    ap.add_argument("--report-only", action="store_true",
                    help="rewrite the report from its JSON (docs/patient.json), nothing run")
    ap.add_argument("--no-new-fe", action="store_true",
                    help="solve no new FE simulation: each liver's K values are those its "
                    "truth has simulations for")
    ap.add_argument("--no-end-to-end", dest="e2e", action="store_false",
                    help="keep the end-to-end times of docs/patient.json")
    return ap


def _arguments() -> tuple[argparse.Namespace, dict]:
    """The checked arguments (the K values, the livers of the scene; a.results where the
    livers' runs go) and the livers' files by name."""
    ap = _parser()
    a = ap.parse_args()
    a.ks = sorted(set(a.ks))
    a.sources_k = min(SOURCES_K, a.ks[-1])
    if a.ks[-1] > TRUTH_SIMS - HELD:
        ap.error(f"--ks {a.ks}: at most {TRUTH_SIMS - HELD} (the truth scene's "
                 f"{TRUTH_SIMS} simulations less the {HELD} held out)")
    if a.ks[0] != 0 or a.sources_k not in a.ks or a.sources_k == 0:
        ap.error(f"--ks {a.ks}: expected 0 and {a.sources_k} among them (the population "
                 "model alone, and where the error's sources are measured)")
    from data_spec import load_scene
    from data_spec.livers import training_files, validation_files

    g = load_scene(SCENE)["geometry"]
    a.livers = a.livers or (DESIGN_LIVERS if a.design else ["Amos-054", "LiTS-100", "LiTS-67"])
    files = {f.stem: f for f in (training_files(g) if a.design else validation_files(g))}
    if not a.design and SOFA.exists():   # seen by no training run either
        files[SOFA.stem] = SOFA
    unknown = [n for n in a.livers if n not in files]
    if unknown:
        ap.error(f"--livers: {unknown} are not {'training' if a.design else 'validation'} "
                 f"livers of {SCENE.name}" + ("" if a.design else f" (nor {SOFA.stem})"))
    a.results = RESULTS.with_name("patient_design") if a.design else RESULTS
    if a.design and a.rest:   # the design livers' own (design_model trains it)
        a.rest = str(a.results / "run_population_linear")
    return a, files


def main() -> int:
    a, files = _arguments()
    md = ROOT / "docs" / ("patient_design.md" if a.design else "patient.md")
    title = "A new patient's model: the design livers" if a.design else "A new patient's model"
    if a.report_only:
        out = json.loads(md.with_suffix(".json").read_text())
        write_report(md, title, report(out["curves"], out["make_patient"], a, out["sources"], md),
                     out)
        return 0
    if a.design:
        a.model = str(design_model(a.livers, a))
    curves, found = map(list, zip(*(curve(files[n], a) for n in a.livers)))
    saved = md.with_suffix(".json")
    e2e = None if a.design else end_to_end(files[a.livers[0]], a, a.sources_k) if a.e2e else (
        json.loads(saved.read_text()).get("make_patient") if saved.exists() else None)
    write_report(md, title, report(curves, e2e, a, found, md),
                 {"curves": curves, "make_patient": e2e, "sources": found})
    return 0


if __name__ == "__main__":
    sys.exit(main())
