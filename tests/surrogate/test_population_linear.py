"""The population basis of what each liver's small-strain base misses (config linear_base), on
make test's population (ci_scene4: six phantoms, P1 at 20 mm, 0.4 N, 3 load steps, with the
bases of ``fem_sim linear --population --order 2``)."""

import os

import numpy as np
import pytest

from surrogate import load_predictor
from surrogate.config import get_config
from surrogate.train import train_and_evaluate
from tests.surrogate.conftest import generated_dataset

DATA = os.environ.get("LIVERFEM_TEST_DATASET4")
pytestmark = pytest.mark.dataset


@pytest.fixture(autouse=True, scope="module")
def _population_dataset():
    generated_dataset("LIVERFEM_TEST_DATASET4")


def _relative_errors(ds, order: int) -> dict:
    """{load fraction: median over the samples of |FE - base| / |FE| (node means)}."""
    from surrogate.linear_base import PopulationLinearBase

    base, out = PopulationLinearBase(ds, order), {}
    for s in range(len(ds.sample_geo)):
        u = np.asarray(ds.targets[ds.sample_offset[s]:ds.sample_offset[s + 1]], float)
        e = np.linalg.norm(u - base.sample(ds, s), axis=1).mean()
        out.setdefault(round(float(ds.sample_fraction[s]), 6), []).append(
            e / np.linalg.norm(u, axis=1).mean())
    return {k: float(np.median(v)) for k, v in sorted(out.items())}


def test_the_bases_are_the_nonlinear_fields_series():
    """Against the nonlinear FE fields at load fractions 1/3, 2/3, 1: the linear response's
    error grows as lam (the next term, lam^2 u2, over lam u1: ratios 2 and 3 to the first
    step's), the second-order series' as lam^2 or faster (4 and 9) and is far below it."""
    from surrogate.data import load_dataset

    ds = load_dataset(DATA)
    one, two = _relative_errors(ds, 1), _relative_errors(ds, 2)
    lam = sorted(one)
    assert np.allclose(lam, [1 / 3, 2 / 3, 1.0])
    assert 1.7 < one[lam[1]] / one[lam[0]] < 2.3 and 2.5 < one[lam[2]] / one[lam[0]] < 3.5, one
    assert two[lam[2]] / two[lam[0]] > 6.0, two
    assert all(two[k] < 0.3 * one[k] for k in lam), (one, two)


def test_a_population_model_of_the_bases_rest(tmp_path):
    """Trained on what the base misses and added back to it, the population basis is far
    closer to the FE fields of livers it never saw than the same network on the whole fields;
    its exported model refuses to give a whole field without a base."""
    small = {"folds": 2, "epochs": 30, "modes": 16, "hidden": [32], "ensemble": 1}
    plain = train_and_evaluate(DATA, tmp_path / "plain", get_config("population_basis", **small),
                               log_fn=lambda m: None)
    rest = train_and_evaluate(DATA, tmp_path / "rest",
                              get_config("population_linear", **small), log_fn=lambda m: None)
    assert rest["network"]["mee"] < 0.1 * plain["network"]["mee"], (rest["network"],
                                                                    plain["network"])
    pred = load_predictor(tmp_path / "rest" / "model")
    assert pred.base.name == "second_order" and pred.base.order == 2
    with pytest.raises(ValueError, match="small-strain base misses.*make patient"):
        pred([[0.0, 0.0, -0.4]], pred.shape_model.loadable_nodes[:1])
    sm = pred.shape_model   # the template itself: shape coefficients 0
    u = pred([[0.0, 0.0, -0.4]], sm.loadable_nodes[:1], rest=True,
             geometry=(sm.template_points, sm.fixed_nodes, np.zeros(pred.spec.geometry_dim)))
    assert u.shape == sm.template_points.shape and np.all(np.isfinite(u))


def test_a_missing_base_is_named_before_training(tmp_path):
    """The population without its bases (DATA/linear/ left out): the file and the command."""
    from pathlib import Path

    bare = tmp_path / "bare"
    bare.mkdir()
    for p in Path(DATA).iterdir():
        if p.name != "linear":
            (bare / p.name).symlink_to(p.resolve())
    with pytest.raises(ValueError, match=r"bare/linear/g[0-9a-f]+\.h5: no small-strain.*"
                                         r"fem_sim linear --population"):
        train_and_evaluate(bare, tmp_path / "run", get_config("population_linear", folds=2,
                           epochs=1, modes=4, hidden=[8], ensemble=1), log_fn=lambda m: None)
