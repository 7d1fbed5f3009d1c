"""Item 10: a read-only output directory gives one clear message and nothing else; the work
is refused before it starts, not at its first write."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from tests.fixtures import synthetic_dataset
from tests.reliability.conftest import read_only

ROOT = Path(__file__).parents[2]


def test_generate_refuses_a_read_only_sims_directory_before_any_work(tmp_path):
    pytest.importorskip("dolfinx", reason="fem_sim runs in the solver environment")
    out = tmp_path / "out"
    (out / "sims").mkdir(parents=True)
    scene = ROOT / "data_spec" / "scenes" / "tiny_scene1.toml"
    with read_only(out / "sims"):
        proc = subprocess.run([sys.executable, "-m", "fem_sim", "generate", str(scene),
                               "--out", str(out), "--no-progress"], capture_output=True,
                              text=True, timeout=300, cwd=ROOT)
    assert proc.returncode == 2, proc.stderr
    assert f"{out / 'sims'}: cannot create files there" in proc.stderr
    assert "Traceback" not in proc.stderr
    assert list((out / "sims").iterdir()) == []


def test_train_refuses_a_read_only_run_directory_before_training(tmp_path):
    pytest.importorskip("jax", reason="the trainer runs in the trainer environment")
    data = tmp_path / "data"
    synthetic_dataset(data, n_sims=4, n=3)
    run = tmp_path / "run"
    run.mkdir()
    with read_only(run):
        proc = subprocess.run([sys.executable, "-m", "surrogate", "train", "--data", str(data),
                               "--run", str(run), "epochs=1", "folds=2"], capture_output=True,
                              text=True, timeout=300, cwd=ROOT)
    assert proc.returncode == 2, proc.stderr
    assert f"{run}: cannot create files there" in proc.stderr
    assert "Traceback" not in proc.stderr and "epoch" not in proc.stderr
    assert list(run.iterdir()) == []


def test_summary_picture_goes_into_a_directory_it_creates(tmp_path):
    pytest.importorskip("dolfinx", reason="fem_sim runs in the solver environment")
    data = tmp_path / "data"
    synthetic_dataset(data, n_sims=2, n=3)
    png = tmp_path / "not" / "yet" / "there.png"
    proc = subprocess.run([sys.executable, "-m", "fem_sim", "summary", str(data), "--png",
                           str(png)], capture_output=True, text=True, timeout=300, cwd=ROOT)
    assert proc.returncode == 0, proc.stderr
    assert png.stat().st_size > 0
