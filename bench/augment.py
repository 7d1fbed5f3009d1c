"""Do phantoms help a population of real livers? Scene 4's real livers with and without
``phantoms = N`` anatomical phantoms mixed in (data_spec/scenes/scene4_livers.toml's
``[geometry] phantoms``).

    .venv-train/bin/python bench/augment.py [--phantoms 60] [--per-liver 2] [--np 2] [--jobs 2]

1. One dataset: the shipped scene's 145 training livers and N phantoms (seeds
   ``population_seed`` onward), ``--per-liver`` random loads each, generated where missing
   (the real livers' prepared meshes are reused from runs/data/scene4_livers when it is there).
2. The population basis cross-validated by liver over the real livers only (the trainer
   never holds a phantom out: a phantom is augmentation), on the same folds twice: with the
   phantoms' simulations in every training set, and without them (``phantoms_in_training =
   false``). The shape model (PCA) is the dataset's in both.
3. Per-liver MEE and skill on the held-out real livers, paired liver by liver.

Resumable: generation skips what is there, a finished training is reused. Writes
docs/augment.md and docs/augment.json.
"""

from __future__ import annotations

import argparse
import shutil
import sys
from pathlib import Path

import numpy as np

from fem_sim.batch.chunked import generate_chunks
from liverviz.report import ROOT, commit, write_report

SHIPPED = ROOT / "data_spec" / "scenes" / "scene4_livers.toml"
REAL = ROOT / "runs" / "data" / "scene4_livers"
RESULTS = ROOT / "bench" / "results" / "augment"
CONFIG = "population_basis"


def write_scene(path: Path, phantoms: int, per_liver: int) -> Path:
    """The shipped real scene with ``phantoms`` phantoms in front of its livers and
    ``per_liver`` simulations per liver, its liver folder made absolute."""
    from data_spec.livers import training_files
    from data_spec.scene_writer import relocated_scene, scene_toml

    d = relocated_scene(SHIPPED)
    g = d["geometry"]
    g["phantoms"] = phantoms
    n = (phantoms + len(training_files(g))) * per_liver
    d["scene"].update(name="scene4_augment", n_simulations=n,
                      description=f"scene4_livers with {phantoms} phantoms, {per_liver} "
                      "simulations per liver (bench/augment.py)")
    path.parent.mkdir(parents=True, exist_ok=True)
    text = scene_toml(d)
    if not path.exists() or path.read_text() != text:
        path.write_text(text)
    return path


def reuse_prepared(data: Path) -> None:
    """The real livers' prepared meshes, their index and their registrations, copied from the
    shipped scene's dataset (the index and population.npz's registrations are keyed by file
    content, settings and code, so nothing stale is reused).
    """
    src, dst = REAL / "geometry", data / "geometry"
    if dst.exists() or not (src / "meshes.json").exists():
        return
    shutil.copytree(src, dst)


def trained(data: Path, folds: int, evaluate: int, jobs: int) -> dict:
    """The population basis on the same folds with and without the phantoms' simulations
    (``jobs`` trainings at a time)."""
    from surrogate.train import train_all

    common = {"folds": folds, "evaluate_folds": evaluate, "final_fit": False}
    return train_all(data, {label: (RESULTS / f"run_{label}", CONFIG,
                                    {**common, "phantoms_in_training": keep})
                            for label, keep in (("with", True), ("without", False))}, jobs)


def paired(runs: dict) -> dict:
    """Liver by liver on the held-out real livers: MEE with and without phantoms."""
    w, wo = ({g: v for g, v in zip(runs[k]["per_liver_mee"]["geometry_ids"],
                                   runs[k]["per_liver_mee"]["values"])}
             for k in ("with", "without"))
    livers = sorted(set(w) & set(wo))
    a, b = np.array([w[g] for g in livers]), np.array([wo[g] for g in livers])
    return {"livers": len(livers), "better": int(np.sum(a < b)),
            "median_ratio": float(np.median(a / b)), "mean_with": float(a.mean()),
            "mean_without": float(b.mean())}


def report(out: dict) -> str:
    w, wo, p = out["runs"]["with"], out["runs"]["without"], out["paired"]
    row = "| {} | {:.3f} | {:.3f} / {:.3f} | {:.3f} | {:.3f} | {:.2f} |"
    lines = [
        f"The shipped real scene's {out['real']} training livers and {out['phantoms']} "
        f"anatomical phantoms, {out['per_liver']} random 0.4 N loads each ({out['sims']} "
        "simulations, `python -m fem_sim generate` on the scene bench/augment.py writes). The "
        f"population basis (`{CONFIG}`), cross-validated by liver over the real livers ("
        + (f"each of {out['folds']} folds held out in turn" if out["evaluate"] in
           (0, out["folds"]) else f"the first {out['evaluate']} of {out['folds']} folds "
           "held out") + "), the phantoms never held out. The same folds with and without "
        "the phantoms' simulations in training; the shape model (PCA over every liver of the "
        "dataset, phantoms included) is the same in both. The naive model is each training "
        "set's mean displacement, so compare the MEE.", "",
        "| training set | pooled skill | skill mean / median liver | MEE mm | naive MEE mm "
        "| % EE < 3 mm |", "|---|---|---|---|---|---|"]
    for label, m in (("real livers and phantoms", w), ("real livers only", wo)):
        pl = m["per_liver_mee"]
        lines.append(row.format(label, m["skill"], pl["skill_mean"], pl["skill_median"],
                                m["network"]["mee"], m["naive"]["mee"],
                                m["network"]["pct_ee_lt_3mm"]))
    verdict = "help" if p["median_ratio"] < 0.98 else (
        "hurt" if p["median_ratio"] > 1.02 else "make no difference (within 2 %)")
    lines += ["", f"Paired on the {p['livers']} held-out real livers: the phantoms lower a "
              f"liver's MEE on {p['better']} of them; median ratio of MEE (with / without) "
              f"{p['median_ratio']:.3f}, mean liver MEE {p['mean_with']:.3f} mm with against "
              f"{p['mean_without']:.3f} mm without. On this population the phantoms "
              f"{verdict}."]
    return "\n".join(lines)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", default=str(ROOT / "runs" / "augment" / "data"),
                    help="the dataset (its wall time goes to DATA/../generation.json)")
    ap.add_argument("--phantoms", type=int, default=60)
    ap.add_argument("--per-liver", type=int, default=2, help="simulations per liver")
    ap.add_argument("--folds", type=int, default=5)
    ap.add_argument("--evaluate-folds", type=int, default=5)
    ap.add_argument("--np", type=int, default=2, help="MPI ranks for generation")
    ap.add_argument("--jobs", type=int, default=2, help="trainings at a time (one core each)")
    ap.add_argument("--generate-only", action="store_true")
    a = ap.parse_args()
    from data_spec import load_scene
    from data_spec.livers import training_files

    data = Path(a.data)
    scene_file = write_scene(RESULTS / "scene.toml", a.phantoms, a.per_liver)
    scene = load_scene(scene_file)
    reuse_prepared(data)
    gen = generate_chunks(scene_file, data, scene["scene"]["n_simulations"], ranks=a.np,
                          chunk=100)
    if a.generate_only:
        return 0
    runs = trained(data, a.folds, a.evaluate_folds, a.jobs)
    out = {"phantoms": a.phantoms, "per_liver": a.per_liver, "folds": a.folds,
           "evaluate": a.evaluate_folds, "sims": gen["sims"], "runs": runs,
           "real": len(training_files(scene["geometry"])), "paired": paired(runs),
           "generation_hours": gen["seconds"] / 3600, "commit": commit()}
    write_report(ROOT / "docs" / "augment.md", "Phantoms mixed into the real livers",
                 report(out), out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
