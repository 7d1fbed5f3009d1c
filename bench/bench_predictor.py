"""Load-step predictors: factorisations and seconds per simulation with the Hermite predictor
(default) and the tangent predictor, on the phantom, the same random loads and materials for
both. Runs under mpirun too (one simulation over all ranks: PETSc's MUMPS path).

    OPENBLAS_NUM_THREADS=1 .venv-solver/bin/python bench/bench_predictor.py [--h 8] [--sims 8]
    OPENBLAS_NUM_THREADS=1 mpirun -n 2 .venv-solver/bin/python bench/bench_predictor.py

Loads: 0.4 N in a random direction on a random surface node; materials: c1 in [2, 6] kPa,
m in [6, 14], K = 0.5 MPa; 10 load steps. Prints a table (means over --sims simulations).
"""

from __future__ import annotations

import argparse
import logging
import time

import numpy as np
from mpi4py import MPI

from fem_sim import Constraint, NodalLoad, OgdenMaterial, OgdenProblem
from fem_sim.geometry.phantom import make_phantom


def main() -> None:
    logging.getLogger().setLevel(logging.WARNING)
    ap = argparse.ArgumentParser()
    ap.add_argument("--h", type=float, default=8.0)
    ap.add_argument("--sims", type=int, default=8)
    a = ap.parse_args()
    comm = MPI.COMM_WORLD
    g = make_phantom(0, a.h)
    fixed = g.regions["vena_cava"]
    surf = np.setdiff1d(g.surface_nodes, fixed)
    rows = []
    for pred in ("tangent", "hermite"):
        prob = OgdenProblem(comm, g.points, g.cells, settings={"predictor": pred},
                            prefix=f"{pred}_")
        rng = np.random.default_rng(0)
        secs, facts, status = [], [], []
        for _ in range(a.sims):
            node = int(rng.choice(surf))
            d = rng.normal(size=3)
            d *= 0.4 / np.linalg.norm(d)
            mat = OgdenMaterial((rng.uniform(2e-3, 6e-3),), (rng.uniform(6, 14),), 0.5)
            t0 = time.perf_counter()
            s = prob.solve(mat, [Constraint(fixed)], [NodalLoad([node], [d])],
                           np.linspace(0.1, 1.0, 10))
            secs.append(time.perf_counter() - t0)
            facts.append(s.factorizations)
            status.append(s.status)
        rows.append((pred, prob.factorization, np.mean(secs), np.mean(facts),
                     status.count("ok")))
    if comm.rank == 0:
        print(f"phantom h = {a.h} mm ({g.n_nodes} nodes), {a.sims} simulations, "
              f"{comm.size} rank(s)")
        print("| predictor | factorisation | s / simulation | factorisations / simulation "
              "| converged |")
        print("|---|---|---|---|---|")
        for pred, fact, t, f, ok in rows:
            print(f"| {pred} | {fact} | {t:.3f} | {f:.1f} | {ok}/{a.sims} |")


if __name__ == "__main__":
    main()
