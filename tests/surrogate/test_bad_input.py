"""The trainer refuses bad settings and bad data with messages that name the key or the file,
before any training, and leaves nothing behind."""

import math
import shutil

import h5py
import numpy as np
import pytest

from data_spec import list_shards
from surrogate.__main__ import main
from surrogate.config import get_config


def test_every_bad_setting_is_listed_at_once():
    with pytest.raises(ValueError) as err:
        get_config("small", epochs=0, node_fraction=0, dtype="float16", stream="maybe",
                   learning_rate=math.nan, batch_size=0, folds=1, colour="red")
    msg = str(err.value)
    for expected in ("unknown config key 'colour'", "epochs: expected an integer >= 1, got 0",
                     "node_fraction: expected a number in (0, 1], got 0",
                     "dtype: expected 'float32'", "stream: expected true, false or 'auto'",
                     "learning_rate: expected a finite number > 0, got nan",
                     "batch_size: expected an integer >= 1, got 0",
                     "folds: expected an integer >= 2"):
        assert expected in msg, (expected, msg)


def test_command_line_refuses_malformed_overrides(synth_dir, tmp_path, capsys):
    assert main(["train", "--data", str(synth_dir), "--run", str(tmp_path / "r"),
                 "epochs"]) == 2
    assert "overrides are key=value, got ['epochs']" in capsys.readouterr().err
    assert main(["train", "--data", str(synth_dir), "--run", str(tmp_path / "r"),
                 "learning_rate=nan"]) == 2
    assert "learning_rate: expected a finite number > 0" in capsys.readouterr().err
    (tmp_path / "file").write_text("x")
    assert main(["train", "--data", str(synth_dir), "--run", str(tmp_path / "file")]) == 2
    assert "is a file, not a directory" in capsys.readouterr().err
    assert not (tmp_path / "r").exists()


def test_corrupt_or_all_failed_dataset_is_named_and_leaves_no_run(synth_dir, tmp_path, capsys):
    data = tmp_path / "data"
    shutil.copytree(synth_dir, data)
    bad = list_shards(data)[3]
    bad.write_bytes(bad.read_bytes()[:2000])
    assert main(["train", "--data", str(data), "--run", str(tmp_path / "r")]) == 2
    err = capsys.readouterr().err
    assert f"{bad}: cannot be read" in err and "data_spec validate" in err
    assert not (tmp_path / "r").exists()
    # every simulation failed before its first step
    for p in list_shards(data):
        if p == bad:
            p.unlink()
            continue
        with h5py.File(p, "a") as f:
            f.attrs["status"] = "failed"
            f.attrs["failure_reason"] = "test"
            for name in ("displacement", "solver/newton_iterations", "solver/residual_norms",
                         "solver/cutbacks", "solver/wall_time"):
                shape = f[name].shape
                del f[name]
                f.create_dataset(name, data=np.zeros((0, *shape[1:]), dtype=np.float64))
            del f["solver/residual_offsets"]
            f["solver/residual_offsets"] = np.zeros(1, np.int64)
            from data_spec.shard_layout import checksum, read_values

            f.attrs["checksum"] = checksum(read_values(f))
    assert main(["train", "--data", str(data), "--run", str(tmp_path / "r")]) == 2
    assert "has a converged load step" in capsys.readouterr().err
    assert not (tmp_path / "r").exists()


def test_basis_design_on_a_many_liver_scene_is_refused_before_any_work(tmp_path, capsys):
    from pathlib import Path

    data = tmp_path / "data"
    data.mkdir()
    scenes = Path(__file__).parents[2] / "data_spec" / "scenes"
    shutil.copy(scenes / "scene4_phantoms.toml", data / "scene.toml")
    assert main(["train", "--data", str(data), "--run", str(tmp_path / "r"),
                 "--config", "basis"]) == 2
    assert "design 'basis' needs a scene with one liver" in capsys.readouterr().err
    assert not (tmp_path / "r").exists()


def test_the_trainer_says_which_simulations_are_missing(tmp_path):
    """11 of the scene's 12 simulations there: the trainer trains on them and says which one
    is missing, pointing at the validator."""
    from surrogate.config import get_config
    from surrogate.train import train_and_evaluate
    from tests.fixtures import synthetic_dataset

    d = synthetic_dataset(tmp_path / "d", n_sims=12)
    for p in (d / "sims").glob("sim_000004.*"):
        p.unlink()
    lines = []
    cfg = get_config("small", folds=2, epochs=1, final_fit=False, hidden=[8])
    result = train_and_evaluate(d, tmp_path / "run", cfg, log_fn=lines.append)
    assert result["n_simulations"] == 11
    assert any("warning: 1 of the scene's simulations have no shard (simulation 4)" in line
               for line in lines), lines
