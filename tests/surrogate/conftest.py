from pathlib import Path

import pytest

from tests.fixtures import synthetic_dataset

ROOT = Path(__file__).parents[2]


@pytest.fixture(scope="session")
def synth_dir(tmp_path_factory):
    """A synthetic scene-1-like dataset (40 simulations on a 5^3 box, 3 load steps)."""
    d = tmp_path_factory.mktemp("synth")
    synthetic_dataset(d, n_sims=40, n=5, n_steps=3)
    return d
