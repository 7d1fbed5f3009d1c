"""Scene 4's population basis: more livers, or more simulations per liver? Into
docs/livers_or_loads.md.

The population basis barely improves when each training liver gets twice the simulations
(docs/table4.md, the point past the budget), while its modes fit the held-out livers' fields
far better than it predicts them: is its network short of livers, or of loads? This measures
it on ``make table4 T4="--scenes 4 --beyond 4=1632"``'s dataset (16 simulations per liver): the
design with the knobs chosen at 8 simulations per liver (input noise 0.3, no weight decay:
docs/population_basis.md) trained on half or all of the training livers (44 or 89, the half
drawn once, seeded) with the first 8 or all 16 simulations of each, and evaluated on the same
held-out livers as table4's row (its fold 1). Half the livers with all their simulations and
all the livers with half theirs train on the same number of simulations. One training seed
per cell (the config's ensemble of five averages its members): differences of a few per cent
are noise.

A regulariser sized for little data, or a network sized for it, may cap it at more. So at 16
per liver with every training liver, those knobs are set against lighter input noise (0.1),
weight decay (1e-2), a wider network (512 x 512 against 256 x 256), two of their
combinations, and a noise of its own on the shape coefficients (``shape_noise`` 0.6, the
loads' features keeping 0.3 or 0.1: the network fits its training livers far better than the
livers held out for early stopping, as if it knew them by their coefficients), every other
knob table4's, each trained on all 8 folds. The list and the rule were fixed before any of
them was trained: the variant with the lowest mean MEE on folds 2-8 is chosen, and fold 1
(table4's held-out livers) is only reported. The choice becomes the shipped config only if it
also has the lower mean MEE on folds 2-8 at 8 simulations per liver, where the first knobs
were chosen; both are trained there too, and again from another training seed (reported
only).

The livers above are halved, not doubled. So scene 4 is generated again with twice its livers
(204: the first 102 are table4's, the other 102 new phantoms of the same population) at 8
simulations each. Simulation i is liver i % 204 with the loads of (scene seed, i), so the
simulations i with i % 204 < 102 are the same cases on the same livers as in the dataset with 16
per liver: every arm below is evaluated on them. On each of table4's 8 folds by liver, the
shipped config (the sweep's choice) is trained on the fold's other livers with 8 simulations
each, with 16 each, with 8 each plus as many new livers (drawn once, seeded) with 8 each, and
on every other liver of the 204 with 8 each; the held-out livers are evaluated on their 8
shared simulations. The second and third train on the same number of simulations. Fixed before
any of them was trained: the comparison is the mean MEE over the 8 folds and the number of
folds where it is lower; the more-livers dataset's shape coefficients come from its own PCA over
204 livers. That makes the arms on 16 simulations per liver differ in two things, so one arm was
added after these four were measured: the 16 per liver told the 204 livers' coefficients (their
registration too), the same shape description as the arms with more livers. Those three arms
on one shape description are then trained again from another training seed (chosen after the
first seed's results: a check of them).

    # after make table4 T4="--scenes 4 --beyond 4=1632":
    .venv-train/bin/python bench/livers_or_loads.py

Resumable: each cell's result is kept under bench/results/livers_or_loads and not computed
again; the dataset with more livers is generated on the first run (MPI, ``--np`` ranks, about an
hour on two cores; ``--generate-only`` stops after it).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "bench"))
from report import header  # noqa: E402

TABLE4 = ROOT / "bench" / "results" / "table4" / "scene4_livers"
DATA = TABLE4 / "beyond_1632" / "data"
CONFIG = TABLE4 / "run_population_basis" / "config.json"
# the regularisers chosen at 8 simulations per liver (docs/population_basis.md), set here so
# that every cell keeps them when table4's config moves on
KNOBS_AT_8 = {"input_noise": 0.3, "l2": 0.0, "shape_noise": None}
# the knobs the sweep chose (table4's since), pinned as KNOBS_AT_8 for the more-livers arms
KNOBS_CHOSEN = {**KNOBS_AT_8, "input_noise": 0.1, "l2": 1e-2}
RESULTS = ROOT / "bench" / "results" / "livers_or_loads"
PER_LIVER = (8, 16)    # the first k simulations of each liver (simulation i is liver i % 102)
# at 16 simulations per liver, beside KNOBS_AT_8 (slug: label, overrides)
VARIANTS = {"noise0.3": ("input noise 0.3 (chosen at 8 per liver)", {}),
            "noise0.1": ("input noise 0.1", {"input_noise": 0.1}),
            "l2": ("weight decay 1e-2", {"l2": 1e-2}),
            "noise0.1_l2": ("input noise 0.1, weight decay 1e-2", {"input_noise": 0.1, "l2": 1e-2}),
            "wide": ("hidden 512 x 512", {"hidden": [512, 512]}),
            "wide_l2": ("hidden 512 x 512, weight decay 1e-2", {"hidden": [512, 512], "l2": 1e-2}),
            "shape0.6": ("shape noise 0.6", {"shape_noise": 0.6}),
            "noise0.1_shape0.6": ("input noise 0.1, shape noise 0.6",
                                  {"input_noise": 0.1, "shape_noise": 0.6})}
BASE = "noise0.3"
REPLICA = 100  # the training seed offset of the choice's replicate at 8 per liver
LIVER_SHARE = (0.5, 1.0)
# more livers: scene 4 with twice the livers (the first 102 are table4's: liver k is phantom
# seed population_seed + k) at 8 simulations each. Simulation i is liver i % 204 with the loads
# of (scene seed, i), so its simulations i with i % 204 < 102 are beyond_1632's simulation i,
# the same case on the same liver.
MORE = RESULTS / "more_livers"
MORE_LIVERS = 204
MORE_PER_LIVER = 8


def more_livers_data(a) -> Path:
    """The dataset of scene 4 with MORE_LIVERS livers, MORE_PER_LIVER simulations each
    (generated with table4's generate: resumable, shards already there are kept)."""
    import tomllib

    from table4 import SCENES, generate, toml_text

    scene = tomllib.loads((ROOT / "data_spec" / "scenes" / SCENES[4]).read_text())
    n = MORE_LIVERS * MORE_PER_LIVER
    scene["scene"].update(name=f"scene4_livers_{MORE_LIVERS}", n_simulations=n,
                          description=f"scene 4 with {MORE_LIVERS} livers, the first 102 "
                                      "scene 4's (bench/livers_or_loads.py)")
    scene["geometry"]["population_size"] = MORE_LIVERS
    MORE.mkdir(parents=True, exist_ok=True)
    path = MORE / "scene.toml"
    text = toml_text(scene)
    if not path.exists() or path.read_text() != text:
        path.write_text(text)
    generate(path, MORE / "data", n, float("inf"), a)
    return MORE / "data"


def cell(ds, cfg: dict, held: np.ndarray, livers: np.ndarray, k: int) -> dict:
    """Pooled and per-liver skill on the held-out samples of the design trained on the
    samples of ``livers`` from their first ``k`` simulations."""
    from surrogate.metrics import displacement_metrics
    from surrogate.train import fit_design, per_liver, predict_design, training_mean

    n_geo = len(ds.geo_ids)
    train = np.flatnonzero(np.isin(ds.sample_geo, livers)
                           & (ds.sample_sim < k * n_geo))
    t0 = time.perf_counter()
    model, _ = fit_design(ds, train, cfg, cfg["seed"] + 1, f"{len(livers)} livers x "
                          f"{k} ", print)
    seconds = time.perf_counter() - t0
    pred, true, smp = predict_design(ds, model, cfg, held)
    naive = np.broadcast_to(training_mean(ds, train), true.shape)
    m, mn = displacement_metrics(pred, true), displacement_metrics(naive, true)
    pl = per_liver(pred, true, naive, ds.sample_geo[smp])
    return {"livers": int(len(livers)), "per_liver": k,
            "train_sims": int(np.unique(ds.sample_sim[train]).size),
            "mee": m["mee"], "naive": mn["mee"], "skill": m["mee"] / mn["mee"],
            "skill_mean": pl["skill_mean"], "skill_median": pl["skill_median"],
            "seconds": seconds}


# the arms on one shape description (the 204 livers' PCA), trained again from training seed
# +REPLICA: the deconfounded comparison's check
REPLICATED = {"old8": "89 livers x 8", "old16_pca204": "89 x 16", "mixed8": "178 x 8"}
# the arms of the more-livers comparison, each evaluated on the same simulations: (slug, label)
ARMS = (("old8", "the fold's other livers of table4's 102, 8 simulations each"),
        ("old16", "the same livers, 16 simulations each (beyond_1632)"),
        ("old16_pca204", "the same, told the shape coefficients of the 204 livers' PCA"),
        ("mixed8", "the same livers and as many new ones, 8 simulations each"),
        ("all8", "every other liver of the 204, 8 simulations each"))


def more_livers(ds, folds: list, cfg: dict, a) -> str:
    """Twice the livers or twice the simulations per liver, at the shipped config, on every
    fold of table4's 102 livers: each fold's held-out livers are evaluated on the same
    simulations (their 8 shared by both datasets) whatever the arm trained on. Returns the
    report's section."""
    from surrogate.data import load_dataset

    more = load_dataset(more_livers_data(a))
    # beyond_1632's simulations with the 204 livers' geometry files (shape coefficients) and
    # registration: the shape description of the more-livers arms, on twice the loads
    view = MORE / "old16_pca204"
    view.mkdir(parents=True, exist_ok=True)
    for name, src in (("scene.toml", DATA / "scene.toml"), ("sims", DATA / "sims"),
                      ("geometry", MORE / "data" / "geometry")):
        if not (view / name).exists():
            (view / name).symlink_to(src.resolve())
    alike = load_dataset(view)
    if alike.geo_ids != ds.geo_ids:
        raise SystemExit(f"{view}: its livers are not in {DATA}'s order")
    where = {g: i for i, g in enumerate(more.geo_ids)}
    old = np.array([where.get(g, -1) for g in ds.geo_ids])  # table4's liver i is more's old[i]
    if (old < 0).any():
        raise SystemExit(f"{MORE}: {int((old < 0).sum())} of table4's livers are not among "
                         "its livers (another mesh?)")
    new = np.setdiff1d(np.arange(len(more.geo_ids)), old)
    draw = np.random.default_rng(1).permutation(new)  # the new livers of "mixed8", drawn once
    out = {slug: [] for slug, _ in ARMS}
    for j, fold in enumerate(folds):
        held = np.unique(ds.sample_geo[fold])
        mine = fold[ds.sample_sim[fold] % MORE_LIVERS < len(ds.geo_ids)]  # the shared cases
        theirs = np.flatnonzero(np.isin(more.sample_geo, old[held]))
        a_, b_ = (np.lexsort((x.sample_fraction[i], x.sample_sim[i]))
                  for x, i in ((ds, mine), (more, theirs)))
        mine, theirs = mine[a_], theirs[b_]
        same = (np.array_equal(ds.sample_sim[mine], more.sample_sim[theirs])
                and np.allclose(ds.load_points[mine], more.load_points[theirs])
                and np.allclose(ds.forces[mine], more.forces[theirs]))
        if not same:
            raise SystemExit(f"fold {j + 1}: the held-out simulations differ between {DATA} "
                             f"and {MORE / 'data'}")
        others = np.setdiff1d(np.arange(len(ds.geo_ids)), held)
        arms = {"old8": (more, theirs, old[others]), "old16": (ds, mine, others),
                "old16_pca204": (alike, mine, others),
                "mixed8": (more, theirs, np.concatenate([old[others], draw[:others.size]])),
                "all8": (more, theirs, np.setdiff1d(np.arange(len(more.geo_ids)),
                                                     old[held]))}
        for slug, seed in [(s, 0) for s, _ in ARMS] + [(s, REPLICA) for s in REPLICATED]:
            path = MORE / f"{tag(slug, seed)}_fold{j + 1}.json"
            if not path.exists():
                print(f"more livers: {tag(slug, seed)}, fold {j + 1}/{len(folds)}", flush=True)
                x, evaluate, livers = arms[slug]
                k = MORE_PER_LIVER if x is more else max(PER_LIVER)
                path.write_text(json.dumps(cell(x, {**cfg, "seed": cfg["seed"] + seed},
                                                evaluate, livers, k), indent=1))
            out.setdefault(tag(slug, seed), []).append(json.loads(path.read_text()))
    ref = out["old16"]

    def mean(runs, key):
        return float(np.mean([r[key] for r in runs]))

    def change(s, t):
        return 100 * (mean(out[s], "mee") / mean(out[t], "mee") - 1)

    def lower(s, t):  # folds where arm s's MEE is below arm t's
        return sum(r["mee"] < q["mee"] for r, q in zip(out[s], out[t]))

    def both(s, t):  # per cent, with each arm's MEE averaged over the two training seeds
        return 100 * ((mean(out[s], "mee") + mean(out[tag(s, REPLICA)], "mee"))
                      / (mean(out[t], "mee") + mean(out[tag(t, REPLICA)], "mee")) - 1)

    # the comparisons on one shape description, from the second seed (and both averaged)
    pairs = (("mixed8", "old8", "Twice the livers"),
             ("old16_pca204", "old8", "twice the simulations per liver"),
             ("mixed8", "old16_pca204", "twice the livers against twice the simulations"))

    def span(runs, key):  # the folds hold 12 or 13 livers: what they train on, not a mean
        lo, hi = min(r[key] for r in runs), max(r[key] for r in runs)
        return f"{lo:,}" if lo == hi else f"{lo:,}-{hi:,}"

    rows = [f"| {label} | {span(out[s], 'livers')} | {out[s][0]['per_liver']} | "
            f"{span(out[s], 'train_sims')} | {mean(out[s], 'mee'):.3f} | "
            f"{mean(out[s], 'skill'):.3f} | {mean(out[s], 'skill_mean'):.3f} / "
            f"{mean(out[s], 'skill_median'):.3f} | "
            + ("" if s == "old16" else f"{lower(s, 'old16')} of {len(ref)}")
            + f" | {out[s][0]['mee']:.3f} | {sum(r['seconds'] for r in out[s]) / 60:.0f} min |"
            for s, label in ARMS]

    return (
        "| training set (per fold) | livers | simulations per liver | training simulations "
        "| MEE mm | skill (pooled) | skill, mean / median liver | folds lower than 16 per "
        "liver | MEE mm, fold 1 | training (8 folds) |\n|---|---|---|---|---|---|---|---|---|"
        "---|\n" + "\n".join(rows) + "\n\n"
        "Pre-registered (the livers told their own dataset's coefficients): on as many "
        f"training simulations, twice the livers differ from twice the simulations per liver by "
        f"{change('mixed8', 'old16'):+.1f} % (lower on {lower('mixed8', 'old16')} of "
        f"{len(ref)} folds). Told one shape description, the 204 livers' PCA: from 89 livers x "
        f"8, twice the livers change the MEE by {change('mixed8', 'old8'):+.1f} % (lower on "
        f"{lower('mixed8', 'old8')} of {len(ref)} folds), twice the simulations per liver by "
        f"{change('old16_pca204', 'old8'):+.1f} % ({lower('old16_pca204', 'old8')} of "
        f"{len(ref)}); twice the livers against twice the simulations: "
        f"{change('mixed8', 'old16_pca204'):+.1f} % (lower on "
        f"{lower('mixed8', 'old16_pca204')} of {len(ref)} folds); every liver of the 204 "
        f"but the held-out ones: {change('all8', 'old16_pca204'):+.1f} %. The shape "
        "description alone: the same 16 simulations per liver told the 204 livers' "
        f"coefficients change by {change('old16_pca204', 'old16'):+.1f} % (lower on "
        f"{lower('old16_pca204', 'old16')} of {len(ref)} folds).\n\n"
        "Again from another training seed (the networks' initialisation, batch order and "
        "early-stopping split; the same data and folds; run after the first seed's results, "
        "as a check of them), the arms on one shape description. Mean MEE over the folds: "
        + ", ".join(f"{label} {mean(out[tag(s, REPLICA)], 'mee'):.3f} mm (the first seed: "
                    f"{mean(out[s], 'mee'):.3f})" for s, label in REPLICATED.items()) + ". "
        + "; ".join(f"{label}: {change(tag(a, REPLICA), tag(b, REPLICA)):+.1f} % (lower on "
                    f"{lower(tag(a, REPLICA), tag(b, REPLICA))} of {len(ref)} folds; both "
                    f"seeds averaged: {both(a, b):+.1f} %)" for a, b, label in pairs) + ".\n")


def tag(slug: str, seed: int) -> str:
    """The name of an arm's results trained from training seed +``seed``."""
    return f"{slug}_seed{seed}" if seed else slug


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--md", default=str(ROOT / "docs" / "livers_or_loads.md"))
    ap.add_argument("--np", type=int, default=2, help="MPI ranks for generation")
    ap.add_argument("--chunk", type=int, default=102, help="simulations per generate call")
    ap.add_argument("--solver-python", default=str(ROOT / ".venv-solver" / "bin" / "python"))
    ap.add_argument("--generate-only", action="store_true",
                    help="generate the dataset with more livers, then stop")
    a = ap.parse_args()
    if a.generate_only:
        more_livers_data(a)
        return 0
    if not (DATA / "sims").is_dir() or not CONFIG.exists():
        print(f"{DATA} or {CONFIG}: missing; run make table4 T4=\"--scenes 4 --beyond "
              "4=1632\" first", file=sys.stderr)
        return 2
    from surrogate.data import kfold_groups, load_dataset

    cfg = {**json.loads(CONFIG.read_text()), **KNOBS_AT_8}
    ds = load_dataset(DATA)
    folds = kfold_groups(ds, cfg["folds"], cfg["seed"])
    held = folds[0]  # table4's fold 1
    choice = range(1, len(folds))  # folds 2-8: the sweep's choice

    def outside(samples: np.ndarray) -> np.ndarray:
        """The livers none of ``samples`` belongs to."""
        return np.setdiff1d(np.unique(ds.sample_geo), np.unique(ds.sample_geo[samples]))

    training = outside(held)
    half = np.sort(np.random.default_rng(0).permutation(training)[:training.size // 2])
    RESULTS.mkdir(parents=True, exist_ok=True)
    cells = {}
    for share in LIVER_SHARE:
        livers = training if share == 1.0 else half
        for k in PER_LIVER:
            path = RESULTS / f"livers{livers.size}_per{k}.json"
            if not path.exists():
                print(f"training on {livers.size} livers x {k} simulations", flush=True)
                path.write_text(json.dumps(cell(ds, cfg, held, livers, k), indent=1))
            cells[(livers.size, k)] = json.loads(path.read_text())
            c = cells[(livers.size, k)]
            print(f"{livers.size} livers x {k}: skill {c['skill']:.3f} (MEE {c['mee']:.3f} mm)",
                  flush=True)
    def per_fold(slug: str, k: int, seed: int = 0) -> list[dict]:
        """The variant trained on each fold's other livers, first ``k`` simulations each
        (``seed``: added to the config's training seed)."""
        out = []
        for j, fold in enumerate(folds):
            path = RESULTS / (f"{slug}{'' if k == max(PER_LIVER) else f'_per{k}'}"
                              f"{f'_seed{seed}' if seed else ''}_fold{j + 1}.json")
            if not path.exists():
                print(f"{VARIANTS[slug][0]}, {k} per liver, seed +{seed}, fold "
                      f"{j + 1}/{len(folds)}", flush=True)
                over = {**VARIANTS[slug][1], "seed": cfg["seed"] + seed}
                path.write_text(json.dumps(cell(ds, {**cfg, **over}, fold, outside(fold), k),
                                           indent=1))
            out.append(json.loads(path.read_text()))
        return out

    def mean(runs: list[dict], key: str, idx) -> float:
        return float(np.mean([runs[j][key] for j in idx]))

    sweep = {slug: per_fold(slug, max(PER_LIVER)) for slug in VARIANTS}
    pick = min(VARIANTS, key=lambda v: mean(sweep[v], "mee", choice))
    small = {v: per_fold(v, min(PER_LIVER)) for v in dict.fromkeys((BASE, pick))}
    keeps = mean(small[pick], "mee", choice) < mean(small[BASE], "mee", choice)
    # reported only: the same two at 8 per liver from another training seed
    again = {v: per_fold(v, min(PER_LIVER), REPLICA) for v in small} if pick != BASE else {}
    base = sweep[BASE]
    base_name = VARIANTS[BASE][0].split(" (")[0]

    def wins(runs: list[dict], ref: list[dict]) -> int:
        return sum(runs[j]["mee"] < ref[j]["mee"] for j in choice)

    sweep_rows = [
        f"| {VARIANTS[v][0]} | `{VARIANTS[v][1]}` | {'**' if v == pick else ''}"
        f"{mean(r, 'mee', choice):.3f}{'**' if v == pick else ''} | "
        f"{mean(r, 'skill', choice):.3f} | "
        + ("" if v == BASE else f"{wins(r, base)} of {len(choice)}") + f" | {r[0]['mee']:.3f} | "
        f"{r[0]['skill']:.3f} | {sum(x['seconds'] for x in r) / 60:.0f} min |"
        for v, r in sweep.items()]
    small_rows = [f"| {VARIANTS[v][0]} | {mean(r, 'mee', choice):.3f} | "
                  f"{mean(r, 'skill', choice):.3f} | {r[0]['mee']:.3f} | {r[0]['skill']:.3f} |"
                  for v, r in small.items()]

    def change(a: list[dict], b: list[dict], idx) -> float:  # per cent, a's MEE against b's
        return 100 * (mean(a, "mee", idx) / mean(b, "mee", idx) - 1)

    slope = " ".join(  # doubling the simulations per liver, on the choice folds
        f"{VARIANTS[v][0]}: {change(sweep[v], small[v], choice):+.1f} %;" for v in small)
    slope = (f"From {min(PER_LIVER)} to {max(PER_LIVER)} simulations per liver, its MEE on "
             f"folds 2-8 changes by {slope.rstrip(';')}.")
    if pick == BASE:
        outcome = "Chosen: the knobs chosen at 8 per liver; they stay."
    else:
        outcome = (
            f"Chosen: {VARIANTS[pick][0]}; on folds 2-8 its MEE differs from {base_name}'s "
            f"by {change(sweep[pick], base, choice):+.1f} % (lower on "
            f"{wins(sweep[pick], base)} of {len(choice)} folds), on fold 1 by "
            f"{change(sweep[pick], base, [0]):+.1f} %. At {min(PER_LIVER)} simulations per "
            f"liver, on folds 2-8, by {change(small[pick], small[BASE], choice):+.1f} %: "
            + ("it is the shipped config (surrogate/config.py), docs/table4.md's." if keeps
               else "the knobs chosen at 8 per liver stay (the rule above).")
            + f" From another training seed (reported only), at {min(PER_LIVER)} per liver: "
            f"folds 2-8 {mean(again[pick], 'mee', choice):.3f} against "
            f"{mean(again[BASE], 'mee', choice):.3f} mm "
            f"({change(again[pick], again[BASE], choice):+.1f} %, lower on "
            f"{wins(again[pick], again[BASE])} of {len(choice)} folds), fold 1 "
            f"{again[pick][0]['mee']:.3f} against {again[BASE][0]['mee']:.3f} mm.")
    n_held = np.unique(ds.sample_geo[held]).size
    rows = [f"| {c['livers']} | {c['per_liver']} | {c['train_sims']:,} | {c['mee']:.3f} | "
            f"{c['naive']:.3f} | **{c['skill']:.3f}** | {c['skill_mean']:.3f} / "
            f"{c['skill_median']:.3f} | {c['seconds'] / 60:.0f} min |" for c in cells.values()]
    few, many = min(k[0] for k in cells), max(k[0] for k in cells)
    lo, hi = min(PER_LIVER), max(PER_LIVER)
    s = {key: c["skill"] for key, c in cells.items()}
    verdict = (
        f"On about as many training simulations ({cells[(many, lo)]['train_sims']:,} and "
        f"{cells[(few, hi)]['train_sims']:,}), {many} livers x {lo} give skill "
        f"{s[(many, lo)]:.3f} and {few} livers x {hi} give {s[(few, hi)]:.3f}. Doubling the "
        "livers changes the skill by "
        f"{100 * (s[(many, lo)] / s[(few, lo)] - 1):+.0f} % at {lo} simulations per liver and "
        f"{100 * (s[(many, hi)] / s[(few, hi)] - 1):+.0f} % at {hi}; doubling the simulations "
        f"per liver by {100 * (s[(few, hi)] / s[(few, lo)] - 1):+.0f} % with {few} livers and "
        f"{100 * (s[(many, hi)] / s[(many, lo)] - 1):+.0f} % with {many}.")
    text = (header("Scene 4's population basis: more livers, or more simulations per liver?")
            .rstrip() + "\n\n" + " ".join(__doc__.split("\n\n")[1].split()) + "\n\n"
            f"Held out: the {n_held} livers of docs/table4.md's scene-4 row. Config: table4's "
            f"`population_basis` run's ({CONFIG.relative_to(ROOT)}) with `{KNOBS_AT_8}`.\n\n"
            "| training livers | simulations per liver | training simulations | MEE mm | "
            "naive MEE mm | skill (pooled) | skill, mean / median liver | training |\n"
            "|---|---|---|---|---|---|---|---|\n" + "\n".join(rows) + "\n\n" + verdict + "\n\n"
            + " ".join(__doc__.split("\n\n")[2].split()) + "\n\n"
            "| variant | config overrides | MEE mm, folds 2-8 (choice) | skill, folds 2-8 | "
            f"folds lower than {base_name} | MEE mm, fold 1 | skill, fold 1 | training "
            "(8 folds) |\n|---|---|---|---|---|---|---|---|\n" + "\n".join(sweep_rows) + "\n\n"
            f"At {min(PER_LIVER)} simulations per liver (each training liver's first "
            f"{min(PER_LIVER)}: table4's row's), all 8 folds, evaluated as above:\n\n"
            "| variant | MEE mm, folds 2-8 | skill, folds 2-8 | MEE mm, fold 1 | skill, fold 1 "
            "|\n|---|---|---|---|---|\n" + "\n".join(small_rows) + "\n\n" + outcome + " "
            + slope + "\n\n" + " ".join(__doc__.split("\n\n")[3].split()) + "\n\n"
            + more_livers(ds, folds, {**cfg, **KNOBS_CHOSEN}, a))
    Path(a.md).write_text(text)
    print(f"report written to {a.md}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
