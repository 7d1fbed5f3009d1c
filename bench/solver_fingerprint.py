"""Solver fingerprint: work counts and answers of every solver configuration on a small
phantom, to check that a refactoring changes neither (counts equal, answers within 1e-10).

    .venv-solver/bin/python bench/solver_fingerprint.py --out before.json
    .venv-solver/bin/python bench/solver_fingerprint.py --compare before.json

Counts (Newton iterations per step, factorisations, chord steps, Krylov iterations) are
deterministic on one machine; answers are compared with a tolerance.
"""

from __future__ import annotations

import argparse
import json
import sys

import numpy as np
from mpi4py import MPI

from fem_sim import Constraint, NodalLoad, OgdenMaterial, OgdenProblem, PatchLoad
from fem_sim.geometry.phantom import make_phantom

MAT = OgdenMaterial((4.1e-3,), (10.06,), 0.82)
CONFIGS = {
    "default": {},
    "double": {"factorization": "double"},
    "petsc": {"factorization": "petsc"},
    "tangent": {"predictor": "tangent"},
    "euler": {"predictor_order": 1},
    "extrapolate": {"predictor": "extrapolate"},
    "plain": {"predictor": "previous", "chord_contraction": 0.0},
    "gamg": {"linear_solver": "gamg", "max_krylov": 500, "krylov_rtol": 1e-12},
    "fallback64": {"max_krylov": 1},
    "no_line_search": {"line_search": False},
}


def run(comm) -> dict:
    g = make_phantom(0, 20.0)
    fixed = g.regions["vena_cava"]
    node = int(np.argmax(g.points[:, 0]))
    fractions = np.linspace(0.1, 1.0, 10)
    out = {}
    cases = [(name, 1, st, [NodalLoad([node], [[0.0, -0.3, -0.3]])]) for name, st in
             CONFIGS.items()]
    cases.append(("p2", 2, {}, [NodalLoad([node], [[0.0, -0.3, -0.3]])]))
    cases.append(("patch", 1, {}, [PatchLoad(g.points[node], [0.0, -0.3, -0.3], 15.0)]))
    cases.append(("cutback", 1, {}, [NodalLoad([node], [[0.0, -2.0, -2.0]])]))
    for name, degree, st, loads in cases:
        prob = OgdenProblem(comm, g.points, g.cells, degree=degree,
                            settings={"rtol": 1e-10, **st}, prefix=f"fp_{name}_")
        fr = [1.0] if name == "cutback" else fractions
        s = prob.solve(MAT, [Constraint(fixed)], loads, fr)
        out[name] = {"status": s.status, "its": s.newton_iterations, "cutbacks": s.cutbacks,
                     "factorizations": s.factorizations, "chord": s.chord_steps,
                     "chord_rejected": s.chord_rejected, "krylov": s.krylov_iterations,
                     "fallbacks": s.double_fallbacks,
                     "u": None if s.displacement is None else s.displacement.tolist()}
        if comm.rank == 0:
            print(f"{name:15s} {s.status:6s} its {s.newton_iterations} fact "
                  f"{s.factorizations} chord {s.chord_steps}/{s.chord_rejected} "
                  f"krylov {s.krylov_iterations}", flush=True)
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out")
    ap.add_argument("--compare")
    a = ap.parse_args()
    comm = MPI.COMM_WORLD
    res = run(comm)
    if comm.rank != 0:
        return 0
    if a.out:
        with open(a.out, "w") as fh:
            json.dump(res, fh)
    bad = 0
    if a.compare:
        with open(a.compare) as fh:
            ref = json.load(fh)
        for name, r in ref.items():
            now = res.get(name)
            keys = ("status", "its", "cutbacks", "factorizations", "chord", "chord_rejected",
                    "fallbacks")
            diff = [k for k in keys if now is None or now[k] != r[k]]
            u0, u1 = np.asarray(r["u"]), np.asarray(now["u"]) if now else None
            err = (np.abs(u1 - u0).max() / max(np.abs(u0).max(), 1e-300)
                   if u1 is not None and u1.shape == u0.shape else np.inf)
            ok = not diff and err <= 1e-10
            bad += not ok
            print(f"{name:15s} {'same' if ok else 'DIFFERENT'} counts {diff or 'equal'} "
                  f"answer rel. diff {err:.1e} (krylov {r['krylov']} -> "
                  f"{now['krylov'] if now else '-'})")
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
