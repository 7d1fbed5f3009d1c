"""A trained model against FE simulations it never trained on: any dataset of its own liver, or
the FE truth of a liver it never saw (``python -m surrogate evaluate RUN DATA``).

For a liver never seen, the truth must carry the model's boundary condition: ``truth_scene``
writes the scene of that truth (a population scene's loads, material, steps and solver on the
liver's own mesh, fixed where the model's placement puts the template's fixed region), which
``fem_sim generate`` solves in the solver environment; ``evaluate_liver`` then compares the
placed model with it, beside the naive model (the population's mean displacement) and, for a
basis design, the floor of its modes (the best any coefficients could do on that liver).
"""

from __future__ import annotations

import functools
import hashlib
import json
import warnings
from pathlib import Path

import numpy as np

from data_spec import list_shards, read_geometry, read_shard
from data_spec.scene_writer import liver_scene
from data_spec.shards import geometry_path
from data_spec.views import shard_count
from surrogate.metrics import mee

# (liver, its mtime, frame, the shape model's digest) -> placement, warnings, its meshed liver
_PLACED: dict = {}


def shape_model_digest(sm) -> str:
    """A digest of what a placement depends on: the shape model's template, PCA, ranges and
    registration settings (every design and seed trained on one dataset shares it).
    """
    h = hashlib.sha256()
    for x in (sm.template_points, sm.template_cells, sm.surface_triangles, sm.fixed_nodes,
              sm.mean, sm.components, sm.coefficient_min, sm.coefficient_max, sm.residuals,
              sm.schedule, sm.population_coefficients, sm.population_inverted,
              sm.population_fixed_area, np.asarray(sm.n_points)):
        a = np.ascontiguousarray(x)
        h.update(f"{a.dtype}{a.shape}".encode())
        h.update(a.tobytes())
    return h.hexdigest()


def place(pred, liver: str | Path, frame: str = "LPS", saved: str | Path | None = None,
          mesh: str | Path | None = None):
    """(placement, warnings): predict-liver's placement of the liver file by the loaded
    population model ``pred`` (``frame`` as its --frame). Registered once per liver, frame and
    shape model in a process: the designs and training seeds of one dataset share it.
    ``saved``: a file that keeps it across processes (``make patient``'s steps), read when it
    holds the placement of the same liver file, frame and shape model, written otherwise.
    ``mesh``: the liver file as the population meshed its livers (``liverfem-sim mesh``, a
    data_spec geometry in the file's frame): the template is registered on its surface, as on
    the population's livers (a liver of the population is then told its own coefficients);
    a placement made on another surface is not reused, and the one made on ``mesh`` is what
    later calls without ``mesh`` get.
    """
    from surrogate.predict_liver import place_liver, read_liver_surface

    liver = Path(liver).resolve()
    key = (str(liver), liver.stat().st_mtime_ns, frame, shape_model_digest(pred.shape_model))
    on = None if mesh is None else _mesh_id(mesh)
    if key not in _PLACED or (on is not None and _PLACED[key][2] != on):
        kept = None if saved is None else read_placement(saved, key, on)
        if kept is not None:
            _PLACED[key] = (kept, pred.shape_model.warnings(kept), kept.surface)
        else:
            points, tris = read_liver_surface(liver if mesh is None else mesh)
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                placement, found = place_liver(pred, points, tris, frame=frame)
            placement.surface = on
            _PLACED[key] = (placement, found, on)
            if saved is not None:
                write_placement(saved, key, placement)
    placement, found, _ = _PLACED[key]
    return placement, list(found)


def _mesh_id(mesh) -> str:
    """A meshed liver file as a placement records it: its path and modification time."""
    mesh = Path(mesh).resolve()
    return f"{mesh} {mesh.stat().st_mtime_ns}"


_ARRAYS = ("points", "coefficients", "offset", "rotation")


def _key_text(key: tuple) -> list[str]:
    """A placement's key as kept in its file (liver path, mtime, frame, shape-model digest)."""
    return [str(k) for k in key]


def write_placement(path: str | Path, key: tuple, placement) -> None:
    """Keeps a placement in ``path`` (.npz) with the key it was made for."""
    meta = {"key": _key_text(key), "surface": placement.surface,
            "residual": float(placement.residual),
            "iterations": [int(i) for i in placement.iterations],
            "inverted": int(placement.inverted), "frame": placement.frame}
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    with open(path, "wb") as fh:
        np.savez(fh, meta=json.dumps(meta), **{a: getattr(placement, a) for a in _ARRAYS})


def read_placement(path: str | Path, key: tuple, surface: str | None = None):
    """The placement kept in ``path`` if it was made for ``key`` (and, given ``surface``, on
    that meshed liver), else None.
    """
    from liverreg.shape_model import Placement

    if not Path(path).is_file():
        return None
    with np.load(path) as z:
        meta = json.loads(str(z["meta"]))
        if meta["key"] != _key_text(key) or surface not in (None, meta.get("surface")):
            return None
        arrays = {a: np.asarray(z[a]) for a in _ARRAYS}
    return Placement(residual=meta["residual"], iterations=meta["iterations"],
                     inverted=meta["inverted"], frame=meta["frame"],
                     surface=meta.get("surface"), **arrays)


NODE_RADIUS = 0.01   # mm: a scene's fixed point selects its mesh node (written to 1 micron)


def truth_scene(pred, scene_file: str | Path, liver: str | Path, n: int,
                frame: str = "LPS", saved: str | Path | None = None,
                mesh: str | Path | None = None, near=None,
                near_radius: float | None = None) -> str:
    """The scene text of a liver's FE truth with the population model's boundary condition:
    fixed where its placement (:func:`place`, ``mesh`` its) puts the template's fixed region,
    grown as the population's livers were (:func:`fixed_area_min`). With ``mesh``, the liver
    as it is solved: its nodes where the region lands, by the population's own rule
    (:func:`liverreg.shape_model.landed_region`); without, the surface within half an element
    of the moved region's nodes. ``near``, ``near_radius``: the loads drawn around that site
    (:func:`~data_spec.scene_writer.liver_scene`).
    """
    placement, _ = place(pred, liver, frame, saved, mesh)
    sm = pred.shape_model
    if mesh is None:
        fixed, radius = placement.to_liver(placement.points[sm.fixed_nodes]), None
    else:   # the mesh's own nodes where the region lands, as on the population
        from data_spec.geometry import read_geometry
        from liverreg.shape_model import landed_region

        g = read_geometry(mesh)
        fixed = g.points[landed_region(placement.points, sm.surface_nodes, sm.fixed_nodes,
                                       placement.to_population(g.points), g.surface_nodes)]
        radius = NODE_RADIUS
    return liver_scene(scene_file, liver, n, fixed, area_min=fixed_area_min(sm, scene_file),
                       mesh=mesh, radius=radius, near=near, near_radius=near_radius)


def fixed_area_min(sm, scene_file) -> float | None:
    """The area (mm^2) a population of liver files grew each liver's fixed region to: the
    scene's ``fixed_area_min``, or half the template's region. None for phantoms (each fixed
    on its own region).
    """
    import tomllib

    from data_spec.geometry import region_area

    g = tomllib.loads(Path(scene_file).read_text())["geometry"]
    if "livers" not in g:
        return None
    return g.get("fixed_area_min") or 0.5 * region_area(sm.template_points,
                                                        sm.surface_triangles, sm.fixed_nodes)


@functools.lru_cache(maxsize=4)
def mean_displacement(data: Path) -> np.ndarray:
    """(3,) mm: the mean displacement of a dataset's simulations (the naive model)."""
    return np.mean([np.asarray(read_shard(p).displacement).reshape(-1, 3).mean(axis=0)
                    for p in list_shards(data)], axis=0)


@functools.cache
def shards_by_liver(data: Path) -> dict[str, list[Path]]:
    """The shard files of a dataset by liver (geometry id), read once per dataset."""
    out: dict[str, list[Path]] = {}
    for path in list_shards(data):
        out.setdefault(read_shard(path).geometry_id, []).append(path)
    return out


@functools.cache
def fixed_extents(data: Path) -> np.ndarray:
    """(livers, 3) mm: the extent along x, y, z of each liver's fixed nodes in a dataset."""
    out = []
    for gid, paths in shards_by_liver(data).items():
        points = read_geometry(geometry_path(data, gid)).points
        out.append(np.ptp(points[read_shard(paths[0]).fixed_nodes], axis=0))
    return np.array(out)


def _placed_fields(pred, placement, shape, points, shards, base=None):
    """(predicted, true) (n, 3) mm of every done load step of ``shards`` at the liver's own
    nodes ``points``, and the placed model; ``base``: the liver's small-strain responses
    (:class:`~data_spec.linear_fields.LinearFields`) a model of their rest adds its field to.
    """
    from surrogate.linear_base import case_base
    from surrogate.predict_liver import PlacedModel

    P, T = [], []
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        placed = PlacedModel(pred, nodes=points, placement=placement, shape=shape)  # once
        for sh in shards:
            fr = np.asarray(sh.load_fractions[:sh.n_done])
            forces = fr[:, None, None] * np.asarray(sh.forces)[None]
            at = np.broadcast_to(points[sh.load_nodes], forces.shape)
            u = placed(forces, placed.load_nodes(at), rest=base is not None)[:, sh.output_nodes]
            if base is not None:
                u = u + case_base(base, pred.base.order, sh.sim_index, fr)
            P.append(u.reshape(-1, 3))
            T.append(np.asarray(sh.displacement[:sh.n_done]).reshape(-1, 3))
    return np.concatenate(P), np.concatenate(T), placed


def _base_of(pred, data: Path):
    """The small-strain responses of ``data``'s liver when ``pred`` models their rest (its
    linear.h5, ``fem_sim linear --order 2``), else None; ValueError naming the file missing.
    """
    from data_spec.linear_fields import linear_fields_path, read_dataset_linear

    if pred.base.whole:
        return None
    path = linear_fields_path(data)
    if not path.exists():
        command = pred.base.liver_command(Path(data) / "scene.toml", data)
        raise ValueError(f"{path}: missing; the model predicts the rest of each liver's "
                         f"small-strain base: run `{command}` first")
    return read_dataset_linear(data)


def _scale_fit(pred_all, true_all) -> dict:
    """Whether the prediction is too large or too small as a whole: the one scale that fits
    the truth best, and the MEE at that scale.
    """
    scale = float(np.sum(pred_all * true_all) / max(float(np.sum(pred_all ** 2)), 1e-30))
    return {"best_scale": scale,
            "truth_mean_mm": mee(true_all), "predicted_mean_mm": mee(pred_all),
            "mee_best_scale": mee(scale * pred_all, true_all)}


def _placement_facts(pred, placement, shape, population_data) -> dict:
    """The registration's and the fixed region's numbers of a placement."""
    from surrogate.predict_liver import shape_rule, told_shape

    sm = pred.shape_model
    out = {"residual_mm": placement.residual, "inverted": placement.inverted,
           "template_cells": int(sm.template_cells.shape[0]),
           "coefficients_out": int(sm.outside_range(placement.coefficients).size),
           "coefficients": int(placement.coefficients.size),
           "shape_asked": shape or shape_rule(pred),
           "shape_rule": told_shape(pred, placement.coefficients, shape)[1],
           # the fixed region the placement gives against the template's (population frame)
           "fixed_extent_mm": np.ptp(placement.points[sm.fixed_nodes], axis=0).tolist(),
           "template_fixed_extent_mm": np.ptp(sm.template_points[sm.fixed_nodes],
                                              axis=0).tolist()}
    if population_data is not None:
        out["population_fixed_extent_max_mm"] = fixed_extents(population_data).max(
            axis=0).tolist()
    return out


def evaluate_liver(pred, data: Path, placement, found: list = (), *, population_data=None,
                   shape: str | None = None, geometry_id: str | None = None) -> dict:
    """The loaded population model ``pred`` on the FE simulations ``data`` of a liver it never
    saw, placed by ``placement`` (predict-liver's), predicted at the liver's own mesh nodes and
    told the shape ``shape`` gives (:meth:`liverreg.shape_model.ShapeModel.shape_told`; None:
    the design's, as predict-liver), against the FE solution (a model of the rest of the
    small-strain base: plus the liver's own base, ``data/linear.h5``). Naive model: the mean
    displacement of ``population_data``'s simulations (None: of ``data``'s), turned into the
    liver's frame. ``geometry_id``: only that liver's simulations of ``data``.
    """
    from surrogate.metrics import displacement_metrics

    data = Path(data)
    paths = list_shards(data) if geometry_id is None else shards_by_liver(data)[geometry_id]
    shards = [sh for sh in map(read_shard, paths) if sh.n_done]
    if not shards:
        raise ValueError(f"{data}: no simulation with a converged load step")
    g = read_geometry(geometry_path(data, shards[0].geometry_id))
    base = _base_of(pred, data)
    pred_all, true_all, placed = _placed_fields(pred, placement, shape, g.points, shards, base)
    mean = mean_displacement(Path(population_data) if population_data else data)
    m_nn = displacement_metrics(pred_all, true_all)
    m_naive = displacement_metrics(np.broadcast_to(placement.vectors_to_liver(mean),
                                                   true_all.shape), true_all)
    floor = ({"modes_floor_mm": modes_floor(pred, placement, placed.interpolation, shards)}
             if pred.modes is not None and base is None else {})
    return {"sims": len(shards), "stopped": stopped_simulations(shards), "nodes": g.n_nodes,
            "network": m_nn, "naive": m_naive,
            "skill": m_nn["mee"] / m_naive["mee"],
            "naive_from": str(population_data or data),
            **_placement_facts(pred, placement, shape, population_data),
            "fixed_nodes": int(shards[0].fixed_nodes.size), "warnings": list(found), **floor,
            **_scale_fit(pred_all, true_all)}


def evaluate_unseen(pred, truth: str | Path, liver: str | Path, frame: str | None = None, *,
                    population_data=None, mesh: str | Path | None = None) -> dict:
    """The model ``pred`` against the FE truth of a liver it never saw (``truth``: the data
    directory of ``surrogate truth-scene`` then ``fem_sim generate``; resumable by
    :func:`fem_sim.batch.chunked.liver_truth`), placed as predict-liver places it:
    :func:`evaluate_liver`'s figures; a model of the rest of a small-strain base is evaluated
    over the base of the truth's own mesh (``truth/linear.h5``, ``fem_sim linear``:
    ValueError naming the command when missing), and the base alone comes as
    ``base_alone``. ``mesh``: :func:`place`'s (the meshed liver truth-scene --mesh placed on).
    """
    from surrogate.linear_base import liver_base_metrics

    truth = Path(truth)
    placement, found = place(pred, liver, frame, mesh=mesh)
    out = evaluate_liver(pred, truth, placement, found, population_data=population_data)
    if not pred.base.whole:
        alone = liver_base_metrics(truth, pred.base.order)
        out["base_alone"] = {"order": pred.base.order, "network": alone,
                             "skill": alone["mee"] / out["naive"]["mee"],
                             "naive": out["naive"], "sims": out["sims"]}
    return out


def stopped_simulations(shards) -> list[dict]:
    """The simulations that stopped part-way (they count with their converged steps): each
    one's number, steps reached, steps asked and reason.
    """
    return [{"sim": sh.sim_index, "steps": sh.n_done, "of": len(sh.load_fractions),
             "reason": sh.failure_reason} for sh in shards if sh.status != "ok"]


def evaluate_own(pred, data: Path) -> dict:
    """A model of one liver on a dataset of that liver (its own mesh and output nodes): the
    metrics of every done load step, beside the naive model (the dataset's mean
    displacement).
    """
    from surrogate.features import material_vector
    from surrogate.metrics import displacement_metrics

    P, T = [], []
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for sh in (s for s in map(read_shard, list_shards(data)) if s.n_done):
            fr = np.asarray(sh.load_fractions[:sh.n_done])
            forces = fr[:, None, None] * np.asarray(sh.forces)[None]
            nodes = np.broadcast_to(sh.load_nodes, forces.shape[:2])
            mat = sh.material
            material = (material_vector(mat.c, mat.m, mat.K) if pred.spec.material_dim
                        else None)
            u = pred(forces, nodes, nodes=np.asarray(sh.output_nodes), material=material)
            P.append(u.reshape(-1, 3))
            T.append(np.asarray(sh.displacement[:sh.n_done]).reshape(-1, 3))
    if not P:
        raise ValueError(f"{data}: no simulation with a converged load step")
    pred_all, true_all = np.concatenate(P), np.concatenate(T)
    m_nn = displacement_metrics(pred_all, true_all)
    m_naive = displacement_metrics(np.broadcast_to(true_all.mean(axis=0), true_all.shape),
                                   true_all)
    return {"sims": len(P), "network": m_nn, "naive": m_naive,
            "skill": m_nn["mee"] / m_naive["mee"], "naive_from": str(data),
            **_scale_fit(pred_all, true_all)}


def modes_floor(pred, placement, interp, shards: list) -> float:
    """MEE (mm) of the best a basis model's modes can do on a liver: each load step's FE field
    at the liver's nodes fitted by least squares with the modes carried there as a prediction
    is (``interp``: the sparse interpolation from the registered template to the liver's
    nodes, :attr:`PlacedModel.interpolation`; then turned into the liver's frame). The rest of
    the model's error is in the coefficients its network gives.
    """
    A = np.stack([placement.vectors_to_liver(interp @ m) for m in pred.modes], axis=-1)
    errors = []
    for sh in shards:
        a = A[sh.output_nodes].reshape(-1, A.shape[-1])  # (3 n_out, modes)
        t = np.asarray(sh.displacement[:sh.n_done], dtype=np.float64).reshape(sh.n_done, -1).T
        c = np.linalg.lstsq(a, t, rcond=None)[0]
        errors.append(np.linalg.norm((a @ c - t).T.reshape(sh.n_done, -1, 3), axis=-1).ravel())
    return float(np.mean(np.concatenate(errors)))


def heldout_floor(data: Path, run: Path) -> dict:
    """A population basis's floor on its evaluated held-out livers: the modes of each fold's
    training fields (on the template, as the design computes them) fitted by least squares to
    the held-out livers' fields, MEE in mm (``held_out``), beside the training fields' own
    (``training``). What is left of the design's error is in the coefficients its network
    gives. Kept in the run's directory (floor.json) for as many simulations as the dataset
    holds.
    """
    import json

    from surrogate.basis import compute_modes, projection_mee
    from surrogate.data import kfold_groups, load_dataset, training_samples
    from surrogate.population_basis import TemplateFields

    cache, shards = Path(run) / "floor.json", shard_count(data)
    if cache.exists():
        saved = json.loads(cache.read_text())
        if saved.get("shards") == shards:
            return saved
    cfg = json.loads((Path(run) / "config.json").read_text())
    ds = load_dataset(data)
    maps = TemplateFields(ds)
    floors = []
    for held in kfold_groups(ds, cfg["folds"], cfg["seed"])[:cfg.get("evaluate_folds") or None]:
        U = maps.fields(ds, training_samples(ds, held, cfg))
        modes = compute_modes(U, cfg["modes"], cfg["seed"])
        floors.append((projection_mee(U, modes), projection_mee(maps.fields(ds, held), modes)))
    out = {"shards": shards, "modes": cfg["modes"],
           "training": float(np.mean([f[0] for f in floors])),
           "held_out": float(np.mean([f[1] for f in floors]))}
    cache.write_text(json.dumps(out))
    return out


def heldout_base(data: str | Path, run: str | Path, order: int = 2) -> dict:
    """The small-strain base alone (no network) on the held-out livers of a population run's
    evaluated folds (``RUN/config.json``: its folds and seed), in metrics.json's terms: its
    MEE beside the naive model's (each fold's training mean displacement), per liver.
    """
    from surrogate.data import kfold_groups, load_dataset
    from surrogate.linear_base import PopulationLinearBase
    from surrogate.metrics import displacement_metrics
    from surrogate.train import per_liver, training_mean, training_samples

    cfg = json.loads((Path(run) / "config.json").read_text())
    ds = load_dataset(data)
    base = PopulationLinearBase(ds, order)
    folds = kfold_groups(ds, cfg["folds"], cfg["seed"])[:cfg.get("evaluate_folds") or None]
    P, T, N, G = [], [], [], []
    for held in folds:
        mean = training_mean(ds, training_samples(ds, held, cfg))
        for s in held:
            t = np.asarray(ds.targets[ds.sample_offset[s]:ds.sample_offset[s + 1]], np.float64)
            P.append(base.sample(ds, s))
            T.append(t)
            N.append(np.broadcast_to(mean, t.shape))
            G.append(np.full(len(t), ds.sample_geo[s]))
    pred, true, naive, geo = (np.concatenate(a) for a in (P, T, N, G))
    m, m_naive = displacement_metrics(pred, true), displacement_metrics(naive, true)
    return {"network": m, "naive": m_naive, "skill": m["mee"] / m_naive["mee"],
            "per_liver_mee": per_liver(pred, true, naive, geo), "order": order,
            "evaluated_folds": len(folds)}


def worst_case_picture(pred, data: Path, placement, png: Path, title: str = "",
                       shape: str | None = None) -> dict:
    """The simulation of ``data`` (a liver's FE truth) the placed model ``pred`` predicts
    worst, drawn at its last load step on the liver's surface: the FE field, the prediction
    and the error between them (a PNG). Returns that simulation's number and MEE (mm).
    """
    from liverviz.pictures import Panel, Surface, render_panels

    shards = [sh for sh in map(read_shard, list_shards(data)) if sh.n_done]
    g = read_geometry(geometry_path(data, shards[0].geometry_id))
    fields = [_placed_fields(pred, placement, shape, g.points, [sh])[:2] for sh in shards]
    errors = [mee(p, t) for p, t in fields]
    worst = int(np.argmax(errors))
    sh, (p, t) = shards[worst], fields[worst]
    n_out = sh.output_nodes.size
    surface = Surface.from_mesh(g.points, g.surface_triangles, sh.fixed_nodes)
    full = np.zeros((2, g.n_nodes, 3))
    full[:, sh.output_nodes] = p[-n_out:], t[-n_out:]  # the last load step
    nn, fe = full[0][surface.nodes], full[1][surface.nodes]
    err = np.linalg.norm(nn - fe, axis=1)
    top = float(max(np.linalg.norm(fe, axis=1).max(), np.linalg.norm(nn, axis=1).max()))
    step = float(sh.load_fractions[sh.n_done - 1])
    common = {"surface": surface, "forces": np.asarray(sh.forces) * step,
              "load_nodes": np.asarray(sh.load_nodes), "clim": (0.0, top),
              "f_ref": float(np.linalg.norm(sh.forces, axis=1).max())}
    render_panels([Panel(u=fe, label=f"FE, simulation {sh.sim_index}", **common),
                   Panel(u=nn, label="population model, placed", **common),
                   Panel(**{**common, "clim": None}, u=nn, scalars=err, title="error (mm)",
                         cmap="inferno", label=f"error: mean {err.mean():.2f} mm, max "
                         f"{err.max():.2f} mm")], png, title=title)
    return {"simulation": int(sh.sim_index), "mee_mm": max(errors), "png": str(png)}
