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
import tempfile
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import tradeoff_fem as tf  # noqa: E402


def run(liver: str, element: str, h: float) -> dict:
    """One simulation as the price list runs it (``tradeoff_fem.run_one``), in this process,
    with its errors against the price list's reference."""
    kw = {"degree": 2} if element == "P2" else {"element": "anp"} if element == "anp" else {}
    spec = tf.spec_of(liver, load="patch", h=h, role="mesh", **kw)
    ref = tf.npz_name(tf.key_of(tf.reference_of(spec)))
    if not ref.exists():
        raise SystemExit(f"{ref} is missing: run `make tradeoff-fem` first (the references)")
    with np.load(ref) as z:
        u_ref, pts = z["u_nodes"], z["nodes"]
    spec["load_point"] = json.loads((tf.RESULTS / f"load_point_{liver}.json").read_text())
    with tempfile.TemporaryDirectory() as tmp:
        rec = tf.run_one(spec, pts, Path(tmp) / "u.npz")
        with np.load(Path(tmp) / "u.npz") as z:
            u = z["u"]
    e = np.linalg.norm(u - u_ref, axis=1)
    scale = np.abs(u_ref).max()
    return {"liver": liver, "element": element, "h": h, "nodes": rec["n_vertices"],
            "status": rec["status"], "seconds": rec["seconds"],
            "its": rec["newton_iterations"], "factorizations": rec["factorizations"],
            "mean": e.mean() / scale, "max": e.max() / scale,
            "signed": tf.signed_error(u, u_ref), "fixed": rec["fixed_nodes"]}


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
