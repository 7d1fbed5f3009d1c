"""Scene -> simulation cases: pure numpy, no MPI.

Every random draw of case ``i`` comes from ``numpy.random.default_rng([scene.seed, i])`` (and a
scene-wide stream for material tables), so the same dataset comes out for any number of ranks
and any order of work. Only what the scene says varies is drawn.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from data_spec import Geometry, OgdenMaterial, Scene, eligible_loads
from data_spec.livers import population_count

_MATERIAL_TABLE_STREAM = 2**31 - 1  # rng stream of the scene-wide material table


class CaseError(ValueError):
    """The scene cannot produce a case on this geometry (e.g. no eligible load node)."""


@dataclass
class Case:
    """One simulation: what acts on which liver with which material."""

    index: int
    geometry_index: int
    load_kind: str
    load_nodes: np.ndarray       # (n_loads,) source node ids (patch centres for patch loads)
    forces: np.ndarray           # (n_loads, 3) N at load fraction 1
    material: OgdenMaterial
    patch_radius: float = 0.0
    # a grasp: each tool's displacement at load fraction 1 (n_loads, 3) mm; forces are zero
    displacements: np.ndarray | None = None


def fixed_nodes(scene: Scene, g: Geometry, source: str = "scene") -> np.ndarray:
    """Zero-displacement nodes of the scene on geometry ``g`` (sorted ids)."""
    f = scene["fixed"]
    kind = f["kind"]
    surf = g.surface_nodes
    x = g.points[surf]
    if kind == "region":
        if f["name"] not in g.regions:
            raise CaseError(f"{source}: fixed.name = {f['name']!r} but the geometry has regions "
                            f"{sorted(g.regions)}")
        ids = g.regions[f["name"]]
    elif kind == "nodes":
        ids = np.asarray(f["nodes"], dtype=np.int64)
    elif kind == "sphere":
        ids = surf[np.linalg.norm(x - f["center"], axis=1) <= f["radius"]]
    elif kind == "points":
        from scipy.spatial import cKDTree

        near = cKDTree(np.asarray(f["points"], dtype=np.float64)).query(x)[0]
        ids = surf[near <= f["radius"]]
    elif kind == "box":
        ids = surf[np.all((x >= f["min"]) & (x <= f["max"]), axis=1)]
    else:  # cylinder
        axis = np.asarray(f["axis"], float) / np.linalg.norm(f["axis"])
        d = x - f["center"]
        along = d @ axis
        radial = np.linalg.norm(d - along[:, None] * axis, axis=1)
        ids = surf[(radial <= f["radius"]) & (np.abs(along) <= f["length"] / 2)]
    ids = np.unique(ids)
    if ids.size == 0:
        raise CaseError(f"{source}: the fixed region ({kind}) selects no node of the geometry")
    if f.get("area_min"):  # grown as a file population grows its livers' regions
        from data_spec.geometry import grown_region

        ids = grown_region(g.points, g.surface_triangles, ids, f["area_min"])[0]
    return ids


def output_nodes(scene: Scene, g: Geometry) -> np.ndarray:
    nodes = scene["output"]["nodes"]
    if nodes == "all":
        return np.arange(g.n_nodes)
    if nodes == "surface":
        return g.surface_nodes
    return np.asarray(nodes, dtype=np.int64)


def eligible_load_nodes(scene: Scene, g: Geometry, fixed: np.ndarray) -> np.ndarray:
    """Nodes a random load may act on (the rule of :mod:`data_spec.eligible_loads`)."""
    return eligible_loads.eligible_load_nodes(scene["loads"], g.points, g.surface_nodes, fixed)


def _draw(rng: np.random.Generator, spec) -> float:
    return float(rng.uniform(spec[0], spec[1])) if isinstance(spec, list) else float(spec)


def material_table(scene: Scene) -> list[OgdenMaterial] | None:
    """The scene-wide table of materials cases pick from (None if each case draws its own or
    the material is fixed).
    """
    mat = scene["material"]
    s = mat.get("sample")
    if s is None:
        return None
    vol = mat["volumetric"]
    if s["kind"] == "table":
        return [_material_from_params(p, vol) for p in s["sets"]]
    if "n_sets" not in s:
        return None
    rng = np.random.default_rng([scene.seed, _MATERIAL_TABLE_STREAM])
    return [_uniform_material(rng, s, vol) for _ in range(s["n_sets"])]


def _uniform_material(rng, s: dict, vol: str) -> OgdenMaterial:
    c = [rng.uniform(lo, hi) for lo, hi in s["c"]]
    m = [rng.uniform(lo, hi) for lo, hi in s["m"]]
    k_over_mu = _draw(rng, s.get("K_over_mu", 200.0))
    return OgdenMaterial(c=c, m=m, K=k_over_mu * 0.5 * sum(c), volumetric=vol)


def _material_from_params(p: dict, vol: str) -> OgdenMaterial:
    c = p["c"]
    K = p["K"] if "K" in p else p.get("K_over_mu", 200.0) * 0.5 * sum(c)
    return OgdenMaterial(c=c, m=p["m"], K=K, volumetric=vol)


def base_material(scene: Scene) -> OgdenMaterial:
    mat = scene["material"]
    return _material_from_params(mat, mat["volumetric"])


def make_case(scene: Scene, index: int, g: Geometry, fixed: np.ndarray,
              table: list[OgdenMaterial] | None = None, eligible: np.ndarray | None = None) -> Case:
    """Case ``index`` of the scene on geometry ``g`` (deterministic in (scene.seed, index))."""
    ld = scene["loads"]
    rng = np.random.default_rng([scene.seed, index])
    geometry_index = 0
    if scene["geometry"]["source"] == "population":
        geometry_index = index % population_count(scene["geometry"])
    patch = float(ld.get("patch_radius", 0.0)) if ld["kind"] == "patch" else 0.0
    if scene.cases:
        spec = scene.cases[index]
        mat = (_material_from_params(spec["material"], scene["material"]["volumetric"])
               if "material" in spec else _case_material(scene, rng, table))
        return Case(index, spec.get("geometry_index", geometry_index), ld["kind"],
                    np.asarray(spec["load_nodes"], np.int64),
                    np.asarray(spec["forces"], np.float64), mat, patch)

    if eligible is None:
        eligible = eligible_load_nodes(scene, g, fixed)
    n = ld["count"]
    if eligible.size < n:
        raise CaseError(f"scene {scene.name}: only {eligible.size} eligible load nodes for "
                        f"{n} loads (check loads.eligible / min_distance_to_fixed)")
    nodes = _pick_nodes(rng, eligible, g.points, n, ld["min_separation"])
    d = load_directions(rng, ld["direction"], g.points[nodes], g.points[fixed])
    mags = np.array([_draw(rng, ld["magnitude"]) for _ in range(n)])
    mat = _case_material(scene, rng, table)
    if ld["kind"] == "grasp":
        return Case(index, geometry_index, "grasp", nodes, np.zeros((n, 3)), mat,
                    float(ld["patch_radius"]), displacements=d * mags[:, None])
    return Case(index, geometry_index, ld["kind"], nodes, d * mags[:, None], mat, patch)


def load_directions(rng, rule, at: np.ndarray, fixed: np.ndarray) -> np.ndarray:
    """(n, 3) unit directions of the loads at the points ``at``: uniform on the sphere,
    ``away`` (uniform over the half-sphere facing away from each point's nearest fixed node:
    a tool pulls the liver off its support, not into it) or the scene's fixed vector.
    """
    n = at.shape[0]
    if rule in ("uniform", "away"):
        d = rng.normal(size=(n, 3))
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        if rule == "away":
            near = fixed[np.argmin(np.linalg.norm(at[:, None] - fixed[None], axis=2), axis=1)]
            out = at - near
            d *= np.where(np.sum(d * out, axis=1) < 0, -1.0, 1.0)[:, None]
        return d
    return np.tile(np.asarray(rule, float) / np.linalg.norm(rule), (n, 1))


def grasp_patches(case: Case, g: Geometry, fixed: np.ndarray) -> list[np.ndarray]:
    """Each tool's grasped nodes: the surface nodes within the case's patch radius of its
    centre node; CaseError when a patch touches the fixed region or another tool's.
    """
    out = []
    for node in case.load_nodes:
        patch = eligible_loads.grasp_patch(g.points, g.surface_nodes, node, case.patch_radius)
        if np.intersect1d(patch, fixed).size:
            raise CaseError(f"case {case.index}: the grasp at node {node} (radius "
                            f"{case.patch_radius:g} mm) reaches the fixed region: raise "
                            "loads.min_distance_to_fixed above the patch radius")
        if any(np.intersect1d(patch, p).size for p in out):
            raise CaseError(f"case {case.index}: two grasps overlap: raise "
                            "loads.min_separation above twice the patch radius")
        out.append(patch)
    return out


def _case_material(scene: Scene, rng, table: list[OgdenMaterial] | None) -> OgdenMaterial:
    s = scene["material"].get("sample")
    if s is None:
        return base_material(scene)
    if table is not None:
        return table[int(rng.integers(len(table)))]
    return _uniform_material(rng, s, scene["material"]["volumetric"])


def _pick_nodes(rng, eligible, points, n, min_sep, tries: int = 1000) -> np.ndarray:
    chosen: list[int] = []
    for _ in range(tries):
        cand = int(eligible[rng.integers(eligible.size)])
        if cand in chosen:
            continue
        if min_sep > 0 and chosen and np.min(
                np.linalg.norm(points[chosen] - points[cand], axis=1)) < min_sep:
            continue
        chosen.append(cand)
        if len(chosen) == n:
            return np.array(chosen, dtype=np.int64)
    raise CaseError(f"could not place {n} loads at least {min_sep} mm apart in {tries} draws")
