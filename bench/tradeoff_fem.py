"""FEM price list: what each speed knob costs in accuracy, measured on this software.

    .venv-solver/bin/python bench/tradeoff_fem.py [--threads 2] [--report]   # make tradeoff-fem

The phantom and the SOFA liver (when present), 0.4 N far from the fixed region as a patch load
(a 15 mm bump traction, with a converged limit) and as the paper's nodal load (its error
measured outside a ball of 2 h around it); each run changes one knob (mesh size and element,
load steps, Newton tolerance, linear solver, predictor, K/mu): seconds, iterations,
factorisations, peak memory and the error against the finest P2 that fits. Resumable
(bench/results/tradeoff_fem/runs.jsonl); writes docs/tradeoff_fem.{md,png}.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import platform
import sys
from pathlib import Path

import numpy as np

from fem_sim.batch.knob_run import (
    C1,
    DEFAULTS,
    M1,
    PATCH_RADIUS,
    element_of,
    field_errors,
    key_of,
    load_point,
    run_job,
    spec_of,
)
from liverviz.ledger import Ledger
from liverviz.plots import fem_price_list
from liverviz.report import ROOT, SOFA, header, render

RESULTS = ROOT / "bench" / "results" / "tradeoff_fem"
RUNS = Ledger(RESULTS / "runs.jsonl", key="key")
DOCS = ROOT / "docs"

# mesh sizes (mm): P1 ~1k to ~30k vertices, P2 on the coarser; the reference P2 at 'ref'
SIZES = {
    "phantom": {"p1": [12.0, 8.0, 6.0, 5.0, 4.0, 3.5], "p2": [16.0, 12.0, 10.0, 8.0],
                "anp": [16.0, 12.0, 10.0, 8.0, 6.0, 5.0],
                "ref": 6.0, "default": 8.0, "kmu": [12.0, 8.0]},
    "sofa": {"p1": [16.0, 10.0, 8.0, 6.0, 5.0, 4.0], "p2": [16.0, 12.0, 10.0, 8.0],
             "anp": [16.0, 12.0, 10.0, 8.0, 6.0, 5.0],
             "ref": 6.0, "default": 8.0, "kmu": []},  # K/mu sweep on the phantom only (time)
}
REF_RTOL = 1e-9  # the references' Newton tolerance (their keys carry it)
TARGET = 0.02  # the accuracy the summary asks of each element: 2 % of the converged answer


def _plan_meshes(add, liver: str, s: dict) -> None:
    """The references (one per K/mu) and the mesh-size and element rows."""
    for kmu in (10.0, 100.0, 200.0, 1000.0):  # references (patch load), one per K/mu
        if kmu == 200.0 or s["kmu"]:
            add(liver=liver, load="patch", h=s["ref"], degree=2, K_over_mu=kmu,
                rtol=REF_RTOL, role="reference")
    add(liver=liver, load="nodal", h=s["ref"], degree=2, rtol=REF_RTOL, role="reference")
    for load in ("patch", "nodal"):
        for h in s["p1"]:
            add(liver=liver, load=load, h=h, degree=1, role="mesh")
        for h in s["p2"]:
            add(liver=liver, load=load, h=h, degree=2, role="mesh")
        for h in s["anp"]:
            add(liver=liver, load=load, h=h, element="anp", role="mesh")


def _plan_steps_and_tolerances(add, liver: str, s: dict) -> None:
    d = s["default"]
    for n in (1, 2, 5, 20):
        add(liver=liver, load="patch", h=d, steps=n, role="steps")
    # the locking-free elements with fewer load steps: one answer sooner
    for n in (1, 2, 5):
        for h in s["p2"]:
            add(liver=liver, load="patch", h=h, degree=2, steps=n, role="steps")
        for h in s["anp"]:
            add(liver=liver, load="patch", h=h, element="anp", steps=n, role="steps")
    for rtol in (1e-4, 1e-5, 1e-8, 1e-10):
        add(liver=liver, load="patch", h=d, rtol=rtol, role="tolerance")
    # P2 at the references' tolerance: what the default saves and costs where P2 reaches 2 %
    for h in s["p2"]:
        add(liver=liver, load="patch", h=h, degree=2, rtol=1e-9, role="tolerance")
        add(liver=liver, load="patch", h=h, degree=2, rtol=1e-9, steps=1, role="tolerance")


def _plan_solvers_and_kmu(add, liver: str, s: dict) -> None:
    d = s["default"]
    for fac in ("double", "petsc"):
        add(liver=liver, load="patch", h=d, factorization=fac, role="linear solver")
    add(liver=liver, load="patch", h=d, linear_solver="gamg", role="linear solver")
    for pred in ("tangent", "extrapolate", "previous"):
        add(liver=liver, load="patch", h=d, predictor=pred, role="predictor")
    for kmu in (10.0, 100.0, 1000.0):
        for h in s["kmu"]:
            for degree in (1, 2):
                add(liver=liver, load="patch", h=h, degree=degree, K_over_mu=kmu, role="K/mu")


def plan(livers: list[str]) -> list[dict]:  # every run of the study, references first
    runs = []

    def add(liver, **kw):
        spec = spec_of(liver, **kw)
        if spec not in runs:
            runs.append(spec)

    for liver in livers:
        for rows in (_plan_meshes, _plan_steps_and_tolerances, _plan_solvers_and_kmu):
            rows(add, liver, SIZES[liver])
    return runs


def npz_name(key: str) -> Path:
    return RESULTS / f"{hashlib.sha1(key.encode()).hexdigest()[:16]}.npz"


def reference_of(spec: dict) -> dict:
    return spec_of(spec["liver"], load=spec["load"], h=SIZES[spec["liver"]]["ref"], degree=2,
                   K_over_mu=spec["K_over_mu"] if spec["load"] == "patch" else 200.0,
                   rtol=REF_RTOL, role="reference")


def study(livers: list[str], timeout: float, loads=("patch", "nodal"), threads: int = 1) -> None:
    from tqdm import tqdm

    RESULTS.mkdir(parents=True, exist_ok=True)
    points = {}
    for liver in livers:
        f = RESULTS / f"load_point_{liver}.json"
        if not f.exists():
            f.write_text(json.dumps(load_point(liver).tolist()))
        points[liver] = json.loads(f.read_text())
    done = RUNS.records()
    todo = [s for s in plan(livers) if key_of(s) not in done and s["load"] in loads]
    bar = tqdm(todo, desc="tradeoff-fem", unit="run")
    for spec in bar:
        key = key_of(spec)
        bar.set_postfix_str(f"{spec['liver']} {spec['load']} {element_of(spec)} h={spec['h']} "
                            f"{spec['role']}")
        ref_key = key_of(reference_of(spec))
        ref_npz = npz_name(ref_key) if spec["role"] != "reference" else None
        if ref_npz is not None and not ref_npz.exists():
            record = {"status": "skipped", "reason": "its reference did not run"}
        else:
            job = {"spec": {**spec, "load_point": points[spec["liver"]]},
                   "eval": str(ref_npz) if ref_npz else None, "out": str(npz_name(key))}
            record = run_job(job, timeout, threads)
        RUNS.add({"key": key, "spec": spec, **record})


def errors(spec: dict, rec: dict, h: float, res: dict) -> dict | None:
    """The run's errors against its reference (``res``: the study's records)."""
    ref = res.get(key_of(reference_of(spec)))
    if ref is None or rec.get("status") != "ok" or not npz_name(key_of(
            reference_of(spec))).exists():
        return None
    with np.load(npz_name(key_of(reference_of(spec)))) as z:
        u_ref, pts = z["u_nodes"], z["nodes"]
    with np.load(npz_name(rec["key"])) as z:
        u = u_ref if spec["role"] == "reference" else z["u"]
    point = None if spec["load"] != "nodal" else json.loads(
        (RESULTS / f"load_point_{spec['liver']}.json").read_text())
    return field_errors(u, u_ref, pts, point, 2 * h)


def knob_cost(spec: dict, rec: dict, res: dict) -> float | None:
    """Largest difference (relative to max |u_ref|) from the default run on the same problem
    and mesh: what the knob alone costs."""
    if spec["role"] in ("reference", "mesh", "K/mu") or rec.get("status") != "ok":
        return None
    base = spec_of(spec["liver"], load=spec["load"], h=spec["h"], role="mesh",
                   degree=spec["degree"], **{k: spec[k] for k in ("element",) if k in spec})
    b = res.get(key_of(base))
    ref = npz_name(key_of(reference_of(spec)))
    if b is None or b.get("status") != "ok" or not ref.exists():
        return None
    with np.load(npz_name(b["key"])) as zb, np.load(npz_name(rec["key"])) as zr, \
            np.load(ref) as zref:
        return float(np.abs(zr["u"] - zb["u"]).max() / np.abs(zref["u_nodes"]).max())


def threads_note(rows: list) -> str:  # the runs' thread counts (older records: one)
    counts = sorted({rec.get("threads", 1) for _, rec, _ in rows})
    return " or ".join(f"{n} thread{'s' if n > 1 else ''}" for n in counts) or "-"


def later_cell(rec: dict, digits: int) -> str:  # a later simulation's seconds ('-': none)
    if "seconds_later" not in rec:
        return "-"
    if rec.get("status_later") != "ok":
        return str(rec.get("status_later"))
    return f"{rec['seconds_later']:.{digits}f}"


def summary(rows: list) -> list[tuple]:
    """Each element's cheapest run within TARGET of the converged answer (by the mean and the
    max error; the most accurate when none is), and the cheapest at the default tolerance:
    (liver, element, measure, spec, record, errors, reached)."""
    out = []
    for liver in SIZES:
        for element in ("P1", "ANP", "P2"):
            runs = [(s, r, e) for s, r, e in rows if s["liver"] == liver and e and
                    s["role"] in ("mesh", "steps", "tolerance") and s["load"] == "patch" and
                    s["K_over_mu"] == 200.0 and element_of(s) == element]
            for measure in ("rel_mean", "rel_max") if runs else ():
                good = [x for x in runs if x[2][measure] <= TARGET]
                # the most accurate: equal errors (other load steps) go to the cheapest run
                best = (min(good, key=lambda x: x[1]["seconds"]) if good else
                        min(runs, key=lambda x: (round(x[2][measure], 5), x[1]["seconds"])))
                shown = [best]
                default = [x for x in good if x[0]["rtol"] == DEFAULTS["rtol"]]
                if best[0]["rtol"] != DEFAULTS["rtol"] and default:
                    shown.append(min(default, key=lambda x: x[1]["seconds"]))
                out += [(liver, element, measure, *x, bool(good)) for x in shown]
    return out


def _rows(res: dict) -> list:  # (spec, record, errors) of the plan's runs, in order
    planned = {key_of(s) for s in plan(list(SIZES))}  # records of an earlier plan: not shown
    rows = []
    for rec in res.values():
        if rec["key"] not in planned:
            continue
        spec = rec["spec"]
        err = errors(spec, rec, spec["h"], res) if rec.get("status") == "ok" else None
        rows.append((spec, rec, err))
    order = ["reference", "mesh", "steps", "tolerance", "linear solver", "predictor", "K/mu"]
    rows.sort(key=lambda r: (r[0]["liver"], order.index(r[0]["role"]), r[0]["load"],
                             r[0]["K_over_mu"], element_of(r[0]), -r[0]["h"],
                             r[0]["steps"]))
    return rows


MARKERS = {"mesh": "o", "steps": "s", "tolerance": "^", "linear solver": "D", "predictor": "v",
           "K/mu": "x"}
COLOURS = {"mesh P1": "C0", "mesh P2": "C1", "mesh ANP": "C8", "steps": "C2",
           "tolerance": "C3", "linear solver": "C4", "predictor": "C5", "K/mu": "C6"}


def _points(rows: list) -> dict:
    """{liver: the chart's points}: each run of the patch load at K/mu = 200 but the
    reference, (label, marker, colour, mesh size, seconds, error); every liver a panel."""
    out: dict = {spec["liver"]: [] for spec, _, _ in rows}
    for spec, rec, err in rows:
        if spec["load"] != "patch" or not err or spec["role"] == "reference" \
                or spec["K_over_mu"] != 200.0:
            continue
        mesh = spec["role"] == "mesh"
        label = f"mesh {element_of(spec)}" if mesh else spec["role"]
        out[spec["liver"]].append(
            (label, MARKERS.get(spec["role"], "o"), COLOURS.get(label, "C7"),
             f"{spec['h']:g}" if mesh else "", rec["seconds"], max(err["rel_mean"], 1e-6)))
    return out


def report() -> None:
    res = RUNS.records()
    rows = _rows(res)
    body = render(Path(__file__).parent / "templates" / "tradeoff_fem.md.j2", shown=summary(rows),
                  rows=[(s, r, e, knob_cost(s, r, res)) for s, r, e in rows],
                  machine=platform.processor() or platform.machine(), cores=os.cpu_count(),
                  threads=threads_note(rows), patch_radius=PATCH_RADIUS, c1=C1, m1=M1,
                  defaults=DEFAULTS, ref_rtol=REF_RTOL, target=TARGET, element_of=element_of,
                  later_cell=later_cell)
    DOCS.mkdir(exist_ok=True)
    (DOCS / "tradeoff_fem.md").write_text(
        header("FEM price list: speed against accuracy").rstrip() + "\n\n" + body)
    # the errors beside the report, for the reports that quote an element's (table4)
    (DOCS / "tradeoff_fem.json").write_text("[\n" + ",\n".join(
        json.dumps({"spec": spec, "element": element_of(spec), "errors": err})
        for spec, _, err in rows if err) + "\n]\n")
    fem_price_list(_points(rows), "patch load, K/mu = 200 (labels: h in mm)",
                   DOCS / "tradeoff_fem.png")
    print(f"wrote {DOCS / 'tradeoff_fem.md'} and {DOCS / 'tradeoff_fem.png'}")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--liver", choices=["phantom", "sofa", "both"], default="both")
    ap.add_argument("--report", action="store_true", help="only write the report")
    ap.add_argument("--timeout", type=float, default=1800.0, help="seconds per run")
    ap.add_argument("--load", choices=["patch", "nodal", "both"], default="both",
                    help="only these runs (two processes can share the study)")
    ap.add_argument("--threads", type=int, default=1,
                    help="threads per run (OMP_NUM_THREADS, OPENBLAS_NUM_THREADS); one MPI rank")
    a = ap.parse_args()
    livers = ["phantom", "sofa"] if a.liver == "both" else [a.liver]
    livers = [v for v in livers if v != "sofa" or SOFA.exists()]
    if not a.report:
        study(livers, a.timeout, ("patch", "nodal") if a.load == "both" else (a.load,),
              a.threads)
    report()
    return 0


if __name__ == "__main__":
    sys.exit(main())
