"""A population of liver files (``geometry.livers``): each liver read, repaired and meshed
(:mod:`fem_sim.geometry.repair`), turned into the template's frame by a rigid fit, the template
registered onto it without folding a tetrahedron (:func:`liverreg.cpd.register`), and fixed
where the template's vena-cava region lands.

The template is the phantom of seed ``population_seed`` (:mod:`data_spec.livers`). Its fixed
region carries over by nearest moved template node: each surface node of the liver takes the
label of the template surface node the registration put nearest to it. A region smaller than
``fixed_area_min`` (by default half the template's own) grows by rings of surface neighbours
until it is that large, so that no liver hangs on a few nodes; the area, the rings and every
registration figure are kept per liver (:class:`LiverRecord`).
"""

from __future__ import annotations

import functools
import json
import logging
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from data_spec import Geometry
from data_spec.geometry import grown_region, region_area
from liverreg.cpd import register, surface_points, surface_samples
from liverreg.morph import SurfaceMorph
from liverreg.shape_model import template_fit

log = logging.getLogger(__name__)

N_POINTS = 600  # CPD samples per surface (liverreg.cpd.build_population's)
# What a prepared liver depends on besides the modules its key digests: change this text when
# the rules of this module change (its other edits then keep the prepared livers).
RULES = "rigid fit refined from the frame; region by nearest moved template surface node; " \
    "grown by rings of surface neighbours to fixed_area_min or half the template's area"


@dataclass
class LiverRecord:
    """How one liver file entered the population."""

    name: str
    nodes: int
    volume_ml: float
    extent_mm: list
    repair: str            # the repair report's summary
    frame: str             # how the rigid fit turned it
    rigid_distance: float  # mm, after the rigid fit
    residual: float        # mm, moved template surface <-> liver surface
    inverted: int          # template tetrahedra the registration folded
    min_jacobian: float    # smallest moved / template cell volume
    unfold_rounds: int
    fixed_nodes: int
    fixed_area: float      # mm^2
    grown_rings: int       # rings added to reach fixed_area_min
    seconds: float


class Registrar:
    """The template, its samples and its morph, set up once for a population."""

    def __init__(self, template: Geometry, region: str, frame: str = "LPS"):
        self.template = template
        self.frame = frame
        self.region = region
        self.samples = surface_samples(template, N_POINTS)
        self.morph = SurfaceMorph(template.points, template.cells, template.surface_nodes)
        self.area = region_area(template.points, template.surface_triangles,
                                template.regions[region])

    def aligned(self, liver: Geometry):
        """(the liver in the template's frame, the rigid fit)."""
        fit = template_fit(liver.points, liver.surface_triangles,
                           self.template.points[self.template.surface_nodes], self.frame)
        moved = Geometry(points=liver.points @ fit.Q.T + fit.t, cells=liver.cells,
                         surface_triangles=liver.surface_triangles, regions=dict(liver.regions),
                         description=liver.description)
        if fit.mirrored:  # a mirror image turns every cell inside out: swap two nodes
            moved.cells = moved.cells[:, [0, 2, 1, 3]]
            moved.surface_triangles = moved.surface_triangles[:, [0, 2, 1]]
        return moved, fit

    def register(self, liver: Geometry):
        """The template registered onto a liver already in its frame."""
        return register(self.morph, self.samples, self.template.surface_triangles,
                        surface_samples(liver, N_POINTS), surface_points(liver))


def grown(liver: Geometry, nodes: np.ndarray, area_min: float) -> tuple[np.ndarray, int]:
    """(nodes, rings): ``nodes`` grown by rings of surface neighbours until their region's
    area reaches ``area_min`` (mm^2).
    """
    return grown_region(liver.points, liver.surface_triangles, nodes, area_min)


def prepare(path, registrar: Registrar, mesh_size: float, area_min: float | None = None):
    """(the liver file meshed, in the template's frame, fixed where the template's region
    lands; its registration; its record).
    """
    import time

    from fem_sim.geometry.repair import mesh_liver_file
    from liverreg.shape_model import landed_region

    t0 = time.perf_counter()
    raw, report = mesh_liver_file(path, mesh_size)
    liver, fit = registrar.aligned(raw)
    reg = registrar.register(liver)
    region = registrar.template.regions[registrar.region]
    landed = landed_region(reg.points, registrar.template.surface_nodes, region, liver.points,
                           liver.surface_nodes)
    fixed, rings = grown(liver, landed, 0.5 * registrar.area if area_min is None else area_min)
    liver.regions = {registrar.region: fixed}
    liver.description = f"{Path(path).name} ({fit.describe()})"
    rec = LiverRecord(
        name=Path(path).stem, nodes=liver.n_nodes, volume_ml=report.volume_after_ml,
        extent_mm=np.ptp(liver.points, axis=0).round(1).tolist(), repair=report.summary(),
        frame=fit.describe(), rigid_distance=fit.distance, residual=reg.residual,
        inverted=reg.inverted, min_jacobian=reg.min_jacobian,
        unfold_rounds=reg.unfold_rounds, fixed_nodes=int(fixed.size),
        fixed_area=region_area(liver.points, liver.surface_triangles, fixed),
        grown_rings=rings, seconds=time.perf_counter() - t0)
    return liver, reg, rec


def write_records(path, records: list[LiverRecord]) -> None:
    """The population's per-liver records as JSON (written atomically)."""
    from data_spec.atomic import atomic_path

    Path(path).parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(path) as tmp:
        tmp.write_text(json.dumps([asdict(r) for r in records], indent=1) + "\n")


def template_of(g: dict) -> Geometry:
    """The population's template: the phantom of seed ``population_seed``."""
    from fem_sim.geometry.phantom import make_phantom

    return make_phantom(g.get("population_seed", 0), g["mesh_size"],
                        g.get("variety", "anatomical"))


def registrar_of(scene) -> Registrar:
    """The registrar of a file population: its template, fixed region and frame."""
    g = scene["geometry"]
    return Registrar(template_of(g), region_name(scene), g.get("frame", "LPS"))


def region_name(scene) -> str:
    f = scene["fixed"]
    return f["name"] if f["kind"] == "region" else "vena_cava"


def _file_prefix(path) -> str:
    """The start of every prepared-liver key of a liver file, whatever its code or settings."""
    return f"file {Path(path).name} "


@functools.lru_cache(maxsize=1)
def _code_bytes() -> bytes:
    """The preparing code (its modules and the rules) as the key hashes it, read once per
    process.
    """
    from fem_sim.geometry import meshing, repair, surfaces
    from liverreg import cpd, morph, rigid

    return b"".join([*(Path(m.__file__).read_bytes()
                       for m in (repair, surfaces, meshing, cpd, morph, rigid)), RULES.encode()])


def prepared_key(path, g: dict) -> str:
    """What a liver file's prepared mesh depends on: the file, the settings and the code."""
    import hashlib

    from fem_sim.geometry.mesh_index import phantom_code

    h = hashlib.sha256(Path(path).read_bytes())
    h.update(_code_bytes())
    return (f"{_file_prefix(path)}{h.hexdigest()[:16]}, mesh size {float(g['mesh_size'])!r}, "
            f"frame {g.get('frame', 'LPS')}, template {g.get('population_seed', 0)} "
            f"{g.get('variety', 'anatomical')}, area {g.get('fixed_area_min')}, "
            f"{phantom_code()}")


def population_geometries(scene, cache=None, dataset=None, meshed=None, progress=None):
    """Every liver of a file population (:func:`data_spec.livers.members`), with its fixed
    region and its shape coefficients; prepared livers are reused from ``dataset``'s mesh
    index, and the records go to DATA/geometry/livers.json.
    """
    from data_spec.livers import members
    from fem_sim.geometry.mesh_index import indexed, phantom_key, read_index
    from fem_sim.geometry.phantom import make_phantom
    from fem_sim.geometry.population import attach_shape_coefficients

    g = scene["geometry"]
    registrar = registrar_of(scene)
    template = registrar.template
    index = read_index(dataset)
    records = _read_records(dataset)
    livers, known = [], {}
    variety = g.get("variety", "anatomical")
    mem = list(members(g))
    keys = [prepared_key(m.path, g) if m.path else phantom_key(m.seed, variety, g["mesh_size"])
            for m in mem]
    _warn_stale(dataset, index, mem, keys)
    for i, (m, key) in enumerate(zip(mem, keys)):
        liver = indexed(dataset, index.get(key))
        if liver is None:
            if m.path is None:
                liver = make_phantom(m.seed, g["mesh_size"], variety)
            else:
                liver, reg, records[m.name] = (read_staged(dataset, key)
                                               or _prepared(m.path, registrar, g))
                known[liver.geometry_id] = reg
            index[key] = liver.geometry_id
            if dataset is not None:  # kept as they come: a long population resumes
                _keep(dataset, liver, index, records)
        livers.append(liver)
        if meshed:
            meshed(i)
    if dataset is not None:  # every staged liver is kept now (or of other code: not used)
        import shutil

        shutil.rmtree(staging_dir(dataset), ignore_errors=True)
    attach_shape_coefficients(livers, g["pca_components"], cache=cache, progress=progress,
                              template=template, known=known, region=registrar.region)
    return livers


def _warn_stale(dataset, index: dict, members: list, keys: list[str]) -> None:
    """A warning when ``dataset`` holds meshes of these liver files that other code or
    settings prepared: they are prepared again, and the simulations of a liver whose mesh or
    fixed region comes out otherwise are run again.
    """
    held = [k for k in index if k.startswith("file ")]
    stale = [m.name for m, k in zip(members, keys) if m.path and k not in index
             and any(h.startswith(_file_prefix(m.path)) for h in held)]
    if stale:
        log.warning("%s: %d of the %d livers were prepared by other code or settings (%s%s): "
                    "they are meshed and registered again, and a liver whose mesh or fixed "
                    "region comes out otherwise is simulated again", dataset, len(stale),
                    len(members), ", ".join(stale[:3]), ", ..." if len(stale) > 3 else "")


def _prepared(path, registrar: Registrar, g: dict):
    """:func:`prepare`, a refusal naming the liver and the way to leave it out."""
    from fem_sim.geometry.errors import GeometryError

    try:
        return prepare(path, registrar, g["mesh_size"], g.get("fixed_area_min"))
    except GeometryError as exc:
        raise GeometryError(f"{exc}; the population cannot use {Path(path).stem}: name it in "
                            "geometry.exclude to leave it out") from None


def _keep(dataset, liver: Geometry, index: dict, records: dict) -> None:
    """A prepared liver's geometry file, the mesh index entry and the records, written."""
    from data_spec import geometry_path, write_geometry
    from fem_sim.geometry.mesh_index import write_index

    path = geometry_path(dataset, liver.geometry_id)
    path.parent.mkdir(parents=True, exist_ok=True)
    write_geometry(path, liver)
    write_index(dataset, index)
    write_records(Path(dataset) / "geometry" / "livers.json", list(records.values()))


def _read_records(dataset) -> dict:
    path = Path(dataset) / "geometry" / "livers.json" if dataset is not None else None
    if path is None or not path.exists():
        return {}
    try:
        return {r["name"]: LiverRecord(**r) for r in json.loads(path.read_text())}
    except (OSError, ValueError, TypeError, KeyError):
        return {}


# Livers prepared by every rank before rank 0 plans (fem_sim generate under MPI): each rank
# prepares its share of the livers the dataset does not hold and stages them here, under their
# prepared-liver key; rank 0 reads them back in the population's order instead of preparing
# them. Preparation is deterministic (the same file gives the same mesh and registration in
# any process), so the dataset is the one a single rank makes.

def staging_dir(dataset) -> Path:
    return Path(dataset) / "geometry" / "staged"


def _staged_path(dataset, key: str) -> Path:
    import hashlib

    return staging_dir(dataset) / hashlib.sha256(key.encode()).hexdigest()[:24]


def unprepared(scene, dataset) -> list:
    """(member, key) of every liver file of a file population that ``dataset`` does not hold
    prepared under its key (all of them for a new dataset); [] for other scenes.
    """
    from data_spec.livers import members
    from fem_sim.geometry.mesh_index import indexed, read_index

    g = scene["geometry"]
    if g["source"] != "population" or "livers" not in g:
        return []
    index = read_index(dataset)
    keyed = [(m, prepared_key(m.path, g)) for m in members(g) if m.path is not None]
    return [(m, k) for m, k in keyed if indexed(dataset, index.get(k)) is None]


def prepare_share(scene, dataset, share: list, ranks: int = 1, progress: bool = False) -> int:
    """Prepares a rank's ``share`` of the livers the dataset lacks (``(member, key)`` as
    :func:`unprepared` gives them; ``ranks`` ranks share them) and stages each for rank 0
    (:func:`read_staged`); returns how many it staged. A liver that fails is left to rank 0,
    which prepares it again and names the reason.
    """
    g = scene["geometry"]
    share = [(m, k) for m, k in share
             if not _staged_path(dataset, k).with_suffix(".npz").exists()]
    if not share:
        return 0
    registrar = registrar_of(scene)
    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=len(share), unit="liver", desc=f"livers prepared ({ranks} ranks)")
    staged = 0
    for m, key in share:
        try:
            stage(dataset, key, *_prepared(m.path, registrar, g))
            staged += 1
        except Exception as exc:  # noqa: BLE001 (rank 0 meets it again and says why)
            log.info("%s: left to rank 0 (%s)", m.name, exc)
        if bar is not None:
            bar.update()
    if bar is not None:
        bar.close()
    return staged


def stage(dataset, key: str, liver: Geometry, reg, record: LiverRecord) -> None:
    """A prepared liver, its registration and its record under ``key``: the geometry file
    first, then the .npz that says it is complete (both written atomically).
    """
    from data_spec import write_geometry
    from data_spec.atomic import atomic_path

    base = _staged_path(dataset, key)
    base.parent.mkdir(parents=True, exist_ok=True)
    write_geometry(base.with_suffix(".h5"), liver)
    scalars = {k: v for k, v in asdict(reg).items() if k != "points"}
    with atomic_path(base.with_suffix(".npz")) as tmp, open(tmp, "wb") as f:
        np.savez(f, points=reg.points, key=np.array(key),
                 registration=np.array(json.dumps(scalars)),
                 record=np.array(json.dumps(asdict(record))))


def read_staged(dataset, key: str):
    """(liver, registration, record) staged under ``key``, or None (none staged, or
    unreadable: then it is prepared again).
    """
    from data_spec import read_geometry
    from liverreg.cpd import Registration

    if dataset is None:
        return None
    base = _staged_path(dataset, key)
    try:
        with np.load(base.with_suffix(".npz"), allow_pickle=False) as z:
            if str(z["key"]) != key:
                return None
            reg = Registration(points=z["points"], **json.loads(str(z["registration"])))
            record = LiverRecord(**json.loads(str(z["record"])))
        return read_geometry(base.with_suffix(".h5")), reg, record
    except (OSError, ValueError, KeyError, TypeError):
        return None
