"""Scene 4 on real livers: Table 4's real-liver rows, and the livers no training run saw.

    .venv-train/bin/python bench/scene4_real.py [--data runs/data/scene4_livers] [--np 2]

The scene's simulations generated where missing; the designs (``population_basis``, the one a
user gets, trained on every liver too; ``population_linear`` and ``population_green`` over
each liver's small-strain base, each beside its base alone; ``paper_scene4`` with table4's
node-wise budget) cross-validated by liver on the scene's first fold (``--every-fold``: all 10,
for ``--designs``); the 15 validation livers and the SOFA liver placed as predict-liver places
them, against an FE truth on their own mesh (a liver whose file is missing keeps its previous
row, marked), ``make liver`` timed on each; latency at 15.4k nodes. Resumable (results under
bench/results/scene4_real/). Writes docs/scene4_real.{md,png,json} (the rows bench/table4.py
puts into docs/table4.md); the report's template says what each row means.
"""

from __future__ import annotations

import argparse
import json
import shutil
import sys
import time
from pathlib import Path

from fem_sim.batch.chunked import generate_chunks, linear_bases, liver_truth, meshed_liver
from liverviz.report import ROOT, SOFA, SOFA_FRAME, commit, render, write_report
from surrogate.reports import REPORT_NAMES, DesignRecord
from surrogate.small_strain import base_of

SCENE = ROOT / "data_spec" / "scenes" / "scene4_livers.toml"
RESULTS = ROOT / "bench" / "results" / "scene4_real"
LATENCY_NODES = 15400
# the designs on the same folds: (config, overrides); node-wise with table4's budget
DESIGNS = (("population_basis", {"folds": 10, "evaluate_folds": 1}),
           ("population_linear", {"folds": 10, "evaluate_folds": 1}),
           ("population_green", {"folds": 10, "evaluate_folds": 1}),
           ("paper_scene4", {"folds": 10, "evaluate_folds": 1, "epochs": 30,
                             "node_fraction": 0.1, "final_fit": False}))
PAPER = {"mean": 0.293, "median": 0.211, "lt3": 99.01}
# --every-fold: the population designs with every one of the 10 folds held out in turn
EVERY_FOLD = (("population_basis", {"folds": 10, "evaluate_folds": 0, "final_fit": False}),
              ("population_linear", {"folds": 10, "evaluate_folds": 0, "final_fit": False}),
              ("population_green", {"folds": 10, "evaluate_folds": 0, "final_fit": False}))


def trained(data: Path, a) -> list[dict]:
    """The designs' cross-validation (and the exported population basis with its latency)."""
    from surrogate.config import get_config
    from surrogate.designs import DESIGNS as REGISTRY
    from surrogate.evaluate import heldout_floor
    from surrogate.latency import timed

    rows = []
    for config, overrides in (d for d in DESIGNS if d[0] in a.designs):
        run, cfg = RESULTS / f"run_{config}", get_config(config)
        row = _trained_row(data, a, config, overrides, run)
        if base_of(cfg["linear_base"]).whole:   # over a base the field needs the liver's own
            if (run / "model" / "model.json").exists():   # a whole field per call
                row.update(timed(run / "model", a.calls, LATENCY_NODES))
            if REGISTRY[cfg["design"]].on_template:
                row["floor"] = heldout_floor(data, run)
        rows.append(row)
    return rows


def _trained_row(data: Path, a, config: str, overrides: dict, run: Path) -> dict:
    """One design trained (or reused) in ``run``: its metrics, and for a design over each
    liver's small-strain base (made first, resumable) the base alone on the same held-out
    livers."""
    from surrogate.config import get_config
    from surrogate.evaluate import heldout_base
    from surrogate.train import train_or_reuse

    kind = base_of(get_config(config)["linear_base"])
    if not kind.whole:
        linear_bases(data, ranks=a.np, order=kind.order)
    t = time.perf_counter()
    m = train_or_reuse(data, run, config, overrides)
    print(f"[{run.name}] skill {m['skill']:.3f} ({time.perf_counter() - t:.0f} s)", flush=True)
    row = {"config": config, "overrides": overrides, "metrics": m,
           "run": str(run.relative_to(ROOT))}
    if not kind.whole:
        row["base_alone"] = heldout_base(data, run, kind.order)
    return row


def every_fold(data: Path, a) -> list[dict]:
    """The population designs cross-validated over all 10 folds (each liver held out once;
    no final fit), the small-strain base alone on the same folds."""
    return [_trained_row(data, a, config, overrides, RESULTS / f"run_{config}_every_fold")
            for config, overrides in EVERY_FOLD if config in a.designs]


def _kept(rows: list[dict], old: dict) -> list[dict]:
    """Rows of the previous report, each marked with the commit that measured it (a design
    not trained again, a liver whose file is not here); a row already marked keeps its
    mark."""
    commit_was = old.get("written", {}).get("commit", "unknown")
    return [{"kept_from": commit_was, **d} for d in rows]


def _merged(old: list[dict], new: list[dict]) -> list[dict]:
    """Rows by design: the new ones replace the old ones of their design, in DESIGNS order."""
    by = {d["config"]: d for d in old} | {d["config"]: d for d in new}
    order = [c for c, _ in DESIGNS]
    return sorted(by.values(), key=lambda d: order.index(d["config"]))


def unseen_livers(scene) -> list[tuple[Path, str | None]]:
    """(file, frame) of every liver no training run saw: the validation livers in the scene's
    frame (the model's default), the SOFA liver by the best rigid fit."""
    from data_spec.livers import validation_files

    out = [(f, None) for f in validation_files(scene["geometry"])]
    return out + ([(SOFA, SOFA_FRAME)] if SOFA.exists() else [])


def unseen(data: Path, a) -> list[dict]:
    """Each unseen liver: the exported population basis placed on it against its FE truth,
    and the seconds from its file to a ready predictor; with each population model of the
    small-strain base's rest (when trained), that model on the base of the liver's own mesh
    and the base alone (over the linear response: also ``make liver`` timed from the file)."""
    from data_spec import load_scene
    from surrogate.evaluate import evaluate_liver, place, truth_scene
    from surrogate.latency import timed_placed
    from surrogate.predict_liver import PlacedModel, read_liver_surface
    from surrogate.predictor import load_predictor

    pred = load_predictor(RESULTS / "run_population_basis" / "model")
    models = {c: RESULTS / f"run_{c}" / "model" for c, _ in DESIGNS[1:]}
    rests = {c: load_predictor(m) for c, m in models.items() if (m / "model.json").exists()}
    rests = {c: p for c, p in rests.items() if not p.base.whole}
    out = []
    for liver, frame in unseen_livers(load_scene(SCENE)):
        t = time.perf_counter()  # file to predictor: read, register, place, first call
        points, tris = read_liver_surface(liver)
        placed = PlacedModel(pred, points, tris, frame=frame)
        placed([[0.0, 0.0, -0.4]], placed.load_nodes(points[:1]))
        seconds = time.perf_counter() - t
        placement, found = place(pred, liver, frame, mesh=meshed_liver(liver, SCENE))
        fe = liver_truth(RESULTS / "unseen" / liver.stem,
                         truth_scene(pred, SCENE, liver, a.unseen_sims, frame,
                                     mesh=meshed_liver(liver, SCENE)), a.unseen_sims,
                         ranks=a.np)
        m = evaluate_liver(pred, fe, placement, found, population_data=data)
        row = {"liver": liver.stem, "frame": frame or "scene", "file_to_predictor_s":
               seconds, "truth": str((RESULTS / "unseen" / liver.stem).relative_to(ROOT)),
               "ms_placed": timed_placed(pred, placement, LATENCY_NODES, a.calls), **m,
               "over": {c: _over_base(p, fe, data, liver, frame, a)
                        for c, p in sorted(rests.items(), key=lambda kv: kv[1].base.order)}}
        out.append(row)
        print(f"[unseen {liver.stem}] MEE {m['network']['mee']:.3f} mm, skill "
              f"{m['skill']:.3f}, {seconds:.1f} s file to predictor", flush=True)
    return out


def kept_rows(old: dict, now: dict) -> list[dict]:
    """The previous report's rows of unseen livers whose file is not on this machine (the
    SOFA liver beside a clone without it), kept when the population basis is the model they
    measured (its cross-validation figures unchanged), each marked with the commit that
    measured it; none otherwise."""
    here = {u["liver"] for u in now["unseen"]}
    design = {d["config"]: d["metrics"]["skill"] for d in old.get("designs", [])}
    same = abs(design.get("population_basis", -1.0)
               - now["designs"][0]["metrics"]["skill"]) < 1e-9
    rows = _kept([u for u in old.get("unseen", []) if u["liver"] not in here], old)
    if rows and not same:
        print(f"[unseen] {', '.join(u['liver'] for u in rows)}: not on this machine and the "
              "population basis changed: left out", flush=True)
        return []
    return rows


def _over_base(pred, fe: Path, data: Path, liver: Path, frame, a) -> dict:
    """A model of a base's rest on the truth's simulations, over the base of the truth's own
    mesh, and the base alone; over the linear response also ``make liver`` from the liver
    file (its wall seconds, a fresh directory) and the calls' latency over the Green's
    function it writes."""
    from surrogate.evaluate import evaluate_unseen, place
    from surrogate.latency import timed_over_green

    linear_bases(fe, scene=fe.parent / "scene.toml", order=pred.base.order, ranks=a.np)
    m = evaluate_unseen(pred, fe, liver, frame, population_data=data)
    row = {"order": pred.base.order, "base_alone": m["base_alone"],
           "over_base": {k: m[k] for k in ("network", "skill", "naive", "sims")}}
    if pred.base.from_green:
        row["make_liver_s"] = make_liver(liver, frame, fe, a)
        placed = place(pred, liver, frame, mesh=meshed_liver(liver, SCENE))[0]
        row.update(timed_over_green(pred, RESULTS / "make_liver" / liver.stem / "data", placed,
                                    LATENCY_NODES, a.calls))
    return row


def make_liver(liver: Path, frame, fe: Path, a) -> float:
    """Wall seconds of ``make liver`` on the liver file (a fresh directory; the force on the
    truth's first load point), the population_green model of this study as MODEL."""
    from data_spec import read_geometry
    from data_spec.shards import geometry_path, list_shards, read_shard
    from surrogate.make_liver import STEPS, timed_steps

    d = RESULTS / "make_liver" / liver.stem
    shutil.rmtree(d, ignore_errors=True)
    sh = read_shard(list_shards(fe)[0])
    at = read_geometry(geometry_path(fe, sh.geometry_id)).points[sh.load_nodes[0]]
    spec = " ".join(f"{v:.6g}" for v in [*at, *sh.forces[0]])
    cmd = ["make", "--no-print-directory", "liver", f"LIVER={liver}",
           f"MODEL={RESULTS / 'run_population_green'}", f"PSCENE={SCENE}", f"AT={spec}",
           f"LIVER_DIR={d}", *([f"FRAME={frame}"] if frame else [])]
    timed = timed_steps(cmd, STEPS, ROOT)
    if not timed["ok"]:
        raise RuntimeError(f"make liver on {liver.name}: {timed['why']}")
    return timed["seconds"]


def worst_picture(rows: list[dict]) -> dict:
    """The unseen liver with the highest skill (the worst), its worst simulation drawn."""
    from surrogate.evaluate import place, worst_case_picture
    from surrogate.predictor import load_predictor

    u = max(rows, key=lambda r: r["skill"])
    pred = load_predictor(RESULTS / "run_population_basis" / "model")
    liver = next(f for f, _ in unseen_livers(_scene()) if f.stem == u["liver"])
    frame = None if u["frame"] == "scene" else u["frame"]
    placement, _ = place(pred, liver, frame, mesh=meshed_liver(liver, SCENE))
    return {"liver": u["liver"], **worst_case_picture(
        pred, ROOT / u["truth"] / "data", placement, ROOT / "docs" / "scene4_real.png",
        title=f"unseen liver {u['liver']} (skill {u['skill']:.2f}): its worst simulation")}


def _scene():
    from data_spec import load_scene

    return load_scene(SCENE)


def _rest_designs(out: dict) -> list[dict]:
    """The designs over each liver's small-strain base, by the base's order."""
    return sorted((d for d in out["designs"] if DesignRecord.from_json(d).base),
                  key=lambda d: DesignRecord.from_json(d).base.order)


def _cv_skill(out: dict, config: str) -> tuple[float, str]:
    """The design's cross-validated skill of the mean held-out liver: over every fold when
    measured, else over the first fold."""
    rows = [d for d in out.get("every_fold", []) if d["config"] == config]
    d = rows[0] if rows else next(d for d in out["designs"] if d["config"] == config)
    where = "every fold" if rows else "the first fold"
    return d["metrics"]["per_liver_mee"]["skill_mean"], f"mean held-out liver, {where}"


def report(out: dict) -> str:
    """docs/scene4_real.md's body after the header (bench/templates/scene4_real.md.j2)."""
    rests = _rest_designs(out)
    configs = [d["config"] for d in rests
               if any(d["config"] in u.get("over", {}) for u in out["unseen"])]
    return render(Path(__file__).parent / "templates" / "scene4_real.md.j2", **REPORT_NAMES,
                  out=out, rests=rests, configs=configs, cv_skill=_cv_skill, paper=PAPER,
                  scene_name=SCENE.name, latency_nodes=LATENCY_NODES).rstrip("\n") + "\n"


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", default=str(ROOT / "runs" / "data" / "scene4_livers"))
    ap.add_argument("--np", type=int, default=2, help="MPI ranks for generation")
    ap.add_argument("--calls", type=int, default=200, help="timed calls per latency")
    ap.add_argument("--sims", type=int, default=None,
                    help="generate until the dataset holds this many simulations (default: "
                    "the scene's; fewer trains on those there, the missing ones named)")
    ap.add_argument("--designs", nargs="+", default=[d[0] for d in DESIGNS],
                    choices=[d[0] for d in DESIGNS], help="the designs trained (the population "
                    "basis first: the unseen livers need its exported model)")
    ap.add_argument("--unseen-sims", type=int, default=12,
                    help="FE simulations of each unseen liver's truth")
    ap.add_argument("--report-only", action="store_true",
                    help="rewrite docs/scene4_real.md from docs/scene4_real.json")
    ap.add_argument("--every-fold", action="store_true",
                    help="cross-validate the population designs over all 10 folds and add them "
                    "to docs/scene4_real.json's report (nothing else run)")
    a = ap.parse_args()
    from surrogate.evaluate import shards_by_liver

    data, scene = Path(a.data), _scene()
    n = min(scene["scene"]["n_simulations"], a.sims or scene["scene"]["n_simulations"])
    gen = None if a.report_only else generate_chunks(SCENE, data, n, ranks=a.np, chunk=n)
    md = ROOT / "docs" / "scene4_real.md"
    if a.report_only or a.every_fold:
        out = json.loads(md.with_suffix(".json").read_text())
        if a.every_fold:
            out["every_fold"] = _merged(out.get("every_fold", []), every_fold(data, a))
    else:
        old = json.loads(md.with_suffix(".json").read_text()) if \
            md.with_suffix(".json").exists() else {}
        out = {"sims": gen["sims"], "scene_sims": scene["scene"]["n_simulations"],
               "designs": _merged(_kept(old.get("designs", []), old), trained(data, a))}
        out["unseen"] = unseen(data, a)
        out["unseen"] += kept_rows(old, out)
        if "every_fold" in old:
            out["every_fold"] = _kept(old["every_fold"], old)
        out["worst"] = worst_picture(out["unseen"])
        out["written"] = {"commit": commit(), "date": time.strftime("%Y-%m-%d %H:%M UTC",
                                                                    time.gmtime())}
    if not a.report_only:  # the livers with simulations, and those prepared
        out["livers"] = len(shards_by_liver(data))
        out["prepared"] = len(json.loads((data / "geometry" / "livers.json").read_text()))
    write_report(md, "Scene 4 on real livers", report(out), out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
