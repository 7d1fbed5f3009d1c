"""Write docs/extremes.md: the outcome of every extreme case (tests/extremes/cases.py).

.venv-solver/bin/python -m scripts.extremes_doc [docs/extremes.md]     (make extremes-doc)
"""

from __future__ import annotations

import logging
import platform
import sys
import time
from pathlib import Path

import numpy as np

from liverviz.report import header
from tests.extremes.cases import MESH_SIZE, extremes, liver, simulate

ROOT = Path(__file__).resolve().parents[1]


def main(out: str = "docs/extremes.md") -> int:
    logging.getLogger().setLevel(logging.WARNING)
    rows = run_cases()
    lines = report_lines(rows)
    Path(out).parent.mkdir(parents=True, exist_ok=True)
    Path(out).write_text("\n".join(lines) + "\n")
    print(f"wrote {out}")
    return 1 if any(r[1] != "ok" for r in rows) else 0


def run_cases() -> list[tuple]:
    """Each extreme case simulated: (case, outcome, steps, cut-backs, Newton iterations,
    factorisations, max |u| mm, seconds); an exception recorded as its outcome.
    """
    rows = []
    for case in extremes():
        t0 = time.perf_counter()
        try:
            _, sol = simulate(case)
            status = sol.status if sol.status == "ok" else f"failed: {sol.failure_reason}"
            umax = float(np.abs(sol.displacement).max()) if sol.n_done else float("nan")
            rows.append((case, status, f"{sol.n_done}/{len(case.fractions)}",
                         sum(sol.cutbacks), " ".join(map(str, sol.newton_iterations)),
                         sol.factorizations, umax, time.perf_counter() - t0))
        except Exception as exc:  # recorded, never hidden
            rows.append((case, f"raised {type(exc).__name__}: {exc}", "-", "-", "-", "-",
                         float("nan"), time.perf_counter() - t0))
        print(case.name, rows[-1][1], flush=True)
    return rows


def report_lines(rows: list[tuple]) -> list[str]:
    """docs/extremes.md's lines: the cases' outcomes and what is refused before any work."""
    n = {name: liver(name)[0].n_nodes for name in sorted({c.liver for c in extremes()})}
    failing = [r for r in rows if r[1] != "ok"]
    lines = [
        *header("Stability at the extremes").rstrip().split("\n"),
        "",
        "The same cases are the "
        "tests of `make test-extremes` (`tests/extremes/`), which also check equilibrium, "
        "positive work, stiffening with force, the K/mu trend and path independence.",
        f"Meshes: {', '.join(f'{k} {v} nodes' for k, v in n.items())} (h = {MESH_SIZE:g} mm), "
        "P1, default solver settings, one rank; "
        f"{platform.processor() or platform.machine()}.",
        "",
        f"**{len(rows) - len(failing)} of {len(rows)} cases converge through every load step; "
        + (f"{len(failing)} fail: see below.**" if failing else "none fails.**"),
        "",
        "| case | what | outcome | steps | cut-backs | Newton its per step | factorisations "
        "| max abs u mm | s |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for case, status, steps, cut, its, fac, umax, secs in rows:
        lines.append(f"| {case.name} | {case.why} | {status} | {steps} | {cut} | {its} | {fac} "
                     f"| {umax:.3g} | {secs:.2f} |")
    lines += [
        "",
        "Refused before any simulation or MPI work, with the file and the reason "
        "(`fem_sim/geometry/quality.py`; tests: `tests/fem_sim/test_geometry.py::"
        "test_tangled_degenerate_and_floating_meshes_are_refused`, "
        "`tests/fem_sim/test_generate.py::test_mesh_with_a_floating_piece_is_refused_before_any_work`):",
        "",
        "- a tangled mesh (an element folded over its neighbour, or a duplicated element);",
        "- a flat (zero-volume or mean-ratio quality < 1e-4) element;",
        "- a piece of the mesh that touches no fixed node.",
        "",
        "A sliver-heavy mesh (half the elements with mean-ratio quality < 0.05) is accepted with "
        "a warning and reproduces a homogeneous state to 1e-8 "
        "(`tests/extremes/test_extremes.py::test_sliver_heavy_mesh_reproduces_a_homogeneous_state`).",
        "",
        "Reading the K/mu rows: at fixed force the displacement keeps falling as K/mu grows "
        "from 1,000 to 10,000 on P1. Part of that is physics (less volume change), part is "
        "volumetric locking of linear tetrahedra; docs/tradeoff_fem.md measures it against P2.",
    ]
    return lines


if __name__ == "__main__":
    sys.exit(main(*sys.argv[1:]))
