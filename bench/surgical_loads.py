"""Surgical loads on the livers no training saw: a 10 mm grasp pulled 5 to 40 mm and 0.4 to
4 N pressed on a 10 mm patch, the Ogden FE against the small-strain base over each liver's own
Green's function (data_spec.green_grasp: the linear part of make liver's answer) and a naive model
(each simulation's own mean displacement).

    .venv-solver/bin/python bench/surgical_loads.py [--livers 15] [--rate N] [--report-only]

scene4_livers' validation livers, meshed and fixed as its population's are, its material and
element; tools 30 mm or more from the fixed region, pulled away from it (rule ``away``); a
pressed force spread by surrogate.grasp.patch_weights, the FE given the same nodal forces.
Resumable (bench/results/surgical_loads/). Writes docs/surgical_loads{.md,.json,.png,_worst.png}.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import sys
import time
import tomllib
import zlib
from pathlib import Path

import numpy as np

from fem_sim.batch.chunked import generation_rate
from liverviz.ledger import Ledger
from liverviz.plots import surgical_curves
from liverviz.report import ROOT, render, write_report
from surrogate.reports import (
    REPORT_NAMES,
    surgical_curve,
    surgical_per_liver,
    surgical_worst_picture,
)

SCENE = ROOT / "data_spec" / "scenes" / "scene4_livers.toml"
GRASP_SCENE = ROOT / "data_spec" / "scenes" / "scene4_grasp.toml"
RESULTS = ROOT / "bench" / "results" / "surgical_loads"
READY = RESULTS / "ready.json"   # make liver timed from each liver file (--ready)
PULLS = (5.0, 10.0, 20.0, 30.0, 40.0)      # mm
FORCES = (0.4, 1.0, 2.0, 4.0)              # N
RADIUS = 10.0                              # mm, the tool's patch
PLACES = 3                                 # grasps, and pressed patches, per liver
GOAL = {"median": 0.5, "worst": 1.0, "lt3": 99.0, "force": 5.0}


def errors(truth: np.ndarray, model: np.ndarray) -> dict:
    """MEE, 95th percentile (mm), % of nodes under 3 mm of a field (or of one displacement,
    the naive model's), and the truth's mean |u|."""
    from surrogate.metrics import displacement_metrics, mee

    m = displacement_metrics(np.broadcast_to(model, truth.shape), truth)
    return {"mee": m["mee"], "p95": m["ee_p95"], "lt3": m["pct_ee_lt_3mm"], "mean_u": mee(truth)}


def solve_liver(name: str, n_grasps: int, n_forces: int) -> dict:
    """One validation liver's record (and the .npz of its worst 40 mm grasp)."""
    from data_spec import load_scene
    from data_spec.eligible_loads import grasp_patch
    from fem_sim import Constraint
    from fem_sim.batch.cases import load_directions
    from fem_sim.batch.grasp_truth import grasp_sites, prepared_problem
    from surrogate.grasp import patch_weights

    scene, t0 = load_scene(SCENE), time.perf_counter()
    liver = ROOT / scene["geometry"]["livers"] / f"{name}.obj"
    g, fixed, prob, mat = prepared_problem(scene, liver)
    rng = np.random.default_rng(zlib.crc32(name.encode()))
    centres = grasp_sites(g, fixed, n_grasps + n_forces, rng)
    patches = [grasp_patch(g.points, g.surface_nodes, c, RADIUS) for c in centres]
    held, t1 = np.unique(np.concatenate(patches)), time.perf_counter()
    green = prob.unit_responses(mat, [Constraint(fixed)], held)
    away = load_directions(rng, "away", g.points[centres[:n_grasps]], g.points[fixed])
    out = {"liver": name, "nodes": int(g.n_nodes), "prepare_s": t1 - t0, "grasps": [],
           "green_rows_s": time.perf_counter() - t1, "forces": []}
    worst, kept = (-1.0,), {}   # every case's fields, for a model's rows (--model)
    for k in range(n_grasps):
        row, fields = _grasp_case(prob, mat, fixed, patches[k], 40.0 * away[k], green, held)
        out["grasps"].append(row)
        kept.update({f"truth_{k}": fields[0].astype(np.float32), f"patch_{k}": patches[k],
                     f"base_{k}": fields[1].astype(np.float32)})
        if row["status"] == "ok" and row["steps"][-1]["base"]["mee"] > worst[0]:
            worst = (row["steps"][-1]["base"]["mee"], (fields[0][-1], fields[1][-1]),
                     patches[k], 40.0 * away[k])
    forces = []
    for k in range(n_grasps, n_grasps + n_forces):
        direction = load_directions(rng, "uniform", g.points[centres[k:k + 1]], None)[0]
        w = patch_weights(g.points, g.surface_triangles, patches[k], centres[k], RADIUS)
        row, fields = _force_case(prob, mat, fixed, patches[k], w, FORCES[-1] * direction,
                                  green, held)
        out["forces"].append(row)
        forces.append(FORCES[-1] * direction)
        kept.update({f"ftruth_{k - n_grasps}": fields[0].astype(np.float32),
                     f"funit_{k - n_grasps}": fields[1].astype(np.float32)})
    (RESULTS / "fields").mkdir(parents=True, exist_ok=True)   # for a model's rows (--model)
    np.savez_compressed(RESULTS / "fields" / f"{name}.npz", points=g.points, **kept,
                        centres=centres[:n_grasps], pulls=40.0 * away,
                        fcentres=centres[n_grasps:], forces=np.array(forces))
    if len(worst) > 1:
        RESULTS.mkdir(parents=True, exist_ok=True)
        np.savez_compressed(RESULTS / f"{name}.npz", points=g.points,
                            triangles=g.surface_triangles, fixed=fixed, patch=worst[2],
                            pull=worst[3], truth=worst[1][0], base=worst[1][1])
    out["seconds"] = time.perf_counter() - t0
    return out


def _row(sol, t: float) -> dict:
    """A simulation's record: its status, reason, seconds since ``t`` and solver counts."""
    return {"status": sol.status, "reason": sol.failure_reason, "steps": [], "factorizations":
            sol.factorizations, "seconds": time.perf_counter() - t, "cutbacks": sum(sol.cutbacks)}


def _grasp_case(prob, mat, fixed, patch, d, green, held):
    """(record, (FE fields, base fields) at each stored pull) of one tool pulled by ``d`` mm."""
    from fem_sim.batch.grasp_truth import grasp_case
    from surrogate.grasp import force_error_pct

    t = time.perf_counter()
    sol, base, force = grasp_case(prob, mat, fixed, patch, d, green, held,
                                  np.array(PULLS) / PULLS[-1])
    row = _row(sol, t)
    for s in range(sol.n_done):
        truth, fe_force = sol.displacement[s], sol.reaction[s, 0]
        row["steps"].append({
            "pull": PULLS[s], "base": errors(truth, base[s]), "naive": errors(truth, truth.mean(0)),
            "fe_force": fe_force.tolist(), "base_force": force[s].tolist(),
            "force_error": float(force_error_pct(force[s], fe_force))})
    return row, (sol.displacement[:sol.n_done], base)


def _force_case(prob, mat, fixed, patch, weights, force, green, held):
    """(record, (FE fields at FORCES, the base's at the last)) of ``force`` (N) spread over
    ``patch`` by ``weights``."""
    from fem_sim import Constraint, NodalLoad
    from surrogate.small_strain import green_product

    fractions = np.array(FORCES) / FORCES[-1]
    nodal = weights[:, None] * force[None]
    t = time.perf_counter()
    sol = prob.solve(mat, [Constraint(fixed)], [NodalLoad(patch, nodal)], fractions)
    row = _row(sol, t)
    unit = green_product(green, np.searchsorted(held, patch)[None], nodal[None])[0]
    for s in range(sol.n_done):
        truth = sol.displacement[s]
        row["steps"].append({"force": FORCES[s], "base": errors(truth, fractions[s] * unit),
                             "naive": errors(truth, truth.mean(0))})
    return row, (sol.displacement[:sol.n_done], unit)


PLACED = b"the population's registration on the prepared mesh; the rest held at its range's edge"


def ready(name: str) -> dict:
    """``make liver`` (no MODEL) from the liver file, timed in all and per step: GRASP= (its
    vertex farthest along its longest axis pulled 20 mm out), AT= (0.4 N pushing there); the
    manipulator's base on the first: opening, new patches while it solves the surface in the
    background and after it, later calls."""
    import shutil

    from data_spec.linear_fields import read_linear_fields as linear
    from fem_sim.geometry.surfaces import read_surface
    from surrogate.latency import timed_manipulator
    from surrogate.make_liver import STEPS, timed_steps

    liver = SCENE.parent / tomllib.loads(SCENE.read_text())["geometry"]["livers"] / f"{name}.obj"
    c = (x := read_surface(liver)[0]).mean(axis=0)
    tip = x[np.argmax(np.abs((x - c) @ np.linalg.svd(x - c, full_matrices=False)[2][0]))]

    def make_liver(d: Path, load: str, v: np.ndarray) -> dict:
        shutil.rmtree(d, ignore_errors=True)
        load = f"{load}={' '.join(f'{w:.4f}' for w in v)}"
        return timed_steps(["make", "--no-print-directory", "liver", f"LIVER={liver}",
                            f"LIVER_DIR={d}", load], STEPS, ROOT)

    d, out = RESULTS / "ready" / name, (tip - c) / np.linalg.norm(tip - c)
    r = {"liver": name, **make_liver(d, "GRASP", np.r_[tip, 20.0 * out]),
         "force": make_liver(RESULTS / "ready_force" / name, "AT", np.r_[tip, -0.4 * out])}
    if not r["ok"]:
        return r
    return {**r, "green_nodes": linear(d / "data/linear.h5").green_nodes.size,
            "view": timed_manipulator(d / "data", str(ROOT / ".venv-solver/bin/python"))}


def _cases(z, r: dict, kind: str) -> list[dict]:
    """A liver's FE cases of ``kind`` (its fields file ``z``, its record ``r``) as
    surrogate.over_green's grasps_on_mesh / forces_on_mesh take them."""
    if kind == "forces":
        return [{"centre": z["fcentres"][k], "force": z["forces"][k], "unit": z[f"funit_{k}"],
                 "fractions": np.array(FORCES) / FORCES[-1], "truth": z[f"ftruth_{k}"]}
                for k in range(len(r["forces"]))]
    return [{"centre": z["centres"][k], "pull": z["pulls"][k], "patch": z[f"patch_{k}"],
             "fractions": np.array(PULLS) / PULLS[-1], "base": z[f"base_{k}"],
             "truth": z[f"truth_{k}"], "base_force": [st["base_force"] for st in c["steps"]],
             "fe_force": [st["fe_force"] for st in c["steps"]]} for k, c in enumerate(r["grasps"])]


def model_rows(run: Path, ledger, names, kind: str = "grasps") -> None:
    """Each solved liver's grasps answered by the model of grasps ``run`` (the trainer's
    environment), or its pressed forces (``kind`` "forces") by a model of forces, registered
    on the liver's mesh as the population's livers were, over the same base (its network's
    rest added, a grasp's force stiffened): MEE (and force error) added to every step of the
    liver's record, once per run and placement rule."""
    from surrogate import over_green
    from surrogate.predictor import load_predictor

    pred = load_predictor(ROOT / run / "model", load="grasp" if kind == "grasps" else "nodal")
    made = hashlib.sha256(b"".join((ROOT / run / "model" / f).read_bytes() for f in (
        "model.json", "params.npz")) + PLACED).hexdigest()[:16]   # which export, placed how
    mark = "model" if kind == "grasps" else "force_model"
    for name, r in ledger.records().items():
        path = RESULTS / "fields" / f"{name}.npz"
        if name not in names or (r.get(f"{mark}_run"), r.get(f"{mark}_trained_on")) == (
                str(run), made) or not path.exists():
            continue
        z = np.load(path)
        if kind == "forces" and "fcentres" not in z.files:   # solved before forces were kept
            continue
        # the liver as its FE solved it: meshed, turned and registered as the population's
        # livers were (file_population.prepare), its nodes in the population's frame
        mesh = np.load(RESULTS / f"{name}.npz")
        rows = getattr(over_green, f"{kind}_on_mesh")(
            pred, z["points"], mesh["triangles"], _cases(z, r, kind),
            *([mesh["fixed"]] if kind == "grasps" else []))
        last = {}   # each case's field at its last step (a grasp's: the picture)
        for k, case in enumerate(r[kind]):
            for step, row in zip(case["steps"], rows[k]):
                step["model"] = {"mee": row["mee"], "p95": row["p95"], "lt3": row["lt3"],
                                 "mean_u": step["base"]["mean_u"]}
                step.update({"model_force_error": row["force_error"]} if "force" in row else {})
            last.update({f"model_{k}": rows[k][-1]["field"].astype(np.float32)} if rows[k] else {})
        np.savez_compressed(path.with_stem(f"{name}_{mark}"), **last)
        ledger.add({**r, f"{mark}_run": str(run), f"{mark}_trained_on": made})
        print(f"[{mark}] {name}", flush=True)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--livers", type=int, default=15, help="the first N validation livers")
    p.add_argument("--report-only", action="store_true")
    p.add_argument("--rate", type=int, metavar="N", help="time scene4_grasp's first N")
    p.add_argument("--np", type=int, default=2)
    p.add_argument("--ready", action="store_true", help="time make liver GRASP=... (the "
                   "shipped model) from each liver file, then the report")
    p.add_argument("--model", metavar="RUN", help="a model of grasps (bench/grasp_rest.py's "
                   "run; the trainer's environment): its rows beside the base's")
    p.add_argument("--force-model", metavar="RUN", help="a model of forces over the base "
                   "(population_green): its rows against the pressed force")
    a = p.parse_args(argv)
    RESULTS.mkdir(parents=True, exist_ok=True)
    if a.rate:
        (RESULTS / "rate.json").write_text(json.dumps(generation_rate(
            GRASP_SCENE, RESULTS / "grasp_rate", a.rate, a.np), indent=1))
    ledger = Ledger(RESULTS / "livers.jsonl", key="liver")
    names = tomllib.loads(SCENE.read_text())["geometry"]["validation"][:a.livers]
    if a.ready:   # one liver after the other, nothing else running
        READY.write_text(json.dumps([ready(n) for n in names], indent=1))
        a.report_only = True
    for i, name in enumerate(names):
        if a.report_only or name in ledger.records():
            continue
        print(f"[{i + 1}/{len(names)}] {name}", flush=True)
        ledger.add(solve_liver(name, PLACES, PLACES))
    if "dolfinx" in sys.modules:   # VTK cannot render beside it: the report in a fresh process
        from subprocess import run

        return run([sys.executable, __file__, "--report-only", f"--livers={a.livers}"]).returncode
    for run, kind in ((a.model, "grasps"), (a.force_model, "forces")):
        if run:
            model_rows(Path(run).resolve().relative_to(ROOT), ledger, names, kind)
    records = [r for n, r in ledger.records().items() if n in names]
    timed = json.loads(READY.read_text()) if READY.exists() else None
    saved = ROOT / "docs" / "surgical_loads.json"
    if a.report_only and not records and saved.exists():   # the results are not on this host
        from surrogate.latency import grasp_latency

        data = {**json.loads(saved.read_text()), "timing": grasp_latency(), "ready": timed}
        write_report(saved.with_suffix(".md"), "Surgical loads on the validation livers",
                     _body(data), data)
        return 0
    report(records, timed)
    return 0


def report(records: list[dict], timed: list | None) -> None:
    if not records:
        return print("no liver solved yet", file=sys.stderr)
    from surrogate.latency import grasp_latency

    grasp = surgical_curve(records, "grasps", "pull", PULLS)
    force = surgical_curve(records, "forces", "force", FORCES)
    rate = json.loads((RESULTS / "rate.json").read_text()) \
        if (RESULTS / "rate.json").exists() else None
    surgical_curves(grasp, force, GOAL, ROOT / "docs" / "surgical_loads.png")
    data = {"livers": records, "grasp_curve": grasp, "force_curve": force,
            "timing": grasp_latency(), "goal": GOAL, "rate": rate, "worst": surgical_worst_picture(
                records, RESULTS, ROOT / "docs" / "surgical_loads_worst.png"),
            "ready": timed}
    write_report(ROOT / "docs" / "surgical_loads.md", "Surgical loads on the validation livers",
                 _body(data), data)


def _body(data: dict) -> str:
    """The report's body (bench/templates/surgical_loads.md.j2) from what it is written from."""
    records = data["livers"]
    cases = [(r["liver"], c) for r in records for c in r["grasps"] + r["forces"]]
    return render(Path(__file__).parent / "templates" / "surgical_loads.md.j2", **REPORT_NAMES,
                  records=records, grasp=data["grasp_curve"], force=data["force_curve"],
                  timing=data["timing"], goal=data["goal"], rate=data["rate"], ready=data["ready"],
                  worst=data.get("worst"), places=PLACES, n_cases=len(cases),
                  model_run=records[0].get("model_run") if records else None,
                  force_model_run=records[0].get("force_model_run") if records else None,
                  ok=[c for _, c in cases if c["status"] == "ok"],
                  failed=[f"{n}: {c['reason']}" for n, c in cases if c["status"] != "ok"],
                  g40=surgical_per_liver(records, "grasps", "pull", 40.0),
                  f4=surgical_per_liver(records, "forces", "force", 4.0)).rstrip("\n")


if __name__ == "__main__":
    sys.exit(main())
