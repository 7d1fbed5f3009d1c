"""The README's example of the trainer and the exported model is demos/predictor_api.py, run
here on the dataset make test generates, so the manual cannot rot."""

import subprocess
import sys
from pathlib import Path

import pytest

from tests.surrogate.conftest import generated_dataset

ROOT = Path(__file__).parents[2]


@pytest.mark.dataset
def test_the_predictor_demo_trains_loads_and_predicts(tmp_path):
    data = generated_dataset("LIVERFEM_TEST_DATASET")
    out = subprocess.run([sys.executable, str(ROOT / "demos" / "predictor_api.py"), str(data),
                          str(tmp_path / "run")], capture_output=True, text=True, timeout=900)
    assert out.returncode == 0, out.stderr[-2000:]
    assert "cross-validated skill" in out.stdout and "8 cases in one call" in out.stdout
    assert (tmp_path / "run" / "model" / "model.json").exists()
