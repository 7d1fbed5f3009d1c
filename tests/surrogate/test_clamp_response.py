"""The unseen-liver report's clamp fit (bench/unseen_frames.py): the per-liver response of a
dataset, and the power law through it, checked against values worked out by hand on a box."""

import sys
from pathlib import Path

import numpy as np

from data_spec.geometry import box_mesh
from data_spec.shards import list_shards, read_shard
from tests.fixtures import synthetic_dataset

sys.path.insert(0, str(Path(__file__).parents[2] / "bench"))
from unseen_frames import clamp_response, power_law  # noqa: E402


def test_clamp_response_of_a_dataset_by_hand(tmp_path):
    """One liver (a unit box, x0 fixed: area 1 mm^2, volume 1e-3 mL): the mean displacement is
    the shards' mean node norm, the distance each load node's x (the nearest point of x = 0)."""
    data = synthetic_dataset(tmp_path / "d", n_sims=4, n=3)
    (row,) = clamp_response(data)
    shards = [read_shard(p) for p in list_shards(data)]
    g = box_mesh(3)
    want_u = np.mean([np.linalg.norm(s.displacement, axis=-1).mean() for s in shards])
    want_d = np.mean([g.points[s.load_nodes[0], 0] for s in shards])
    np.testing.assert_allclose(row, [want_u, 1.0, want_d, 1e-3], rtol=1e-9)


def test_power_law_recovers_exponents_and_scatter_lowers_r2():
    rng = np.random.default_rng(1)
    X = rng.uniform(1.0, 100.0, size=(50, 3))
    y = 3.0 * X[:, 0] ** -0.7 * X[:, 1] ** 1.4 * X[:, 2] ** 0.2
    b, r2 = power_law(X, y)
    np.testing.assert_allclose(b, [np.log(3.0), -0.7, 1.4, 0.2], atol=1e-9)
    assert r2 > 1 - 1e-12
    b, r2 = power_law(X, y * np.exp(rng.normal(scale=0.5, size=50)))
    assert 0.3 < r2 < 0.99
