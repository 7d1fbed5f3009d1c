"""A network over the grasp's small-strain base, cross-validated on the training livers: does
it learn what the Ogden liver does beyond the base?

    .venv-train/bin/python bench/grasp_rest.py [--sims 145] [--folds 5] [--evaluate-folds 2]
        [--report-only]

scene4_grasp's first ``--sims`` simulations with each liver's grasp base (fem_sim linear
--population --order 1), ``population_green`` trained by liver folds: per pull on the held-out
livers the MEE of the model, the base and the naive model; then the model of grasps on them
all (bench/results/grasp_rest/run), which ``bench/surgical_loads.py --model`` places on the
validation livers; the tool's force laws on every fold (no network). Resumable. Writes the
sections "grasp-network" and "grasp-force" of docs/surgical_loads.md.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from liverviz.report import ROOT, commit, put_section

SCENE = ROOT / "data_spec" / "scenes" / "scene4_grasp.toml"
RESULTS = ROOT / "bench" / "results" / "grasp_rest"


def fold_figures(data: Path, folds: int, k: int, sims: int) -> dict:
    """Fold ``k``'s held-out livers: {pull: {model: [per liver MEE]}} (its own file kept)."""
    from surrogate.config import get_config
    from surrogate.data import kfold_groups, load_dataset
    from surrogate.linear_base import PopulationLinearBase
    from surrogate.reports import per_liver_at
    from surrogate.train import fit_design, predict_design, training_mean, training_samples

    kept = RESULTS / f"fold{k}_of_{folds}_{sims}_sims.json"
    if kept.exists():
        return json.loads(kept.read_text())
    cfg = get_config("population_green", folds=folds)
    ds = load_dataset(data)
    if np.unique(ds.sample_sim).size != sims:   # the dataset grows; a fold trains on it all
        raise SystemExit(f"{data} holds {np.unique(ds.sample_sim).size} simulations, not "
                         f"--sims {sims}: its kept folds of {sims} are reported as they are")
    held = kfold_groups(ds, folds, cfg["seed"])[k]
    train = training_samples(ds, held, cfg)
    model, _ = fit_design(ds, train, cfg, cfg["seed"] + 1 + k, f"fold {k + 1}/{folds} ")
    pred, true, rows = predict_design(ds, model, cfg, held)
    base = PopulationLinearBase(ds, 1)
    fields = {"model": pred, "base": np.concatenate([base.sample(ds, s) for s in held]),
              "naive": np.broadcast_to(training_mean(ds, train), true.shape)}
    err = {m: np.linalg.norm(np.asarray(f, np.float64) - true, axis=1) for m, f in fields.items()}
    out = per_liver_at(err, np.linalg.norm(ds.forces[rows, 0], axis=-1), ds.sample_geo[rows])
    RESULTS.mkdir(parents=True, exist_ok=True)
    kept.write_text(json.dumps(out))
    return out


def section(a) -> str:
    """The report's section: a table per dataset size measured (every kept fold's figures)."""
    lines = [
        "The network over the base, cross-validated on the training livers "
        f"(`bench/grasp_rest.py`, {a.folds} folds by liver, {a.evaluate_folds} held out in "
        f"turn; commit {commit()}): scene4_grasp's first simulations (grasps pulled to 40 mm), "
        "each liver's grasp base (`fem_sim linear --population --order 1`), the population "
        "model of what the base misses (`population_green`, its shipped settings) trained "
        "with the load as the tool's pull; on the held-out livers, MEE per liver (mm), median "
        "/ worst."]
    for n in sorted({int(f.stem.split("_")[3]) for f in RESULTS.glob(f"fold*_of_{a.folds}_*")}):
        figures = [json.loads(f.read_text()) for k in range(a.evaluate_folds)
                   if (f := RESULTS / f"fold{k}_of_{a.folds}_{n}_sims.json").exists()]
        pulls = sorted({p for f in figures for p in f}, key=float)
        lines += ["", f"{n} simulations ({n // 145} a liver):", "",
                  "| pull mm | livers | model | base alone | naive |", "|---" * 5 + "|"]
        for p in pulls:
            per = [sum((f[p][m] for f in figures if p in f), []) for m in ("model", "base",
                                                                           "naive")]
            lines.append(f"| {p} | {len(per[0])} | " + " | ".join(
                f"{np.median(v):.2f} / {np.max(v):.2f}" for v in per) + " |")
    lines += ["", "The model placed on the validation livers: the model rows of the tables above; "
              "the tool's force: the next section."]
    return "\n".join(lines)


def main(argv=None) -> int:
    from fem_sim.batch.chunked import generate_chunks, linear_bases
    from surrogate.reports import grasp_force_section
    from surrogate.train import train_or_reuse

    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--sims", type=int, default=145)
    p.add_argument("--folds", type=int, default=5)
    p.add_argument("--evaluate-folds", type=int, default=2)
    p.add_argument("--report-only", action="store_true")
    a = p.parse_args(argv)
    data = RESULTS / "data"
    if not a.report_only:
        generate_chunks(SCENE, data, a.sims, ranks=2, chunk=a.sims)
        linear_bases(data, ranks=2, order=1)
        for k in range(a.evaluate_folds):
            fold_figures(data, a.folds, k, a.sims)
        train_or_reuse(data, RESULTS / "run", "population_green",
                       {"folds": a.folds, "evaluate_folds": 1})
    if any(RESULTS.glob(f"fold*_of_{a.folds}_*")):   # else the section stays as it was
        put_section(ROOT / "docs" / "surgical_loads.md", "grasp-network", section(a))
    if (data / "linear").exists():
        put_section(ROOT / "docs" / "surgical_loads.md", "grasp-force",
                    grasp_force_section(data, a.folds, commit()))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
