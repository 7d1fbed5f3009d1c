"""One row of the FEM price list as a dataset runs it: first and later simulations, side by side.

The price list (``bench/tradeoff_fem.py``) times one simulation per fresh process. A dataset
runs many simulations on one problem (one liver, material and fixed region): the first pays
PARDISO's analysis and the small-strain factorisation, the later ones reuse them. This script
times both on the price list's setting (the real liver, 0.4 N along -z as a patch load, radius
15 mm, at the price list's load point, its fixed region, Ogden c1 = 4.1e-3 MPa, m1 = 10.06,
K/mu = 200, 10 load steps unless --steps, each checkout at its own default Newton
tolerance), by default on its 2 % row (P2 at 10 mm), and compares
variants in the same run, their runs interleaved so that they share the machine's load:

    .venv-solver/bin/python bench/bench_price_row.py [--element p2] [--h 10] [--sims 3]
        [--runs 2] [--settings '{"rtol": 1e-9}']   # a solver variant (OgdenProblem settings)
        [--steps 10 5 2 1]   # output load fractions (equally spaced); each a row per variant
        [--baseline DIR]   # the same runs with the fem_sim of another checkout (git worktree)

Each run is a fresh process (``--worker``) on OMP_NUM_THREADS / OPENBLAS_NUM_THREADS threads
(default 2); the table gives medians over the runs, the counts of the first run, the ratio of
seconds to the first variant (at the same number of steps), and the largest difference of the
final displacement from the first variant's at the first --steps value (relative to its max
|u|): what a variant, or fewer output steps, costs in accuracy.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent


def worker(job: dict) -> None:
    """Set up one problem and solve ``sims`` simulations on it; one JSON line each."""
    import logging

    logging.getLogger().setLevel(logging.ERROR)
    sys.path.insert(0, str(HERE))
    import tradeoff_fem as T
    from mpi4py import MPI

    import fem_sim
    from fem_sim import Constraint, OgdenProblem, PatchLoad

    root = job.get("root")
    if root and not Path(fem_sim.__file__).resolve().is_relative_to(Path(root).resolve()):
        raise SystemExit(f"fem_sim came from {fem_sim.__file__}, not from {root}")
    t0 = time.perf_counter()
    g, fixed = T.mesh("sofa", job["h"])
    kw = {"element": "anp"} if job["element"] == "anp" else {}
    prob = OgdenProblem(MPI.COMM_WORLD, g.points, g.cells, settings=job["settings"],
                        degree=2 if job["element"] == "p2" else 1, **kw)
    mat = T.material(200.0)
    load = [PatchLoad(np.asarray(job["load_point"]), T.FORCE, T.PATCH_RADIUS)]
    n = job.get("steps", 10)
    fractions = np.arange(1, n + 1) / n
    print(json.dumps({"setup_seconds": time.perf_counter() - t0, "vertices": g.n_nodes}),
          flush=True)
    for k in range(job["sims"]):
        t1 = time.perf_counter()
        sol = prob.solve(mat, [Constraint(fixed)], load, fractions)
        secs = time.perf_counter() - t1
        if k == 0 and sol.n_done:
            np.save(job["u_out"], sol.displacement[-1])
        print(json.dumps({"sim": k, "seconds": secs, "status": sol.status,
                          "its": sol.newton_iterations, "factorizations": sol.factorizations,
                          "back_solves": sol.back_solves, "krylov": sol.krylov_iterations,
                          "chord": sol.chord_steps,
                          "increments": getattr(sol, "increments", None)}), flush=True)


def run(job: dict, root: str | None, threads: int) -> list[dict]:
    env = {**os.environ, "OMP_NUM_THREADS": str(threads), "OPENBLAS_NUM_THREADS": str(threads)}
    if root:  # the other checkout's fem_sim first on the path (ahead of the editable install)
        env["PYTHONPATH"] = os.pathsep.join([root, env.get("PYTHONPATH", "")])
    proc = subprocess.run([sys.executable, __file__, "--worker", json.dumps({**job,
                           "root": root})], capture_output=True, text=True, env=env)
    if proc.returncode:
        raise SystemExit(f"worker failed ({root or 'this checkout'}):\n{proc.stderr[-2000:]}")
    return [json.loads(ln) for ln in proc.stdout.splitlines() if ln.startswith("{")]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--worker", default=None, help=argparse.SUPPRESS)
    ap.add_argument("--element", choices=("p1", "p2", "anp"), default="p2")
    ap.add_argument("--h", type=float, default=10.0, help="mesh size, mm")
    ap.add_argument("--sims", type=int, default=3, help="simulations on one problem")
    ap.add_argument("--runs", type=int, default=2, help="fresh processes per variant")
    ap.add_argument("--settings", default=None, help="JSON: a solver variant to compare")
    ap.add_argument("--baseline", default=None, metavar="DIR",
                    help="a checkout (git worktree) whose fem_sim runs as the baseline")
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--steps", type=int, nargs="+", default=[10],
                    help="numbers of output load fractions to time (the first: the answer "
                         "every row is compared with)")
    a = ap.parse_args()
    if a.worker:
        worker(json.loads(a.worker))
        return 0
    if a.sims < 1 or a.runs < 1 or min(a.steps) < 1:
        ap.error("--sims, --runs and --steps must be >= 1")
    sys.path.insert(0, str(HERE))
    import tradeoff_fem as T

    if not T.SOFA.exists():
        print(f"{T.SOFA} not found: the price list's real liver is needed")
        return 1
    point = T.load_point("sofa").tolist()
    variants = {"defaults": (None, {})}
    if a.baseline:
        variants = {"baseline": (str(Path(a.baseline).resolve()), {}), **variants}
    if a.settings:
        variants["variant"] = (None, json.loads(a.settings))
    tmp = Path(tempfile.mkdtemp(prefix="price_row_"))
    rows = [(n, v) for n in a.steps for v in variants]
    recs: dict[tuple, list[list[dict]]] = {r: [] for r in rows}
    for r in range(a.runs):
        for n, v in rows:
            root, settings = variants[v]
            job = {"h": a.h, "element": a.element, "sims": a.sims, "load_point": point,
                   "steps": n, "settings": settings,
                   "u_out": str(tmp / f"{v}_{n}.npy")}
            out = run(job, root, a.threads)
            recs[n, v].append(out)
            sims = out[1:]
            times = ", ".join(f"{s['seconds']:.2f} ({s['status']})" for s in sims)
            print(f"run {r + 1}/{a.runs} {v}, {n} steps: setup {out[0]['setup_seconds']:.1f} s, "
                  f"simulations {times} s, "
                  f"factorisations {[s['factorizations'] for s in sims]}", flush=True)
    first_n, first_v = rows[0]
    u0 = np.load(tmp / f"{first_v}_{first_n}.npy")
    print(f"\nreal liver, patch load, {a.element.upper()} at {a.h:g} mm "
          f"({recs[rows[0]][0][0]['vertices']} vertices), {a.threads} threads; median of "
          f"{a.runs} runs, each a fresh process with {a.sims} simulations on one problem; "
          f"max diff: the final displacement against {first_v} at {first_n} steps, relative "
          "to its max |u|\n")
    print("| steps | variant | settings | setup s | first sim s | later sims s | x first variant "
          "(first / later) | factorisations first / later | increments | Newton its per step | "
          "back-solves | GMRES its | max diff |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    base: dict[int, tuple] = {}
    for n, v in rows:
        root, settings = variants[v]
        runs = recs[n, v]
        setup = np.median([o[0]["setup_seconds"] for o in runs])
        first = np.median([o[1]["seconds"] for o in runs])
        later = (np.median([s["seconds"] for o in runs for s in o[2:]]) if a.sims > 1
                 else float("nan"))
        b = base.setdefault(n, (first, later))
        s0 = runs[0][1:]
        facts = f"{s0[0]['factorizations']} / " + (
            ", ".join(str(s["factorizations"]) for s in s0[1:]) or "-")
        incs = s0[0].get("increments")
        diff = float(np.abs(np.load(tmp / f"{v}_{n}.npy") - u0).max() / np.abs(u0).max())
        print(f"| {n} | {v} | {json.dumps(settings) if settings else (root or '-')} | "
              f"{setup:.1f} | {first:.2f} | {later:.2f} | {first / b[0]:.2f} / "
              f"{later / b[1]:.2f} | {facts} | {sum(incs) if incs else '-'} | "
              f"{' '.join(map(str, s0[0]['its']))} | {s0[0]['back_solves']} | "
              f"{s0[0]['krylov']} | {diff:.1e} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
