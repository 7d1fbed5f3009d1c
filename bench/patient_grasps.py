"""A patient's model of grasps against FE on the validation livers: docs/patient_grasps.md.

    .venv-train/bin/python bench/patient_grasps.py [--livers ...] [--report-only]

Per liver, ``make patient LOAD=grasp SITE=...`` at its ``grasp_site`` (resumable, under
bench/results/patient_grasps/), each K's corrections measured on the same last HELD grasps.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import time
from pathlib import Path

import numpy as np

from liverviz.report import ROOT, render, write_report

RESULTS = ROOT / "bench" / "results" / "patient_grasps"
SCENE = ROOT / "data_spec" / "scenes" / "scene4_grasp.toml"
KS, HELD, CLEAR, LARGE = (4, 8, 16), 8, 50.0, 35.0   # -, -, mm from the fixed region, mm


def measured(pred, liver: Path, ks) -> dict:
    """make patient LOAD=grasp (once), each K on the held out, the largest K's frame timed."""
    from surrogate.data import load_dataset
    from surrogate.evaluate import place
    from surrogate.model_files import model_digest
    from surrogate.over_green import OverGreen
    from surrogate.patient import grasps as pg
    from surrogate.reports import held_force_rows

    d, where = RESULTS / liver.stem, pg.grasp_site(pred, liver, CLEAR)
    if not (d / "wall.json").exists():
        t = time.perf_counter()
        subprocess.run(["make", "--no-print-directory", "patient", "LOAD=grasp",
                        f"LIVER={liver}", f"K={max(ks)}", f"HELD={HELD}", f"PATIENT={d}",
                        "SITE=" + " ".join(map(str, where))], cwd=ROOT, check=True,
                       stdout=subprocess.DEVNULL)
        (d / "wall.json").write_text(json.dumps({"seconds": time.perf_counter() - t}))
    ds, placed = load_dataset(d / "data"), place(pred, liver, None, d / "placement.npz")[0]
    over = OverGreen(pred, d / "data", placed)
    c = pg.grasp_cases(over, ds, sims := np.unique(ds.sample_sim))
    fit = pg.fit_patient_grasp(c.take(np.isin(c.sims, sims[:-HELD][:max(ks)])))[0]
    fit.model = model_digest(pred.directory)   # what OverGreen checks it corrects
    at, patient = (c.centres[0], [0.0, 0.0, 20.0]), OverGreen(pred, d / "data", placed,
                                                              patient=fit)
    return {"liver": liver.stem, "site": where, "nodes": int(ds.points[0].shape[0]),
            "rows": pg.against_k(c, ks, HELD, LARGE), "timed": {
                k: pg.timed(o, *at) for k, o in (("population", over), ("patient", patient))},
            "wall_seconds": json.loads((d / "wall.json").read_text())["seconds"],
            "held": held_force_rows(over, c)}


def main() -> int:
    from data_spec import livers, load_scene
    from surrogate.predictor import load_predictor
    from surrogate.reports import held_force_table

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--livers", nargs="+", help="validation livers (default: all 15)")
    ap.add_argument("--report-only", action="store_true", help="from docs/patient_grasps.json")
    a = ap.parse_args()
    if (md := ROOT / "docs" / "patient_grasps.md") and a.report_only:
        found = json.loads(md.with_suffix(".json").read_text())["livers"]
    else:
        files = {f.stem: f for f in livers.validation_files(load_scene(SCENE)["geometry"])}
        pred = load_predictor(ROOT / "models" / "scene4_grasp" / "model", load="grasp")
        found = [measured(pred, files[n], KS) for n in a.livers or sorted(files)]
    body = render(Path(__file__).parent / "templates" / "patient_grasps.md.j2", livers=found,
                  ks=[r["k"] for r in found[0]["rows"]], held=HELD, clear=CLEAR, median=np.median,
                  held_rows=held_force_table(found), inf=float("inf"))
    write_report(md, "A patient's model of grasps", body, {"livers": found})
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
