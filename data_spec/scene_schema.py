"""The scene schema as a table: every section, key, value check, default and one-line doc.

The value checkers are tiny pure functions (None when a value is acceptable, else what was
expected), so the schema reads as a table; :mod:`data_spec.scene` applies it and adds the
checks that span several keys. ``data_spec/README.md`` documents it key by key (tested), and
the ``[solver]`` keys come from :class:`data_spec.solver_settings.SolverSettings`.
"""

from __future__ import annotations

import dataclasses
import json
import re
from collections.abc import Callable
from typing import Any

from data_spec import solver_settings
from data_spec.checks import is_int, is_num

SCENE_SCHEMA_VERSION = 1

_NAME_RE = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.-]*$")


# ----------------------------------------------------------------------------------------------
# Value checkers. Each returns None when the value is acceptable, else a description of what was
# expected. They are tiny pure functions so the schema below reads as a table.
# ----------------------------------------------------------------------------------------------
Check = Callable[[Any], "str | None"]


def _int(lo: int | None = None, hi: int | None = None) -> Check:
    def check(v):
        if not is_int(v) or (lo is not None and v < lo) or (hi is not None and v > hi):
            rng = f" >= {lo}" if hi is None and lo is not None else (
                f" in [{lo}, {hi}]" if lo is not None else "")
            return f"an integer{rng}"
        return None
    return check


def _num(lo: float | None = None, *, strict: bool = True) -> Check:
    def check(v):
        if not is_num(v):
            return "a finite number"
        if lo is not None and (v <= lo if strict else v < lo):
            return f"a number {'>' if strict else '>='} {lo}"
        return None
    return check


def _positive_or_range(v: Any) -> str | None:
    """A number > 0, or a range [lo, hi] with 0 < lo <= hi."""
    if is_num(v) and v > 0:
        return None
    if (isinstance(v, list) and len(v) == 2 and all(is_num(x) for x in v)
            and 0 < v[0] <= v[1]):
        return None
    return "a number > 0 or a range [lo, hi] with 0 < lo <= hi"


def _choice(*options: str) -> Check:
    def check(v):
        return None if v in options else "one of " + ", ".join(repr(o) for o in options)
    return check


def _string(v: Any) -> str | None:
    return None if isinstance(v, str) else "a string"


def _name(v: Any) -> str | None:
    ok = isinstance(v, str) and _NAME_RE.match(v)
    return None if ok else "a name of letters, digits, '_', '-', '.' (no spaces)"


def _vec3(v: Any) -> str | None:
    ok = isinstance(v, list) and len(v) == 3 and all(is_num(x) for x in v)
    return None if ok else "a list of 3 finite numbers [x, y, z]"


def _points(v: Any) -> str | None:
    ok = isinstance(v, list) and len(v) > 0 and all(_vec3(x) is None for x in v)
    return None if ok else "a non-empty list of points [[x, y, z], ...]"


def _node_ids(v: Any) -> str | None:
    ok = isinstance(v, list) and len(v) > 0 and all(is_int(x) and x >= 0 for x in v)
    return None if ok else "a non-empty list of node ids (integers >= 0)"


def _num_list(positive: bool = False, nonzero: bool = False) -> Check:
    def check(v):
        if not (isinstance(v, list) and len(v) > 0 and all(is_num(x) for x in v)):
            return "a non-empty list of finite numbers"
        if positive and any(x <= 0 for x in v):
            return "a list of numbers > 0"
        if nonzero and any(x == 0 for x in v):
            return "a list of non-zero numbers"
        return None
    return check


def _names(v: Any) -> str | None:
    ok = isinstance(v, list) and all(isinstance(x, str) and x for x in v)
    return None if ok else "a list of liver names (file names without their suffix)"


def _table(v: Any) -> str | None:
    return None if isinstance(v, dict) else "a table"


def _output_nodes(v: Any) -> str | None:
    if v in ("all", "surface"):
        return None
    return None if _node_ids(v) is None else "'all', 'surface' or a list of node ids"


def _direction(v: Any) -> str | None:
    if v in ("uniform", "away"):
        return None
    if _vec3(v) is None and any(x != 0 for x in v):
        return None
    return "'uniform', 'away' or a non-zero vector [x, y, z]"


def _fractions(v: Any) -> str | None:
    ok = (isinstance(v, list) and len(v) > 0 and all(is_num(x) for x in v)
          and all(0 < x <= 1 for x in v) and all(a < b for a, b in zip(v, v[1:]))
          and v[-1] == 1.0)
    return None if ok else "a strictly increasing list of numbers in (0, 1] ending at 1.0"


@dataclasses.dataclass(frozen=True)
class Key:
    """One key of a section: its check, default (``REQUIRED`` if none) and a one-line doc."""

    check: Check
    default: Any
    doc: str


REQUIRED = object()
OPTIONAL = None  # a key with default None is optional and only checked when present

def _solver_keys() -> dict[str, Key]:
    """The scene's solver keys: the ``scene=True`` fields of :class:`SolverSettings`, with their
    defaults, checks and documentation (one source for the scene and the solver).
    """
    return {f.name: Key(lambda v, f=f: solver_settings.check(f, v), solver_settings.default(f),
                        f.metadata["doc"]) for f in solver_settings.fields(scene_only=True)}


_SCHEMA: dict[str, dict[str, Key]] = {
    "scene": {
        "name": Key(_name, REQUIRED, "scene name, used in file names and shards"),
        "description": Key(_string, "", "free text"),
        "n_simulations": Key(_int(1, 10_000_000), OPTIONAL,
                             "number of simulations (default: the number of [[cases]])"),
        "seed": Key(_int(0), 0, "master seed; case i's draws depend only on (seed, i)"),
    },
    "geometry": {
        "source": Key(_choice("phantom", "file", "population"), REQUIRED,
                      "phantom: the embedded liver; file: a mesh/surface; population: many"),
        "mesh_size": Key(_num(0.0), 8.0, "target tetrahedron edge length, mm"),
        "phantom_seed": Key(_int(0), 0, "shape seed of the embedded phantom"),
        "path": Key(_string, OPTIONAL, "mesh or surface file (relative to the scene file)"),
        "scale_to_mm": Key(_num(0.0), 1.0, "factor from the file's length unit to mm"),
        "population_size": Key(_int(1), OPTIONAL, "number of livers (population of phantoms); "
                               "with livers: at most this many liver files"),
        "livers": Key(_string, OPTIONAL, "population: a folder or a glob of liver surface files "
                      "(relative to the scene file); data_spec/livers.py"),
        "validation": Key(_names, [], "population: livers of the folder set aside, never "
                          "simulated, registered into the PCA or trained on"),
        "exclude": Key(_names, [], "population: livers of the folder left out (named with "
                       "the reason in a comment, e.g. refused by the repair)"),
        "phantoms": Key(_int(0), 0, "population with livers: this many phantoms as well "
                        "(seeds population_seed onward), augmentation: trained on, never "
                        "held out"),
        "frame": Key(_choice("population", "LPS", "RAS", "auto"), "LPS",
                     "population with livers: the files' frame (refined by a rigid fit onto "
                     "the template), or auto: the best of 48 axis maps"),
        "fixed_area_min": Key(_num(0.0), OPTIONAL, "population with livers: the fixed region "
                              "grows to at least this area, mm^2 (default: half the template's)"),
        "population_seed": Key(_int(0), 0, "first phantom seed of the population"),
        "pca_components": Key(_int(1), 27, "shape coefficients per liver (population)"),
        "variety": Key(_choice("anatomical", "narrow"), OPTIONAL,
                       "population shapes: anatomical (the default: published ranges of real "
                       "livers, docs/population.md) or narrow (the first phantoms: two "
                       "ellipsoids varying a few mm)"),
        "spacing": Key(_vec3, OPTIONAL, "voxel size (mm) of a .npy segmentation mask"),
    },
    "fixed": {
        "kind": Key(_choice("region", "sphere", "box", "cylinder", "nodes", "points"),
                    "region", "how the zero-displacement nodes are chosen"),
        "name": Key(_name, "vena_cava", "named region of the geometry (kind = region)"),
        "center": Key(_vec3, OPTIONAL, "sphere/cylinder centre, mm"),
        "radius": Key(_num(0.0), OPTIONAL, "sphere/cylinder radius; points: distance, mm"),
        "axis": Key(_vec3, OPTIONAL, "cylinder axis direction"),
        "length": Key(_num(0.0), OPTIONAL, "cylinder length along the axis, mm"),
        "min": Key(_vec3, OPTIONAL, "box lower corner, mm"),
        "max": Key(_vec3, OPTIONAL, "box upper corner, mm"),
        "nodes": Key(_node_ids, OPTIONAL, "explicit node ids (kind = nodes)"),
        "points": Key(_points, OPTIONAL, "surface nodes within radius of any of these points, "
                      "mm (kind = points; e.g. a region mapped from another mesh)"),
        "area_min": Key(_num(0.0), OPTIONAL, "grow the region by rings of surface neighbours "
                        "until its area reaches this, mm^2 (as a file population fixes its "
                        "livers)"),
    },
    "material": {
        "law": Key(_choice("ogden"), "ogden", "uncoupled first-order Ogden (FEBio convention)"),
        "volumetric": Key(_choice("log", "quadratic"), "log",
                          "log: K/2 (ln J)^2, quadratic: K/2 (J-1)^2"),
        "c": Key(_num_list(positive=True), [4.1e-3], "Ogden c_k, MPa"),
        "m": Key(_num_list(nonzero=True), [10.06], "Ogden m_k (dimensionless)"),
        "K": Key(_num(0.0), OPTIONAL, "bulk modulus, MPa (default: K_over_mu * mu)"),
        "K_over_mu": Key(_num(0.0), 200.0, "K / mu with mu = sum(c)/2 (K = 100 c1 for one term)"),
        "sample": Key(_table, OPTIONAL, "sampled materials: see [material.sample]"),
    },
    "material.sample": {
        "kind": Key(_choice("uniform", "table"), REQUIRED,
                    "uniform: draw from ranges; table: pick one of the listed sets"),
        "c": Key(lambda v: None if _ranges(v) else "a list of [lo, hi] ranges, one per term",
                 OPTIONAL, "ranges of c_k, MPa (uniform)"),
        "m": Key(lambda v: None if _ranges(v, positive=False) else
                 "a list of [lo, hi] ranges, one per term", OPTIONAL, "ranges of m_k (uniform)"),
        "K_over_mu": Key(_positive_or_range, OPTIONAL, "K/mu, a value or a range (uniform)"),
        "n_sets": Key(_int(1), OPTIONAL,
                      "draw this many sets once, then each simulation picks one (uniform)"),
        "sets": Key(lambda v: None if isinstance(v, list) and v and all(
            isinstance(x, dict) for x in v) else "a non-empty array of tables {c, m, K or "
            "K_over_mu}", OPTIONAL, "explicit parameter sets (table)"),
    },
    "loads": {
        "count": Key(_int(1), 1, "simultaneous forces per simulation"),
        "kind": Key(_choice("nodal", "patch", "grasp"), "nodal",
                    "nodal: on one node; patch: spread over the surface within patch_radius; "
                    "grasp: the surface within patch_radius moved rigidly by a prescribed "
                    "displacement (a tool), its reaction force recorded"),
        "magnitude": Key(_positive_or_range, REQUIRED, "force magnitude, N (value or [lo, hi]); "
                         "a grasp: its displacement, mm"),
        "direction": Key(_direction, "uniform", "'uniform' on the sphere, 'away' (uniform "
                         "over the half facing away from the nearest fixed node), or a fixed "
                         "vector"),
        "eligible": Key(_choice("surface", "all"), "surface", "nodes a load may act on"),
        "min_distance_to_fixed": Key(_num(0.0, strict=False), 0.0,
                                     "eligible nodes are at least this far from fixed nodes, mm"),
        "min_separation": Key(_num(0.0, strict=False), 0.0,
                              "minimum distance between simultaneous load nodes, mm"),
        "near": Key(_vec3, OPTIONAL, "a site [x, y, z] mm (one liver's frame): eligible "
                    "nodes are within near_radius of it (a patient's planned grasp)"),
        "near_radius": Key(_num(0.0), OPTIONAL, "mm, with near (default 20)"),
        "patch_radius": Key(_num(0.0), OPTIONAL, "patch radius, mm (kind = patch; grasp: "
                            "default 10)"),
    },
    "steps": {
        "n": Key(_int(1), 10, "number of equal load steps (ignored if fractions is given)"),
        "fractions": Key(_fractions, OPTIONAL, "explicit output load fractions"),
    },
    "output": {
        "nodes": Key(_output_nodes, "all", "'all', 'surface' or a list of node ids"),
    },
    "solver": {
        "degree": Key(_int(1, 2), 1, "Lagrange degree of the displacement (1 or 2)"),
        "quadrature_degree": Key(_int(1), OPTIONAL, "default: 1 for P1 (FEBio tet4), 2 for P2"),
        "element": Key(_choice("lagrange", "anp"), OPTIONAL,
                       "default 'lagrange' (P1/P2 by degree); 'anp': P1 with averaged nodal "
                       "pressure, which does not lock (degree 1, one rank per simulation)"),
        **_solver_keys(),
    },
    "surrogate": {
        "node_fraction": Key(lambda v: None if is_num(v) and 0 < v <= 1 else
                             "a number in (0, 1]", 1.0, "fraction of nodes sampled per step"),
        "folds": Key(_int(2), 10, "k of k-fold cross-validation"),
        "config": Key(_name, "paper_scene1", "trainer config name (surrogate/configs)"),
    },
}

_CASE_KEYS = {
    "load_nodes": Key(_node_ids, REQUIRED, "load node ids (or patch centres), one per force"),
    "forces": Key(lambda v: None if isinstance(v, list) and v and all(
        _vec3(f) is None for f in v) else "a list of [fx, fy, fz] vectors", REQUIRED,
        "full force vectors at load fraction 1, N"),
    "material": Key(_table, OPTIONAL, "{c, m, K or K_over_mu}, overrides [material]"),
    "geometry_index": Key(_int(0), 0, "liver index in a population"),
}

_TOP_LEVEL = ["schema_version", *[s for s in _SCHEMA if "." not in s], "cases"]


def _ranges(v: Any, positive: bool = True) -> bool:
    return (isinstance(v, list) and len(v) > 0 and all(
        isinstance(r, list) and len(r) == 2 and all(is_num(x) for x in r) and r[0] <= r[1]
        and (not positive or r[0] > 0) for r in v))


_PARAM_SET_KEYS = {
    "c": Key(_num_list(positive=True), REQUIRED, "Ogden c_k, MPa"),
    "m": Key(_num_list(nonzero=True), REQUIRED, "Ogden m_k"),
    "K": Key(_num(0.0), OPTIONAL, "bulk modulus, MPa"),
    "K_over_mu": Key(_num(0.0), OPTIONAL, "K / mu"),
}


def schema_table() -> list[tuple[str, str, str]]:
    """(section.key, default, doc) rows for documentation and ``--help`` texts."""
    rows = []
    for section, keys in _SCHEMA.items():
        for key, spec in keys.items():
            default = "required" if spec.default is REQUIRED else (
                "-" if spec.default is None else json.dumps(spec.default))
            rows.append((f"{section}.{key}", default, spec.doc))
    return rows
