"""fem_sim summary's picture: the dataset's range (largest, median, smallest maximum
displacement) drawn with pyvista in a process without dolfinx.
"""

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from fem_sim.batch.summary import range_cases
from tests.fixtures import synthetic_dataset

ROOT = Path(__file__).parents[2]


def test_the_range_cases_are_the_largest_the_median_and_the_smallest():
    cands = [(3.0, Path("c")), (1.0, Path("a")), (9.0, Path("e")), (2.0, Path("b")),
             (5.0, Path("d"))]
    assert range_cases(cands) == [("largest", Path("e")), ("median", Path("c")),
                                  ("smallest", Path("a"))]
    assert range_cases(cands[:1]) == [("largest", Path("c"))]
    assert range_cases([]) == []


def test_summary_draws_three_livers_with_pyvista(tmp_path):
    from PIL import Image

    data = tmp_path / "data"
    synthetic_dataset(data, n_sims=5, n=3)
    png = tmp_path / "summary.png"
    proc = subprocess.run([sys.executable, "-m", "fem_sim", "summary", str(data), "--png",
                           str(png)], capture_output=True, text=True, timeout=300, cwd=ROOT)
    assert proc.returncode == 0, proc.stderr
    img = np.asarray(Image.open(png).convert("RGB")).astype(int)
    assert img.shape[1] == 3 * 560  # three panels
    for k in range(3):  # a liver in each
        panel = img[:, k * 560:(k + 1) * 560]
        assert np.any(np.abs(panel - 255) > 30, axis=2).mean() > 0.03


def test_pictures_refuse_to_run_beside_dolfinx():
    import dolfinx  # noqa: F401

    from liverviz.pictures import pyvista

    with pytest.raises(RuntimeError, match="separate process"):
        pyvista()
