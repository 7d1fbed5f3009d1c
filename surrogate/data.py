"""Read a dataset (through data_spec only) into compact arrays for node-wise training.

A *sample* is one stored load step of one simulation. An *example* is one (sample, output node)
pair. Nothing node-by-feature is materialised: per geometry we keep the static node features of
its output nodes; per sample the (scaled) forces, load-node coordinates and the material/shape
vector; features are assembled in jit (``surrogate.features``).
"""

from __future__ import annotations

import contextlib
import dataclasses
import logging
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from data_spec import list_shards, load_scene, read_geometry, read_shard
from data_spec.atomic import atomic_path
from data_spec.eligible_loads import eligible_load_nodes
from data_spec.shards import geometry_path
from surrogate.features import FeatureSpec, material_vector, static_node_features

log = logging.getLogger(__name__)


@dataclass
class Dataset:
    """Everything the trainer needs, as numpy arrays."""

    spec: FeatureSpec
    scene_name: str
    static: np.ndarray          # (N_out_total, 11) static features, all geometries' output nodes
    geo_offset: np.ndarray      # (n_geo + 1,) rows of each geometry in ``static``
    geo_ids: list[str]
    points: list[np.ndarray]    # per geometry: (n_nodes, 3)
    fixed: list[np.ndarray]     # per geometry: fixed node ids
    out_nodes: list[np.ndarray]  # per geometry: output node ids
    triangles: list[np.ndarray]  # per geometry: outward surface triangles (node ids)
    shape_coeffs: list[np.ndarray]
    sample_geo: np.ndarray      # (S,) geometry of each sample
    sample_sim: np.ndarray      # (S,) simulation index
    sample_fraction: np.ndarray  # (S,) load fraction
    forces: np.ndarray          # (S, n_loads, 3) force at this step, N (a grasp: the tool's
    #                             displacement at this step, mm: see load_kind)
    load_points: np.ndarray     # (S, n_loads, 3) load node coordinates, mm
    load_nodes: np.ndarray      # (S, n_loads) load node ids
    extra: np.ndarray           # (S, e) material and/or shape coefficients
    targets: np.ndarray         # (E, 3) float32 displacement, mm, examples of all samples
    sample_offset: np.ndarray   # (S + 1,) examples of each sample in ``targets``
    failed_sims: int = 0
    # per geometry: the nodes the scene's random loads may act on, and those loaded in the
    # shards (None: the scene lists its cases explicitly)
    loadable: list | None = None
    directory: Path | None = None   # the dataset directory it was read from
    missing_sims: tuple = ()        # simulations of the scene without a shard
    # phantoms mixed into a population of liver files (geometry.phantoms): augmentation,
    # trained on and never held out
    augmenting: frozenset = frozenset()
    # "grasp": each load is a tool moving a patch (load_points: its centre) and ``forces`` hold
    # its displacement (mm); "nodal" (and "patch"): forces in N
    load_kind: str = "nodal"
    # a grasp: each tool's reaction force on the liver at the sample's step, N (S, n_loads, 3)
    reactions: np.ndarray | None = None

    @property
    def n_samples(self) -> int:
        return self.sample_geo.shape[0]


def available_memory() -> int:
    """Bytes of memory available to this process (Linux MemAvailable; else physical pages)."""
    try:
        for line in Path("/proc/meminfo").read_text().splitlines():
            if line.startswith("MemAvailable:"):
                return int(line.split()[1]) * 1024
    except OSError:
        pass
    import os

    return os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")


def _estimated_target_bytes(paths) -> int:
    """Bytes of all displacement targets, from the first shard's size and the shard count."""
    sh = read_shard(paths[0])
    per = max(sh.displacement.shape[0], 1) * sh.displacement.shape[1] * 3 * 4
    return per * len(paths)


class DataError(ValueError):
    """A dataset that cannot be trained on; the message names the directory or shard."""


class _Reader:
    """The arrays of a dataset, filled shard by shard: per liver (geometry) and per sample
    (a converged load step); targets in memory or written to ``spill``.
    """

    def __init__(self, directory: Path, scene, spill):
        self.directory, self.scene, self.spill = directory, scene, spill
        self.geo_index: dict[str, int] = {}
        self.geo = {k: [] for k in ("points", "fixed", "out_nodes", "triangles", "shapes",
                                    "statics", "loadable")}
        self.smp = {k: [] for k in ("geo", "sim", "fr", "f", "lp", "ln", "extra", "targets",
                                    "rf")}
        self.failed = 0

    def liver(self, sh) -> int:
        """The index of the shard's liver, read the first time one of its shards comes."""
        if sh.geometry_id not in self.geo_index:
            g = read_geometry(geometry_path(self.directory, sh.geometry_id))
            self.geo_index[sh.geometry_id] = len(self.geo["points"])
            for key, value in (
                    ("points", g.points), ("fixed", sh.fixed_nodes),
                    ("out_nodes", sh.output_nodes), ("triangles", g.surface_triangles),
                    ("loadable", eligible_load_nodes(self.scene["loads"], g.points,
                                                     g.surface_nodes, sh.fixed_nodes)),
                    ("shapes", g.shape_coefficients if g.shape_coefficients is not None
                     else np.zeros(0)),
                    ("statics", static_node_features(g.points,
                                                     sh.fixed_nodes)[sh.output_nodes])):
                self.geo[key].append(value)
        return self.geo_index[sh.geometry_id]

    def add(self, sh) -> None:
        """The shard's converged load steps as samples."""
        if sh.status != "ok":
            self.failed += 1
        if sh.n_done == 0:
            return
        gi = self.liver(sh)
        lp = self.geo["points"][gi][sh.load_nodes]  # load nodes, or patch centres
        mat = material_vector(sh.material.c, sh.material.m, sh.material.K)
        s, grasp = self.smp, sh.load_kind == "grasp"   # a grasp's load: the tool's pull, mm
        for k in range(sh.n_done):
            f = sh.tool_displacement[k] if grasp else sh.forces * sh.load_fractions[k]
            for key, value in (("geo", gi), ("sim", sh.sim_index), ("fr", sh.load_fractions[k]),
                               ("f", f), ("lp", lp),
                               ("ln", sh.load_nodes), ("extra", mat)):
                s[key].append(value)
            if grasp:
                s["rf"].append(sh.reaction[k])
            t = sh.displacement[k].astype(np.float32)
            if self.spill is not None:
                self.spill.write(np.ascontiguousarray(t).tobytes())
                t = np.empty((t.shape[0], 0), np.float32)  # its size only
            s["targets"].append(t)

    def dataset(self, final: Path | None) -> Dataset:
        geo, s = self.geo, self.smp
        n_shape = geo["shapes"][0].size if geo["shapes"] else 0
        spec = FeatureSpec.from_scene(self.scene, n_shape)
        extra = np.asarray(s["extra"])[:, : spec.material_dim] if spec.material_dim else \
            np.zeros((len(s["geo"]), 0))
        if spec.geometry_dim:
            extra = np.concatenate([extra, np.asarray([geo["shapes"][g] for g in s["geo"]])],
                                   axis=1)
        sizes = np.array([t.shape[0] for t in s["targets"]])
        targets = (np.memmap(final, dtype=np.float32, mode="r", shape=(int(sizes.sum()), 3))
                   if final is not None else np.concatenate(s["targets"]))
        sample_geo, load_nodes = np.asarray(s["geo"]), np.asarray(s["ln"])
        return Dataset(
            spec=spec, scene_name=self.scene.name,
            static=np.concatenate(geo["statics"]).astype(np.float32),
            geo_offset=np.concatenate([[0], np.cumsum([a.shape[0] for a in geo["statics"]])]),
            geo_ids=list(self.geo_index), points=geo["points"], fixed=geo["fixed"],
            out_nodes=geo["out_nodes"], triangles=geo["triangles"], shape_coeffs=geo["shapes"],
            sample_geo=sample_geo, sample_sim=np.asarray(s["sim"]),
            sample_fraction=np.asarray(s["fr"]), forces=np.asarray(s["f"], dtype=np.float32),
            load_points=np.asarray(s["lp"], dtype=np.float32), load_nodes=load_nodes,
            extra=np.asarray(extra, dtype=np.float32), targets=targets,
            sample_offset=np.concatenate([[0], np.cumsum(sizes)]), failed_sims=self.failed,
            load_kind=self.scene["loads"]["kind"],
            reactions=np.asarray(s["rf"], dtype=np.float64) if s["rf"] else None,
            loadable=None if self.scene.cases else [
                np.union1d(rule, load_nodes[sample_geo == g].ravel())
                for g, rule in enumerate(geo["loadable"])], directory=self.directory)


def load_dataset(directory: str | Path, stream: bool | str = "auto",
                 spill_dir: str | Path | None = None) -> Dataset:
    """Read every shard of ``directory`` (ok shards and the converged steps of failed ones).

    ``stream``: True keeps the displacement targets (the only array that grows with nodes x
    samples; 12 bytes per example) in a file under ``spill_dir`` (default: the dataset
    directory), memory-mapped, written shard by shard, so the dataset never has to fit in
    memory; batches then read their rows from disk through the page cache. "auto" does this
    when the targets would take more than half of the available memory.
    """
    directory = Path(directory)
    try:
        scene = load_scene(directory / "scene.toml")
    except ValueError as exc:  # SceneError
        raise DataError(str(exc)) from None
    paths = list_shards(directory)
    if not paths:
        raise DataError(f"{directory}: no shards (expected {directory}/sims/sim_*.h5)")
    if stream == "auto":
        stream = _estimated_target_bytes(paths) > 0.5 * available_memory()
    spill, final = None, None
    stack = contextlib.ExitStack()
    if stream:
        # Written through data_spec's atomic_path: a temporary next to targets.f32, fsynced
        # and renamed once every shard is in, removed if reading fails half-way.
        final = Path(spill_dir or directory) / "targets.f32"
        spill = stack.enter_context(open(stack.enter_context(atomic_path(final)), "wb"))
        log.info("streaming targets to %s", final)
    reader = _Reader(directory, scene, spill)
    with stack:  # on leaving: the spill file is closed, then renamed (last in, first out)
        for p in paths:
            try:
                sh = read_shard(p)
            except (OSError, ValueError, KeyError) as exc:
                raise DataError(f"{p}: cannot be read ({exc}); run `python -m data_spec "
                                f"validate {directory}` and regenerate it") from None
            reader.add(sh)
    have = {int(p.stem.split("_")[1]) for p in paths if p.stem.split("_")[1].isdigit()}
    missing = tuple(sorted(set(range(scene.n_simulations)) - have))
    if missing:
        log.warning("%s: %d of the scene's %d simulations have no shard (%s%s): training on "
                    "the %d there", directory, len(missing), scene.n_simulations,
                    ", ".join(map(str, missing[:10])), " ..." if len(missing) > 10 else "",
                    len(have))
    if not reader.smp["geo"]:
        raise DataError(f"{directory}: none of the {len(paths)} shards has a converged load "
                        f"step ({reader.failed} failed): nothing to train on")
    ds = reader.dataset(final)
    ds.missing_sims = missing
    ds.augmenting = augmenting_geometries(directory, scene)
    return ds


def augmenting_geometries(directory: Path, scene) -> frozenset:
    """The geometry ids of the phantoms a population of liver files mixes in: the first
    ``phantoms`` livers of its DATA/geometry/population.npz (data_spec.livers' order).
    """
    from surrogate.population import population_file

    g = scene["geometry"]
    path = population_file(directory)
    if "livers" not in g or not g.get("phantoms") or not path.exists():
        return frozenset()
    with np.load(path, allow_pickle=False) as z:
        return frozenset(str(i) for i in z["geometry_ids"][:g["phantoms"]])


def restrict_nodes(ds: Dataset, keep: list[np.ndarray]) -> Dataset:
    """The same dataset with fewer output nodes: ``keep[g]`` are the mesh node ids of geometry
    g to keep (e.g. its surface nodes: a surface-only model, as a scene with
    ``[output] nodes = "surface"`` would give). Ids that are not output nodes are ignored.
    """
    if len(keep) != len(ds.out_nodes):
        raise ValueError(f"restrict_nodes: {len(keep)} node lists for {len(ds.out_nodes)} "
                         "geometries")
    kept = [np.flatnonzero(np.isin(o, k)) for o, k in zip(ds.out_nodes, keep)]  # per geometry
    counts = np.array([i.size for i in kept])
    static = np.concatenate([ds.static[ds.geo_offset[g]:ds.geo_offset[g + 1]][i]
                             for g, i in enumerate(kept)])
    rows = [ds.sample_offset[s] + kept[g] for s, g in enumerate(ds.sample_geo)]
    return dataclasses.replace(
        ds, static=static, geo_offset=np.concatenate([[0], np.cumsum(counts)]),
        out_nodes=[o[i] for o, i in zip(ds.out_nodes, kept)],
        targets=np.asarray(ds.targets[np.concatenate(rows)]),
        sample_offset=np.concatenate([[0], np.cumsum(counts[ds.sample_geo])]))


def phantom_livers(ds: Dataset) -> np.ndarray:
    """(n_geometries,) bool: the phantoms mixed into liver files (``ds.augmenting``)."""
    if not (ds.augmenting and ds.spec.geometry_dim):
        return np.zeros(len(ds.geo_ids), bool)
    return np.array([i in ds.augmenting for i in ds.geo_ids])


def kfold_groups(ds: Dataset, k: int, seed: int) -> list[np.ndarray]:
    """Split simulations (livers, when the geometry varies) into k folds of sample indices.
    Phantoms mixed into liver files (``ds.augmenting``) are in no fold: always trained on.
    """
    key = ds.sample_geo if ds.spec.geometry_dim else ds.sample_sim
    units = np.unique(key)
    if ds.spec.geometry_dim:
        units = units[~phantom_livers(ds)[units]]
    if units.size < k:
        raise ValueError(f"{k}-fold cross-validation needs at least {k} "
                         f"{'livers' if ds.spec.geometry_dim else 'simulations'}, "
                         f"the dataset has {units.size}")
    perm = np.random.default_rng(seed).permutation(units)
    folds = np.array_split(perm, k)
    return [np.flatnonzero(np.isin(key, f)) for f in folds]


def training_samples(ds: Dataset, held: np.ndarray, cfg: dict) -> np.ndarray:
    """The samples a fold trains on: all but ``held``, less the mixed-in phantoms' when
    ``cfg["phantoms_in_training"]`` is false (to measure what they bring), thinned as
    :func:`thinned` says.
    """
    train = np.setdiff1d(np.arange(ds.n_samples), held)
    if not cfg.get("phantoms_in_training", True):
        train = train[~phantom_livers(ds)[ds.sample_geo[train]]]
    return thinned(ds, train, cfg)


def thinned(ds: Dataset, train: np.ndarray, cfg: dict) -> np.ndarray:
    """The learning-curve knobs on a fold's training samples ``train``, its held-out ones
    untouched: ``cfg["train_fraction"]`` of its livers (of its simulations, for one liver),
    drawn with ``cfg["seed"]`` so that a smaller fraction's livers are among a larger one's;
    then each liver's first ``cfg["simulations_per_liver"]`` simulations (0: all). Mixed-in
    phantoms are left as they are (``phantoms_in_training`` says whether they train).
    """
    fraction, per = cfg.get("train_fraction", 1.0), cfg.get("simulations_per_liver", 0)
    if per and not ds.spec.geometry_dim:
        raise ValueError("trainer config: simulations_per_liver needs a scene whose liver "
                         f"varies (a population); got {per} on one liver")
    geo, sim = ds.sample_geo[train], ds.sample_sim[train]
    key = geo if ds.spec.geometry_dim else sim
    thin = ~phantom_livers(ds)[geo]  # samples the knobs act on
    keep = np.ones(len(train), bool)
    if fraction < 1:
        units = np.unique(key[thin])
        drawn = np.random.default_rng(cfg["seed"]).permutation(units)
        keep &= np.isin(key, drawn[:max(1, round(fraction * len(units)))]) | ~thin
    if per:
        for g in np.unique(geo[thin]):
            mine = geo == g
            keep[mine & ~np.isin(sim, np.unique(sim[mine])[:per])] = False
    return train[keep]
