"""Locking-free choices against P1: error against the converged answer, seconds, factorisations.

The setting of the FEM price list (``bench/tradeoff_fem.py``: 0.4 N as a patch load at the
surface point farthest from the fixed region, K/mu = 200, 10 load steps, one rank) and its
references (P2 on the 6 mm mesh), which must exist: run ``make tradeoff-fem`` first (it skips
what is done). Rows: P1 (the paper's element), P1 with averaged nodal pressure ("anp",
``solver.element = "anp"``, ``fem_sim/solver/anp.py``) and P2, on the meshes given. Errors
against the reference at its vertices, relative to its largest displacement (mean, max), and
the signed error: the component of u - u_ref along u_ref over |u_ref|^2 (negative: too stiff).

    OPENBLAS_NUM_THREADS=1 .venv-solver/bin/python bench/locking_free.py \\
        [--livers phantom sofa] [--runs P1:8 anp:8 anp:12 P2:16 P2:12]
"""

from __future__ import annotations

import argparse
import json
import logging
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import tradeoff_fem as tf  # noqa: E402


def run(liver: str, element: str, h: float) -> dict:
    from mpi4py import MPI

    from fem_sim import Constraint, OgdenMaterial, OgdenProblem, PatchLoad

    spec = tf.spec_of(liver, load="patch", h=h, role="mesh")
    ref = tf.npz_name(tf.key_of(tf.reference_of(spec)))
    if not ref.exists():
        raise SystemExit(f"{ref} is missing: run `make tradeoff-fem` first (the references)")
    with np.load(ref) as z:
        u_ref, pts = z["u_nodes"], z["nodes"]
    g, fixed = tf.mesh(liver, h)
    p = np.asarray(json.loads((tf.RESULTS / f"load_point_{liver}.json").read_text()))
    kw = {"degree": 2} if element == "P2" else {"element": "anp"} if element == "anp" else {}
    prob = OgdenProblem(MPI.COMM_WORLD, g.points, g.cells, settings={"rtol": 1e-9}, **kw)
    c1 = 4.1e-3
    mat = OgdenMaterial((c1,), (10.06,), 100 * c1)
    t0 = time.perf_counter()
    sol = prob.solve(mat, [Constraint(fixed)], [PatchLoad(p, tf.FORCE, tf.PATCH_RADIUS)],
                     np.arange(1, 11) / 10)
    secs = time.perf_counter() - t0
    u = prob.displacement_at(pts)
    e = np.linalg.norm(u - u_ref, axis=1)
    scale = np.abs(u_ref).max()
    signed = tf.signed_error(u, u_ref)
    return {"liver": liver, "element": element, "h": h, "nodes": g.n_nodes,
            "status": sol.status, "seconds": secs, "its": sol.newton_iterations,
            "factorizations": sol.factorizations, "mean": e.mean() / scale,
            "max": e.max() / scale, "signed": signed, "fixed": int(len(fixed))}


def main() -> int:
    logging.getLogger().setLevel(logging.ERROR)
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--livers", nargs="+", default=["phantom", "sofa"])
    ap.add_argument("--runs", nargs="+", default=["P1:8", "anp:8", "anp:12", "P2:16", "P2:12"],
                    help="element:h pairs (element P1, anp or P2)")
    a = ap.parse_args()
    print("| liver | element | h mm | vertices | fixed nodes | status | Newton its per step | "
          "factorisations | s / sim | mean error | max error | signed error |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|")
    for liver in a.livers:
        for item in a.runs:
            element, h = item.split(":")
            r = run(liver, element, float(h))
            print(f"| {liver} | {element} | {r['h']:g} | {r['nodes']} | {r['fixed']} | "
                  f"{r['status']} | {' '.join(map(str, r['its']))} | {r['factorizations']} | "
                  f"{r['seconds']:.1f} | {r['mean']:.2%} | {r['max']:.2%} | "
                  f"{r['signed']:+.1%} |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
