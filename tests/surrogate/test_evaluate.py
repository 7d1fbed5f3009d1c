"""``liverfem-surrogate evaluate``: a model against a dataset of its liver it never trained on,
its metrics worked out again by hand from the predictor; bad requests refused with exit 2."""

import json

import numpy as np
import pytest

from data_spec import list_shards, read_shard
from surrogate import load_predictor
from surrogate.__main__ import main
from surrogate.config import get_config
from surrogate.train import train_and_evaluate
from tests.fixtures import synthetic_dataset


@pytest.fixture(scope="module")
def trained(tmp_path_factory):
    """A small model trained on 30 synthetic simulations, and 10 others of the same liver
    and scene it never saw (indices 30-39)."""
    root = tmp_path_factory.mktemp("evaluate")
    synthetic_dataset(root / "all", n_sims=40, n=5, n_steps=3)
    train_dir, held_dir = root / "train", root / "held"
    for d, keep in ((train_dir, range(30)), (held_dir, range(30, 40))):
        (d / "sims").mkdir(parents=True)
        (d / "geometry").symlink_to(root / "all" / "geometry")
        (d / "scene.toml").write_text((root / "all" / "scene.toml").read_text())
        for i in keep:
            for p in (root / "all" / "sims").glob(f"sim_{i:06d}.*"):
                (d / "sims" / p.name).symlink_to(p)
    cfg = get_config("small", folds=2, epochs=30, hidden=[64, 64])
    train_and_evaluate(train_dir, root / "run", cfg, log_fn=lambda m: None)
    return root / "run", held_dir


def test_the_metrics_are_the_predictors_against_the_shards(trained, tmp_path, capsys):
    run, held = trained
    out = tmp_path / "m.json"
    assert main(["evaluate", str(run), str(held), "--out", str(out)]) == 0
    m = json.loads(out.read_text())
    pred = load_predictor(run / "model")
    errors, truth = [], []
    for p in list_shards(held):
        sh = read_shard(p)
        forces = sh.load_fractions[:, None, None] * sh.forces[None]
        u = pred(forces, np.broadcast_to(sh.load_nodes, forces.shape[:2]))
        errors.append(np.linalg.norm(u - sh.displacement, axis=-1).ravel())
        truth.append(sh.displacement.reshape(-1, 3))
    truth = np.concatenate(truth)
    naive = np.linalg.norm(truth - truth.mean(axis=0), axis=1).mean()
    assert m["sims"] == 10
    assert m["network"]["mee"] == pytest.approx(np.concatenate(errors).mean(), rel=1e-4)
    assert m["naive"]["mee"] == pytest.approx(naive, rel=1e-6)
    assert m["skill"] == pytest.approx(m["network"]["mee"] / naive, rel=1e-6)
    assert m["skill"] < 0.8  # it learnt something the mean field does not have
    assert f"skill {m['skill']:.3f} on 10 simulations" in capsys.readouterr().out


def test_bad_requests_are_refused_before_any_work(trained, tmp_path, capsys):
    run, held = trained
    assert main(["evaluate", str(run), str(tmp_path / "nothing")]) == 2
    assert "not a valid dataset" in capsys.readouterr().err
    assert main(["truth-scene", str(run), str(held / "scene.toml"), "--scene",
                 str(held / "scene.toml"), "--out", str(tmp_path / "t.toml")]) == 2
    assert "not trained on a population" in capsys.readouterr().err
    assert not (tmp_path / "t.toml").exists()


def test_a_simulation_that_stopped_part_way_is_named_with_its_steps_and_reason():
    from types import SimpleNamespace

    from surrogate.evaluate import stopped_simulations

    ok = SimpleNamespace(sim_index=0, n_done=10, load_fractions=np.linspace(0.1, 1, 10),
                         status="ok", failure_reason="")
    stopped = SimpleNamespace(sim_index=3, n_done=2, load_fractions=np.linspace(0.1, 1, 10),
                              status="failed", failure_reason="Newton is not converging")
    assert stopped_simulations([ok]) == []
    assert stopped_simulations([ok, stopped]) == [
        {"sim": 3, "steps": 2, "of": 10, "reason": "Newton is not converging"}]
