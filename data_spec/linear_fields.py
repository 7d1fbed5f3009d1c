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
                                              ``--green``; with ``--green-near`` only those
                                              near the given points)
    /green         (n_g, 3, n_out, 3) float32 mm/N: the response to a unit force at each of
                                              them along x, y, z (the small-strain Green's
                                              function: any nodal load's response is
                                              green[node] contracted with its force)
    /fixed_nodes   (n_f,)            int64    the fixed region's nodes (written with the
                                              Green's function; an older file's are the
                                              surface nodes without a unit response)
    /tool_force    (n, n_tools, 3)   float64  N: a grasp's tools' forces at load fraction 1
                                              (optional; a grasp population's files)
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
    tool_force: np.ndarray | None = None
    fixed_nodes: np.ndarray | None = None

    def fixed(self, surface_nodes: np.ndarray) -> np.ndarray:
        """The liver's fixed nodes (a file with a Green's function): its own record, or in
        a file that does not hold them the surface nodes without a unit response.
        """
        if self.fixed_nodes is not None:
            return np.asarray(self.fixed_nodes, np.int64)
        return np.setdiff1d(surface_nodes, self.green_nodes)

    def uncomputed(self, surface_nodes: np.ndarray) -> np.ndarray:
        """The free surface nodes without a unit response (``fem_sim linear --green-near``
        computes those near its points only).
        """
        return np.setdiff1d(np.setdiff1d(surface_nodes, self.fixed(surface_nodes)),
                            self.green_nodes)

    def missing_response(self, nodes, surface_nodes: np.ndarray) -> str:
        """Why the Green's function cannot answer a load at the mesh ``nodes``, or "": a
        node fixed or inside, or free but not computed.
        """
        out = np.setdiff1d(np.asarray(nodes, np.int64).ravel(), self.green_nodes)
        if out.size == 0:
            return ""
        n = int(out[0])
        if n in self.uncomputed(surface_nodes):
            return (f"node {n} has no unit response: this Green's function holds the "
                    f"{self.green_nodes.size} surface nodes near a known load (fem_sim linear "
                    "--green-near); run fem_sim linear --green without --green-near for the "
                    "whole surface")
        return f"node {n} has no unit response (a fixed or interior node: loads act on the " \
               "free surface)"

    def whole_surface_problem(self, surface_nodes: np.ndarray, data) -> str:
        """Why a manipulator (loads anywhere) cannot open on the Green's function of the
        directory ``data``, or "": some free surface nodes are not computed.
        """
        n = self.uncomputed(surface_nodes).size
        if n == 0:
            return ""
        d = Path(data)
        return (f"{d}: its Green's function holds {self.green_nodes.size} of the liver's "
                f"{self.green_nodes.size + n} free surface nodes, those near make liver's load "
                "(fem_sim linear --green-near); the manipulator grasps anywhere: give it the "
                "solver's python to solve the others when grasped (--solver "
                ".venv-solver/bin/python; make manipulate LIVER=... does), or all of them "
                f"first (fem_sim linear {d.parent / 'scene.toml'} --out {d} --green)")

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
        if lf.fixed_nodes is not None:
            f["fixed_nodes"] = np.asarray(lf.fixed_nodes, np.int64)
        if lf.tool_force is not None:
            f["tool_force"] = np.asarray(lf.tool_force, np.float64)
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
                                                          "green", "tool_force",
                                                          "fixed_nodes")})


def _shape_problems(lf: LinearFields) -> list[str]:
    """The arrays' shapes against each other, and their finiteness."""
    n, n_out = lf.case_index.size, lf.output_nodes.size
    want = {"load_nodes": (n, None), "forces": (n, None, 3), "displacement": (n, n_out, 3),
            "second_order": (n, n_out, 3), "tool_force": (n, None, 3)}
    if lf.green is not None:
        want["green_nodes"] = (None,) if lf.green_nodes is None else (lf.green_nodes.size,)
        want["green"] = (want["green_nodes"][0], 3, n_out, 3)
    p = []
    for name, shape in want.items():
        a = getattr(lf, name)
        if a is None:
            continue
        if a.ndim != len(shape) or any(s is not None and s != d for s, d in zip(shape, a.shape)):
            p.append(f"'{name}' has shape {a.shape}, expected {shape} (None: any)")
        elif a.dtype.kind == "f" and not np.all(np.isfinite(a)):
            p.append(f"'{name}' contains NaN or inf")
    return p


def _dataset_problems(lf: LinearFields, directory: Path, geometry_id: str | None) -> list[str]:
    """The file against the dataset that holds it: its scene (the hash the file was made for
    among those the dataset's scene accepts), its liver (named as the file is, a geometry
    file of the dataset, node ids within it).
    """
    from data_spec.grown import accepted_hashes
    from data_spec.scene import SceneError, load_scene
    from data_spec.shards import geometry_path

    p = []
    copy = directory / "scene.toml"
    made_for = f"scene {lf.scene_name!r} (hash {lf.scene_hash[:12]})"
    if not copy.exists():
        p.append(f"made for {made_for}, but {copy} is missing: which scene the dataset holds "
                 "is unknown (rerun fem_sim linear with the dataset's scene)")
    else:
        try:
            scene = load_scene(copy)
            if lf.scene_hash not in accepted_hashes(scene, directory):
                p.append(f"made for {made_for}, but {directory} holds scene {scene.name!r} (hash "
                         f"{scene.hash[:12]}): another scene's responses; rerun fem_sim linear "
                         "with the dataset's scene")
        except (SceneError, ValueError) as exc:
            p.append(f"{copy} is not a valid scene ({exc})")
    if geometry_id is not None and lf.geometry_id != geometry_id:
        p.append(f"named for liver {geometry_id} but holds liver {lf.geometry_id}")
    geo = geometry_path(directory, lf.geometry_id)
    try:
        with h5py.File(geo, "r") as g:
            n_nodes = int(g["points"].shape[0])
    except (OSError, KeyError) as exc:
        return p + [f"its liver {lf.geometry_id} has no readable geometry file {geo} ({exc})"]
    for name in ("load_nodes", "output_nodes", "green_nodes", "fixed_nodes"):
        ids = getattr(lf, name)
        if ids is not None and ids.size and (ids.min() < 0 or ids.max() >= n_nodes):
            p.append(f"'{name}' has node ids outside [0, {n_nodes}) of liver {lf.geometry_id}")
    return p


def _checked(directory: Path, geometry_id: str | None) -> tuple:
    """(the dataset's small-strain file (None when it cannot be read), everything wrong with
    it, each naming the file).
    """
    path = linear_fields_path(directory, geometry_id)
    if not path.exists():
        return None, [f"{path}: missing (fem_sim linear writes it)"]
    try:
        lf = read_linear_fields(path)
    except (OSError, KeyError, ValueError) as exc:
        return None, [f"{path}: cannot be read (truncated or corrupt?): {exc}"]
    return lf, [f"{path}: {msg}" for msg in _shape_problems(lf)
                + _dataset_problems(lf, directory, geometry_id)]


def linear_file_problems(directory: str | Path, geometry_id: str | None = None) -> list[str]:
    """Everything wrong with the small-strain file of the dataset ``directory`` (with
    ``geometry_id``: that liver's file of a population), each naming the file: missing,
    unreadable or truncated, arrays of inconsistent shapes or not finite, made for another
    scene or liver.
    """
    return _checked(Path(directory), geometry_id)[1]


def read_dataset_linear(directory: str | Path, geometry_id: str | None = None) -> LinearFields:
    """The small-strain file of the dataset ``directory`` (with ``geometry_id``: that liver's,
    of a population), checked against the dataset: ValueError naming the file and both scenes
    (or livers) when it was made for another, or is not whole.
    """
    lf, problems = _checked(Path(directory), geometry_id)
    if problems:
        raise ValueError("; ".join(problems))
    return lf
