"""FE half of the error budget: scene-1 load cases solved on every budget mesh and on the reference.

A few load cases are drawn exactly as scene 1 draws them (a random eligible surface node, a
uniform random direction, 0.4 N; ``make_case`` at indices no dataset uses) on the coarsest mesh;
every other mesh loads the eligible node nearest to the same point. Each case is solved on each
mesh of ``MESHES`` and on the reference (P2 at 6 mm, the reference of ``tradeoff_fem.py``), and the
reference is evaluated at the vertices of every budget mesh, so that
``bench/tradeoff_surrogate.py`` (trainer environment) can compare, at a mesh's own nodes, the FE
answer of that mesh, the surrogate trained on it and the reference.

    .venv-solver/bin/python bench/budget_fem.py   # resumable: bench/results/budget_fem
"""

from __future__ import annotations

import argparse
import json
import sys

from fem_sim.batch.knob_run import (
    BUDGET_CASES,
    BUDGET_MESHES,
    BUDGET_REFERENCE,
    BUDGET_RESULTS,
    BUDGET_RUNS,
    DEFAULTS,
    budget_npz,
    mesh,
    run_job,
)
from liverviz.report import ROOT

SCENE = ROOT / "data_spec" / "scenes" / "scene1_base.toml"
FIRST_INDEX = 100_000      # case indices of the budget: no dataset of the study reaches them


def cases() -> list[dict]:
    """The load cases: point (mm) and force (N), drawn by scene 1's own rule on the 16 mm mesh."""
    from data_spec import load_scene
    from fem_sim.batch import cases as cs

    f = BUDGET_RESULTS / "cases.json"
    if f.exists():
        return json.loads(f.read_text())
    scene = load_scene(SCENE)
    g, fixed = mesh("phantom", 16.0)
    out = []
    for k in range(BUDGET_CASES):
        c = cs.make_case(scene, FIRST_INDEX + k, g, fixed)
        out.append({"index": FIRST_INDEX + k, "point": g.points[c.load_nodes[0]].tolist(),
                    "force": c.forces[0].tolist()})
    BUDGET_RESULTS.mkdir(parents=True, exist_ok=True)
    f.write_text(json.dumps(out, indent=1))
    return out


def run(case: dict, k: int, degree: int, h: float, timeout: float) -> dict:
    spec = {**DEFAULTS, "liver": "phantom", "load": "nodal", "h": h, "degree": degree,
            "load_point": case["point"], "force": case["force"]}
    job = {"spec": spec, "out": str(budget_npz(k, degree, h)),
           "eval_meshes": (BUDGET_MESHES if (degree, h) == BUDGET_REFERENCE else [])}
    return run_job(job, timeout)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--timeout", type=float, default=1800.0, help="seconds per run")
    a = ap.parse_args()
    from tqdm import tqdm

    BUDGET_RESULTS.mkdir(parents=True, exist_ok=True)
    done = BUDGET_RUNS.records()
    todo = [(k, d, h) for k in range(BUDGET_CASES)
            for d, h in [BUDGET_REFERENCE, *BUDGET_MESHES]
            if (k, d, h) not in done]
    cs = cases()
    bar = tqdm(todo, desc="budget-fem", unit="run")
    for k, d, h in bar:
        bar.set_postfix_str(f"case {k} P{d} h={h:g}")
        BUDGET_RUNS.add({"case": k, "degree": d, "h": h, **run(cs[k], k, d, h, a.timeout)})
    return 0


if __name__ == "__main__":
    sys.exit(main())
