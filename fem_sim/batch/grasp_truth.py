"""The FE truth of grasps on one liver file, beside the small-strain base a model of grasps
adds its rest to (solver environment).

    .venv-solver/bin/python -m fem_sim.batch.grasp_truth LIVER --scene SCENE --out FILE.npz
        [--grasps 1] [--pulls 5 10 20 30 40]

The liver is meshed, turned and fixed as the population of SCENE (liver files) prepares its
livers (:func:`fem_sim.geometry.file_population.prepare`: its nodes in the population's
frame); each tool holds the 10 mm patch around a surface node at least 30 mm from the fixed
region (drawn from the liver's name: bench/surgical_loads.py's grasps) and pulls it away from
the fixed region, stored at the pulls asked; the base is the liver's Green's function on the
patch (:class:`data_spec.green_grasp.GreenGrasp`). FILE holds the mesh (points, surface
triangles, fixed nodes) and per grasp ``k``: its centre and pull, ``patch_k``, ``truth_k`` and
``base_k`` (steps, nodes, 3) mm, ``fe_force_k`` and ``base_force_k`` (steps, 3) N, and the
solver's record.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
import zlib
from pathlib import Path

import numpy as np

RADIUS = 10.0   # mm, the tool's patch
CLEARANCE = 30.0   # mm from the fixed region to a tool's centre


def grasp_sites(g, fixed, n: int, rng, radius: float = RADIUS) -> np.ndarray:
    """``n`` surface nodes at least 30 mm from the fixed region, 2.5 patches apart."""
    from data_spec.eligible_loads import eligible_load_nodes

    cand = eligible_load_nodes({"eligible": "surface", "min_distance_to_fixed": CLEARANCE},
                               g.points, g.surface_nodes, fixed)
    chosen: list[int] = []
    for node in rng.permutation(cand):
        if len(chosen) < n and all(np.linalg.norm(g.points[node] - g.points[chosen], axis=1)
                                   > 2.5 * radius):
            chosen.append(int(node))
    return np.array(chosen, dtype=np.int64)


def prepared_problem(scene, liver: str | Path):
    """(prepared liver, its fixed nodes, OgdenProblem on one process, material) of a liver
    file as the population of ``scene`` (a loaded scene of liver files) prepares its own.
    """
    from mpi4py import MPI

    from fem_sim import OgdenProblem
    from fem_sim.batch.cases import base_material
    from fem_sim.batch.generate import solver_settings
    from fem_sim.geometry.file_population import prepare, region_name, registrar_of

    g, _, _ = prepare(liver, registrar_of(scene), scene["geometry"]["mesh_size"])
    solver = scene["solver"]
    prob = OgdenProblem(MPI.COMM_SELF, g.points, g.cells, degree=solver["degree"],
                        quadrature_degree=solver["quadrature_degree"],
                        settings=solver_settings(scene))
    return g, g.regions[region_name(scene)], prob, base_material(scene)


def grasp_case(prob, mat, fixed, patch, d, green, held, fractions):
    """(solution, base fields (steps, nodes, 3) mm, base forces (steps, 3) N) of one tool
    pulled by ``d`` (3,) mm, stored at ``fractions`` of it; ``green``: the unit responses at
    the nodes ``held`` (the patch among them).
    """
    from data_spec.green_grasp import GreenGrasp
    from fem_sim import Constraint

    sol = prob.solve(mat, [Constraint(fixed), Constraint(patch, values=d)], [], fractions,
                     reactions=[patch])
    grasp = GreenGrasp(green, held, np.arange(prob.n_nodes), [patch])
    base, force = [], []
    for s in range(sol.n_done):
        u, f = grasp(fractions[s] * np.asarray(d)[None])
        base.append(u)
        force.append(f[0])
    return sol, np.reshape(base, (-1, prob.n_nodes, 3)), np.reshape(force, (-1, 3))


PULLS = (5.0, 10.0, 20.0, 30.0, 40.0)   # mm, the stored steps of a tool's pull


def grasp_truth(scene_file, liver, n_grasps: int = 1, pulls=PULLS) -> dict:
    """The arrays of the module's FILE for ``n_grasps`` tools on the liver file ``liver``."""
    from data_spec import load_scene
    from data_spec.eligible_loads import grasp_patch
    from fem_sim import Constraint
    from fem_sim.batch.cases import load_directions

    scene = load_scene(scene_file)
    g, fixed, prob, mat = prepared_problem(scene, liver)
    rng = np.random.default_rng(zlib.crc32(Path(liver).stem.encode()))
    centres = grasp_sites(g, fixed, n_grasps, rng)
    patches = [grasp_patch(g.points, g.surface_nodes, c, RADIUS) for c in centres]
    held = np.unique(np.concatenate(patches))
    green = prob.unit_responses(mat, [Constraint(fixed)], held)
    pull = float(pulls[-1]) * load_directions(rng, "away", g.points[centres], g.points[fixed])
    out = {"points": g.points, "triangles": g.surface_triangles, "fixed": fixed,
           "centres": centres, "pulls": pull, "fractions": np.asarray(pulls) / pulls[-1]}
    records = []
    for k, patch in enumerate(patches):
        t = time.perf_counter()
        sol, base, force = grasp_case(prob, mat, fixed, patch, pull[k], green, held,
                                      out["fractions"])
        records.append({"status": sol.status, "reason": sol.failure_reason,
                        "steps": int(sol.n_done), "seconds": time.perf_counter() - t,
                        "factorizations": sol.factorizations})
        out.update({f"patch_{k}": patch, f"truth_{k}": sol.displacement[:sol.n_done],
                    f"fe_force_{k}": sol.reaction[:sol.n_done, 0], f"base_{k}": base,
                    f"base_force_{k}": force})
    out["records"] = json.dumps(records)
    return out


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("liver", help="a liver surface file")
    p.add_argument("--scene", required=True, help="a population scene of liver files")
    p.add_argument("--out", required=True, help="the .npz to write")
    p.add_argument("--grasps", type=int, default=1)
    p.add_argument("--pulls", type=float, nargs="+", default=PULLS, help="mm, increasing")
    a = p.parse_args(argv)
    out = Path(a.out)
    if out.suffix != ".npz" or not Path(a.liver).is_file():
        print(f"grasp_truth: expected a liver file and an --out .npz, got {a.liver} and "
              f"{out}", file=sys.stderr)
        return 2
    arrays = grasp_truth(a.scene, a.liver, a.grasps, a.pulls)
    out.parent.mkdir(parents=True, exist_ok=True)
    with open(out, "wb") as fh:
        np.savez_compressed(fh, **arrays)
    print(f"wrote {out}: {arrays['records']}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
