"""Hard cases beside the easy one: what a liver and a load that make Newton work cost.

The easy case: the SOFA liver, 0.4 N along -z on the surface node farthest from the fixed
region. The hard ones change one thing: the phantom, a thin-lobe phantom, 2x and 5x the force,
scene 3's softest material. Per row: Newton iterations per step, factorisations, back-solves,
chord steps, cut-backs, fallbacks, seconds, and factorisations relative to the easy case.

    .venv-solver/bin/python bench/bench_hard.py [--h 5] [--runs 1] [--settings '{"k": v}']
        [--md docs/solver.md]   # the report (header: machine, date, commit, command)
        [--textbook]   # also the textbook dolfinx solver on the easy case, side by side
        [--elements 16 12]   # also P2 against P1 on the same meshes (easy load)
        [--batch 3]   # also 3 more easy-case simulations on the first one's problem

``--settings`` runs a solver variant against the defaults in the same run (the same load).
"""

from __future__ import annotations

import argparse
import json
import logging
import sys
import time

import numpy as np
from mpi4py import MPI

from fem_sim import Constraint, NodalLoad, OgdenMaterial, OgdenProblem
from liverviz.report import ROOT, SOFA, capture

NOMINAL = np.array([0.0, 0.0, -0.4])  # N
C1, M1 = 4.1e-3, 10.06
CASES = {  # name -> (liver, force scale, (c1, m1))
    "easy: real liver": ("sofa", 1.0, (C1, M1)),
    "phantom": ("phantom", 1.0, (C1, M1)),
    "thin-lobe phantom": ("thin", 1.0, (C1, M1)),
    "real liver, softest scene-3 material": ("sofa", 1.0, (2e-3, 6.0)),
    "real liver, 2x force": ("sofa", 2.0, (C1, M1)),
    "real liver, 5x force": ("sofa", 5.0, (C1, M1)),
}


def thin_lobe_seed() -> int:
    from fem_sim.geometry.phantom import phantom_parameters

    return min(range(100), key=lambda s: phantom_parameters(s).left_axes[2])


_MESHES: dict = {}


def liver(kind: str, h: float):
    """(geometry, fixed nodes, load node) of a liver: the load on the free surface node
    farthest from the fixed region."""
    if (kind, h) not in _MESHES:
        from fem_sim.geometry.phantom import make_phantom
        from fem_sim.geometry.repair import mesh_surface_file

        if kind == "sofa":
            g = mesh_surface_file(SOFA, h)
        else:
            g = make_phantom(thin_lobe_seed() if kind == "thin" else 0, h)
        fixed = g.regions["vena_cava"]
        surf = np.setdiff1d(g.surface_nodes, fixed)
        d = np.linalg.norm(g.points[surf][:, None] - g.points[fixed][None], axis=2).min(axis=1)
        _MESHES[kind, h] = (g, fixed, int(surf[np.argmax(d)]))
    return _MESHES[kind, h]


def run_case(name: str, h: float, settings: dict, degree: int = 1,
             prob: OgdenProblem | None = None) -> dict:
    """One simulation of a case, on a new OgdenProblem unless ``prob`` is given (a batch
    solves many simulations on one problem, which keeps the small-strain factorisation)."""
    kind, scale, (c1, m1) = CASES[name]
    g, fixed, node = liver(kind, h)
    mat = OgdenMaterial((c1,), (m1,), 100 * c1)
    if prob is None:
        prob = OgdenProblem(MPI.COMM_WORLD, g.points, g.cells, degree=degree,
                            settings={"rtol": 1e-10, "atol": 1e-12, **settings})
    t0 = time.perf_counter()
    sol = prob.solve(mat, [Constraint(fixed)], [NodalLoad([node], [scale * NOMINAL])],
                     np.linspace(0.1, 1.0, 10))
    secs = time.perf_counter() - t0
    return {"case": name, "nodes": g.n_nodes, "status": sol.status, "seconds": secs,
            "its": sol.newton_iterations, "factorizations": sol.factorizations,
            "back_solves": sol.back_solves, "chord": sol.chord_steps,
            "reused": sol.reused_factorizations, "problem": prob,
            "fallbacks": sol.cholesky_fallbacks + sol.double_fallbacks,
            "cutbacks": int(sum(sol.cutbacks)),
            "max_u": float(np.linalg.norm(sol.displacement[-1], axis=1).max())
            if sol.n_done else float("nan"), "u": sol.displacement}


def main() -> int:
    logging.getLogger().setLevel(logging.WARNING)
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--h", type=float, default=5.0, help="mesh size, mm (5: ~15k nodes)")
    ap.add_argument("--runs", type=int, default=1)
    ap.add_argument("--settings", default=None, help="JSON: a solver variant to compare")
    ap.add_argument("--cases", default=None, help="comma-separated case numbers (1-based)")
    ap.add_argument("--textbook", action="store_true")
    ap.add_argument("--batch", type=int, default=0, metavar="N",
                    help="also N more simulations of the easy case on the problem of its "
                         "first run, as a dataset's simulations on one liver (they reuse the "
                         "small-strain factorisation)")
    ap.add_argument("--elements", type=float, nargs="*", default=None, metavar="H",
                    help="also P2 against P1 on meshes of these sizes (mm)")
    ap.add_argument("--md", default=str(ROOT / "docs/solver.md"),
                    help="the report to write (default: docs/solver.md)")
    a = ap.parse_args()
    with capture(a.md, "Solver: the easy case beside the hard cases and the textbook solver"):
        return _run(a, ap)


def _cases(a, names: list[str]) -> tuple[list, object]:
    """Every case with the defaults (and the variant): (rows, the easy case's problem)."""
    variants = {"defaults": {}}
    if a.settings:
        variants["variant"] = json.loads(a.settings)
    rows, easy_problem = [], None
    for name in names:
        per = {}
        for vname, settings in variants.items():
            recs = [run_case(name, a.h, settings) for _ in range(a.runs)]
            rec = recs[0]
            problems = [r.pop("problem") for r in recs]  # each holds its factorisations
            if a.batch and name == "easy: real liver" and vname == "defaults":
                easy_problem = problems[0]  # --batch goes on with it
            del problems
            rec["seconds"] = float(np.median([r["seconds"] for r in recs]))
            per[vname] = rec
        if "variant" in per and per["variant"]["status"] == per["defaults"]["status"] == "ok":
            ua, ub = per["variant"]["u"], per["defaults"]["u"]
            per["variant"]["diff"] = max(np.linalg.norm(x - y) / np.linalg.norm(y)
                                         for x, y in zip(ua, ub))
        rows += list(per.items())
        for vname, r in per.items():
            print(f"  {name} [{vname}]: {r['status']}, {r['seconds']:.1f} s, its {r['its']}, "
                  f"{r['factorizations']} factorisations", flush=True)
    return rows, easy_problem


def _table(rows: list) -> None:
    easy = {v: r["factorizations"] for v, r in rows if r["case"] == "easy: real liver"}
    print("\n| case | solver | nodes | max abs u mm | Newton its per step | factorisations | "
          "x easy | back-solves | chord steps | cut-backs | fallbacks | s / sim | vs defaults |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    for vname, r in rows:
        ratio = (f"{r['factorizations'] / easy[vname]:.2f}" if vname in easy else "-")
        diff = f"rel. diff {r['diff']:.1e}" if "diff" in r else ""
        print(f"| {r['case']} | {vname} | {r['nodes']} | {r['max_u']:.1f} | "
              f"{' '.join(map(str, r['its']))} | {r['factorizations']} | {ratio} | "
              f"{r['back_solves']} | {r['chord']} | {r['cutbacks']} | {r['fallbacks']} | "
              f"{r['seconds']:.1f} | {diff} |")


def _easy(rows: list) -> dict:
    return next(r for v, r in rows if v == "defaults" and r["case"] == "easy: real liver")


def _batch(a, rows: list, easy_problem) -> None:
    """More simulations of the easy case on its problem, as a dataset runs them."""
    first = _easy(rows)
    later = [run_case("easy: real liver", a.h, {}, prob=easy_problem) for _ in range(a.batch)]
    diff = max(max(np.linalg.norm(x - y) / np.linalg.norm(y)
                   for x, y in zip(r["u"], first["u"])) for r in later)
    each = ", ".join(f"{r['seconds']:.1f}" for r in later)
    print(f"\neasy case, {a.batch} more simulations on the same problem (as in a "
          f"dataset): {float(np.median([r['seconds'] for r in later])):.1f} s median "
          f"({each}), factorisations "
          f"{[r['factorizations'] for r in later]}, reused {[r['reused'] for r in later]}; "
          f"largest relative difference to the first {diff:.1e}")


def _elements(a) -> None:
    """The locking-free element's price: P2 against P1 on the same mesh and against P1 on
    the shipped scenes' 8 mm mesh. Accuracy of each: docs/tradeoff_fem.md."""
    print("\n| liver | h mm | element | Newton its per step | factorisations | "
          "x P1 same mesh | back-solves | s / sim | x P1 at 8 mm |")
    print("|---|---|---|---|---|---|---|---|---|")
    for name in ("easy: real liver", "phantom"):
        shipped = run_case(name, 8.0, {})
        table = [(8.0, 1, shipped, shipped)]
        for h in a.elements:
            p1 = run_case(name, h, {})
            table += [(h, 1, p1, p1), (h, 2, run_case(name, h, {}, degree=2), p1)]
        for h, degree, r, p1 in table:
            print(f"| {CASES[name][0]} | {h:g} | P{degree} | "
                  f"{' '.join(map(str, r['its']))} | {r['factorizations']} | "
                  f"{r['factorizations'] / p1['factorizations']:.2f} | "
                  f"{r['back_solves']} | {r['seconds']:.1f} | "
                  f"{r['seconds'] / shipped['seconds']:.2f} |", flush=True)


def _textbook(a, rows: list) -> None:
    """The textbook dolfinx solver (fem_sim.solver.textbook) on the easy case."""
    from fem_sim.solver.textbook import textbook_simulation

    g, fixed, node = liver("sofa", a.h)
    mat = OgdenMaterial((C1,), (M1,), 100 * C1)
    u_tb, its, secs, _ = textbook_simulation(g, fixed, node, NOMINAL, mat,
                                             np.linspace(0.1, 1.0, 10))
    ours = _easy(rows)
    diff = max(np.linalg.norm(x - y) / np.linalg.norm(y) for x, y in zip(u_tb, ours["u"]))
    print(f"\ntextbook dolfinx on the easy case: {secs:.1f} s, Newton its {its} "
          f"({sum(its)} factorisations); fem_sim {ours['seconds']:.1f} s: "
          f"{secs / ours['seconds']:.1f}x; the two answers differ by {diff:.1e} (largest "
          "relative L2 difference over the load steps)")


def _run(a, ap) -> int:
    names = list(CASES)
    if a.cases:
        names = [names[int(i) - 1] for i in a.cases.split(",")]
    print(f"mesh size {a.h} mm, P1, 10 load steps, rtol 1e-10; thin-lobe phantom = seed "
          f"{thin_lobe_seed()}; {MPI.COMM_WORLD.size} rank(s); variant: {a.settings or '-'}")
    if a.batch and "easy: real liver" not in names:
        ap.error("--batch continues the easy case: include case 1")
    rows, easy_problem = _cases(a, names)
    _table(rows)
    if a.batch:
        _batch(a, rows, easy_problem)
    if a.elements:
        _elements(a)
    if a.textbook:
        _textbook(a, rows)
    return 0


if __name__ == "__main__":
    sys.exit(main())
