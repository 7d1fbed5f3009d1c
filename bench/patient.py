"""A new patient's model against K, the FE simulations on the patient's own mesh: docs/patient.md
(its prose: bench/templates/patient.md.j2).

    .venv-train/bin/python bench/patient.py [--model RUN] [--livers Amos-054 LiTS-100 LiTS-67]
        [--ks 0 5 10 20 40 80] [--design] [--order 1] [--no-green] [--no-tune]

Per validation liver: its FE truth with the model's boundary condition (resumable under
bench/results/patient/), every K's MEE on the same first HELD simulations of every model the
table names (:func:`surrogate.patient.curve.evaluate_patient`), ``make patient`` timed on the
first liver. ``--design``: training livers, a population model trained without them.
"""

from __future__ import annotations

import argparse
import json
import shutil
import subprocess
import sys
import time
from pathlib import Path

from fem_sim.batch.chunked import generate_chunks, linear_bases, liver_truth, meshed_liver
from liverviz.plots import error_against_peak
from liverviz.report import ROOT, SOFA, SOFA_FRAME, render, write_report
from surrogate.patient import SYNTHETIC, study
from surrogate.reports import REPORT_NAMES

SCENE = ROOT / "data_spec" / "scenes" / "scene4_livers.toml"
RESULTS = ROOT / "bench" / "results" / "patient"
MODEL = ROOT / "bench" / "results" / "scene4_real" / "run_population_basis"
DATA = ROOT / "runs" / "data" / "scene4_livers"   # scene 4's dataset (bench/scene4_real.py)
DESIGN_OVERRIDES = {"folds": 10, "evaluate_folds": 1}   # as bench/scene4_real.py trains it
DESIGN_LIVERS = ["Amos-005", "LiTS-12", "LiTS-16"]
KS, HELD = (0, 5, 10, 20, 40, 80), 10   # the K asked; the simulations held out of each liver
TRUTH_SIMS = HELD + max(KS)   # the truth scene's simulations, solved up to HELD + the K asked
SOURCES_K = 40  # the K at which the error's sources are measured (the largest K if less)
GOAL_MM = 0.5   # the goal: this MEE within GOAL_MINUTES on two cores
GOAL_MINUTES = 5.0
FRAMES = {SOFA.stem: SOFA_FRAME}   # a liver file not in the scene's frame: predict-liver's --frame
BIG_PEAK_MM = 30.0   # a held-out simulation's FE peak displacement counted as a large one


def truth(pred, liver: Path, a, frame: str | None = None) -> Path:
    """The liver's FE truth with the model's boundary condition (the file in ``frame``): a
    scene of TRUTH_SIMS simulations, the first HELD + the largest K solved."""
    from surrogate.evaluate import truth_scene

    d, n = a.results / liver.stem, HELD + max(a.ks)
    data = liver_truth(d, truth_scene(pred, SCENE, liver, TRUTH_SIMS, frame,
                                   mesh=meshed_liver(liver, SCENE)), n,
                       generate=False)   # the scene; another one's truth emptied
    if not (a.no_new_fe and (data / "sims").is_dir()):
        generate_chunks(d / "scene.toml", data, n, ranks=a.np, chunk=n)
    linear(d / "scene.toml", data, d / "linear.json", a.order, a.green)
    return data


def linear(scene: Path, data: Path, record: Path, order: int = 1, green: bool = False) -> dict:
    """``fem_sim linear`` on the truth's scene as make patient runs it, once per setting: its
    wall seconds in ``record``."""
    from data_spec.linear_fields import linear_fields_path, read_linear_fields

    done = json.loads(record.read_text()) if record.exists() else {}
    if (done.get("order"), done.get("green")) != (order, green):   # timed again
        linear_fields_path(data).unlink(missing_ok=True)
    seconds = linear_bases(data, scene=scene, order=order, green=green, synthetic=SYNTHETIC)
    if seconds is not None:
        done = {"seconds": seconds, "order": order, "green": green,
                "solves_seconds": read_linear_fields(linear_fields_path(data)).seconds}
        record.write_text(json.dumps(done))
    return done


def curve(liver: Path, a) -> tuple[dict, dict]:
    """Every K's errors on the liver's held-out simulations (``evaluate_patient``'s), and
    where the corrected model's error is at SOURCES_K or the largest K below."""
    from surrogate.data import load_dataset
    from surrogate.evaluate import place
    from surrogate.patient.curve import evaluate_patient
    from surrogate.predictor import load_predictor

    model = Path(a.model) / "model"
    pred = load_predictor(model)
    t = time.perf_counter()
    frame = FRAMES.get(liver.stem)
    placement, _ = place(pred, liver, frame, mesh=meshed_liver(liver, SCENE))
    placing = time.perf_counter() - t
    data = truth(pred, liver, a, frame)
    found = evaluate_patient(model, data, liver, a.results / liver.stem, ks=a.ks, held=HELD,
                             rest=Path(a.rest) / "model" if a.rest else None, tune=a.tune,
                             placement=placement,
                             log_fn=lambda m: print(f"[{liver.stem}] {m}", flush=True))
    ks, ds = found["ks"], load_dataset(data)
    return ({"liver": liver.stem, "nodes": found["nodes"], "points": found["points"],
             "held_out_sims": found["held_out_sims"],
             "fe_seconds": study.fe_seconds(data, a.np, ks, HELD), "place_seconds": placing,
             "linear_seconds": json.loads((data.parent / "linear.json").read_text())["seconds"]},
            {"liver": liver.stem, "k": min(a.sources_k, ks[-1]),
             **sources(pred, placement, ds, min(a.sources_k, ks[-1]))})


def sources(pred, placement, ds, k: int) -> dict:
    """Where the corrected model's error is on the held-out simulations of ``ds`` at K = k
    (:func:`surrogate.patient_errors.error_sources`)."""
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


def end_to_end(liver: Path, a, k: int = 40) -> dict:
    """Wall seconds of ``make patient`` (K simulations, two ranks) in all and by step, from
    when each step's last output was written."""
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
            "solves": study.fe_seconds(out / "data", a.np, [k], first=0)[str(k)],
            "adapt": end - solved, "k": k, "liver": liver.stem}


def report(curves: list[dict], e2e: dict | None, a, found: list[dict], md: Path) -> str:
    """docs/patient.md's body after the header (bench/templates/patient.md.j2)."""
    # the FE start-up (meshing, MPI, the forms, the ranks' uneven end) as make patient spent
    # it: its FE step's wall seconds less its simulations' own solves over the ranks
    start = max(0.0, e2e["fe"] - e2e["solves"]) if e2e and "solves" in e2e else None
    size = study.load_size(curves, BIG_PEAK_MM, GOAL_MM)
    if size:   # the curves that kept their held-out simulations, one colour a liver
        error_against_peak([c for c in curves if c.get("held_out_sims", {}).get("0")],
                           size["kmax"], GOAL_MM, BIG_PEAK_MM,
                           md.with_suffix(".png").with_stem(md.stem + "_loads"))
    return render(Path(__file__).parent / "templates" / "patient.md.j2", **REPORT_NAMES,
                  **study.curve_figures(curves, a.ks, start, GOAL_MM, GOAL_MINUTES),
                  curves=curves, e2e=e2e, a=a, found=found, start=start, size=size, md_stem=md.stem,
                  frames=FRAMES,
                  model=Path(a.model).resolve().relative_to(ROOT),
                  rest=a.rest and Path(a.rest).resolve().relative_to(ROOT), held=HELD,
                  synthetic=SYNTHETIC, goal_mm=GOAL_MM, goal_minutes=GOAL_MINUTES,
                  big_peak=BIG_PEAK_MM, mee=study.patient_mee, minutes=study.patient_minutes,
                  ratios=[s["corrected_mm"] / s["projection_floor_mm"] for s in found],
                  gaps=[abs(s["relative_first_step"] - s["relative_last_step"]) for s in found]
                  ).rstrip("\n") + "\n"


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
