"""The dataset's index of meshed livers (DATA/geometry/meshes.json): what each mesh depends on
(a key) -> its geometry id, so that a run meshes a liver once and a resumed run reads it back.
"""

from __future__ import annotations

import functools
import hashlib
import json
from pathlib import Path

from data_spec import Geometry, geometry_path, read_geometry

MESH_INDEX = "meshes.json"


def phantom_key(seed: int, variety: str, mesh_size: float) -> str:
    """What a phantom's mesh depends on: its seed, variety and mesh size, and the code."""
    return f"phantom {seed} {variety}, mesh size {float(mesh_size)!r}, {phantom_code()}"


@functools.cache
def phantom_code() -> str:
    """A digest of the code that meshes a phantom (its modules and gmsh's version), read once
    per process (every liver's key holds it).
    """
    import gmsh

    from fem_sim.geometry import meshing, phantom

    h = hashlib.sha256(gmsh.__version__.encode())
    for module in (phantom, meshing):
        h.update(Path(module.__file__).read_bytes())
    return "code " + h.hexdigest()[:16]


def index_path(dataset) -> Path:
    return Path(dataset) / "geometry" / MESH_INDEX


def read_index(dataset) -> dict:
    path = index_path(dataset) if dataset is not None else None
    if path is None or not path.exists():
        return {}
    try:
        index = json.loads(path.read_text())
        return index if isinstance(index, dict) else {}
    except (OSError, ValueError):  # unreadable: everything is meshed again and it is rewritten
        return {}


def write_index(dataset, index: dict) -> None:
    from data_spec.atomic import atomic_path

    path = index_path(dataset)
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(path) as tmp:
        tmp.write_text(json.dumps(index, indent=1, sort_keys=True) + "\n")


def indexed(dataset, geometry_id) -> Geometry | None:
    """The geometry file the index names, if it holds that mesh (its coefficients dropped:
    the caller attaches the scene's).
    """
    if dataset is None or not geometry_id:
        return None
    path = geometry_path(dataset, geometry_id)
    try:
        g = read_geometry(path) if path.exists() else None
    except Exception:  # truncated or corrupt: meshed again, and the caller rewrites the file
        return None
    if g is None or g.geometry_id != geometry_id:
        return None
    g.shape_coefficients = None
    return g
