"""Scene schema v1: a TOML file that says what a dataset contains and what varies.

A scene is data (STYLE.md principle 2): both packages derive their behaviour from the validated
``Scene`` returned by :func:`load_scene`, never from scene-specific code paths.

Validation collects *every* problem (file, key, what was expected, what was found) and raises one
:class:`SceneError` listing them all, so a user fixes a scene in one pass. Only numpy and the
standard library are used here (``tomllib``), so the solver and the trainer interpreters both
import it.

The schema itself is the ``_SCHEMA`` table below; ``data_spec/README.md`` documents it key by key.
"""

from __future__ import annotations

import copy
import dataclasses
import hashlib
import json
import math
import re
import tomllib
from collections.abc import Callable
from pathlib import Path
from typing import Any

from data_spec import solver_settings

SCENE_SCHEMA_VERSION = 1

_NAME_RE = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.-]*$")


class SceneError(ValueError):
    """A scene file is malformed. ``problems`` lists every problem found, one string each."""

    def __init__(self, source: str, problems: list[str]):
        self.source = source
        self.problems = list(problems)
        lines = "\n".join(f"  - {p}" for p in self.problems)
        super().__init__(f"{source}: {len(self.problems)} problem(s) in scene:\n{lines}")


# ----------------------------------------------------------------------------------------------
# Value checkers. Each returns None when the value is acceptable, else a description of what was
# expected. They are tiny pure functions so the schema below reads as a table.
# ----------------------------------------------------------------------------------------------
Check = Callable[[Any], "str | None"]


def _is_int(v: Any) -> bool:
    return isinstance(v, int) and not isinstance(v, bool)


def _is_num(v: Any) -> bool:
    return (isinstance(v, (int, float)) and not isinstance(v, bool)) and math.isfinite(v)


def _int(lo: int | None = None, hi: int | None = None) -> Check:
    def check(v):
        if not _is_int(v) or (lo is not None and v < lo) or (hi is not None and v > hi):
            rng = f" >= {lo}" if hi is None and lo is not None else (
                f" in [{lo}, {hi}]" if lo is not None else "")
            return f"an integer{rng}"
        return None
    return check


def _num(lo: float | None = None, *, strict: bool = True) -> Check:
    def check(v):
        if not _is_num(v):
            return "a finite number"
        if lo is not None and (v <= lo if strict else v < lo):
            return f"a number {'>' if strict else '>='} {lo}"
        return None
    return check


def _positive_or_range(v: Any) -> str | None:
    """A number > 0, or a range [lo, hi] with 0 < lo <= hi."""
    if _is_num(v) and v > 0:
        return None
    if (isinstance(v, list) and len(v) == 2 and all(_is_num(x) for x in v)
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
    ok = isinstance(v, list) and len(v) == 3 and all(_is_num(x) for x in v)
    return None if ok else "a list of 3 finite numbers [x, y, z]"


def _node_ids(v: Any) -> str | None:
    ok = isinstance(v, list) and len(v) > 0 and all(_is_int(x) and x >= 0 for x in v)
    return None if ok else "a non-empty list of node ids (integers >= 0)"


def _num_list(positive: bool = False, nonzero: bool = False) -> Check:
    def check(v):
        if not (isinstance(v, list) and len(v) > 0 and all(_is_num(x) for x in v)):
            return "a non-empty list of finite numbers"
        if positive and any(x <= 0 for x in v):
            return "a list of numbers > 0"
        if nonzero and any(x == 0 for x in v):
            return "a list of non-zero numbers"
        return None
    return check


def _table(v: Any) -> str | None:
    return None if isinstance(v, dict) else "a table"


def _output_nodes(v: Any) -> str | None:
    if v in ("all", "surface"):
        return None
    return None if _node_ids(v) is None else "'all', 'surface' or a list of node ids"


def _direction(v: Any) -> str | None:
    if v == "uniform":
        return None
    if _vec3(v) is None and any(x != 0 for x in v):
        return None
    return "'uniform' or a non-zero vector [x, y, z]"


def _fractions(v: Any) -> str | None:
    ok = (isinstance(v, list) and len(v) > 0 and all(_is_num(x) for x in v)
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
        "n_simulations": Key(_int(1), OPTIONAL,
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
        "population_size": Key(_int(1), OPTIONAL, "number of livers (population)"),
        "population_seed": Key(_int(0), 0, "first phantom seed of the population"),
        "pca_components": Key(_int(1), 27, "shape coefficients per liver (population)"),
        "spacing": Key(_vec3, OPTIONAL, "voxel size (mm) of a .npy segmentation mask"),
    },
    "fixed": {
        "kind": Key(_choice("region", "sphere", "box", "cylinder", "nodes"), "region",
                    "how the zero-displacement nodes are chosen"),
        "name": Key(_name, "vena_cava", "named region of the geometry (kind = region)"),
        "center": Key(_vec3, OPTIONAL, "sphere/cylinder centre, mm"),
        "radius": Key(_num(0.0), OPTIONAL, "sphere/cylinder radius, mm"),
        "axis": Key(_vec3, OPTIONAL, "cylinder axis direction"),
        "length": Key(_num(0.0), OPTIONAL, "cylinder length along the axis, mm"),
        "min": Key(_vec3, OPTIONAL, "box lower corner, mm"),
        "max": Key(_vec3, OPTIONAL, "box upper corner, mm"),
        "nodes": Key(_node_ids, OPTIONAL, "explicit node ids (kind = nodes)"),
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
        "kind": Key(_choice("nodal", "patch"), "nodal",
                    "nodal: on one node; patch: spread over the surface within patch_radius"),
        "magnitude": Key(_positive_or_range, REQUIRED, "force magnitude, N (value or [lo, hi])"),
        "direction": Key(_direction, "uniform", "'uniform' on the sphere, or a fixed vector"),
        "eligible": Key(_choice("surface", "all"), "surface", "nodes a load may act on"),
        "min_distance_to_fixed": Key(_num(0.0, strict=False), 0.0,
                                     "eligible nodes are at least this far from fixed nodes, mm"),
        "min_separation": Key(_num(0.0, strict=False), 0.0,
                              "minimum distance between simultaneous load nodes, mm"),
        "patch_radius": Key(_num(0.0), OPTIONAL, "patch radius, mm (kind = patch)"),
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
        **_solver_keys(),
    },
    "surrogate": {
        "node_fraction": Key(lambda v: None if _is_num(v) and 0 < v <= 1 else
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
        isinstance(r, list) and len(r) == 2 and all(_is_num(x) for x in r) and r[0] <= r[1]
        and (not positive or r[0] > 0) for r in v))


# ----------------------------------------------------------------------------------------------
# The validated scene
# ----------------------------------------------------------------------------------------------
@dataclasses.dataclass(frozen=True)
class Scene:
    """A validated scene: every section filled with defaults, plus derived facts.

    Attributes:
        source: the file it came from (or ``"<dict>"``).
        data: the normalised nested dict (sections -> keys -> values); JSON-serialisable.
    """

    source: str
    data: dict

    def __getitem__(self, section: str) -> dict:
        return self.data[section]

    @property
    def name(self) -> str:
        return self.data["scene"]["name"]

    @property
    def n_simulations(self) -> int:
        return self.data["scene"]["n_simulations"]

    @property
    def seed(self) -> int:
        return self.data["scene"]["seed"]

    @property
    def cases(self) -> list[dict]:
        return self.data["cases"]

    @property
    def load_fractions(self) -> list[float]:
        return self.data["steps"]["fractions"]

    @property
    def varies(self) -> dict[str, bool]:
        """What changes between simulations; features and shards contain only these."""
        mat_cases = any("material" in c for c in self.cases)
        return {
            "loads": True,
            "material": "sample" in self.data["material"] or mat_cases,
            "geometry": self.data["geometry"]["source"] == "population",
        }

    @property
    def hash(self) -> str:
        """sha256 of the canonical JSON of the normalised scene (source path excluded)."""
        text = json.dumps(self.data, sort_keys=True, separators=(",", ":"))
        return hashlib.sha256(text.encode()).hexdigest()

    def to_json(self) -> str:
        return json.dumps(self.data, sort_keys=True, indent=1)

    def check_mesh(self, n_nodes: int) -> None:
        """Check node ids of the scene against a mesh of ``n_nodes`` nodes; raise SceneError."""
        problems = mesh_problems(self, n_nodes)
        if problems:
            raise SceneError(self.source, problems)


def _check_section(section: str, raw: Any, schema: dict[str, Key], problems: list[str],
                   where: str | None = None) -> dict:
    """Check one table against its schema; return it with defaults filled in."""
    where = where or section
    if raw is None:
        raw = {}
    if not isinstance(raw, dict):
        problems.append(f"[{where}]: expected a table, got {type(raw).__name__}")
        return {}
    out: dict[str, Any] = {}
    for key in raw:
        if key not in schema:
            problems.append(f"{where}.{key}: unknown key (expected one of: "
                            f"{', '.join(sorted(schema))})")
    for key, spec in schema.items():
        if key in raw:
            value = raw[key]
            expected = spec.check(value)
            if expected is not None:
                problems.append(f"{where}.{key}: expected {expected}, got {value!r}")
            out[key] = value
        elif spec.default is REQUIRED:
            problems.append(f"{where}.{key}: missing (expected {spec.doc})")
        elif spec.default is not None:
            out[key] = copy.deepcopy(spec.default)
    return out


def _check_material_params(where: str, params: dict, problems: list[str]) -> None:
    """Cross-key checks of a {c, m, K} parameter set."""
    c, m = params.get("c"), params.get("m")
    if isinstance(c, list) and isinstance(m, list) and len(c) != len(m):
        problems.append(f"{where}: c and m must have one entry per Ogden term, got "
                        f"{len(c)} c and {len(m)} m")


def _normalise(raw: dict, source: str) -> tuple[dict, list[str]]:
    problems: list[str] = []
    for key in raw:
        if key not in _TOP_LEVEL:
            problems.append(f"{key}: unknown top-level key (expected sections: "
                            f"{', '.join(_TOP_LEVEL)})")
    version = raw.get("schema_version", SCENE_SCHEMA_VERSION)
    if version != SCENE_SCHEMA_VERSION:
        problems.append(f"schema_version: expected {SCENE_SCHEMA_VERSION}, got {version!r}")
    data: dict[str, Any] = {"schema_version": SCENE_SCHEMA_VERSION}
    for section, schema in _SCHEMA.items():
        if "." in section:
            continue
        data[section] = _check_section(section, raw.get(section), schema, problems)

    _check_geometry(data["geometry"], problems)
    _check_fixed(data["fixed"], problems)
    _check_material(data["material"], raw.get("material") or {}, problems)
    _check_loads(data["loads"], problems)
    _check_steps(data["steps"], problems)
    _check_solver(data["solver"], problems)
    data["cases"] = _check_cases(raw.get("cases", []), data, problems)

    scene = data["scene"]
    if "n_simulations" not in scene:
        if data["cases"]:
            scene["n_simulations"] = len(data["cases"])
        else:
            problems.append("scene.n_simulations: missing (expected an integer >= 1, "
                            "or a list of [[cases]])")
    elif data["cases"] and scene["n_simulations"] != len(data["cases"]):
        problems.append(f"scene.n_simulations: {scene['n_simulations']} but "
                        f"{len(data['cases'])} [[cases]] are listed; they must agree")
    return data, problems


def _check_geometry(g: dict, problems: list[str]) -> None:
    src = g.get("source")
    if src == "file" and "path" not in g:
        problems.append("geometry.path: missing (expected a mesh/surface file when "
                        "source = 'file')")
    if src == "population" and "population_size" not in g:
        problems.append("geometry.population_size: missing (expected an integer >= 1 when "
                        "source = 'population')")
    if src != "file":
        for key in ("path",):
            if key in g:
                problems.append(f"geometry.{key}: only used when source = 'file'")
    if src == "population" and "population_size" in g and \
            g.get("pca_components", 27) > g["population_size"] - 1:
        problems.append(f"geometry.pca_components: {g.get('pca_components', 27)} components "
                        f"need more than {g['population_size']} livers (expected at most "
                        "population_size - 1)")
    if src != "population" and "population_size" in g:
        problems.append("geometry.population_size: only used when source = 'population'")


def _check_fixed(f: dict, problems: list[str]) -> None:
    needs = {"sphere": ("center", "radius"), "box": ("min", "max"),
             "cylinder": ("center", "axis", "radius", "length"), "nodes": ("nodes",),
             "region": ("name",)}
    kind = f.get("kind")
    for key in needs.get(kind, ()):
        if key not in f:
            problems.append(f"fixed.{key}: missing (needed when kind = {kind!r})")
    used = set(needs.get(kind, ())) | {"kind"}
    for key in ("center", "radius", "axis", "length", "min", "max", "nodes"):
        if key in f and key not in used:
            problems.append(f"fixed.{key}: not used when kind = {kind!r}")
    if kind != "region":
        f.pop("name", None)
    if kind == "box" and _vec3(f.get("min")) is None and _vec3(f.get("max")) is None:
        if any(a >= b for a, b in zip(f["min"], f["max"])):
            problems.append(f"fixed.min/max: expected min < max in every coordinate, got "
                            f"{f['min']} and {f['max']}")
    if kind == "nodes" and isinstance(f.get("nodes"), list):
        if len(set(f["nodes"])) != len(f["nodes"]):
            problems.append("fixed.nodes: contains duplicate node ids")


def _check_material(mat: dict, raw: dict, problems: list[str]) -> None:
    if "K" in raw and "K_over_mu" in raw:
        problems.append("material: give K or K_over_mu, not both")
    if "K" in raw:
        mat.pop("K_over_mu", None)
    _check_material_params("material", mat, problems)
    if "sample" in mat and isinstance(mat["sample"], dict):
        mat["sample"] = _check_section("material.sample", mat["sample"],
                                       _SCHEMA["material.sample"], problems)
        s = mat["sample"]
        if s.get("kind") == "uniform":
            for key in ("c", "m"):
                if key not in s:
                    problems.append(f"material.sample.{key}: missing (needed when kind = "
                                    "'uniform')")
            if isinstance(s.get("c"), list) and isinstance(s.get("m"), list) and (
                    len(s["c"]) != len(s["m"])):
                problems.append("material.sample: c and m need one range per Ogden term")
            if "sets" in s:
                problems.append("material.sample.sets: only used when kind = 'table'")
        elif s.get("kind") == "table":
            if "sets" not in s:
                problems.append("material.sample.sets: missing (needed when kind = 'table')")
            for i, item in enumerate(s.get("sets", []) if isinstance(s.get("sets"), list)
                                     else []):
                _check_param_set(f"material.sample.sets[{i}]", item, problems)
            for key in ("c", "m", "K_over_mu", "n_sets"):
                if key in s:
                    problems.append(f"material.sample.{key}: only used when kind = 'uniform'")


_PARAM_SET_KEYS = {
    "c": Key(_num_list(positive=True), REQUIRED, "Ogden c_k, MPa"),
    "m": Key(_num_list(nonzero=True), REQUIRED, "Ogden m_k"),
    "K": Key(_num(0.0), OPTIONAL, "bulk modulus, MPa"),
    "K_over_mu": Key(_num(0.0), OPTIONAL, "K / mu"),
}


def _check_param_set(where: str, item: Any, problems: list[str]) -> dict:
    out = _check_section(where, item, _PARAM_SET_KEYS, problems, where=where)
    if "K" in out and "K_over_mu" in out:
        problems.append(f"{where}: give K or K_over_mu, not both")
    if "K" not in out and "K_over_mu" not in out:
        problems.append(f"{where}: missing K or K_over_mu")
    _check_material_params(where, out, problems)
    return out


def _check_loads(ld: dict, problems: list[str]) -> None:
    if ld.get("kind") == "patch" and "patch_radius" not in ld:
        problems.append("loads.patch_radius: missing (needed when kind = 'patch')")
    if ld.get("kind") == "nodal" and "patch_radius" in ld:
        problems.append("loads.patch_radius: only used when kind = 'patch'")


def _check_steps(st: dict, problems: list[str]) -> None:
    if "fractions" in st:
        if _fractions(st["fractions"]) is None:
            st["fractions"] = [float(x) for x in st["fractions"]]
            st["n"] = len(st["fractions"])
    elif _is_int(st.get("n")) and st["n"] >= 1:
        n = st["n"]
        st["fractions"] = [(i + 1) / n for i in range(n)]


def _check_solver(sv: dict, problems: list[str]) -> None:
    if "quadrature_degree" not in sv and sv.get("degree") in (1, 2):
        # P1 with one-point quadrature is FEBio's tet4; P2 integrates the (nonlinear) integrand
        # with a degree-2 rule, enough for its linear strains at the nodes of the reference test.
        sv["quadrature_degree"] = 1 if sv["degree"] == 1 else 2


def _check_cases(raw_cases: Any, data: dict, problems: list[str]) -> list[dict]:
    if not isinstance(raw_cases, list):
        problems.append(f"cases: expected an array of tables [[cases]], got "
                        f"{type(raw_cases).__name__}")
        return []
    out = []
    count = data["loads"].get("count")
    for i, item in enumerate(raw_cases):
        where = f"cases[{i}]"
        case = _check_section(where, item, _CASE_KEYS, problems, where=where)
        nodes, forces = case.get("load_nodes"), case.get("forces")
        if isinstance(nodes, list) and isinstance(forces, list) and len(nodes) != len(forces):
            problems.append(f"{where}: {len(nodes)} load_nodes but {len(forces)} forces")
        if _is_int(count) and isinstance(nodes, list) and len(nodes) != count:
            problems.append(f"{where}.load_nodes: {len(nodes)} given, loads.count = {count}")
        if isinstance(case.get("material"), dict):
            case["material"] = _check_param_set(f"{where}.material", case["material"], problems)
        out.append(case)
    return out


def mesh_problems(scene: Scene, n_nodes: int) -> list[str]:
    """Problems of the scene's explicit node ids against a mesh with ``n_nodes`` nodes."""
    problems = []
    lists = []
    f = scene["fixed"]
    if f.get("kind") == "nodes" and _node_ids(f.get("nodes")) is None:
        lists.append(("fixed.nodes", f["nodes"]))
        if len(f["nodes"]) > n_nodes:
            problems.append(f"fixed.nodes: {len(f['nodes'])} ids given but the mesh has only "
                            f"{n_nodes} nodes")
    if _node_ids(scene["output"].get("nodes")) is None:
        lists.append(("output.nodes", scene["output"]["nodes"]))
    for i, case in enumerate(scene.cases):
        if _node_ids(case.get("load_nodes")) is None:
            lists.append((f"cases[{i}].load_nodes", case["load_nodes"]))
    for where, ids in lists:
        bad = [i for i in ids if i >= n_nodes]
        if bad:
            problems.append(f"{where}: node ids {bad[:5]}{'...' if len(bad) > 5 else ''} are "
                            f"out of range (expected ids < {n_nodes}, the mesh's node count)")
    return problems


def parse_scene(raw: dict, source: str = "<dict>", base_dir: Path | None = None) -> Scene:
    """Validate a scene given as a dict (the parsed TOML). Raises SceneError with all problems."""
    data, problems = _normalise(raw, source)
    geom = data["geometry"]
    if geom.get("source") == "file" and isinstance(geom.get("path"), str):
        path = Path(geom["path"])
        if not path.is_absolute() and base_dir is not None:
            path = (base_dir / path).resolve()
        geom["path"] = str(path)
        if not path.exists():
            problems.append(f"geometry.path: file {str(path)!r} does not exist")
        elif path.suffix in (".h5", ".hdf5"):
            from data_spec.geometry import read_geometry_node_count

            try:
                n_nodes = read_geometry_node_count(path)
                problems.extend(mesh_problems(Scene(source, data), n_nodes))
            except (OSError, KeyError, ValueError) as exc:
                problems.append(f"geometry.path: cannot read geometry file {str(path)!r}: {exc}")
    if problems:
        raise SceneError(source, problems)
    return Scene(source, data)


def load_scene(path: str | Path) -> Scene:
    """Read and validate a scene TOML file. Raises SceneError naming the file and every problem."""
    path = Path(path)
    try:
        text = path.read_text()
    except OSError as exc:
        raise SceneError(str(path), [f"cannot read the file: {exc.strerror or exc}"]) from None
    try:
        raw = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise SceneError(str(path), [f"not valid TOML: {exc}"]) from None
    return parse_scene(raw, str(path), base_dir=path.parent)


def schema_table() -> list[tuple[str, str, str]]:
    """(section.key, default, doc) rows for documentation and ``--help`` texts."""
    rows = []
    for section, keys in _SCHEMA.items():
        for key, spec in keys.items():
            default = "required" if spec.default is REQUIRED else (
                "-" if spec.default is None else json.dumps(spec.default))
            rows.append((f"{section}.{key}", default, spec.doc))
    return rows
