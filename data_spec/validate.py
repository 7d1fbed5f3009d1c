"""Dataset validator: reports *everything* wrong with a dataset directory as a list of strings.

Each problem names the file, the field and what was expected. An empty list means every shard
opens, has all fields with consistent shapes and finite values, references an existing geometry
file that matches it, and has a coherent status.
"""

from __future__ import annotations

from pathlib import Path

import h5py
import numpy as np

from data_spec.atomic import leftover_temporaries
from data_spec.geometry import GEOMETRY_FORMAT, geometry_problems, read_geometry
from data_spec.shard_layout import (
    CHECKSUM_MISMATCH,
    DATASETS,
    READABLE_VERSIONS,
    SHARD_FORMAT,
    SHARD_SCHEMA_VERSION,
    STATUSES,
    checksum_ok,
    missing,
    read_values,
    shape_problems,
)
from data_spec.shards import list_shards


def _geometry_facts(path: Path, cache: dict) -> tuple[int, str] | str:
    """(n_nodes, geometry_id) of a geometry file, or a problem string: unreadable, not a
    geometry, arrays that fail :func:`geometry_problems` (e.g. inverted cells), or contents that
    no longer match the stored hash. Cached per path: read once per dataset.
    """
    if path in cache:
        return cache[path]
    if not path.exists():
        cache[path] = f"geometry file {path} is missing"
        return cache[path]
    try:
        with h5py.File(path, "r") as g:
            if g.attrs.get("format") != GEOMETRY_FORMAT:
                cache[path] = f"geometry file {path} is not a {GEOMETRY_FORMAT} file"
                return cache[path]
            facts = (int(g["points"].shape[0]), str(g.attrs["geometry_id"]))
            stored_hash = str(g.attrs.get("content_hash", ""))
        geo = read_geometry(path)
        bad = geometry_problems(geo)
        if geo.content_hash != stored_hash:
            bad.insert(0, "points or cells differ from the stored content hash "
                       "(corrupted or edited)")
        cache[path] = f"geometry file {path}: " + "; ".join(bad) if bad else facts
    except (OSError, KeyError, ValueError) as exc:
        cache[path] = f"geometry file {path} cannot be read: {exc}"
    return cache[path]


def _read(path: Path) -> tuple[list[str], dict | None, dict]:
    """(problems so far, the shard's arrays (None when it cannot be read on), its attributes)."""
    try:
        f = h5py.File(path, "r")
    except OSError as exc:
        return [f"{path}: cannot open as HDF5 (truncated or corrupt?): {exc}"], None, {}
    p: list[str] = []
    with f:
        if f.attrs.get("format") != SHARD_FORMAT:
            return [f"{path}: attribute 'format' is {f.attrs.get('format')!r}, expected "
                    f"{SHARD_FORMAT!r}"], None, {}
        p += [f"{path}: missing {what}" for what in missing(f)]
        if p:
            return p, None, {}
        if f.attrs["schema_version"] not in READABLE_VERSIONS:
            p.append(f"{path}: schema_version {f.attrs['schema_version']}, expected one of "
                     f"{READABLE_VERSIONS} (written: {SHARD_SCHEMA_VERSION})")
        try:
            values = read_values(f)
        except OSError as exc:
            return p + [f"{path}: data cannot be read (truncated or corrupt?): {exc}"], None, {}
        if not checksum_ok(f, values):
            p.append(f"{path}: {CHECKSUM_MISMATCH}")
        attrs = {k: str(f.attrs[k]) for k in ("status", "failure_reason", "geometry_file",
                                              "geometry_id", "scene_hash")}
        return p, {e.path: values[e.path] for e in DATASETS}, attrs


def _content_problems(path: Path, arr: dict, status: str, reason: str) -> list[str]:
    """Shapes, step counts, finiteness, status and the fixed region of a shard's arrays."""
    shapes, dims = shape_problems(arr)
    p = [f"{path}: {msg}" for msg in shapes]
    if not shapes:
        n_done, n_steps = dims["n_done"], dims["n_steps"]
        if n_done > n_steps:
            p.append(f"{path}: '/displacement' has {n_done} steps but only {n_steps} load "
                     "fractions")
        if status == "ok" and n_done != n_steps:
            p.append(f"{path}: status 'ok' but {n_done} of {n_steps} load steps stored")
        off = np.asarray(arr["/solver/residual_offsets"])
        if off[0] != 0 or off[-1] != dims["n_history"] or np.any(np.diff(off) < 0):
            p.append(f"{path}: '/solver/residual_offsets' must rise from 0 to the length of "
                     f"'/solver/residual_history' ({dims['n_history']})")
    for e in DATASETS:
        if e.finite:
            bad = ~np.isfinite(np.asarray(arr[e.path], dtype=np.float64))
            if bad.any():
                p.append(f"{path}: '{e.path}' contains {int(bad.sum())} NaN/inf value(s)")
    if status not in STATUSES:
        p.append(f"{path}: status {status!r}, expected one of {STATUSES}")
    if status == "failed" and not reason:
        p.append(f"{path}: status 'failed' without a failure_reason")
    if np.size(arr["/fixed_nodes"]) == 0:
        p.append(f"{path}: 'fixed_nodes' is empty (the problem has rigid-body modes)")
    return p


def _liver_problems(path: Path, arr: dict, geo_rel: str, geo_id: str, cache: dict) -> list:
    """The shard's geometry file: readable, the liver it names, node ids within it."""
    facts = _geometry_facts((path.parent / geo_rel).resolve(), cache)
    if isinstance(facts, str):
        return [f"{path}: {facts}"]
    p = []
    n_nodes, real_id = facts
    if real_id != geo_id:
        p.append(f"{path}: geometry_id {geo_id!r} but {geo_rel} holds {real_id!r}")
    for name in ("/load/nodes", "/fixed_nodes", "/output_nodes"):
        ids = np.asarray(arr[name])
        if ids.size and (ids.min() < 0 or ids.max() >= n_nodes):
            p.append(f"{path}: '{name}' has node ids outside [0, {n_nodes})")
    return p


def shard_problems(path: str | Path, geometry_cache: dict | None = None) -> list[str]:
    """Everything wrong with one shard file."""
    return checked_shard(path, geometry_cache)[0]


def checked_shard(path: str | Path, geometry_cache: dict | None = None
                  ) -> tuple[list[str], dict | None, dict]:
    """(everything wrong with one shard file, its arrays by path (None when it cannot be
    read), its attributes status, failure_reason, geometry_file, geometry_id and
    scene_hash), the file opened once.
    """
    path = Path(path)
    geometry_cache = {} if geometry_cache is None else geometry_cache
    p, arr, attrs = _read(path)
    if arr is None:
        return p, None, attrs
    p += _content_problems(path, arr, attrs["status"], attrs["failure_reason"])
    p += _liver_problems(path, arr, attrs["geometry_file"], attrs["geometry_id"],
                         geometry_cache)
    if not path.with_suffix(".xdmf").exists():
        p.append(f"{path}: its XDMF file {path.with_suffix('.xdmf').name} is missing")
    return p, arr, attrs


def _missing_problems(directory: Path, shards: list[Path]) -> list[str]:
    """The scene's simulations without a shard (each index named, with the command that makes
    just those).
    """
    from data_spec.scene import SceneError, load_scene

    p = []
    try:
        n = load_scene(directory / "scene.toml").n_simulations
    except (SceneError, OSError):
        return p  # the scene's own problem is reported by _scene_problems
    have = {int(s.stem.split("_")[1]) for s in shards if s.stem.split("_")[1].isdigit()}
    missing = sorted(set(range(n)) - have)
    if missing:
        shown = ", ".join(map(str, missing[:10])) + (" ..." if len(missing) > 10 else "")
        p.append(f"{directory}: {len(missing)} of the scene's {n} simulations have no shard "
                 f"(simulation {shown}); `mpirun -n 2 python -m fem_sim generate "
                 f"{directory}/scene.toml --out {directory}` makes just those")
    return p


def _scene_problems(path: Path, shard_hashes: set[str]) -> list[str]:
    """The dataset's scene.toml: present, valid, and the scene its shards were made from (at
    its size or at an earlier one: :mod:`data_spec.grown`).
    """
    from data_spec.grown import accepted_hashes
    from data_spec.scene import SceneError, load_scene

    if not path.exists():
        return [f"{path}: missing (every dataset keeps the scene that produced it)"]
    try:
        scene = load_scene(path)
        accepted = accepted_hashes(scene, path.parent)
    except (SceneError, ValueError) as exc:
        why = "; ".join(exc.problems) if isinstance(exc, SceneError) else str(exc)
        return [f"{path}: not a valid scene: {why}"]
    other = sorted(shard_hashes - accepted)
    if other:
        return [f"{path}: its hash {scene.hash[:12]}... is not the scene_hash of some shards "
                f"({', '.join(h[:12] + '...' for h in other)}): the scene was edited after "
                "the dataset was made (only n_simulations may change)"]
    return []


def _linear_problems(directory: Path) -> list[str]:
    """The dataset's small-strain files (``linear.h5``, ``linear/<geometry id>.h5``): readable,
    whole and of this dataset's scene and livers.
    """
    from data_spec.linear_fields import linear_fields_path, linear_file_problems

    p = linear_file_problems(directory) if linear_fields_path(directory).exists() else []
    for path in sorted((directory / "linear").glob("*.h5")):
        p += linear_file_problems(directory, path.stem)
    return p


def validate_dataset(directory: str | Path, complete: bool = True) -> list[str]:
    """Every problem of a dataset directory (empty list if valid). ``complete``: every
    simulation of its scene must have a shard (False: a subset, such as held-out simulations
    or a view of the first n, is valid too).
    """
    directory = Path(directory)
    if not directory.is_dir():
        return [f"{directory}: not a directory"]
    shards = list_shards(directory)
    if not shards:   # a liver's small-strain responses alone (make liver's directory)
        from data_spec.linear_fields import linear_fields_path

        if linear_fields_path(directory).exists():
            return _linear_problems(directory)
        return [f"{directory}: no shards found (expected {directory}/sims/sim_*.h5)"]
    problems: list[str] = []
    cache: dict = {}
    hashes = set()
    for path in shards:
        problems.extend(shard_problems(path, cache))
        try:
            with h5py.File(path, "r") as f:
                hashes.add(str(f.attrs.get("scene_hash")))
        except OSError:
            pass
    problems += _scene_problems(directory / "scene.toml", hashes)
    problems += [f"{x}: an XDMF file without its shard {x.with_suffix('.h5').name}"
                 for x in sorted((directory / "sims").glob("sim_*.xdmf"))
                 if not x.with_suffix(".h5").exists()]
    if complete:
        problems += _missing_problems(directory, shards)
    problems += _linear_problems(directory)
    for tmp in leftover_temporaries(directory):
        problems.append(f"{tmp}: leftover temporary file of an interrupted writer")
    return problems
