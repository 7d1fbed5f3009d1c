import os
from pathlib import Path

import pytest

from tests.fixtures import synthetic_dataset

ROOT = Path(__file__).parents[2]


def generated_dataset(variable: str) -> Path:
    """The fem_sim dataset named by the environment ``variable`` (make test generates it in
    the solver environment and sets the variable). Missing, the test fails: a run outside
    make test deselects these tests with -m 'not dataset' rather than passing without them.
    """
    d = os.environ.get(variable)
    if not d:
        pytest.fail(f"{variable} not set: make test generates the fem_sim dataset this test "
                    "needs; deselect the dataset tests with -m 'not dataset'")
    if not (Path(d) / "scene.toml").exists():
        pytest.fail(f"{variable}={d}: not a dataset (no scene.toml)")
    return Path(d)


@pytest.fixture(scope="session")
def synth_dir(tmp_path_factory):
    """A synthetic scene-1-like dataset (40 simulations on a 5^3 box, 3 load steps)."""
    d = tmp_path_factory.mktemp("synth")
    synthetic_dataset(d, n_sims=40, n=5, n_steps=3)
    return d
