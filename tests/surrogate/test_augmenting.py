"""Phantoms mixed into a population of liver files (geometry.phantoms) are augmentation: no
fold holds one out, every fold trains on them unless ``phantoms_in_training`` is false."""

from types import SimpleNamespace

import numpy as np

from surrogate.data import augmenting_geometries, kfold_groups, training_samples


def _dataset(augmenting=frozenset()):
    """8 livers (p0, p1 phantoms; f0..f5 files), 3 simulations of 2 samples each."""
    ids = ["p0", "p1"] + [f"f{i}" for i in range(6)]
    geo = np.repeat(np.arange(8), 6)
    return SimpleNamespace(geo_ids=ids, sample_geo=geo, sample_sim=np.arange(geo.size) // 2,
                           n_samples=geo.size, spec=SimpleNamespace(geometry_dim=4),
                           augmenting=frozenset(augmenting))


def test_phantoms_are_in_no_fold_and_in_every_training_set_unless_left_out():
    ds = _dataset({"p0", "p1"})
    folds = kfold_groups(ds, 3, seed=0)
    held = np.concatenate(folds)
    phantom_samples = np.flatnonzero(ds.sample_geo < 2)
    assert not np.isin(phantom_samples, held).any()
    assert np.array_equal(np.sort(held), np.flatnonzero(ds.sample_geo >= 2))  # every file once
    for f in folds:
        with_p = training_samples(ds, f, {"phantoms_in_training": True})
        without = training_samples(ds, f, {"phantoms_in_training": False})
        assert np.isin(phantom_samples, with_p).all()
        assert not np.isin(phantom_samples, without).any()
        assert np.array_equal(np.setdiff1d(with_p, phantom_samples), without)
        assert not np.isin(f, with_p).any()


def test_without_phantoms_the_folds_are_over_every_liver():
    ds = _dataset()
    held = np.sort(np.concatenate(kfold_groups(ds, 4, seed=0)))
    assert np.array_equal(held, np.arange(ds.n_samples))
    assert np.array_equal(training_samples(ds, held[:6], {"phantoms_in_training": False}),
                          np.arange(6, ds.n_samples))


def test_the_augmenting_phantoms_are_the_populations_first_livers(tmp_path):
    (tmp_path / "geometry").mkdir()
    np.savez(tmp_path / "geometry" / "population.npz", geometry_ids=np.array(["a", "b", "c"]))
    mixed = {"geometry": {"livers": "x", "phantoms": 2}}
    assert augmenting_geometries(tmp_path, mixed) == {"a", "b"}
    assert augmenting_geometries(tmp_path, {"geometry": {"livers": "x"}}) == frozenset()
    # a population of phantoms alone: they are the population, not augmentation
    assert augmenting_geometries(tmp_path, {"geometry": {"population_size": 3}}) == frozenset()
