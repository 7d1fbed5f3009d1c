"""Scene files written from Python: a scene dict as TOML, a scene moved elsewhere, and a
scene's settings on one liver.

``scene_toml(d)`` writes the tables of scalars and lists a scene has (:mod:`data_spec.scene`
reads it back); ``relocated_scene`` is a scene file's dict with its liver folder (or file)
absolute, to be changed and written anywhere; ``liver_scene`` makes the scene of a liver's FE
truth: a population scene's loads, material, steps and solver on one liver file, fixed where a
model puts its fixed region.
"""

from __future__ import annotations

import json
import tomllib
from pathlib import Path


def _value(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, str):
        return json.dumps(v)
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_value(x) for x in v) + "]"
    return repr(v)


def _table(name: str, d: dict) -> list[str]:
    lines = ["", f"[{name}]"] + [f"{k} = {_value(v)}" for k, v in d.items()
                                 if not isinstance(v, dict)]
    for k, v in d.items():
        if isinstance(v, dict):
            lines += _table(f"{name}.{k}", v)
    return lines


def scene_toml(d: dict) -> str:
    """A scene dict (tables of scalars, lists and nested tables) as TOML text."""
    lines = [f"{k} = {_value(v)}" for k, v in d.items() if not isinstance(v, dict)]
    for k, v in d.items():
        if isinstance(v, dict):
            lines += _table(k, v)
    return "\n".join(lines) + "\n"


def relocated_scene(scene_file: str | Path) -> dict:
    """Scene file ``scene_file`` as a dict whose ``geometry.livers`` (a population's folder)
    or ``geometry.path`` (a liver file), when relative, is made absolute: the dict stays the
    same scene wherever :func:`scene_toml` writes it (a study changes its size or phantoms).
    """
    from data_spec.scene import absolute_path

    scene_file = Path(scene_file)
    d = tomllib.loads(scene_file.read_text())
    g = d.get("geometry", {})
    for key in ("livers", "path"):
        if isinstance(g.get(key), str) and not Path(g[key]).is_absolute():
            g[key] = absolute_path(scene_file.parent, g[key])
    return d


def liver_scene(scene_file: str | Path, liver: str | Path, n: int, fixed=None,
                seed: int = 44, area_min: float | None = None,
                mesh: str | Path | None = None, radius: float | None = None,
                near=None, near_radius: float | None = None) -> str:
    """The scene of a liver's FE truth: ``scene_file``'s loads, material, steps and solver on
    the liver file ``liver`` (its own mesh at the scene's mesh size), ``n`` simulations.
    ``fixed`` (k, 3) mm in the liver's frame: the surface nodes within half an element of
    these points are fixed (where a model's placement puts its fixed region); None: the
    file's default region. ``area_min`` (mm^2): that region grown to it, as a file
    population grows its livers'. ``mesh``: the liver already meshed at the scene's size
    (``fem_sim mesh --scene``), solved as it is instead of meshing the file again;
    ``radius`` (mm): how near a fixed point a node is fixed (half an element by default);
    ``near`` (3,) mm, ``near_radius``: the loads drawn within that reach of the site
    (``[loads] near``).
    """
    scene_file, liver = Path(scene_file), Path(liver)
    raw = tomllib.loads(scene_file.read_text())
    raw["scene"] = {"name": "truth_" + liver.stem, "n_simulations": n, "seed": seed,
                    "description": f"{scene_file.name}'s settings on {liver.name}: the FE "
                                   "truth a model is evaluated against."}
    raw["geometry"] = {"source": "file", "path": str(Path(mesh or liver).resolve()),
                       "mesh_size": raw["geometry"]["mesh_size"]}
    if fixed is not None:
        raw["fixed"] = {"kind": "points",
                        "radius": radius or 0.5 * raw["geometry"]["mesh_size"],
                        "points": [[round(float(v), 3) for v in p] for p in fixed]}
        if area_min:
            raw["fixed"]["area_min"] = round(float(area_min), 1)
    if near is not None:
        raw["loads"]["near"] = [round(float(v), 3) for v in near]
        if near_radius:
            raw["loads"]["near_radius"] = float(near_radius)
    raw.pop("cases", None)
    raw["surrogate"] = {"config": "small"}
    return scene_toml(raw)
