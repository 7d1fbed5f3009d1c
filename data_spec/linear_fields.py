"""Small-strain responses of a one-liver dataset: one HDF5 file beside its shards
(``DATA/linear.h5``) that ``fem_sim linear`` writes and the patient adaptation reads; in a
population dataset, one such file per liver (``DATA/linear/<geometry id>.h5``).

The liver linearised at u = 0 (its Ogden tangent there, the small-strain elasticity of the
material) under the loads of the scene's simulations and of drawn cases of the same rule
(case index ``SYNTHETIC_FIRST`` on), at load fraction 1: a linear response scales with the
fraction, so case ``i`` at fraction ``lam`` is ``lam * displacement[i]``; with the optional
second-order term (``fem_sim linear --order 2``), ``lam * displacement[i] + lam**2 *
second_order[i]``, the Taylor expansion of the Ogden body's response to second order::

    /case_index    (n,)              int64    the scene's case index of each response
    /load_nodes    (n, n_loads)      int64    source node ids (patch centres for patch loads)
    /forces        (n, n_loads, 3)   float64  N at load fraction 1
    /output_nodes  (n_out,)          int64    the scene's output nodes
    /displacement  (n, n_out, 3)     float32  mm at load fraction 1, at the output nodes
    /second_order  (n, n_out, 3)     float32  mm, the lam^2 coefficient (optional)
    /green_nodes   (n_g,)            int64    surface nodes off the fixed region (optional,
                                              ``--green``)
    /green         (n_g, 3, n_out, 3) float32 mm/N: the response to a unit force at each of
                                              them along x, y, z (the small-strain Green's
                                              function: any nodal load's response is
                                              green[node] contracted with its force)
    attrs: format, scene_name, scene_hash, geometry_id, synthetic_first, units_length,
           units_force, seconds (the factorisation and the solves)
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import h5py
import numpy as np

from data_spec.atomic import atomic_path

FORMAT = "liverfem-linear-fields-1"
FILE_NAME = "linear.h5"
SYNTHETIC_FIRST = 1_000_000   # case index of the first drawn case: beyond any scene's


@dataclass
class LinearFields:
    """The file's content (see the module docstring)."""

    case_index: np.ndarray
    load_nodes: np.ndarray
    forces: np.ndarray
    output_nodes: np.ndarray
    displacement: np.ndarray
    scene_name: str
    scene_hash: str
    geometry_id: str
    seconds: float = 0.0
    second_order: np.ndarray | None = None
    green_nodes: np.ndarray | None = None
    green: np.ndarray | None = None

    @property
    def order(self) -> int:
        """1 (the linear response) or 2 (with its second-order term)."""
        return 1 if self.second_order is None else 2

    def rows(self, cases) -> np.ndarray:
        """Row of each case index in ``cases``; KeyError naming the missing ones."""
        where = {int(c): i for i, c in enumerate(self.case_index)}
        missing = [int(c) for c in np.asarray(cases).ravel() if int(c) not in where]
        if missing:
            raise KeyError(f"no small-strain response of case(s) {missing[:5]} (the file has "
                           f"{self.case_index.size}; rerun fem_sim linear on the grown scene)")
        return np.array([where[int(c)] for c in np.asarray(cases).ravel()], dtype=np.int64)

    @property
    def synthetic(self) -> np.ndarray:
        """Rows of the drawn cases, in case order."""
        return np.flatnonzero(self.case_index >= SYNTHETIC_FIRST)


def linear_fields_path(directory: str | Path, geometry_id: str | None = None) -> Path:
    """The one-liver dataset's file, or with ``geometry_id`` that liver's file in a
    population dataset (``DATA/linear/<geometry id>.h5``: the same format, the responses of
    that liver's simulations).
    """
    if geometry_id is None:
        return Path(directory) / FILE_NAME
    return Path(directory) / "linear" / f"{geometry_id}.h5"


def write_linear_fields(path: str | Path, lf: LinearFields) -> Path:
    """Write atomically (a reader sees no file or a whole one)."""
    with atomic_path(path) as tmp, h5py.File(tmp, "w") as f:
        for name in ("case_index", "load_nodes", "forces", "output_nodes"):
            f[name] = np.asarray(getattr(lf, name))
        if lf.green is not None:
            f["green_nodes"] = np.asarray(lf.green_nodes, np.int64)
        for name in ("displacement", "second_order", "green"):
            if getattr(lf, name) is not None:
                f.create_dataset(name, data=np.asarray(getattr(lf, name), np.float32),
                                 compression="gzip", compression_opts=1, shuffle=True)
        f.attrs.update(format=FORMAT, scene_name=lf.scene_name, scene_hash=lf.scene_hash,
                       geometry_id=lf.geometry_id, synthetic_first=SYNTHETIC_FIRST,
                       units_length="mm", units_force="N", seconds=float(lf.seconds))
    return Path(path)


def read_linear_fields(path: str | Path) -> LinearFields:
    """The file at ``path``; ValueError naming it when it is not one."""
    with h5py.File(path, "r") as f:
        if f.attrs.get("format") != FORMAT:
            raise ValueError(f"{path}: not a small-strain response file (format "
                             f"{f.attrs.get('format')!r}, expected {FORMAT!r})")
        return LinearFields(
            **{k: f[k][()] for k in ("case_index", "load_nodes", "forces", "output_nodes",
                                      "displacement")},
            scene_name=str(f.attrs["scene_name"]), scene_hash=str(f.attrs["scene_hash"]),
            geometry_id=str(f.attrs["geometry_id"]), seconds=float(f.attrs["seconds"]),
            **{k: f[k][()] if k in f else None for k in ("second_order", "green_nodes",
                                                          "green")})
