"""A dataset's liver population on the trainer's side: the shape model a population model
exports (template, PCA, registration settings, ranges), and the template registered onto
every liver of the dataset (one node order for the whole population: the population basis
design's fields live there).
"""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np

from data_spec import read_geometry
from data_spec.eligible_loads import eligible_load_nodes
from data_spec.scene import load_scene
from data_spec.shards import geometry_path
from liverreg.cpd import surface_displacements
from liverreg.morph import SurfaceMorph
from liverreg.shape_model import ShapeModel

log = logging.getLogger(__name__)


def population_file(directory) -> Path:
    """The population's registration of the dataset in ``directory``."""
    return Path(directory) / "geometry" / "population.npz"


def population_shape_model(ds):
    """The dataset's population as a :class:`liverreg.shape_model.ShapeModel` (template = the
    population's liver 0), from DATA/geometry/population.npz; None when the dataset has none.
    """
    path = population_file(ds.directory)
    if not path.exists():
        log.warning("%s: missing; the model cannot place a new liver", path)
        return None
    k = ds.spec.geometry_dim
    with np.load(path, allow_pickle=False) as z:
        ids = [str(i) for i in z["geometry_ids"]]
        coeff, mean, comps = z["coefficients"][:, :k], z["mean"], z["components"][:k]
        D = surface_displacements(z)
        residuals = z["registration_error"]
        inverted = z["inverted"] if "inverted" in z.files else None
    template = template_geometry(ds.directory)
    scene = load_scene(Path(ds.directory) / "scene.toml")
    if "template_fixed" in template.regions:  # a file population's template: not a member
        fixed = template.regions["template_fixed"]
    elif ids[0] in ds.geo_ids:
        fixed = ds.fixed[ds.geo_ids.index(ids[0])]
    else:  # the template's simulations are not in this dataset: its region, as the scene says
        fixed = template.regions[scene["fixed"]["name"]]
    loadable = eligible_load_nodes(scene["loads"], template.points, template.surface_nodes,
                                   fixed)
    sm = ShapeModel(template_points=template.points, template_cells=template.cells,
                    surface_triangles=template.surface_triangles, fixed_nodes=fixed,
                    mean=mean, components=comps, coefficient_min=coeff.min(axis=0),
                    coefficient_max=coeff.max(axis=0), residuals=residuals,
                    loadable_nodes=loadable, population_inverted=inverted,
                    population_coefficients=coeff,
                    frame=scene["geometry"].get("frame", "") if "livers" in scene["geometry"]
                    else "")
    sm.population_fixed_area = sm.fixed_areas(D)
    return sm


def template_geometry(directory):
    """The template's own mesh (:class:`data_spec.Geometry`) of the dataset in ``directory``:
    the population's liver 0, or the template kept in population.npz when it is not one of
    the livers (a file population; its fixed region as ``regions["template_fixed"]``).
    """
    from data_spec import Geometry

    with np.load(population_file(directory), allow_pickle=False) as z:
        if "template_points" in z.files:
            return Geometry(points=z["template_points"], cells=z["template_cells"],
                            surface_triangles=z["template_triangles"],
                            regions={"template_fixed": z["template_fixed"]},
                            description="population template")
        first = str(z["geometry_ids"][0])
    return read_geometry(geometry_path(directory, first))


def registered_templates(directory) -> dict[str, np.ndarray]:
    """The template's nodes registered onto each liver of the population of the dataset in
    ``directory``, by geometry id ((n_template, 3) each: (its surface as the population's CPD
    put it, the interior by harmonic extension, as
    :meth:`liverreg.shape_model.ShapeModel.place` does for a new liver)).
    """
    path = population_file(directory)
    with np.load(path, allow_pickle=False) as z:
        ids = [str(i) for i in z["geometry_ids"]]
        D = surface_displacements(z)
    template = template_geometry(directory)
    surf = template.surface_nodes
    morph = SurfaceMorph(template.points, template.cells, surf)
    S = template.points[surf]
    return {gid: morph.place(S + d.reshape(-1, 3)) for gid, d in zip(ids, D)}
