"""One training engine for every design: a killed training resumes where it stopped and ends
where an uninterrupted one ends."""

import json
import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

from surrogate import engine
from surrogate.config import get_config
from surrogate.data import load_dataset
from surrogate.train import fit_design


class Killed(Exception):
    pass


class KilledAfter(engine.Checkpoint):
    """A checkpoint whose process dies right after saving epoch ``epoch``."""

    def __init__(self, directory, identity, epoch):
        super().__init__(directory, identity)
        self.kill_at = epoch

    def save(self, tree, meta):
        super().save(tree, meta)
        if meta["epoch"] == self.kill_at:
            raise Killed(meta["epoch"])


@pytest.mark.parametrize("design, overrides", [
    ("small", {"hidden": [16, 16], "epochs": 5, "early_stopping": 10, "batch_size": 256}),
    ("basis", {"hidden": [16], "modes": 8, "epochs": 6, "early_stopping": 10,
               "batch_size": 16, "ensemble": 1}),
])
def test_killed_fit_resumes_and_ends_where_an_uninterrupted_fit_ends(synth_dir, tmp_path,
                                                                      design, overrides):
    ds = load_dataset(synth_dir, stream=False)
    cfg = get_config(design, **overrides)
    train = np.arange(ds.n_samples - 9)
    whole, hist = fit_design(ds, train, cfg, 3, "", lambda m: None)
    ck = engine.Checkpoint(tmp_path / "ck", "id")
    with pytest.raises(Killed):
        fit_design(ds, train, cfg, 3, "", lambda m: None, KilledAfter(ck.dir, "id", 2))
    assert json.loads(ck.meta_file.read_text())["epoch"] == 2
    said = []
    resumed, hist2 = fit_design(ds, train, cfg, 3, "", said.append, ck)
    assert said[0].startswith("resumed after epoch 2"), said[0]
    assert [h["epoch"] for h in hist2] == [h["epoch"] for h in hist]
    # the first two epochs were another process's: a run's cost counts them
    assert [bool(h.get("earlier")) for h in hist2] == [True, True] + [False] * (len(hist) - 2)
    np.testing.assert_allclose([h["val_loss"] for h in hist2], [h["val_loss"] for h in hist],
                               rtol=1e-4)
    _assert_same_params(resumed[0] if design == "small" else resumed.params,
                        whole[0] if design == "small" else whole.params)


def test_a_killed_ensemble_resumes_member_by_member(synth_dir, tmp_path, monkeypatch):
    """The shipped basis is an ensemble: killed in its second member's third epoch, the
    resumed fit takes the first member from its finished checkpoint, the second from its
    epoch 2, trains the third, and ends with the parameters of an uninterrupted fit."""
    ds = load_dataset(synth_dir, stream=False)
    cfg = get_config("basis", hidden=[16], modes=8, epochs=4, early_stopping=10, batch_size=16,
                     ensemble=3)
    assert get_config("basis")["ensemble"] > 1  # what this test is for
    train = np.arange(ds.n_samples - 9)
    whole, _ = fit_design(ds, train, cfg, 3, "", lambda m: None)
    save = engine.Checkpoint.save

    def dying(self, tree, meta):
        save(self, tree, meta)
        if self.dir.name == "member1" and meta["epoch"] == 2:
            raise Killed(meta["epoch"])

    ck = engine.Checkpoint(tmp_path / "ck", "id")
    monkeypatch.setattr(engine.Checkpoint, "save", dying)
    with pytest.raises(Killed):
        fit_design(ds, train, cfg, 3, "", lambda m: None, ck)
    monkeypatch.setattr(engine.Checkpoint, "save", save)
    said = []
    resumed, _ = fit_design(ds, train, cfg, 3, "", said.append, ck)
    resumes = [s for s in said if "resumed after" in s]
    assert len(resumes) == 2, said
    assert "member 1/3 resumed after epoch 4" in resumes[0], resumes
    assert "member 2/3 resumed after epoch 2" in resumes[1], resumes
    _assert_same_params(resumed.params, whole.params)


class KilledBetween(engine.Checkpoint):
    """A checkpoint whose process dies while saving epoch ``epoch``: after the new state is on
    disk but before ``state.json`` names it ("state"), or after that but before the states it
    no longer names are removed ("cleanup")."""

    def __init__(self, directory, identity, epoch, where):
        super().__init__(directory, identity)
        self.kill_at, self.where = epoch, where

    def _write_meta(self, meta):
        if meta["epoch"] == self.kill_at and self.where == "state":
            raise Killed(meta["epoch"])
        super()._write_meta(meta)
        if meta["epoch"] == self.kill_at and self.where == "cleanup":
            raise Killed(meta["epoch"])


@pytest.mark.parametrize("where, resumed_after", [("state", 2), ("cleanup", 3)])
def test_a_kill_in_the_middle_of_a_save_leaves_a_loadable_checkpoint(synth_dir, tmp_path,
                                                                     where, resumed_after):
    ds = load_dataset(synth_dir, stream=False)
    cfg = get_config("small", hidden=[8], epochs=5, early_stopping=10, batch_size=256)
    train = np.arange(ds.n_samples - 9)
    whole, hist = fit_design(ds, train, cfg, 1, "", lambda m: None)
    ck = tmp_path / "ck"
    with pytest.raises(Killed):
        fit_design(ds, train, cfg, 1, "", lambda m: None, KilledBetween(ck, "id", 3, where))
    # "state": epoch 3's state and epoch 2's, which state.json still names, are both on disk
    assert len(list(ck.glob("state-*.msgpack"))) == 2
    said = []
    resumed, hist2 = fit_design(ds, train, cfg, 1, "", said.append,
                                engine.Checkpoint(ck, "id"))
    assert said[0].startswith(f"resumed after epoch {resumed_after}"), said[0]
    assert [h["epoch"] for h in hist2] == [h["epoch"] for h in hist]
    np.testing.assert_allclose([h["val_loss"] for h in hist2], [h["val_loss"] for h in hist],
                               rtol=1e-4)
    assert len(list(ck.glob("state-*.msgpack"))) == 1  # the states no longer named are gone


def test_a_checkpoint_whose_state_is_missing_is_not_used(synth_dir, tmp_path):
    ds = load_dataset(synth_dir, stream=False)
    cfg = get_config("small", hidden=[8], epochs=2, batch_size=256)
    train = np.arange(ds.n_samples - 9)
    fit_design(ds, train, cfg, 0, "", lambda m: None, engine.Checkpoint(tmp_path, "id"))
    for f in tmp_path.glob("state-*.msgpack"):
        f.unlink()
    said = []
    fit_design(ds, train, cfg, 0, "", said.append, engine.Checkpoint(tmp_path, "id"))
    assert not any("resumed" in m for m in said)


def _leaves(tree):
    import jax

    return [np.asarray(x) for x in jax.tree_util.tree_leaves(tree)]


def _assert_same_params(got, expected):
    """Two parameter trees equal to float32 training noise (a resumed fit against an
    uninterrupted one)."""
    flat_e = np.concatenate([np.ravel(v) for v in _leaves(expected)])
    flat_g = np.concatenate([np.ravel(v) for v in _leaves(got)])
    np.testing.assert_allclose(flat_g, flat_e, rtol=1e-4, atol=1e-6 * np.abs(flat_e).max())


def test_checkpoint_of_another_configuration_is_not_used(synth_dir, tmp_path):
    ds = load_dataset(synth_dir, stream=False)
    cfg = get_config("small", hidden=[8], epochs=3, batch_size=256)
    train = np.arange(ds.n_samples - 9)
    fit_design(ds, train, cfg, 0, "", lambda m: None, engine.Checkpoint(tmp_path, "one"))
    said = []
    fit_design(ds, train, cfg, 0, "", said.append, engine.Checkpoint(tmp_path, "two"))
    assert not any("resumed" in m for m in said)
    assert json.loads((tmp_path / "state.json").read_text())["identity"] == "two"


@pytest.mark.slow
def test_a_training_killed_by_sigkill_resumes_from_the_command_line(synth_dir, tmp_path):
    """The real thing: `python -m surrogate train` killed with SIGKILL during the second fold,
    run again: it reports the first fold done and resumes the second, and finishes with the
    metrics of a run never interrupted."""
    run = tmp_path / "run"
    cmd = [sys.executable, "-m", "surrogate", "train", "--data", str(synth_dir), "--run",
           str(run), "--config", "small", "hidden=[16,16]", "epochs=60", "folds=3",
           "early_stopping=100", "batch_size=512", "final_fit=false"]
    # 60 epochs of several ms each: the second fold is still training when the kill lands
    env = {**os.environ, "JAX_PLATFORMS": "cpu"}
    proc = subprocess.Popen(cmd, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    target = run / "checkpoints" / "fold1" / "state.json"
    deadline = time.monotonic() + 300
    while not target.exists() and proc.poll() is None and time.monotonic() < deadline:
        time.sleep(0.05)
    assert proc.poll() is None, proc.communicate()[1].decode()[-2000:]
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    again = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=600)
    assert again.returncode == 0, again.stderr[-2000:]
    assert "fold 1/3 done before" in again.stderr
    assert "fold 2/3 resumed after epoch" in again.stderr
    assert not (run / "checkpoints").exists()  # removed once the run is complete
    resumed = json.loads((run / "metrics.json").read_text())
    fresh = subprocess.run(cmd[:7] + [str(tmp_path / "clean")] + cmd[8:], env=env,
                           capture_output=True, text=True, timeout=600)
    assert fresh.returncode == 0, fresh.stderr[-2000:]
    clean = json.loads((tmp_path / "clean" / "metrics.json").read_text())
    assert resumed["network"]["mee"] == pytest.approx(clean["network"]["mee"], rel=1e-3)
    # the run's cost counts the epochs the killed process trained (fold 1, part of fold 2)
    history = json.loads((run / "history.json").read_text())
    earlier = sum(h["seconds"] for f in history.values() for h in f if h.get("earlier"))
    assert earlier >= sum(h["seconds"] for h in history["fold0"]) > 0
    assert resumed["total_seconds"] >= resumed["training_seconds"] > earlier
