"""Newton's stalls on real livers: simulations of a dataset solved again with a baseline's
settings and with others, side by side (docs/solver_stalls.md).

    .venv-solver/bin/python bench/solver_stalls.py [--data DIR ...] [--worst 2] [--typical 1]
        [--baseline '{"stall_iterations": 0}'] [--settings '{}']

By default the solver's defaults (``settings``, where ``stall_iterations`` gives up an attempt
still far from converging after 10 Newton iterations) against the same without that rule
(``baseline``: every attempt runs to ``max_iterations``). From each dataset (default: the
patient truths bench/patient.py writes, bench/results/patient/<liver>/data), the ``--worst``
simulations with the most factorisations in their own records (a load step where Newton
wandered: an indefinite tangent near the point load) and ``--typical`` of the median ones;
each solved with both on one rank, in alternating order, from the shard's own load,
fixed nodes and material. Reported: factorisations, Newton iterations, cut-backs, seconds,
the status, and the largest nodal difference between the two solutions (the same
equilibrium must come out).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np
from mpi4py import MPI

from liverviz.report import ROOT, write_report

PATIENTS = ROOT / "bench" / "results" / "patient"


def chosen(data: Path, worst: int, typical: int) -> list[int]:
    """The shards' indices: the ``worst`` by factorisations, and ``typical`` median ones."""
    from data_spec import list_shards, read_shard

    f = {sh.sim_index: int(sh.stats.info["factorizations"])
         for sh in map(read_shard, list_shards(data))}
    order = sorted(f, key=lambda i: (f[i], i))
    mid = len(order) // 2
    return sorted(order[::-1][:worst]) + order[mid:mid + typical]


def solve(data: Path, index: int, settings: dict) -> dict:
    """One stored simulation solved again with ``settings`` on one rank."""
    from data_spec import read_geometry, read_shard
    from data_spec.shards import geometry_path
    from fem_sim.solver.problem import Constraint, NodalLoad, OgdenProblem

    sh = read_shard(data / "sims" / f"sim_{index:06d}.h5")
    g = read_geometry(geometry_path(data, sh.geometry_id))
    p = OgdenProblem(MPI.COMM_SELF, g.points, g.cells, degree=2, quadrature_degree=2,
                     settings=settings)
    t = time.perf_counter()
    sol = p.solve(sh.material, [Constraint(sh.fixed_nodes)],
                  [NodalLoad(sh.load_nodes, sh.forces)], sh.load_fractions)
    return {"seconds": time.perf_counter() - t, "status": sol.status,
            "factorizations": int(sol.factorizations),
            "iterations": int(np.sum(sol.newton_iterations)),
            "cutbacks": int(np.sum(sol.cutbacks)), "u": sol.displacement}


def compared(data: Path, index: int, settings: dict, k: int) -> dict:
    """Both settings on one simulation (the second first on every other one)."""
    runs = {}
    for name in (("baseline", "settings") if k % 2 == 0 else ("settings", "baseline")):
        runs[name] = solve(data, index, settings[name])
    u0, u1 = runs["baseline"].pop("u"), runs["settings"].pop("u")
    n = min(len(u0), len(u1))
    diff = float(np.linalg.norm(u0[:n] - u1[:n], axis=2).max()) if n else float("nan")
    return {"data": str(data.relative_to(ROOT)), "sim": index, **runs, "max_diff_mm": diff,
            "max_u_mm": float(np.linalg.norm(u0[-1], axis=1).max()) if len(u0) else 0.0}


def report(rows: list[dict], settings: dict) -> str:
    line = "| {} {} | {} | {} | {} | {} | {} | {:.1f} / {:.1f} | {:.1e} |"
    out = [f"Baseline `{json.dumps(settings['baseline'])}` against "
           f"`{json.dumps(settings['settings'])}` (over the solver's defaults), one rank each, "
           "on the same simulations (a shard's load, fixed nodes and material solved again).",
           "", "| liver, simulation | status | factorisations | Newton iterations | "
           "cut-backs | max displacement mm | seconds | max difference mm |",
           "|---|---|---|---|---|---|---|---|"]
    for r in rows:
        d, v = r["baseline"], r["settings"]
        out.append(line.format(Path(r["data"]).parent.name, r["sim"],
                               f"{d['status']} / {v['status']}",
                               f"{d['factorizations']} / {v['factorizations']}",
                               f"{d['iterations']} / {v['iterations']}",
                               f"{d['cutbacks']} / {v['cutbacks']}", f"{r['max_u_mm']:.1f}",
                               d["seconds"], v["seconds"], r["max_diff_mm"]))
    fd, fv = (sum(r[k]["factorizations"] for r in rows) for k in ("baseline", "settings"))
    sd, sv = (sum(r[k]["seconds"] for r in rows) for k in ("baseline", "settings"))
    out += ["", f"In all: {fd} factorisations with the baseline, {fv} with the settings "
            f"(ratio {fv / fd:.2f}); {sd:.0f} s against {sv:.0f} s (ratio {sv / sd:.2f}, "
            "one run each: the counts are the steadier figure). Each cell: baseline / "
            "settings. A difference of exactly 0: the attempts one gave up early, the other "
            "gave up too at max_iterations, so both cut back the same increments and reach "
            "the same states; otherwise one of them converged an attempt the other cut back "
            "(the two equilibria then agree to the Newton tolerance)."]
    return "\n".join(out)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", nargs="+", default=None,
                    help="datasets (default: bench/results/patient/*/data)")
    ap.add_argument("--worst", type=int, default=2)
    ap.add_argument("--typical", type=int, default=1)
    ap.add_argument("--baseline", default='{"stall_iterations": 0}',
                    help="JSON: the baseline's OgdenProblem settings over the defaults")
    ap.add_argument("--settings", default="{}", help="JSON: the settings compared with it")
    a = ap.parse_args()
    settings = {"baseline": json.loads(a.baseline), "settings": json.loads(a.settings)}
    sets = [Path(d).resolve() for d in a.data] if a.data else sorted(
        p.parent / "data" for p in PATIENTS.glob("*/k.json"))
    if not sets:
        ap.error("no dataset: run bench/patient.py first, or name them with --data")
    rows, k = [], 0
    for data in sets:
        for index in chosen(data, a.worst, a.typical):
            rows.append(compared(data, index, settings, k))
            k += 1
            print(json.dumps({key: rows[-1][key] for key in ("data", "sim", "max_diff_mm")}
                             | {s: rows[-1][s]["factorizations"]
                                for s in ("baseline", "settings")}), flush=True)
    write_report(ROOT / "docs" / "solver_stalls.md", "Newton's stalls on real livers",
                 report(rows, settings), {"settings": settings, "rows": rows})
    return 0


if __name__ == "__main__":
    sys.exit(main())
