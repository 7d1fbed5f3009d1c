"""Exported models: plain files only (JSON + .npz read with allow_pickle=False), so loading a
model never executes code. This module writes them and reads them back checked;
:func:`surrogate.predictor.load_predictor` turns a directory into a jitted predictor in mm.

    RUN/model/model.json     format, version, config, feature spec, normalisation statistics,
                             training ranges
    RUN/model/params.npz     network parameters, keys "hidden_0/kernel", ..., "output/bias"
                             (the reduced basis: "coefficients/..." for its last layer)
    RUN/model/geometry.npz   the liver (points, fixed nodes, output nodes, outward surface
                             triangles, the nodes the scene loads) when the scene has one
                             liver: enough to draw it
    RUN/model/linear_part.npz  optional (a patient model): the liver's small-strain Green's
                             function, "nodes" (n_g,) and "green" (n_g, 3, n_out, 3) mm/N at
                             the output nodes; the predictor adds green[load node] . force
                             to the network's output, which is then what is left beyond it
    RUN/model/shape_model.npz  when the scene varies the liver: the template, the PCA of the
                             population and the registration settings
                             (:class:`liverreg.shape_model.ShapeModel`): what a new liver
                             needs (``python -m surrogate predict-liver``)
"""

from __future__ import annotations

import dataclasses
import json
import logging
from pathlib import Path

import numpy as np
from flax import traverse_util

from surrogate.model_files import MODEL_FORMAT, MODEL_VERSION

log = logging.getLogger(__name__)


def export_model(directory, model, cfg, ds, unseen=(), linear_part=None) -> Path:
    """Write a model directory from a trained model of the config's design (node-wise:
    (parameters, normaliser); basis: a :class:`surrogate.basis.BasisModel`) and its dataset.
    ``unseen``: the simulations the model never trained on (recorded for viewers).
    ``linear_part``: (nodes, green) of a one-liver model trained on what is left beyond it.
    """
    from surrogate.designs import DESIGNS

    design = DESIGNS[cfg["design"]]
    params, stats, files = design.export_parts(model)
    d = _export(directory, params, {"design": design.name, "stats": stats}, cfg, ds, unseen,
                on_template=design.on_template)
    for name, arrays in files.items():
        np.savez(d / name, **arrays)
    if linear_part is not None:
        nodes, green = linear_part
        np.savez(d / "linear_part.npz", nodes=np.asarray(nodes, np.int64),
                 green=np.asarray(green, np.float32))
        meta = json.loads((d / "model.json").read_text())
        meta["linear_part"] = "linear_part.npz"
        (d / "model.json").write_text(json.dumps(meta, indent=1))
    return d


def _grasp_force(ds):
    """The tools' force beyond the small-strain one (:class:`surrogate.grasp.GraspForce`)
    fitted on every sample of the grasp dataset ``ds``; None without its small-strain files'
    tools' forces (the model then gives the base's force).
    """
    from surrogate.grasp import GraspForce, base_forces, tool_distances

    try:
        return GraspForce.fit(ds.forces, base_forces(ds), ds.reactions, tool_distances(ds))
    except (ValueError, OSError):
        return None


def _export(directory, params, design: dict, cfg, ds, unseen=(), on_template=False) -> Path:
    d = Path(directory)
    d.mkdir(parents=True, exist_ok=True)
    flat = traverse_util.flatten_dict(params, sep="/")
    np.savez(d / "params.npz", **{k: np.asarray(v) for k, v in flat.items()})
    fnorm = np.linalg.norm(ds.forces, axis=-1)
    meta = {
        "format": MODEL_FORMAT, "version": MODEL_VERSION, "scene": ds.scene_name,
        "config": cfg, "feature_spec": ds.spec.to_dict(), "feature_names": ds.spec.names(),
        **design,
        "training_range": {
            "force_norm_max": float(fnorm.max()),
            "extra_min": ds.extra.min(axis=0).tolist() if ds.extra.size else [],
            "extra_max": ds.extra.max(axis=0).tolist() if ds.extra.size else []},
        "units": {"length": "mm", "force": "N", "stress": "MPa"},
        # Simulations held out of the exported model's training (its early-stopping slice):
        # the honest cases to compare it with the FE solution on (surrogate.viewer --compare).
        "unseen_simulations": sorted(int(i) for i in unseen),
    }
    if getattr(ds, "load_kind", "nodal") == "grasp":   # its "forces" are the tools' pulls, mm
        meta["load"], meta["units"]["force"] = "grasp", "mm (a tool's displacement)"
        force = _grasp_force(ds)
        if force is not None:
            meta["grasp_force"] = dataclasses.asdict(force)
    meta["embedded_geometry"] = len(ds.points) == 1
    loadable = getattr(ds, "loadable", None)
    if meta["embedded_geometry"]:
        extra = {} if loadable is None else {"loadable": loadable[0]}
        np.savez(d / "geometry.npz", points=ds.points[0], fixed=ds.fixed[0],
                 output_nodes=ds.out_nodes[0], triangles=ds.triangles[0], **extra)
    if ds.spec.geometry_dim and getattr(ds, "directory", None) is not None:
        from surrogate.population import population_shape_model

        shape_model = population_shape_model(ds)
        if shape_model is not None:
            shape_model.save(d / "shape_model.npz")
            meta["shape_model"] = "shape_model.npz"
            if on_template:  # the design's modes live on the template
                np.savez(d / "geometry.npz", points=shape_model.template_points,
                         fixed=shape_model.fixed_nodes,
                         output_nodes=np.arange(shape_model.template_points.shape[0]),
                         triangles=shape_model.surface_triangles,
                         loadable=shape_model.loadable_nodes)
    (d / "model.json").write_text(json.dumps(meta, indent=1))
    return d
