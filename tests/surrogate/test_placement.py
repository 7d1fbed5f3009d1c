"""A liver file placed in a population model's population (:func:`surrogate.evaluate.place`,
as make liver, make patient and make truth place it): a liver of the population itself,
meshed as make liver meshes it (``liverfem-sim mesh --scene``), is told the shape
coefficients the population's registration gave it, and its nodes land where the
population's preparation put them."""

import warnings
from pathlib import Path

import numpy as np
import pytest

from data_spec import load_scene, read_geometry
from data_spec.livers import members
from surrogate import load_predictor
from tests.surrogate.conftest import generated_dataset

pytestmark = pytest.mark.dataset


def _member(livers: Path, name: str):
    """(row of the population, prepared geometry) of the liver file ``name``."""
    with np.load(livers / "geometry" / "population.npz") as z:
        ids = [str(i) for i in z["geometry_ids"]]
    for row, gid in enumerate(ids):
        g = read_geometry(livers / "geometry" / f"{gid}.h5")
        if g.description.startswith(f"{name}.obj "):
            return row, g
    raise AssertionError(f"{name} is not in {livers}'s population")


def test_a_population_liver_meshed_as_make_liver_meshes_it_gets_its_own_coefficients():
    """Amos-005, one of the three livers of make test's population, placed from its file and
    its make-liver mesh: the coefficients are the population's own for it (to 1e-6 of their
    spread: the same rigid fit, samples and registration; the file's own surface or a fit
    onto another target gives coefficients whole standard deviations away), the template
    lands on the prepared liver's template registration, and the mesh's nodes mapped into
    the population's frame are the prepared liver's nodes."""
    from surrogate.evaluate import place

    d = generated_dataset("LIVERFEM_TEST_PATIENT")
    livers = generated_dataset("LIVERFEM_TEST_LIVERS")
    mesh = d / "member" / "Amos-005.h5"
    assert mesh.exists(), f"{mesh}: missing (make test's patient data meshes it)"
    pred = load_predictor(d / "population" / "model")
    sm = pred.shape_model
    g = load_scene(livers / "scene.toml")["geometry"]
    liver = next(Path(m.path) for m in members(g) if m.path and Path(m.path).stem == "Amos-005")
    row, prepared = _member(livers, "Amos-005")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        placement, _ = place(pred, liver, None, mesh=mesh)
    spread = sm.population_coefficients.std(axis=0)
    own = sm.population_coefficients[row]
    assert np.all(np.abs(placement.coefficients - own) <= 1e-6 * spread + 1e-9), \
        np.abs(placement.coefficients - own) / spread
    meshed = read_geometry(mesh)
    assert meshed.n_nodes == prepared.n_nodes
    np.testing.assert_allclose(placement.to_population(meshed.points), prepared.points,
                               atol=1e-6)
