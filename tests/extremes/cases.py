"""The extreme cases, as data: which liver, which material, which loads, which load fractions.

Built from the shipped scenes (the corners of every sampled range) and from the list of the
trade-off issue (forces 5x/10x nominal, next to the fixed region, K/mu from 10 to 10000, two
opposite forces on neighbouring nodes, zero force, the whole load in one step). Used by the
tests in this folder and by ``scripts/extremes_doc.py`` (docs/extremes.md).
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass, field
from functools import cache
from pathlib import Path

import numpy as np

from data_spec import OgdenMaterial, load_scene
from liverviz.report import SOFA

ROOT = Path(__file__).resolve().parents[2]
SCENES = sorted((ROOT / "data_spec" / "scenes").glob("scene*.toml"))
MESH_SIZE = 16.0  # mm: ~600 (phantom) and ~1,300 (real liver) nodes: many cases in minutes
# Training livers of scene 4 (no validation liver) for the surgical loads: a grasp pulled
# 40 mm and a 4 N patch force, each on a CT liver of ../shared
REAL = ROOT.parent / "shared" / "data" / "livers" / "real"
SURGICAL_LIVERS = ("Amos-005", "LiTS-12", "LiTS-16")
GRASP_RADIUS = 10.0  # mm, a tool's patch (scene loads.patch_radius's default for a grasp)
NOMINAL = OgdenMaterial((4.1e-3,), (10.06,), 200 * 4.1e-3 / 2)
TEN_STEPS = tuple(np.linspace(0.1, 1.0, 10))


@dataclass(frozen=True)
class Extreme:
    name: str
    liver: str                      # "phantom", "sofa" or a CT liver of REAL
    material: OgdenMaterial
    loads: tuple                    # ((where, direction, magnitude[, kind]), ...), see loads()
    fractions: tuple = TEN_STEPS
    degree: int = 1                 # element: the scene's on the phantom (P2 for the paper's)
    why: str = ""
    tags: tuple = field(default_factory=tuple)


@cache
def liver(name: str):
    """(geometry, fixed nodes) at MESH_SIZE."""
    if name == "phantom":
        from fem_sim.geometry.phantom import make_phantom

        g = make_phantom(0, MESH_SIZE)
    else:
        from fem_sim.geometry.repair import mesh_surface_file

        g = mesh_surface_file(SOFA if name == "sofa" else REAL / f"{name}.obj", MESH_SIZE)
    return g, g.regions["vena_cava"]


def livers() -> list[str]:
    return ["phantom"] + (["sofa"] if SOFA.exists() else [])


def _far_nodes(g, fixed) -> np.ndarray:
    """Free surface nodes, farthest from the fixed region first."""
    surf = np.setdiff1d(g.surface_nodes, fixed)
    d = np.linalg.norm(g.points[surf][:, None] - g.points[fixed][None], axis=2).min(axis=1)
    return surf[np.argsort(-d)]


def _where(case: Extreme, where: str, direction) -> tuple[int, np.ndarray]:
    """(node, unit direction) of a load: ``where`` "far" (the free surface node farthest
    from the fixed region), "far2" (the free surface node farthest from "far") or "near" (the
    free surface node closest to the fixed region); ``direction`` "away" (from the fixed
    region's centroid: stretching), "toward" (compressing) or a vector."""
    g, fixed = liver(case.liver)
    far = _far_nodes(g, fixed)
    node = {"far": far[0], "near": far[-1],
            "far2": far[np.argmax(np.linalg.norm(g.points[far] - g.points[far[0]], axis=1))]
            }[where]
    if isinstance(direction, str):
        v = g.points[node] - g.points[fixed].mean(axis=0)
        return int(node), v / np.linalg.norm(v) * (1 if direction == "away" else -1)
    return int(node), np.asarray(direction, float) / np.linalg.norm(direction)


def loads(case: Extreme):
    """The solver's loads of a case on its liver: a NodalLoad for each (where, direction,
    magnitude N) (:func:`_where`; "pair": two neighbouring surface nodes near "far", with
    opposite forces along their edge), a PatchLoad of GRASP_RADIUS for kind "patch"; a grasp
    (kind "grasp", magnitude mm) is no load but a tool (:func:`tools`)."""
    from fem_sim import NodalLoad, PatchLoad

    g, fixed = liver(case.liver)
    out = []
    for where, direction, magnitude, *kind in case.loads:
        kind = kind[0] if kind else "nodal"
        if where == "pair":
            a = int(_far_nodes(g, fixed)[0])
            tri = g.surface_triangles[(g.surface_triangles == a).any(axis=1)][0]
            b = int(tri[tri != a][0])
            e = g.points[b] - g.points[a]
            e /= np.linalg.norm(e)
            out.append(NodalLoad([a, b], [-magnitude * e, magnitude * e]))
        elif kind != "grasp":
            node, v = _where(case, where, direction)
            out.append(PatchLoad(g.points[node], magnitude * v, GRASP_RADIUS)
                       if kind == "patch" else NodalLoad([node], [magnitude * v]))
    return out


def tools(case: Extreme) -> list[tuple[np.ndarray, np.ndarray]]:
    """Each grasp of a case: (its patch: the surface nodes within GRASP_RADIUS of the node,
    its displacement mm)."""
    g, _ = liver(case.liver)
    out = []
    for where, direction, magnitude, *kind in case.loads:
        if kind and kind[0] == "grasp":
            node, v = _where(case, where, direction)
            surf = g.surface_nodes
            out.append((surf[np.linalg.norm(g.points[surf] - g.points[node], axis=1)
                             <= GRASP_RADIUS], magnitude * v))
    return out


def applied_force(case: Extreme, sol) -> np.ndarray:
    """The total force the loads and tools put on the liver at the last stored step (N)."""
    force = np.zeros(3)
    for ld in loads(case):
        force += ld.forces.sum(axis=0) if hasattr(ld, "forces") else ld.force
    return force + sol.reaction[-1, 1:].sum(axis=0)


def _scene_corners() -> list[Extreme]:
    """The corners of every sampled range of every shipped scene: softest/stiffest c,
    smallest/largest m, the largest force magnitude, stretching and compressing."""
    out, seen = [], set()
    for path in SCENES:
        sc = load_scene(path)
        m, ld = sc["material"], sc["loads"]
        mag = ld["magnitude"][1] if isinstance(ld["magnitude"], list) else ld["magnitude"]
        sample = m.get("sample")
        if sample and sample["kind"] == "uniform":
            kmu = sample.get("K_over_mu", m["K_over_mu"])
            kmu = kmu[1] if isinstance(kmu, list) else kmu
            mats = [OgdenMaterial((c,), (mm,), kmu * c / 2, m["volumetric"])
                    for c, mm in itertools.product(sample["c"][0], sample["m"][0])]
        else:
            mats = [NOMINAL]
        where = ("far", "far2")[: ld["count"]]
        degree = sc["solver"]["degree"]
        for mat, direction in itertools.product(mats, ("away", "toward")):
            key = (mat, ld["count"], direction, degree)
            if key in seen:
                continue
            seen.add(key)
            for name in livers():
                # The scenes' element on the phantom (the scenes' liver); P1 on the real
                # liver, where P2 costs ~20 s per case at this size (too slow for the suite).
                p = degree if name == "phantom" else 1
                out.append(Extreme(
                    f"{name}-{path.stem.split('_')[0]}-P{p}-c{mat.c[0]:g}-m{mat.m[0]:g}-"
                    f"{ld['count']}x{mag:g}N-{direction}", name, mat,
                    tuple((w, direction, mag) for w in where), degree=p,
                    why=f"corner of {path.name}", tags=("corner",)))
    return out


def extremes() -> list[Extreme]:
    cases = _scene_corners()
    for name in livers():
        cases += [
            Extreme(f"{name}-force-5x", name, NOMINAL, (("far", "away", 2.0),),
                    why="5x the nominal force", tags=("force",)),
            Extreme(f"{name}-force-10x", name, NOMINAL, (("far", "away", 4.0),),
                    why="10x the nominal force", tags=("force",)),
            Extreme(f"{name}-next-to-fixed", name, NOMINAL, (("near", "away", 2.0),),
                    why="5x force on the free node closest to the fixed region",
                    tags=("near",)),
            Extreme(f"{name}-opposite-pair", name, NOMINAL, (("pair", None, 0.4),),
                    why="two opposite 0.4 N forces on neighbouring nodes", tags=("pair",)),
            Extreme(f"{name}-zero-force", name, NOMINAL, (("far", "away", 0.0),),
                    why="zero force", tags=("zero",)),
            Extreme(f"{name}-one-step-5x", name, NOMINAL, (("far", "away", 2.0),),
                    fractions=(1.0,), why="5x force in one load step (cut-backs)",
                    tags=("one-step",)),
        ]
        for kmu in (10.0, 100.0, 1000.0, 10000.0):
            mat = OgdenMaterial((4.1e-3,), (10.06,), kmu * 4.1e-3 / 2)
            cases.append(Extreme(f"{name}-K_over_mu-{kmu:g}", name, mat,
                                 (("far", "away", 0.4),), why=f"K/mu = {kmu:g}",
                                 tags=("kmu",)))
    for name in SURGICAL_LIVERS:
        if (REAL / f"{name}.obj").exists():
            cases += [
                Extreme(f"{name}-grasp-40mm", name, NOMINAL, (("far", "away", 40.0, "grasp"),),
                        why="a 10 mm grasp pulled 40 mm away from the fixed region (the most "
                        "a liver moves in surgery)", tags=("surgical", "grasp")),
                Extreme(f"{name}-patch-4N", name, NOMINAL, (("far", "away", 4.0, "patch"),),
                        why="4 N over a 10 mm patch (above the 3.4 N forceps measure at most)",
                        tags=("surgical",)),
            ]
    return cases


def simulate(case: Extreme):
    """(problem, Solution) of one case: the reactions on the fixed region, then on each
    tool's patch, at every stored step (``Solution.reaction``)."""
    from mpi4py import MPI

    from fem_sim import Constraint, OgdenProblem

    g, fixed = liver(case.liver)
    prob = OgdenProblem(MPI.COMM_WORLD, g.points, g.cells, degree=case.degree)
    grasps = tools(case)
    return prob, prob.solve(case.material, [Constraint(fixed), *(Constraint(p, values=d)
                                                                  for p, d in grasps)],
                            loads(case), list(case.fractions),
                            reactions=[fixed, *(p for p, _ in grasps)])
