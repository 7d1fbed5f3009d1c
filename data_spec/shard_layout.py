"""The shard layout, declared once: every attribute and dataset of a shard file, where its value
comes from in a :class:`~data_spec.shards.Shard`, its type, symbolic shape and whether it must be
finite. The writer, the reader and the validator all walk this table; ``data_spec/README.md``
documents each entry (a test checks that none is missing there).

A path ``"/load@kind"`` is the attribute ``kind`` of the group ``/load``; ``"@status"`` an
attribute of the file; anything else a dataset. Shapes use named dimensions (``n_loads``,
``n_done``, ...; ``"n_done+1"`` is one more), bound by the first entry that uses them.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

SHARD_FORMAT = "liver-fem-shard"
# 2: a sha256 checksum of every entry (attribute "checksum"); 3: the tools of a grasp, their
# displacement and reaction force at every stored step (a shard of 2 reads as no tool)
SHARD_SCHEMA_VERSION = 3
READABLE_VERSIONS = (2, 3)
UNITS = {"units_length": "mm", "units_force": "N", "units_stress": "MPa", "units_time": "s"}
STATUSES = ("ok", "failed")


@dataclass(frozen=True)
class Entry:
    """One attribute or dataset of a shard."""

    path: str               # "/group/dataset", "/group@attr" or "@attr"
    source: str             # dotted attribute of the Shard ("forces", "material.c", ...)
    dtype: str              # "str", "int", "float" (attributes); numpy dtype names (datasets)
    shape: tuple = ()       # symbolic, datasets only
    finite: bool = False    # NaN/inf is a defect
    compress: bool = False  # gzip, one chunk per leading index
    since: int = 2          # the schema version that brought it (absent from older files)

    @property
    def is_attr(self) -> bool:
        return "@" in self.path

    @property
    def group(self) -> str:
        return self.path.split("@")[0] or "/"

    @property
    def name(self) -> str:
        return self.path.split("@")[1] if self.is_attr else self.path


LAYOUT: tuple[Entry, ...] = (
    Entry("@scene_name", "scene_name", "str"),
    Entry("@scene_hash", "scene_hash", "str"),
    Entry("@sim_index", "sim_index", "int"),
    Entry("@seed", "seed", "int"),
    Entry("@geometry_id", "geometry_id", "str"),
    Entry("@geometry_file", "geometry_file", "str"),
    Entry("@status", "status", "str"),
    Entry("@failure_reason", "failure_reason", "str"),
    Entry("/load@kind", "load_kind", "str"),
    Entry("/load@patch_radius", "patch_radius", "float"),
    Entry("/load/nodes", "load_nodes", "int64", ("n_loads",)),
    Entry("/load/forces", "forces", "float64", ("n_loads", 3), finite=True),
    Entry("/material@law", "material.law", "str"),
    Entry("/material@volumetric", "material.volumetric", "str"),
    Entry("/material/c", "material.c", "float64", ("n_terms",), finite=True),
    Entry("/material/m", "material.m", "float64", ("n_terms",), finite=True),
    Entry("/material/K", "material.K", "float64", (), finite=True),
    Entry("/fixed_nodes", "fixed_nodes", "int64", ("n_fixed",)),
    Entry("/load_fractions", "load_fractions", "float64", ("n_steps",), finite=True),
    Entry("/output_nodes", "output_nodes", "int64", ("n_out",)),
    Entry("/displacement", "displacement", "float64", ("n_done", "n_out", 3), finite=True,
          compress=True),
    Entry("/load/tool_displacement", "tool_displacement", "float64", ("n_done", "n_tools", 3),
          finite=True, since=3),
    Entry("/load/reaction", "reaction", "float64", ("n_done", "n_tools", 3), finite=True,
          since=3),
    Entry("/solver/newton_iterations", "stats.newton_iterations", "int32", ("n_done",)),
    Entry("/solver/residual_norms", "stats.residual_norms", "float64", ("n_done",),
          finite=True),
    Entry("/solver/cutbacks", "stats.cutbacks", "int32", ("n_done",)),
    Entry("/solver/wall_time", "stats.wall_time", "float64", ("n_done",), finite=True),
    Entry("/solver/residual_history", "stats.history_flat", "float64", ("n_history",)),
    Entry("/solver/residual_offsets", "stats.history_offsets", "int64", ("n_done+1",)),
)
DATASETS = tuple(e for e in LAYOUT if not e.is_attr)


def get(obj, source: str):
    for part in source.split("."):
        obj = getattr(obj, part)
    return obj


def _canonical(e: Entry, value) -> bytes:
    if e.is_attr:
        return repr({"str": str, "int": int, "float": float}[e.dtype](value)).encode()
    a = np.ascontiguousarray(np.asarray(value, dtype=e.dtype))
    return repr(a.shape).encode() + a.tobytes()


def entries(version: int = SHARD_SCHEMA_VERSION) -> tuple[Entry, ...]:
    """The entries a file of schema ``version`` holds."""
    return tuple(e for e in LAYOUT if e.since <= version)


def version_of(f) -> int:
    """An open shard's schema version."""
    return int(f.attrs.get("schema_version", SHARD_SCHEMA_VERSION))


def checksum(values: dict, version: int = SHARD_SCHEMA_VERSION) -> str:
    """sha256 over every entry of a file of ``version`` (path, shape and bytes in the layout's
    order): written into the file as the attribute ``checksum``, recomputed by the reader and
    the validator, so one flipped bit in a label is caught (uncompressed datasets have no
    checksum of their own).
    """
    import hashlib

    h = hashlib.sha256()
    for e in entries(version):
        h.update(e.path.encode() + b"\0" + _canonical(e, values[e.path]) + b"\0")
    return h.hexdigest()


CHECKSUM_MISMATCH = "checksum mismatch: the file was changed or corrupted after it was written"


def checksum_ok(f, values: dict) -> bool:
    """Whether the ``values`` read from the open shard ``f`` match its stored checksum."""
    return checksum(values, version_of(f)) == str(f.attrs["checksum"])


def read_values(f) -> dict:
    """Every entry of an open shard file, by path (after :func:`missing` found none absent);
    an entry newer than the file is its empty value (a shard of version 2: no tool).
    """
    values = {e.path: read_entry(f, e) for e in entries(version_of(f))}
    n_done = np.shape(values["/displacement"])[0]
    for e in LAYOUT:
        if e.path not in values:   # the tools' entries, (n_done, 0, 3)
            values[e.path] = np.zeros((n_done, 0, 3))
    return values


def write_entry(f, e: Entry, value) -> None:
    """Write one entry's value into an open HDF5 file (groups are created as needed)."""
    if e.is_attr:
        group = f.require_group(e.group) if e.group != "/" else f
        group.attrs[e.name] = {"str": str, "int": int, "float": float}[e.dtype](value)
        return
    data = np.asarray(value, dtype=e.dtype)
    packed = {}
    if e.compress and data.size:
        # One chunk per leading index (load step): reading one step decompresses only it.
        packed = dict(chunks=(1, *data.shape[1:]), compression="gzip", compression_opts=4,
                      shuffle=True)
    f.create_dataset(e.path, data=data, **packed)


def read_entry(f, e: Entry):
    if e.is_attr:
        raw = (f[e.group] if e.group != "/" else f).attrs[e.name]
        return {"str": str, "int": int, "float": float}[e.dtype](raw)
    return f[e.path][()]


def missing(f) -> list[str]:
    """Entries (and constant attributes) absent from an open shard file."""
    out = [f"attribute '{k}'" for k in ("format", "schema_version", "checksum", *UNITS)
           if k not in f.attrs]
    for e in entries(version_of(f)):
        if e.is_attr:
            holder = f.get(e.group) if e.group != "/" else f
            if holder is None or e.name not in holder.attrs:
                out.append(f"attribute '{e.path}'")
        elif e.path not in f:
            out.append(f"dataset '{e.path}'")
    return out


def shape_problems(values: dict[str, np.ndarray]) -> tuple[list[str], dict[str, int]]:
    """Check the datasets' shapes against the layout; returns (problems, bound dimensions)."""
    dims: dict[str, int] = {}
    problems = []

    def size(sym):  # the bound size of a symbolic dimension, or None
        if isinstance(sym, int):
            return sym
        base, plus = (sym.split("+") + ["0"])[:2]
        return dims[base] + int(plus) if base in dims else None

    for e in DATASETS:
        got = np.shape(values[e.path])
        want = [size(sym) for sym in e.shape]
        ok = len(got) == len(e.shape) and all(w is None or w == n for w, n in zip(want, got))
        if ok:
            for sym, n in zip(e.shape, got):
                if isinstance(sym, str):
                    base, plus = (sym.split("+") + ["0"])[:2]
                    dims.setdefault(base, n - int(plus))
        else:
            shown = [str(s if w is None else w) for s, w in zip(e.shape, want)]
            exp = "(" + ", ".join(shown) + (",)" if len(shown) == 1 else ")")
            problems.append(f"'{e.path}' has shape {got}, expected {exp}")
    return problems, dims
