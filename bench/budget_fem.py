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
from pathlib import Path

import numpy as np
import tradeoff_fem as tf  # a sibling driver: its liver, load and reference

RESULTS = tf.ROOT / "bench" / "results" / "budget_fem"
SCENE = tf.ROOT / "data_spec" / "scenes" / "scene1_base.toml"
N_CASES = 4
FIRST_INDEX = 100_000      # case indices of the budget: no dataset of the study reaches them
REFERENCE = (2, 6.0)       # (degree, mesh size mm)
# Meshes of the error budget: (degree, mesh size mm). P2 at 16 mm is the shipped scene 1.
MESHES = [(2, 16.0), (1, 12.0), (1, 8.0), (2, 12.0)]


def mesh_name(degree: int, h: float) -> str:
    return f"p{degree}_h{h:g}"


def npz_path(case: int, degree: int, h: float) -> Path:
    return RESULTS / f"case{case}_{mesh_name(degree, h)}.npz"


def cases() -> list[dict]:
    """The load cases: point (mm) and force (N), drawn by scene 1's own rule on the 16 mm mesh."""
    from data_spec import load_scene
    from fem_sim.batch import cases as cs

    f = RESULTS / "cases.json"
    if f.exists():
        return json.loads(f.read_text())
    scene = load_scene(SCENE)
    g, fixed = tf.mesh("phantom", 16.0)
    out = []
    for k in range(N_CASES):
        c = cs.make_case(scene, FIRST_INDEX + k, g, fixed)
        out.append({"index": FIRST_INDEX + k, "point": g.points[c.load_nodes[0]].tolist(),
                    "force": c.forces[0].tolist()})
    RESULTS.mkdir(parents=True, exist_ok=True)
    f.write_text(json.dumps(out, indent=1))
    return out


def vertices(degree: int, h: float) -> np.ndarray:
    g, _ = tf.mesh("phantom", h)
    return g.points


def run(case: dict, k: int, degree: int, h: float, timeout: float) -> dict:
    spec = {**tf.DEFAULTS, "liver": "phantom", "load": "nodal", "h": h, "degree": degree,
            "load_point": case["point"], "force": case["force"]}
    job = {"spec": spec, "out": str(npz_path(k, degree, h)),
           "eval_meshes": [[d, s] for d, s in MESHES] if (degree, h) == REFERENCE else []}
    return tf.run_job(__file__, job, timeout)


def one(job: dict) -> dict:
    """In a fresh process: solve, and save u at the own vertices (and, for the reference, at
    the vertices of every budget mesh, concatenated in MESHES order)."""
    ev = None
    if job["eval_meshes"]:
        ev = np.concatenate([vertices(d, s) for d, s in job["eval_meshes"]])
    return tf.run_one(job["spec"], ev, Path(job["out"]))


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--timeout", type=float, default=1800.0, help="seconds per run")
    ap.add_argument("--one", help=argparse.SUPPRESS)
    a = ap.parse_args()
    if a.one:
        import logging

        logging.getLogger().setLevel(logging.WARNING)
        print(json.dumps(one(json.loads(a.one))))
        return 0
    from tqdm import tqdm

    RESULTS.mkdir(parents=True, exist_ok=True)
    log = RESULTS / "runs.jsonl"
    done = set()
    if log.exists():
        done = {(r["case"], r["degree"], r["h"]) for r in map(json.loads, log.read_text()
                                                                .splitlines()) if r}
    todo = [(k, d, h) for k in range(N_CASES) for d, h in [REFERENCE, *MESHES]
            if (k, d, h) not in done]
    cs = cases()
    bar = tqdm(todo, desc="budget-fem", unit="run")
    for k, d, h in bar:
        bar.set_postfix_str(f"case {k} P{d} h={h:g}")
        rec = run(cs[k], k, d, h, a.timeout)
        with open(log, "a") as fh:
            fh.write(json.dumps({"case": k, "degree": d, "h": h, **rec}) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
