"""Newton's stalls on real livers: simulations of a dataset solved again with a baseline's
settings and with others, side by side (docs/solver_stalls.md, docs/guess_guard.md).

    .venv-solver/bin/python bench/solver_stalls.py [--data DIR ...] [--worst 2] [--typical 1]
        [--all] [--baseline '{"stall_iterations": 0}'] [--settings '{}'] [--variants '[...]']
        [--out REPORT] [--title TITLE]

By default the solver's defaults (``settings``, where ``stall_iterations`` gives up an attempt
still far from converging after 10 Newton iterations) against the same without that rule
(``baseline``: every attempt runs to ``max_iterations``). From each dataset (default: the
patient truths bench/patient.py writes, bench/results/patient/<liver>/data), the ``--worst``
simulations with the most factorisations in their own records (a load step where Newton
wandered: an indefinite tangent near the point load) and ``--typical`` of the median ones, or
with ``--all`` every simulation (what a whole dataset costs); each solved with both on one
rank, in alternating order, from the shard's own load, fixed nodes and material. Reported:
factorisations, Newton iterations, cut-backs, seconds, the status, and the largest nodal
difference between the two solutions (the same equilibrium must come out).

The guard on the predictor's guess (docs/guess_guard.md, whose header has the whole command):
the training livers of bench/stalls_lits.toml and bench/stalls_amos.toml, generated first
(their headers say how), ``--all --baseline '{"guess_guard": 0}'`` with ``--variants`` (a JSON
list of more settings, each solved on the same simulations and reported as totals).
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

from liverviz.report import ROOT, write_report

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


def _row(r: dict) -> str:
    d, v = r["baseline"], r["settings"]
    return "| {} {} | {} / {} | {} / {} | {} / {} | {} / {} | {:.1f} | {:.1f} / {:.1f} | {:.1e} |" \
        .format(Path(r["data"]).parent.name if Path(r["data"]).name == "data"
                else Path(r["data"]).name, r["sim"], d["status"], v["status"],
                d["factorizations"], v["factorizations"], d["iterations"], v["iterations"],
                d["cutbacks"], v["cutbacks"], r["max_u_mm"], d["seconds"], v["seconds"],
                r["max_diff_mm"])


def _totals(rows: list[dict]) -> list[str]:
    """One line per dataset: the sums of both runs over its simulations."""
    out = ["| dataset | simulations | failed | factorisations | Newton iterations | cut-backs | "
           "seconds | max difference mm |", "|---|---|---|---|---|---|---|---|"]
    for data in dict.fromkeys(r["data"] for r in rows):
        rs = [r for r in rows if r["data"] == data]

        def both(key, rs=rs):
            return " / ".join(f"{sum(r[k][key] for r in rs):.0f}" for k in ("baseline", "settings"))

        failed = " / ".join(str(sum(r[k]["status"] != "ok" for r in rs))
                            for k in ("baseline", "settings"))
        out.append(f"| {data} | {len(rs)} | {failed} | {both('factorizations')} | "
                   f"{both('iterations')} | {both('cutbacks')} | {both('seconds')} | "
                   f"{max(r['max_diff_mm'] for r in rs):.1e} |")
    return out


def _variants(rows: list[dict], settings: dict, variants: list[dict]) -> list[str]:
    """The variants' totals beside the baseline's and the settings' (all datasets)."""
    runs = [("baseline", settings["baseline"], [r["baseline"] for r in rows]),
            ("settings", settings["settings"], [r["settings"] for r in rows])]
    runs += [(f"variant {i + 1}", v, [r["variants"][i] for r in rows])
             for i, v in enumerate(variants)]
    base = sum(r["factorizations"] for r in runs[0][2])
    out = ["Variants, each over the solver's defaults, on the same simulations (their "
           "difference against the baseline):", "",
           "| run | settings | factorisations | ratio to the baseline | Newton iterations | "
           "cut-backs | failed | max difference mm |", "|---|---|---|---|---|---|---|---|"]
    for name, v, rs in runs:
        f = sum(r["factorizations"] for r in rs)
        diff = ("" if name == "baseline" else
                f"{max(r['max_diff_mm'] for r in (rows if name == 'settings' else rs)):.1e}")
        out.append(f"| {name} | `{json.dumps(v)}` | {f} | {f / base:.3f} | "
                   f"{sum(r['iterations'] for r in rs)} | {sum(r['cutbacks'] for r in rs)} | "
                   f"{sum(r['status'] != 'ok' for r in rs)} | {diff} |")
    return out


def report(rows: list[dict], settings: dict, every: bool, variants=()) -> str:
    shown = [r for r in rows if not every
             or r["baseline"]["factorizations"] != r["settings"]["factorizations"]]
    out = [f"Baseline `{json.dumps(settings['baseline'])}` against "
           f"`{json.dumps(settings['settings'])}` (over the solver's defaults), one rank each, "
           "on the same simulations (a shard's load, fixed nodes and material solved again). "
           "Each cell: baseline / settings.", "", *_totals(rows), "",
           ("The simulations whose factorisations differ:" if every else "Each simulation:"),
           "", "| liver, simulation | status | factorisations | Newton iterations | "
           "cut-backs | max displacement mm | seconds | max difference mm |",
           "|---|---|---|---|---|---|---|---|", *map(_row, shown)]
    fd, fv = (sum(r[k]["factorizations"] for r in rows) for k in ("baseline", "settings"))
    sd, sv = (sum(r[k]["seconds"] for r in rows) for k in ("baseline", "settings"))
    out += ["", f"In all: {fd} factorisations with the baseline, {fv} with the settings "
            f"(ratio {fv / fd:.2f}); {sd:.0f} s against {sv:.0f} s (ratio {sv / sd:.2f}, "
            "one run each: the counts are the steadier figure). Max difference: the largest "
            "nodal distance between the two solutions over the load steps (both converged to "
            "Newton's tolerance; exactly 0 where both took the same path)."]
    if variants:
        out += ["", *_variants(rows, settings, list(variants))]
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
    ap.add_argument("--all", action="store_true", help="every simulation of each dataset")
    ap.add_argument("--out", default=str(ROOT / "docs" / "solver_stalls.md"), help="report")
    ap.add_argument("--title", default="Newton's stalls on real livers")
    ap.add_argument("--variants", default="[]",
                    help="JSON list: more settings solved on the same simulations, reported "
                    "as totals")
    a = ap.parse_args()
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
