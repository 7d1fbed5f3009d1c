"""One FE run of a speed-and-accuracy study, in a process of its own: a liver (the embedded
phantom or the SOFA liver), a 0.4 N load far from its fixed region (a patch or the paper's
nodal load), the defaults with one knob changed (mesh size, element, load steps, tolerance,
factorisation, predictor, K/mu). ``bench/tradeoff_fem.py`` (the price list) and
``bench/budget_fem.py`` (the FE half of the error budget) plan the runs; this module makes one
and records its seconds, Newton work, peak memory and displacement at given points.

    record = run_job({"spec": spec_of("phantom", load="patch", h=8.0, role="mesh"),
                      "eval": None, "out": "u.npz"}, timeout=600)

A run is ``python -m fem_sim.batch.knob_run JOB``: a clean peak-memory figure, and a crash
costs one run. dolfinx is imported only inside the run, so the trainer's environment can read
the study's definitions (:data:`BUDGET_MESHES`, :func:`mesh_name`).
"""

from __future__ import annotations

import json
import os
import resource
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from liverviz.ledger import Ledger
from liverviz.report import ROOT, SOFA

FORCE = [0.0, 0.0, -0.4]  # N
PATCH_RADIUS = 15.0  # mm
DEFAULTS = {"degree": 1, "steps": 10, "rtol": 1e-6, "factorization": "auto",
            "linear_solver": "direct", "predictor": "hermite", "K_over_mu": 200.0}
C1, M1 = 4.1e-3, 10.06  # the Ogden term of every run (MPa, -)
# Keys a liver's runs carry beyond DEFAULTS (they enter the run keys, so runs made under an
# earlier definition are not reused): the real liver's fixed region is the surface triangles
# whose centroid is within 25 mm of a point (see ``mesh``), no longer the surface nodes there.
LIVER_KEYS = {"sofa": {"clamp": "triangles"}}
# The error budget's meshes, (degree, mesh size mm): P2 at 16 mm is the shipped scene 1; its
# reference is P2 at 6 mm, the price list's
BUDGET_MESHES = [(2, 16.0), (1, 12.0), (1, 8.0), (2, 12.0)]
BUDGET_REFERENCE = (2, 6.0)
BUDGET_CASES = 4  # scene-1 load cases solved on each budget mesh
BUDGET_RESULTS = ROOT / "bench" / "results" / "budget_fem"
# the budget's FE records by (case, degree, h)
BUDGET_RUNS = Ledger(BUDGET_RESULTS / "runs.jsonl", key=lambda r: (r["case"], r["degree"], r["h"]))


def mesh_name(degree: int, h: float) -> str:
    """A budget mesh's name: its datasets and runs are kept under it."""
    return f"p{degree}_h{h:g}"


def price_list_error(degree: int, h: float) -> str:
    """Mean / max relative FE error of P``degree`` at mesh size ``h`` on the phantom under a
    nodal load (outside 2h of the load; K/mu 200, 10 steps) against the converged answer, as
    the price list (``bench/tradeoff_fem.py``) wrote it beside its report.
    """
    path = ROOT / "docs" / "tradeoff_fem.json"
    if not path.exists():
        return "n/a"
    for row in json.loads(path.read_text()):
        s = row["spec"]
        if (s["liver"], s["load"], s["role"], row["element"], s["h"], s["K_over_mu"],
                s["steps"]) == ("phantom", "nodal", "mesh", f"P{degree}", h, 200.0, 10):
            return f"{row['errors']['rel_mean']:.2%} / {row['errors']['rel_max']:.2%}"
    return "not in the price list"


def budget_npz(case: int, degree: int, h: float) -> Path:
    """Where a budget case's displacement on a mesh is kept (the reference's holds it at the
    vertices of every budget mesh too, in BUDGET_MESHES order).
    """
    return BUDGET_RESULTS / f"case{case}_{mesh_name(degree, h)}.npz"


def budget_reference_offsets(case: int) -> dict:
    """Where each budget mesh's vertices start in case ``case``'s reference values (the
    reference's npz holds them for every mesh, in BUDGET_MESHES order).
    """
    sizes = []
    for degree, h in BUDGET_MESHES:
        with np.load(budget_npz(case, degree, h)) as z:
            sizes.append(z["nodes"].shape[0])
    return dict(zip(BUDGET_MESHES, np.cumsum([0, *sizes[:-1]])))


def budget_case_errors(case: int, point, degree: int, h: float, predicted, fem: dict,
                       exclude: float) -> dict | None:
    """Node errors of budget case ``case`` on mesh (degree, h): FE (the mesh's answer against
    the reference), surrogate (``predicted``, the network's field at the mesh's nodes, against
    the mesh's answer) and total (the network against the reference); beyond ``exclude`` mm of
    the load ``point`` (a point load has no converged limit there) and at every node (_all),
    the reference's largest component and how far the mesh's loaded node is from the
    reference's. ``fem``: BUDGET_RUNS' records. None when a solve is missing.
    """
    ref_rec, rec = fem.get((case, *BUDGET_REFERENCE)), fem.get((case, degree, h))
    if not (ref_rec and rec and ref_rec["status"] == "ok" and rec["status"] == "ok"):
        return None
    with np.load(budget_npz(case, degree, h)) as z:
        u, pts = z["u_nodes"], z["nodes"]
    start = budget_reference_offsets(case)[(degree, h)]
    with np.load(budget_npz(case, *BUDGET_REFERENCE)) as z:
        u_ref = z["u"][start:start + pts.shape[0]]
        scale = np.abs(z["u_nodes"]).max()
        offset = np.linalg.norm(pts[rec["load_node"]] - z["nodes"][ref_rec["load_node"]])
    far = np.linalg.norm(pts - np.asarray(point), axis=1) > exclude
    fe, sur, tot = (np.linalg.norm(a - b, axis=1) for a, b in
                    ((u, u_ref), (predicted, u), (predicted, u_ref)))
    return {"fe": fe[far], "sur": sur[far], "tot": tot[far], "fe_all": fe, "tot_all": tot,
            "scale": scale, "offset": offset, "nodes": pts}


def budget_summary(per: list[dict]) -> dict:
    """One budget mesh's row from its cases' node errors (:func:`budget_case_errors`): the
    mean FE, surrogate and total errors beyond the load's ball, the 95th percentiles, the
    means at every node, the reference's mean largest component and the mean load offset.
    """
    def cat(key):
        return np.concatenate([e[key] for e in per])

    return {"cases": len(per), "fe": float(cat("fe").mean()), "surrogate": float(cat("sur").mean()),
            "total": float(cat("tot").mean()), "fe_p95": float(np.percentile(cat("fe"), 95)),
            "total_p95": float(np.percentile(cat("tot"), 95)),
            "fe_all": float(cat("fe_all").mean()), "total_all": float(cat("tot_all").mean()),
            "u_ref_max": float(np.mean([e["scale"] for e in per])),
            "offset": float(np.mean([e["offset"] for e in per]))}


def material(k_over_mu: float):
    """The study's Ogden material at bulk-to-shear ratio ``k_over_mu`` (kappa = K/mu * c1/2,
    as the scenes set it).
    """
    from fem_sim import OgdenMaterial

    return OgdenMaterial((C1,), (M1,), k_over_mu * C1 / 2)


def signed_error(u: np.ndarray, u_ref: np.ndarray) -> float:
    """The component of u - u_ref along u_ref over |u_ref|^2 (-0.1: the field is 10 % too
    stiff overall; locking shows as a large negative value). The mean error is dominated by
    the many small far-field displacements; this says which way and how far the field is off.
    """
    return float(np.sum((u - u_ref) * u_ref) / np.sum(u_ref * u_ref))


def field_errors(u: np.ndarray, u_ref: np.ndarray, nodes: np.ndarray,
                 load_point: np.ndarray | None = None, radius: float = 0.0) -> dict:
    """Mean and max of |u - u_ref| over ``nodes`` (mm, and relative to max |u_ref|) and the
    signed error; with ``load_point`` (a nodal load, no converged limit there) over the nodes
    farther than ``radius`` from it, the error inside reported apart (inside_mean, _max).
    """
    e = np.linalg.norm(u - u_ref, axis=1)
    scale = np.abs(u_ref).max()
    out = {}
    if load_point is not None:
        near = np.linalg.norm(nodes - np.asarray(load_point), axis=1) <= radius
        out["inside_mean"] = float(e[near].mean()) if near.any() else float("nan")
        out["inside_max"] = float(e[near].max()) if near.any() else float("nan")
        e, u, u_ref = e[~near], u[~near], u_ref[~near]
    out.update(mean=float(e.mean()), max=float(e.max()), rel_mean=float(e.mean() / scale),
               rel_max=float(e.max() / scale), u_ref_max=float(scale),
               signed=signed_error(u, u_ref))  # over the same points
    return out


def spec_of(liver: str, **kw) -> dict:
    """A run of the study: the defaults, the liver's own keys, then ``kw``."""
    return {**DEFAULTS, **LIVER_KEYS.get(liver, {}), "liver": liver, **kw}


def element_of(spec: dict) -> str:
    """P1, P2 or ANP (P1 with averaged nodal pressure, ``fem_sim/solver/anp.py``)."""
    return "ANP" if spec.get("element") == "anp" else f"P{spec['degree']}"


def key_of(spec: dict) -> str:
    return json.dumps(spec, sort_keys=True)


def mesh(liver: str, h: float):
    """The liver's mesh at size ``h`` and the nodes it is fixed at."""
    if liver == "phantom":
        from fem_sim.geometry.phantom import make_phantom

        g = make_phantom(0, h)
        return g, g.regions["vena_cava"]
    from fem_sim.geometry.repair import mesh_surface_file

    g = mesh_surface_file(SOFA, h)
    # The default region (surface nodes within 25 mm of the most posterior surface node)
    # moves with the mesh; the study fixes the same physical region on every mesh: the part of
    # the surface within 25 mm of the most posterior point of the surface file itself. On a
    # mesh it is the surface triangles whose centroid lies inside (all their vertices fixed),
    # which covers about the region's area at every h. Fixing only the vertices inside the
    # ball fixes just the triangles wholly inside: on a 16 mm mesh 13 nodes, a region far
    # smaller than on a fine one, so every coarse mesh was too soft by its clamp alone.
    from fem_sim.geometry.surfaces import clean_surface, read_vtk_polydata

    pts, _ = clean_surface(*read_vtk_polydata(SOFA), str(SOFA))
    top = pts[np.argmax(pts[:, 1])]
    tri = g.surface_triangles
    inside = np.linalg.norm(g.points[tri].mean(axis=1) - top, axis=1) <= 25.0
    return g, np.unique(tri[inside])


def load_point(liver: str) -> np.ndarray:
    """The surface vertex of the coarsest mesh farthest from the fixed region: the same
    physical point for every mesh of the liver.
    """
    g, fixed = mesh(liver, 16.0)
    surf = np.setdiff1d(g.surface_nodes, fixed)
    d = np.linalg.norm(g.points[surf][:, None] - g.points[fixed][None], axis=2).min(axis=1)
    return g.points[surf[np.argmax(d)]]


def run_one(spec: dict, eval_points: np.ndarray | None, out_npz: Path) -> dict:
    """Solve ``spec``; save its displacement at ``eval_points`` (the own vertices when None)
    and at its nodes into ``out_npz``; return its record.
    """
    from mpi4py import MPI

    from fem_sim import Constraint, NodalLoad, OgdenProblem, PatchLoad

    t0 = time.perf_counter()
    g, fixed = mesh(spec["liver"], spec["h"])
    p_star = np.asarray(spec["load_point"])
    if spec["load"] == "patch":
        loads = [PatchLoad(p_star, spec.get("force", FORCE), PATCH_RADIUS)]
        node = -1
    else:
        surf = np.setdiff1d(g.surface_nodes, fixed)
        node = int(surf[np.argmin(np.linalg.norm(g.points[surf] - p_star, axis=1))])
        loads = [NodalLoad([node], [spec.get("force", FORCE)])]
    settings = {"rtol": spec["rtol"], "factorization": spec["factorization"],
                "linear_solver": spec["linear_solver"], "predictor": spec["predictor"]}
    if spec["linear_solver"] == "gamg":
        settings.update(max_krylov=1000, krylov_rtol=1e-12)
    kw = {"element": "anp"} if spec.get("element") == "anp" else {}
    prob = OgdenProblem(MPI.COMM_WORLD, g.points, g.cells, degree=spec["degree"],
                        settings=settings, **kw)
    mat = material(spec["K_over_mu"])
    setup = time.perf_counter() - t0
    fractions = np.arange(1, spec["steps"] + 1) / spec["steps"]
    t1 = time.perf_counter()
    sol = prob.solve(mat, [Constraint(fixed)], loads, fractions)
    secs = time.perf_counter() - t1
    ev = eval_points if eval_points is not None else g.points
    u_eval = prob.displacement_at(ev) if sol.status == "ok" else np.full(ev.shape, np.nan)
    # A dataset solves many simulations on one problem: the later ones reuse PARDISO's
    # analysis and the small-strain factorisation. One more here, timed apart (not for the
    # references, which only give the errors).
    later = {}
    if sol.status == "ok" and spec.get("role") != "reference":
        t2 = time.perf_counter()
        sol2 = prob.solve(mat, [Constraint(fixed)], loads, fractions)
        later = {"seconds_later": time.perf_counter() - t2,
                 "factorizations_later": sol2.factorizations, "status_later": sol2.status}
        if sol2.status == "ok":
            later["later_diff"] = float(np.abs(sol2.displacement[-1] - sol.displacement[-1]).max()
                                        / np.abs(sol.displacement[-1]).max())
    np.savez(out_npz, u=u_eval, points=ev, u_nodes=sol.displacement[-1] if sol.n_done else
             np.zeros((0, 3)), nodes=g.points)
    return {"status": sol.status, "reason": sol.failure_reason, "seconds": secs,
            "setup_seconds": setup, "n_vertices": int(g.n_nodes),
            "n_dofs": int(prob.disc.V.dofmap.index_map.size_global * 3),
            "newton_iterations": sol.newton_iterations, "factorizations": sol.factorizations,
            "chord_steps": sol.chord_steps, "cutbacks": sol.cutbacks,
            "max_u": float(np.abs(sol.displacement[-1]).max()) if sol.n_done else None,
            "load_node": node, "fixed_nodes": int(len(fixed)),
            "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024, **later}


def run_job(job: dict, timeout: float, threads: int = 1) -> dict:
    """Run ``job`` (its ``spec``, where to evaluate it, its ``out`` npz) in a fresh process (a
    clean peak-memory figure; a crash costs one run) on ``threads`` threads and return the
    JSON record it prints last, or why there is none.
    """
    t0 = time.perf_counter()
    try:
        proc = subprocess.run([sys.executable, "-m", "fem_sim.batch.knob_run", json.dumps(job)],
                              capture_output=True, text=True, timeout=timeout,
                              env={**os.environ, "OPENBLAS_NUM_THREADS": str(threads),
                                   "OMP_NUM_THREADS": str(threads)})
        lines = [ln for ln in proc.stdout.splitlines() if ln.startswith("{")]
        record = (json.loads(lines[-1]) if proc.returncode == 0 and lines else
                  {"status": "crashed", "reason": proc.stderr.strip()[-500:]})
    except subprocess.TimeoutExpired:
        record = {"status": "timeout", "reason": f"over {timeout:.0f} s"}
    record["wall_seconds"] = time.perf_counter() - t0
    record["threads"] = threads
    return record


def _eval_points(job: dict) -> np.ndarray | None:
    """Where a job's displacement is wanted: a reference's nodes (``eval``: its npz), the
    vertices of the budget meshes concatenated (``eval_meshes``), else the run's own.
    """
    if job.get("eval"):
        with np.load(job["eval"]) as z:
            return z["nodes"]
    if job.get("eval_meshes"):
        return np.concatenate([mesh("phantom", h)[0].points for _, h in job["eval_meshes"]])
    return None


if __name__ == "__main__":
    import logging

    logging.getLogger().setLevel(logging.WARNING)
    job = json.loads(sys.argv[1])
    print(json.dumps(run_one(job["spec"], _eval_points(job), Path(job["out"]))))
