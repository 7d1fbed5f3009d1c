"""Shards: one HDF5 file (+ XDMF) per simulation; the writer, the reader and the layout.

The writer takes plain numpy arrays (no MPI): ``fem_sim`` gathers one simulation to its group's
first rank and calls :func:`write_shard`; the trainer's tests build synthetic shards with the same
function. Files are written atomically (temporary name, then rename): XDMF first, HDF5 last, so a
shard whose HDF5 file exists is complete. ``data_spec/README.md`` documents every field.

Dataset directory layout::

    DIR/scene.toml               copy of the scene that produced the dataset
    DIR/geometry/<id>.h5         one file per mesh, shared by all shards that use it
    DIR/sims/sim_000123.h5       one shard per simulation (index zero-padded to 6 digits)
    DIR/sims/sim_000123.xdmf     its ParaView time series over load steps
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path

import h5py
import numpy as np

from data_spec.atomic import atomic_path, write_text_atomic
from data_spec.material import OgdenMaterial
from data_spec.shard_layout import (
    CHECKSUM_MISMATCH,
    LAYOUT,
    READABLE_VERSIONS,
    SHARD_FORMAT,
    SHARD_SCHEMA_VERSION,
    STATUSES,
    UNITS,
    checksum,
    checksum_ok,
    get,
    missing,
    read_values,
    version_of,
    write_entry,
)
from data_spec.xdmf import shard_xdmf

__all__ = ["SHARD_FORMAT", "SHARD_SCHEMA_VERSION", "STATUSES", "UNITS", "Shard", "SolverStats",
           "geometry_path", "list_shards", "read_shard", "shard_path", "write_shard"]


def shard_path(directory: str | Path, index: int) -> Path:
    return Path(directory) / "sims" / f"sim_{index:06d}.h5"


def geometry_path(directory: str | Path, geometry_id: str) -> Path:
    return Path(directory) / "geometry" / f"{geometry_id}.h5"


def list_shards(directory: str | Path) -> list[Path]:
    """Shard files of a dataset directory, sorted by simulation index."""
    return sorted((Path(directory) / "sims").glob("sim_*.h5"))


@dataclass
class SolverStats:
    """Per stored load step: Newton iterations, final residual, cut-backs, wall time and the
    residual history (all Newton residual norms of the step, sub-steps included).
    """

    newton_iterations: np.ndarray
    residual_norms: np.ndarray
    cutbacks: np.ndarray
    wall_time: np.ndarray
    residual_history: list[np.ndarray] = field(default_factory=list)
    info: dict = field(default_factory=dict)

    def __post_init__(self):
        self.newton_iterations = np.asarray(self.newton_iterations, dtype=np.int32)
        self.residual_norms = np.asarray(self.residual_norms, dtype=np.float64)
        self.cutbacks = np.asarray(self.cutbacks, dtype=np.int32)
        self.wall_time = np.asarray(self.wall_time, dtype=np.float64)
        self.residual_history = [np.asarray(h, dtype=np.float64) for h in self.residual_history]

    @classmethod
    def empty(cls) -> SolverStats:
        return cls(np.zeros(0), np.zeros(0), np.zeros(0), np.zeros(0), [])

    @property
    def history_flat(self) -> np.ndarray:
        """The residual histories of all steps, concatenated (as stored)."""
        h = self.residual_history
        return np.concatenate(h) if h else np.zeros(0)

    @property
    def history_offsets(self) -> np.ndarray:
        """Step i's history is ``history_flat[off[i]:off[i + 1]]``."""
        return np.cumsum([0] + [len(h) for h in self.residual_history]).astype(np.int64)


@dataclass
class Shard:
    """One simulation's results and provenance, as plain numpy arrays.

    ``displacement`` holds only the converged output steps: shape (n_done, n_out, 3) with
    n_done == len(load_fractions) when status == "ok", fewer when the simulation failed.
    """

    scene_name: str
    scene_hash: str
    sim_index: int
    seed: int
    geometry_id: str
    load_kind: str
    load_nodes: np.ndarray
    forces: np.ndarray
    material: OgdenMaterial
    fixed_nodes: np.ndarray
    load_fractions: np.ndarray
    output_nodes: np.ndarray
    displacement: np.ndarray
    stats: SolverStats
    status: str = "ok"
    failure_reason: str = ""
    patch_radius: float = 0.0
    geometry_file: str = ""  # relative to the shard file; filled by write_shard/read_shard
    # a grasp: each tool's displacement (mm) and reaction force (N) at every stored step,
    # (n_done, n_tools, 3); None: no tool (loads given as forces; written as (n_done, 0, 3))
    tool_displacement: np.ndarray | None = None
    reaction: np.ndarray | None = None

    def __post_init__(self):
        self.load_nodes = np.asarray(self.load_nodes, dtype=np.int64)
        self.forces = np.asarray(self.forces, dtype=np.float64).reshape(-1, 3)
        self.fixed_nodes = np.asarray(self.fixed_nodes, dtype=np.int64)
        self.load_fractions = np.asarray(self.load_fractions, dtype=np.float64)
        self.output_nodes = np.asarray(self.output_nodes, dtype=np.int64)
        self.displacement = np.asarray(self.displacement, dtype=np.float64)
        for name in ("tool_displacement", "reaction"):
            if getattr(self, name) is not None:
                setattr(self, name, np.asarray(getattr(self, name), dtype=np.float64))

    @property
    def n_done(self) -> int:
        return int(self.displacement.shape[0])


def write_shard(directory: str | Path, shard: Shard) -> Path:
    """Write ``shard`` atomically into the dataset ``directory``; return the HDF5 path.

    The geometry file ``DIR/geometry/<geometry_id>.h5`` must already exist (written once per
    mesh by :func:`data_spec.geometry.write_geometry`); the shard references it by relative path.
    """
    directory = Path(directory)
    h5_path = shard_path(directory, shard.sim_index)
    geo = geometry_path(directory, shard.geometry_id)
    if not geo.exists():
        raise FileNotFoundError(f"{h5_path}: geometry file {geo} must be written before shards")
    rel_geo = os.path.relpath(geo, h5_path.parent)
    shard.geometry_file = rel_geo
    with h5py.File(geo, "r") as g:
        n_nodes, n_cells = g["points"].shape[0], g["cells"].shape[0]
        points = g["points"][...]
    n_out = shard.output_nodes.shape[0]
    output_is_all = n_out == n_nodes and np.array_equal(shard.output_nodes, np.arange(n_nodes))

    xdmf = shard_xdmf(shard_file=h5_path.name, geometry_file=rel_geo, n_nodes=n_nodes,
                      n_cells=n_cells, n_out=n_out, output_is_all=output_is_all,
                      fractions=[float(x) for x in shard.load_fractions[:shard.n_done]],
                      name=f"{shard.scene_name}/sim_{shard.sim_index:06d}")
    write_text_atomic(h5_path.with_suffix(".xdmf"), xdmf)

    with atomic_path(h5_path) as tmp, h5py.File(tmp, "w") as f:
        f.attrs["format"] = SHARD_FORMAT
        f.attrs["schema_version"] = SHARD_SCHEMA_VERSION
        for k, v in UNITS.items():
            f.attrs[k] = v
        values = {e.path: get(shard, e.source) for e in LAYOUT}
        for e in LAYOUT:   # no tool: the tools' entries empty
            if values[e.path] is None:
                values[e.path] = np.zeros((shard.n_done, 0, 3))
        for e in LAYOUT:
            write_entry(f, e, values[e.path])
        f.attrs["checksum"] = checksum(values)
        for k, v in shard.stats.info.items():
            f["solver"].attrs[k] = v
        if not output_is_all:
            f["xdmf/points"] = points[shard.output_nodes]
    return h5_path


def read_shard(path: str | Path) -> Shard:
    """Read one shard file into a :class:`Shard` (plain numpy arrays)."""
    with h5py.File(path, "r") as f:
        if f.attrs.get("format") != SHARD_FORMAT:
            raise ValueError(f"{path}: not a {SHARD_FORMAT} file")
        if version_of(f) not in READABLE_VERSIONS:
            raise ValueError(f"{path}: shard schema_version {version_of(f)}; this code reads "
                             f"{READABLE_VERSIONS}")
        absent = missing(f)
        if absent:
            raise ValueError(f"{path}: missing {', '.join(absent)}")
        flat = read_values(f)
        if not checksum_ok(f, flat):
            raise ValueError(f"{path}: {CHECKSUM_MISMATCH}")
        info = dict(f["solver"].attrs)
    values: dict = {}
    for e in LAYOUT:  # nested by source: {"material": {...}, "stats": {...}, ...}
        *parents, leaf = e.source.split(".")
        node = values
        for part in parents:
            node = node.setdefault(part, {})
        node[leaf] = flat[e.path]
    mat = values.pop("material")
    law = mat.pop("law")
    if law != OgdenMaterial.law:
        raise ValueError(f"{path}: material law {law!r}; this code reads {OgdenMaterial.law!r}")
    try:
        material = OgdenMaterial(**mat)
    except ValueError as exc:
        raise ValueError(f"{path}: /material: {exc}") from None
    st = values.pop("stats")
    flat, offsets = st.pop("history_flat"), st.pop("history_offsets")
    history = [flat[i:j] for i, j in zip(offsets[:-1], offsets[1:])]
    return Shard(material=material, stats=SolverStats(**st, residual_history=history, info=info),
                 **values)
