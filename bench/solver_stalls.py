"""Newton's stalls on real livers: simulations of a dataset solved again with a baseline's
settings and with others, side by side (docs/solver_stalls.md, docs/guess_guard.md).

    .venv-solver/bin/python bench/solver_stalls.py [--data DIR ...] [--worst 2] [--typical 1]
        [--all] [--baseline '{"stall_iterations": 0}'] [--settings '{}'] [--variants '[...]']
        [--out REPORT] [--title TITLE] [--report-only]

By default the solver's defaults (``stall_iterations`` gives up an attempt still far from
converging after 10 Newton iterations) against the same without that rule, on the ``--worst``
simulations of each dataset (most factorisations; default: bench/patient.py's truths) and
``--typical`` median ones, or ``--all``; each solved with both on one rank, in alternating
order, from the shard's own load, fixed nodes and material: factorisations, iterations,
cut-backs, seconds, status and the largest nodal difference of the two solutions. The guess
guard (docs/guess_guard.md, its header has the command): bench/stalls_*.toml's livers, ``--all
--baseline '{"guess_guard": 0}'`` with ``--variants``.
"""

from __future__ import annotations

import argparse
import functools
import json
import sys
import time
from pathlib import Path

import numpy as np
from mpi4py import MPI

from liverviz.report import ROOT, render, write_report

PATIENTS = ROOT / "bench" / "results" / "patient"


def chosen(data: Path, worst: int, typical: int, every: bool = False) -> list[int]:
    """The shards' indices: the ``worst`` by factorisations, and ``typical`` median ones (or
    all of them with ``every``).
    """
    from data_spec import list_shards, read_shard

    f = {sh.sim_index: int(sh.stats.info["factorizations"])
         for sh in map(read_shard, list_shards(data))}
    order = sorted(f, key=lambda i: (f[i], i))
    if every:
        return sorted(order)
    mid = len(order) // 2
    return sorted(order[::-1][:worst]) + order[mid:mid + typical]


@functools.cache
def _problem(data: Path, geometry_id: str, settings: str):
    """One problem per mesh and settings (its forms and factorisation plan built once)."""
    from data_spec import read_geometry
    from data_spec.shards import geometry_path
    from fem_sim.solver.problem import OgdenProblem

    g = read_geometry(geometry_path(data, geometry_id))
    return OgdenProblem(MPI.COMM_SELF, g.points, g.cells, degree=2, quadrature_degree=2,
                        settings=json.loads(settings))


def solve(data: Path, index: int, settings: dict) -> dict:
    """One stored simulation solved again with ``settings`` on one rank."""
    from data_spec import read_shard
    from fem_sim.solver.problem import Constraint, NodalLoad

    sh = read_shard(data / "sims" / f"sim_{index:06d}.h5")
    p = _problem(data, sh.geometry_id, json.dumps(settings, sort_keys=True))
    constraints, loads = [Constraint(sh.fixed_nodes)], [NodalLoad(sh.load_nodes, sh.forces)]
    if sh.load_kind == "grasp":   # each tool's patch moved by its pull
        constraints, loads = constraints + _tools(data, sh), []
    t = time.perf_counter()
    sol = p.solve(sh.material, constraints, loads, sh.load_fractions)
    return {"seconds": time.perf_counter() - t, "status": sol.status,
            "factorizations": int(sol.factorizations),
            "iterations": int(np.sum(sol.newton_iterations)),
            "cutbacks": int(np.sum(sol.cutbacks)), "u": sol.displacement}


def _tools(data: Path, sh) -> list:
    """A grasp shard's tools: each patch (the scene's radius) moved by its full pull."""
    from data_spec import load_scene, read_geometry
    from data_spec.eligible_loads import grasp_patch
    from data_spec.shards import geometry_path
    from fem_sim.solver.problem import Constraint

    g = read_geometry(geometry_path(data, sh.geometry_id))
    radius = load_scene(data / "scene.toml")["loads"]["patch_radius"]
    pull = sh.tool_displacement[-1] / sh.load_fractions[-1]
    return [Constraint(grasp_patch(g.points, g.surface_nodes, n, radius), values=d)
            for n, d in zip(sh.load_nodes, pull)]


def _difference(u0: np.ndarray, u1: np.ndarray) -> float:
    """The largest nodal distance between two solutions over their common load steps."""
    n = min(len(u0), len(u1))
    return float(np.linalg.norm(u0[:n] - u1[:n], axis=2).max()) if n else float("nan")


def compared(data: Path, index: int, settings: dict, k: int, variants=()) -> dict:
    """Both settings on one simulation (the second first on every other one), then each of
    ``variants`` (its difference measured against the baseline).
    """
    runs = {}
    for name in (("baseline", "settings") if k % 2 == 0 else ("settings", "baseline")):
        runs[name] = solve(data, index, settings[name])
    u0, u1 = runs["baseline"].pop("u"), runs["settings"].pop("u")
    others = []
    for v in variants:
        run = solve(data, index, v)
        others.append(run | {"max_diff_mm": _difference(u0, run.pop("u"))})
    return {"data": str(data.relative_to(ROOT)), "sim": index, **runs,
            "max_diff_mm": _difference(u0, u1), "variants": others,
            "max_u_mm": float(np.linalg.norm(u0[-1], axis=1).max()) if len(u0) else 0.0}


def report(rows: list[dict], settings: dict, every: bool, variants=()) -> str:
    """The report's body (bench/templates/solver_stalls.md.j2)."""
    def dataset_name(data: str) -> str:   # a patient truth's liver, else the folder's name
        return Path(data).parent.name if Path(data).name == "data" else Path(data).name

    return render(Path(__file__).parent / "templates" / "solver_stalls.md.j2", rows=rows,
                  settings=settings, every=every, variants=list(variants),
                  datasets=list(dict.fromkeys(r["data"] for r in rows)),
                  dataset_name=dataset_name, settings_json=json.dumps).rstrip("\n")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", nargs="+", default=None,
                    help="datasets (default: bench/results/patient/*/data)")
    ap.add_argument("--worst", type=int, default=2)
    ap.add_argument("--typical", type=int, default=1)
    ap.add_argument("--baseline", default='{"stall_iterations": 0}',
                    help="JSON: the baseline's OgdenProblem settings over the defaults")
    ap.add_argument("--settings", default="{}", help="JSON: the settings compared with it")
    ap.add_argument("--all", action="store_true", help="every simulation of each dataset")
    ap.add_argument("--out", default=str(ROOT / "docs" / "solver_stalls.md"), help="report")
    ap.add_argument("--title", default="Newton's stalls on real livers")
    ap.add_argument("--variants", default="[]",
                    help="JSON list: more settings solved on the same simulations, reported "
                    "as totals")
    ap.add_argument("--report-only", action="store_true", help="rewrite --out from the JSON "
                    "beside it (with --all if it was run with it)")
    a = ap.parse_args()
    if a.report_only:
        saved = json.loads(Path(a.out).with_suffix(".json").read_text())
        write_report(a.out, a.title, report(saved["rows"], saved["settings"], a.all,
                                            saved.get("variants", ())), saved)
        return 0
    settings = {"baseline": json.loads(a.baseline), "settings": json.loads(a.settings)}
    variants = json.loads(a.variants)
    sets = [Path(d).resolve() for d in a.data] if a.data else sorted(
        p.parent / "data" for p in PATIENTS.glob("*/k.json"))
    if not sets:
        ap.error("no dataset: run bench/patient.py first, or name them with --data")
    rows, k = [], 0
    for data in sets:
        for index in chosen(data, a.worst, a.typical, a.all):
            rows.append(compared(data, index, settings, k, variants))
            k += 1
            print(json.dumps({key: rows[-1][key] for key in ("data", "sim", "max_diff_mm")}
                             | {s: rows[-1][s]["factorizations"]
                                for s in ("baseline", "settings")}), flush=True)
    write_report(a.out, a.title, report(rows, settings, a.all, variants),
                 {"settings": settings, "variants": variants, "rows": rows})
    return 0


if __name__ == "__main__":
    sys.exit(main())
