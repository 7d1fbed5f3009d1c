"""The error budget: scene-1 load cases (drawn as scene 1 draws them, on every budget mesh at
the node nearest the same point) solved on each budget mesh and the reference (P2 at 6 mm);
with ``--errors``, after ``bench/tradeoff_surrogate.py`` trained a network on each mesh's
dataset, the FE error, the network's and the total a user gets: the section ``error-budget``
of docs/tradeoff_surrogate.md and docs/error_budget.png.

    .venv-solver/bin/python bench/budget_fem.py            # resumable: bench/results/budget_fem
    .venv-train/bin/python bench/budget_fem.py --errors    # make tradeoff-surrogate runs both
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

from fem_sim.batch import knob_run as kr
from liverviz.ledger import Ledger
from liverviz.plots import error_budget
from liverviz.report import ROOT, put_section, render

SCENE = ROOT / "data_spec" / "scenes" / "scene1_base.toml"
FIRST_INDEX = 100_000      # case indices of the budget: no dataset of the study reaches them
SURROGATE = ROOT / "bench" / "results" / "tradeoff_surrogate"   # its datasets and networks
DOCS = ROOT / "docs"


def cases() -> list[dict]:
    """The load cases: point (mm) and force (N), drawn by scene 1's own rule on the 16 mm mesh."""
    from data_spec import load_scene
    from fem_sim.batch import cases as cs

    f = kr.BUDGET_RESULTS / "cases.json"
    if f.exists():
        return json.loads(f.read_text())
    scene = load_scene(SCENE)
    g, fixed = kr.mesh("phantom", 16.0)
    out = []
    for k in range(kr.BUDGET_CASES):
        c = cs.make_case(scene, FIRST_INDEX + k, g, fixed)
        out.append({"index": FIRST_INDEX + k, "point": g.points[c.load_nodes[0]].tolist(),
                    "force": c.forces[0].tolist()})
    kr.BUDGET_RESULTS.mkdir(parents=True, exist_ok=True)
    f.write_text(json.dumps(out, indent=1))
    return out


def run(case: dict, k: int, degree: int, h: float, timeout: float) -> dict:
    spec = {**kr.DEFAULTS, "liver": "phantom", "load": "nodal", "h": h, "degree": degree,
            "load_point": case["point"], "force": case["force"]}
    job = {"spec": spec, "out": str(kr.budget_npz(k, degree, h)),
           "eval_meshes": (kr.BUDGET_MESHES if (degree, h) == kr.BUDGET_REFERENCE else [])}
    return kr.run_job(job, timeout)


EXCLUDE = 32.0  # mm: errors are measured outside this ball around the load point (2 x the
                # coarsest h; a point load has no converged limit next to the load), on every mesh


def simulation_seconds(name: str, n: int) -> float:
    """Solver seconds of ``n`` simulations of dataset ``name`` (the mean over its shards; one
    rank each: CPU-seconds)."""
    from data_spec import list_shards, read_shard

    per = [read_shard(p).stats.wall_time.sum() for p in list_shards(SURROGATE / "data" / name)]
    return float(np.mean(per) * n)


def _case_errors(k, case, degree, h, ds, predict, fem) -> dict | None:
    """Load case k's node errors on mesh (degree, h) (None: a solve is missing)."""
    rec = fem.get((k, degree, h))
    if rec is None or rec.get("status") != "ok":
        return None
    e = kr.budget_case_errors(k, case["point"], degree, h,
                           predict(np.asarray([case["force"]]), [rec["load_node"]]), fem, EXCLUDE)
    if e is not None and (e["nodes"].shape != ds.points[0].shape
                          or not np.allclose(e["nodes"], ds.points[0])):
        raise RuntimeError(f"{kr.mesh_name(degree, h)}: the budget's mesh is not the dataset's")
    return e


def budget() -> list[dict]:
    """Per budget mesh: FE error against the reference, surrogate error against its own FE
    answer, and the surrogate's error against the reference (the sum a user gets), on the
    budget's load cases at full load, at the mesh's vertices outside EXCLUDE of the load."""
    from surrogate import load_predictor
    from surrogate.data import load_dataset

    fem = kr.BUDGET_RUNS.records()
    if not (kr.BUDGET_RESULTS / "cases.json").exists():
        return []
    cases = json.loads((kr.BUDGET_RESULTS / "cases.json").read_text())
    runs = Ledger(SURROGATE / "runs.jsonl", key="id").records().values()
    trained = {r["spec"]["data"]: r for r in runs if "error budget" in
               [r["spec"]["group"], *r["spec"].get("also", [])]}
    rows = []
    for degree, h in sorted(kr.BUDGET_MESHES, key=lambda m: (m[0], -m[1])):  # P1, P2; coarse 1st
        name = kr.mesh_name(degree, h)
        if name not in trained:
            continue
        ds = load_dataset(SURROGATE / "data" / name, stream=False)
        n = trained[name]["spec"]["n_train"]
        predict = load_predictor(SURROGATE / "models" / trained[name]["id"])
        per = [e for k, case in enumerate(cases)
               if (e := _case_errors(k, case, degree, h, ds, predict, fem)) is not None]
        if not per:
            continue
        rows.append({"mesh": name, "degree": degree, "h": h, "vertices": ds.points[0].shape[0],
                     **kr.budget_summary(per),
                     "sim_hours": simulation_seconds(name, n) / 3600,
                     "train_hours": trained[name]["training_seconds"] / 3600,
                     "sims": n})
    return rows


def errors() -> None:
    """The error budget's section of docs/tradeoff_surrogate.md and docs/error_budget.png."""
    b = budget()
    put_section(DOCS / "tradeoff_surrogate.md", "error-budget", render(
        Path(__file__).parent / "templates" / "error_budget.md.j2", b=b, exclude=EXCLUDE,
        n_budget=b[0]["sims"] if b else "n/a", budget_cases=kr.BUDGET_CASES))
    error_budget(b, EXCLUDE, DOCS / "error_budget.png")
    print(f"wrote the error budget into {DOCS / 'tradeoff_surrogate.md'} and "
          f"{DOCS / 'error_budget.png'}")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--timeout", type=float, default=1800.0, help="seconds per run")
    ap.add_argument("--errors", action="store_true", help="the budget's errors and report "
                    "(trainer environment), after bench/tradeoff_surrogate.py")
    a = ap.parse_args()
    if a.errors:
        errors()
        return 0
    from tqdm import tqdm

    kr.BUDGET_RESULTS.mkdir(parents=True, exist_ok=True)
    done = kr.BUDGET_RUNS.records()
    todo = [(k, d, h) for k in range(kr.BUDGET_CASES)
            for d, h in [kr.BUDGET_REFERENCE, *kr.BUDGET_MESHES]
            if (k, d, h) not in done]
    cs = cases()
    bar = tqdm(todo, desc="budget-fem", unit="run")
    for k, d, h in bar:
        bar.set_postfix_str(f"case {k} P{d} h={h:g}")
        kr.BUDGET_RUNS.add({"case": k, "degree": d, "h": h, **run(cs[k], k, d, h, a.timeout)})
    return 0


if __name__ == "__main__":
    sys.exit(main())
