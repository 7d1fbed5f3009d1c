"""Scene schema v1: a TOML file that says what a dataset contains and what varies.

A scene is data (STYLE.md principle 2): both packages derive their behaviour from the validated
``Scene`` returned by :func:`load_scene`, never from scene-specific code paths.

Validation collects *every* problem (file, key, what was expected, what was found) and raises one
:class:`SceneError` listing them all, so a user fixes a scene in one pass. Only numpy and the
standard library are used here (``tomllib``), so the solver and the trainer interpreters both
import it.

The schema itself is the table in :mod:`data_spec.scene_schema`; this module applies it and adds
the checks that span several keys.
"""

from __future__ import annotations

import copy
import dataclasses
import hashlib
import json
import os
import tomllib
from pathlib import Path
from typing import Any

from data_spec import solver_rules
from data_spec.checks import is_int
from data_spec.scene_schema import (  # noqa: F401  (SCENE_SCHEMA_VERSION, schema_table: API)
    _CASE_KEYS,
    _PARAM_SET_KEYS,
    _SCHEMA,
    _TOP_LEVEL,
    REQUIRED,
    SCENE_SCHEMA_VERSION,
    Key,
    _fractions,
    _node_ids,
    _vec3,
    schema_table,
)


class SceneError(ValueError):
    """A scene file is malformed. ``problems`` lists every problem found, one string each."""

    def __init__(self, source: str, problems: list[str]):
        self.source = source
        self.problems = list(problems)
        lines = "\n".join(f"  - {p}" for p in self.problems)
        super().__init__(f"{source}: {len(self.problems)} problem(s) in scene:\n{lines}")


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
        return self.hash_at(self.n_simulations)

    def hash_at(self, n_simulations: int) -> str:
        """The hash of this scene with ``n_simulations`` simulations: a simulation's draws
        depend on the seed and its index only, so the shards of the same scene at another
        size (a dataset grown by raising ``n_simulations``) carry this hash.
        """
        data = {**self.data, "scene": {**self.data["scene"], "n_simulations": n_simulations}}
        text = json.dumps(data, sort_keys=True, separators=(",", ":"))
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
    if src == "population" and "population_size" not in g and "livers" not in g:
        problems.append("geometry.population_size: missing (expected an integer >= 1 when "
                        "source = 'population')")
    if src != "file":
        for key in ("path",):
            if key in g:
                problems.append(f"geometry.{key}: only used when source = 'file'")
    if src == "population" and "population_size" in g and "livers" not in g and \
            g.get("pca_components", 27) > g["population_size"] - 1:
        problems.append(f"geometry.pca_components: {g.get('pca_components', 27)} components "
                        f"need more than {g['population_size']} livers (expected at most "
                        "population_size - 1)")
    for key in ("population_size", "variety", "livers", "fixed_area_min"):
        if src != "population" and key in g:
            problems.append(f"geometry.{key}: only used when source = 'population'")


def _check_fixed(f: dict, problems: list[str]) -> None:
    needs = {"sphere": ("center", "radius"), "box": ("min", "max"),
             "cylinder": ("center", "axis", "radius", "length"), "nodes": ("nodes",),
             "points": ("points", "radius"), "region": ("name",)}
    kind = f.get("kind")
    for key in needs.get(kind, ()):
        if key not in f:
            problems.append(f"fixed.{key}: missing (needed when kind = {kind!r})")
    used = set(needs.get(kind, ())) | {"kind"}
    for key in ("center", "radius", "axis", "length", "min", "max", "nodes", "points"):
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


def _check_uniform_sample(s: dict, problems: list[str]) -> None:
    for key in ("c", "m"):
        if key not in s:
            problems.append(f"material.sample.{key}: missing (needed when kind = 'uniform')")
    if isinstance(s.get("c"), list) and isinstance(s.get("m"), list) and (
            len(s["c"]) != len(s["m"])):
        problems.append("material.sample: c and m need one range per Ogden term")
    if "sets" in s:
        problems.append("material.sample.sets: only used when kind = 'table'")


def _check_table_sample(s: dict, problems: list[str]) -> None:
    if "sets" not in s:
        problems.append("material.sample.sets: missing (needed when kind = 'table')")
    for i, item in enumerate(s.get("sets", []) if isinstance(s.get("sets"), list) else []):
        _check_param_set(f"material.sample.sets[{i}]", item, problems)
    for key in ("c", "m", "K_over_mu", "n_sets"):
        if key in s:
            problems.append(f"material.sample.{key}: only used when kind = 'uniform'")


def _check_material(mat: dict, raw: dict, problems: list[str]) -> None:
    if "K" in raw and "K_over_mu" in raw:
        problems.append("material: give K or K_over_mu, not both")
    if "K" in raw:
        mat.pop("K_over_mu", None)
    _check_material_params("material", mat, problems)
    if "sample" in mat and isinstance(mat["sample"], dict):
        mat["sample"] = _check_section("material.sample", mat["sample"],
                                       _SCHEMA["material.sample"], problems)
        kind = mat["sample"].get("kind")
        if kind == "uniform":
            _check_uniform_sample(mat["sample"], problems)
        elif kind == "table":
            _check_table_sample(mat["sample"], problems)


def _check_param_set(where: str, item: Any, problems: list[str]) -> dict:
    out = _check_section(where, item, _PARAM_SET_KEYS, problems, where=where)
    if "K" in out and "K_over_mu" in out:
        problems.append(f"{where}: give K or K_over_mu, not both")
    if "K" not in out and "K_over_mu" not in out:
        problems.append(f"{where}: missing K or K_over_mu")
    _check_material_params(where, out, problems)
    return out


GRASP_RADIUS = 10.0   # mm: a grasping tool's patch when the scene does not say
GRASP_TOOLS = 2       # tools at most


def _check_loads(ld: dict, problems: list[str]) -> None:
    if ld.get("kind") == "patch" and "patch_radius" not in ld:
        problems.append("loads.patch_radius: missing (needed when kind = 'patch')")
    if ld.get("kind") == "nodal" and "patch_radius" in ld:
        problems.append("loads.patch_radius: only used when kind = 'patch' or 'grasp'")
    if ld.get("kind") == "grasp":
        ld.setdefault("patch_radius", GRASP_RADIUS)
        if isinstance(ld.get("count"), int) and ld["count"] > GRASP_TOOLS:
            problems.append(f"loads.count: {ld['count']} tools; a grasp has 1 to {GRASP_TOOLS}")


def _check_steps(st: dict, problems: list[str]) -> None:
    if "fractions" in st:
        if _fractions(st["fractions"]) is None:
            st["fractions"] = [float(x) for x in st["fractions"]]
            st["n"] = len(st["fractions"])
    elif is_int(st.get("n")) and st["n"] >= 1:
        n = st["n"]
        st["fractions"] = [(i + 1) / n for i in range(n)]


def _check_solver(sv: dict, problems: list[str]) -> None:
    keys = ("element", "degree", "quadrature_degree", "linear_solver", "factorization",
            "petsc_options")
    if "quadrature_degree" not in sv and sv.get("degree") in (1, 2):
        sv["quadrature_degree"] = solver_rules.default_quadrature(sv["degree"])
    filled = all(k in sv for k in keys if k != "element")  # not when [solver] was no table
    if filled and not any(p.startswith(tuple(f"solver.{k}" for k in keys)) for p in problems):
        # the one rule table of element, degree, solver and factorisation (any rank count
        # here; fem_sim generate checks its --ranks-per-sim against the same table)
        problems += solver_rules.scene_problems(sv)


def _check_cases(raw_cases: Any, data: dict, problems: list[str]) -> list[dict]:
    if not isinstance(raw_cases, list):
        problems.append(f"cases: expected an array of tables [[cases]], got "
                        f"{type(raw_cases).__name__}")
        return []
    out = []
    count = data["loads"].get("count")
    if raw_cases and data["loads"].get("kind") == "grasp":
        problems.append("cases: explicit cases give forces; a grasp scene draws its tools "
                        "(loads.kind = 'grasp' with no [[cases]])")
        return []
    for i, item in enumerate(raw_cases):
        where = f"cases[{i}]"
        case = _check_section(where, item, _CASE_KEYS, problems, where=where)
        nodes, forces = case.get("load_nodes"), case.get("forces")
        if isinstance(nodes, list) and isinstance(forces, list) and len(nodes) != len(forces):
            problems.append(f"{where}: {len(nodes)} load_nodes but {len(forces)} forces")
        if is_int(count) and isinstance(nodes, list) and len(nodes) != count:
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
            path = Path(absolute_path(base_dir, path))
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
    if geom.get("source") == "population" and isinstance(geom.get("livers"), str):
        problems.extend(_population_files(geom, base_dir))
    if problems:
        raise SceneError(source, problems)
    return Scene(source, data)


def absolute_path(base_dir: str | Path, rel: str | Path) -> str:
    """A scene's relative ``geometry.path`` or ``geometry.livers`` made absolute: the scene's
    directory resolved, the rest normalised without following links (a linked ``../shared``
    stays as written). The one rule for every place that makes it absolute (loading, the
    dataset's copy, a relocated scene): the scene's hash holds this path.
    """
    return os.path.normpath(Path(base_dir).resolve() / rel)


def _population_files(geom: dict, base_dir: Path | None) -> list[str]:
    """A file population's folder made absolute, its files and its size checked."""
    from data_spec.livers import file_problems, members

    path = Path(geom["livers"])
    if not path.is_absolute() and base_dir is not None:
        geom["livers"] = absolute_path(base_dir, path)
    found = file_problems(geom)
    if found:
        return found
    n = len(members(geom))
    if geom.get("pca_components", 27) > n - 1:
        return [f"geometry.pca_components: {geom.get('pca_components', 27)} components need "
                f"more than {n} livers (expected at most {n - 1})"]
    return []


def load_scene(path: str | Path) -> Scene:
    """Read and validate a scene TOML file. Raises SceneError naming the file and every problem."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as exc:
        raise SceneError(str(path), [f"cannot read the file: {exc.strerror or exc}"]) from None
    except UnicodeDecodeError as exc:
        raise SceneError(str(path), [f"not UTF-8 text (byte {exc.start}): TOML files are "
                                     "UTF-8"]) from None
    try:
        raw = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise SceneError(str(path), [f"not valid TOML: {exc}"]) from None
    return parse_scene(raw, str(path), base_dir=path.parent)


def dataset_copy_text(path: str | Path) -> str:
    """The text of scene file ``path`` as a dataset directory keeps it (DIR/scene.toml): the
    same scene, with a relative ``geometry.path`` made absolute, so the copy reads from its new
    place (a relative path would point into the dataset directory). The scene must be valid.
    """
    import re

    path = Path(path)
    text = path.read_text(encoding="utf-8")
    geom = tomllib.loads(text).get("geometry", {})
    key = {"file": "path", "population": "livers"}.get(geom.get("source"))
    rel = geom.get(key) if key else None
    if not isinstance(rel, str) or Path(rel).is_absolute():
        return text
    absolute = absolute_path(path.parent, rel)
    lines = text.splitlines(keepends=True)
    section, done = None, False
    assign = re.compile(rf"""^(\s*{key}\s*=\s*)("[^"]*"|'[^']*')""")
    for k, line in enumerate(lines):
        header = re.match(r"^\s*\[\s*([A-Za-z0-9_.\-]+)\s*\]", line)
        if header:
            section = header.group(1)
        elif section == "geometry" and not done and assign.match(line):
            lines[k] = assign.sub(lambda m: m.group(1) + json.dumps(absolute), line, count=1)
            done = True
    out = "".join(lines)
    if not done or tomllib.loads(out)["geometry"].get(key) != absolute:
        raise SceneError(str(path), [f"geometry.{key}: cannot rewrite it as an absolute path "
                                     "in the dataset's copy; write it as a plain string on "
                                     "its own line under [geometry]"])
    return out
