"""The learning-curve knobs (``train_fraction``, ``simulations_per_liver``) thin a fold's
training livers and simulations; the held-out livers and the mixed-in phantoms stay as they
are, so that every point of a curve is measured on the same held-out livers."""

from types import SimpleNamespace

import numpy as np
import pytest

from surrogate.config import get_config
from surrogate.data import kfold_groups, training_samples


def _dataset(geometry_dim=4):
    """10 livers (p0, p1 phantoms; f0..f7 files), 3 simulations of 2 samples each."""
    ids = ["p0", "p1"] + [f"f{i}" for i in range(8)]
    geo = np.repeat(np.arange(10), 6)
    return SimpleNamespace(geo_ids=ids, sample_geo=geo, sample_sim=np.arange(geo.size) // 2,
                           n_samples=geo.size, spec=SimpleNamespace(geometry_dim=geometry_dim),
                           augmenting=frozenset({"p0", "p1"}))


def _livers(ds, samples):
    return set(np.unique(ds.sample_geo[samples]).tolist())


def test_a_fraction_of_the_training_livers_nested_phantoms_and_held_out_untouched():
    ds = _dataset()
    held = kfold_groups(ds, 4, seed=0)[0]  # 2 of the 8 files
    cfg = {"seed": 3}
    full = training_samples(ds, held, cfg)
    half = training_samples(ds, held, {**cfg, "train_fraction": 0.5})
    quarter = training_samples(ds, held, {**cfg, "train_fraction": 0.25})
    real = _livers(ds, full) - {0, 1}
    assert len(real) == 6
    assert len(_livers(ds, half) - {0, 1}) == 3  # round(0.5 x 6)
    assert len(_livers(ds, quarter) - {0, 1}) == 2  # round(0.25 x 6) = 2 (1.5 to even)
    assert _livers(ds, quarter) <= _livers(ds, half) <= _livers(ds, full)
    for part in (half, quarter):
        assert {0, 1} <= _livers(ds, part)  # phantoms: augmentation, always trained on
        assert not np.isin(held, part).any()
        # a liver kept keeps all its samples
        for g in _livers(ds, part):
            assert np.isin(np.flatnonzero(ds.sample_geo == g), part).all()
    # another seed draws other livers (the draw is seeded, not the first ones)
    draws = {frozenset(_livers(ds, training_samples(ds, held, {"seed": s,
                                                                "train_fraction": 0.5})))
             for s in range(6)}
    assert len(draws) > 1
    assert np.array_equal(training_samples(ds, held, {**cfg, "train_fraction": 1.0}), full)


def test_each_training_liver_keeps_its_first_simulations():
    ds = _dataset()
    held = kfold_groups(ds, 4, seed=0)[0]
    one = training_samples(ds, held, {"seed": 0, "simulations_per_liver": 1})
    for g in _livers(ds, training_samples(ds, held, {"seed": 0})):
        sims = np.unique(ds.sample_sim[one][ds.sample_geo[one] == g])
        first = ds.sample_sim[ds.sample_geo == g].min()
        # phantoms keep their three simulations; a file liver only its first (both samples)
        assert sims.tolist() == ([first, first + 1, first + 2] if g < 2 else [first])
        assert np.count_nonzero(ds.sample_geo[one] == g) == 2 * len(sims)
    assert not np.isin(held, one).any()


def test_one_liver_thins_simulations_and_refuses_simulations_per_liver():
    ds = _dataset(geometry_dim=0)
    ds.augmenting = frozenset()
    held = kfold_groups(ds, 5, seed=0)[0]  # 6 of the 30 simulations
    half = training_samples(ds, held, {"seed": 0, "train_fraction": 0.5})
    assert np.unique(ds.sample_sim[half]).size == 12
    with pytest.raises(ValueError, match="simulations_per_liver"):
        training_samples(ds, held, {"seed": 0, "simulations_per_liver": 2})


@pytest.mark.parametrize("key,value", [("train_fraction", 0), ("train_fraction", 1.5),
                                       ("simulations_per_liver", -1),
                                       ("simulations_per_liver", 2.5)])
def test_the_config_refuses_knobs_out_of_range(key, value):
    with pytest.raises(ValueError, match=key):
        get_config("population_basis", **{key: value})
