"""Issue 81's probes of the small-strain files (``fem_sim linear``'s ``linear.h5``, a
population's ``linear/``): one of another scene was added to a dataset and read as its own,
a truncated one validated, a bad shard or argument gave a traceback or left a mesh behind.
Each test failed on the code before the fix."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import h5py
import numpy as np
import pytest

from data_spec import validate_dataset
from data_spec.linear_fields import linear_fields_path, read_dataset_linear
from tests.fixtures import synthetic_dataset

ROOT = Path(__file__).parents[2]
SCENES = ROOT / "data_spec" / "scenes"
TINY = SCENES / "tiny_scene1.toml"


def _linear(*args):
    return subprocess.run([sys.executable, "-m", "fem_sim", "linear", *map(str, args)],
                          capture_output=True, text=True, timeout=600, cwd=ROOT)


def _listing(d: Path) -> dict:
    return {str(p.relative_to(d)): p.read_bytes() for p in sorted(d.rglob("*")) if p.is_file()}


@pytest.fixture(scope="module")
def liver_dir(tmp_path_factory):
    """The tiny scene's liver and its small-strain responses (``fem_sim linear``, 2 s)."""
    pytest.importorskip("dolfinx", reason="fem_sim linear runs in the solver environment")
    d = tmp_path_factory.mktemp("linear") / "data"
    proc = _linear(TINY, "--out", d, "--green")
    assert proc.returncode == 0, proc.stderr
    return d


def test_linear_refuses_a_dataset_of_another_scene_and_writes_nothing(tmp_path):
    """fem_sim linear of another scene's liver into a dataset added its linear.h5 and its
    geometry and edited meshes.json; validate then said "valid"."""
    pytest.importorskip("dolfinx", reason="fem_sim linear runs in the solver environment")
    d = synthetic_dataset(tmp_path / "data", scene_file=SCENES / "ci_scene1.toml")
    before = _listing(d)
    proc = _linear(TINY, "--out", d, "--green")
    assert proc.returncode == 2 and "Traceback" not in proc.stderr, proc.stderr
    assert "holds a dataset of scene 'ci_scene1'" in proc.stderr
    assert "not of" in proc.stderr and "'tiny_scene1'" in proc.stderr
    assert _listing(d) == before


def test_a_liver_directory_records_its_scene_and_validates(liver_dir):
    assert (liver_dir / "scene.toml").exists()
    assert validate_dataset(liver_dir) == []
    assert read_dataset_linear(liver_dir).green is not None


def _copy(src: Path, dst: Path) -> Path:
    import shutil

    shutil.copytree(src, dst)
    return dst


def test_another_scenes_file_is_refused_by_readers_and_validate(liver_dir, tmp_path):
    """The scene the file was made for against the directory's: both named."""
    d = _copy(liver_dir, tmp_path / "d")
    with h5py.File(linear_fields_path(d), "r+") as f:
        f.attrs["scene_hash"] = "f" * 64
        f.attrs["scene_name"] = "elsewhere"
    with pytest.raises(ValueError, match=r"made for scene 'elsewhere' \(hash ffffffffffff\), "
                                         r"but .* holds scene 'tiny_scene1'"):
        read_dataset_linear(d)
    (problem,) = validate_dataset(d)
    assert "another scene's responses" in problem and str(linear_fields_path(d)) in problem


def test_a_truncated_or_nan_file_is_not_valid(liver_dir, tmp_path):
    """validate never opened linear.h5: a truncated one reported "valid"."""
    d = _copy(liver_dir, tmp_path / "d")
    with h5py.File(linear_fields_path(d), "r+") as f:
        u = f["displacement"][...]
        u[0, 0, 0] = np.nan
        f["displacement"][...] = u
    assert any("'displacement' contains NaN" in p for p in validate_dataset(d))
    path = linear_fields_path(d)
    path.write_bytes(path.read_bytes()[: path.stat().st_size // 3])
    (problem,) = validate_dataset(d)
    assert problem.startswith(f"{path}: cannot be read (truncated or corrupt?)")
    with pytest.raises(ValueError, match="cannot be read"):
        read_dataset_linear(d)


def test_a_population_file_of_another_liver_is_named(liver_dir, tmp_path):
    """A population's linear/<geometry id>.h5 holding another liver's responses."""
    d = _copy(liver_dir, tmp_path / "d")
    (d / "linear").mkdir()
    linear_fields_path(d).rename(linear_fields_path(d, "g0000000000000000"))
    with pytest.raises(ValueError, match="named for liver g0000000000000000 but holds liver"):
        read_dataset_linear(d, "g0000000000000000")


def test_bad_arguments_are_refused_before_anything_is_meshed(tmp_path):
    """--synthetic -5 left a mesh cache behind; an --out under a file gave a traceback."""
    pytest.importorskip("dolfinx", reason="fem_sim linear runs in the solver environment")
    proc = _linear(TINY, "--out", tmp_path / "d", "--synthetic", "-5")
    assert proc.returncode == 2 and "--synthetic: expected a whole number >= 0" in proc.stderr
    assert not (tmp_path / "d").exists()
    (tmp_path / "file").write_text("x")
    proc = _linear(TINY, "--out", tmp_path / "file" / "d")
    assert proc.returncode == 2 and "is a file, not a directory" in proc.stderr
    assert "Traceback" not in proc.stderr


def test_a_truncated_shard_is_named_by_linear_population(tmp_path):
    """fem_sim linear --population on a truncated shard named no file."""
    pytest.importorskip("dolfinx", reason="fem_sim linear runs in the solver environment")
    d = synthetic_dataset(tmp_path / "data", n_sims=2)
    shard = sorted((d / "sims").glob("sim_*.h5"))[1]
    shard.write_bytes(shard.read_bytes()[:2000])
    proc = _linear("--population", d)
    assert proc.returncode == 2 and "Traceback" not in proc.stderr, proc.stderr
    assert f"{shard}: cannot be read" in proc.stderr and "data_spec validate" in proc.stderr


@pytest.mark.parametrize("command", [
    ["-m", "fem_sim", "population", str(SCENES / "ci_scene4.toml"), "--out"],
    ["-m", "fem_sim", "phantom", "0", "--out"]])
def test_population_and_phantom_refuse_an_out_under_a_file_first(tmp_path, command):
    pytest.importorskip("gmsh", reason="fem_sim runs in the solver environment")
    (tmp_path / "file").write_text("x")
    out = tmp_path / "file" / ("d" if "population" in command else "l.h5")
    proc = subprocess.run([sys.executable, *command, str(out)], capture_output=True, text=True,
                          timeout=120, cwd=ROOT)
    assert proc.returncode == 2 and "is a file, not a directory" in proc.stderr, proc.stderr
    assert "Traceback" not in proc.stderr
