"""What a resumable study reuses: a finished run only for the same config and the
simulations the dataset holds now (surrogate.train.train_or_reuse); dataset views that link
another's shards (data_spec.views); a liver placed once per shape model (surrogate.evaluate)."""

import json

import h5py
import pytest

import surrogate.train
from data_spec import views
from surrogate import evaluate
from surrogate.train import train_all, train_or_reuse


def test_a_run_is_trained_again_when_the_dataset_grows_or_the_config_changes(tmp_path,
                                                                              monkeypatch):
    data, run = tmp_path / "data", tmp_path / "run"
    (data / "sims").mkdir(parents=True)
    calls = []

    def fake_train(d, r, cfg):  # what train_and_evaluate leaves: the config and the metrics
        calls.append(cfg)
        r.mkdir(exist_ok=True)
        (r / "config.json").write_text(json.dumps(cfg))
        n = len(list((d / "sims").glob("sim_*.h5")))
        (r / "metrics.json").write_text(json.dumps({"n_simulations": n, "calls": len(calls)}))

    monkeypatch.setattr(surrogate.train, "train_and_evaluate", fake_train)

    def shards(n, checksum="a"):
        for i in range(n):
            path = data / "sims" / f"sim_{i:06d}.h5"
            if not path.exists() or checksum != "a":
                with h5py.File(path, "w") as f:
                    f.attrs["checksum"] = f"{checksum}{i}"

    shards(4)
    assert train_or_reuse(data, run, "small", {"folds": 2})["calls"] == 1
    assert train_or_reuse(data, run, "small", {"folds": 2})["calls"] == 1  # reused
    assert train_or_reuse(data, run, "small", {"folds": 3})["calls"] == 2  # another config
    shards(6)  # the generation went on
    m = train_or_reuse(data, run, "small", {"folds": 3})
    assert (m["calls"], m["n_simulations"]) == (3, 6)
    assert train_or_reuse(data, run, "small", {"folds": 3})["calls"] == 3
    # a run from before the count was kept beside it: its metrics' simulations stand in
    (run / "trained_on.json").unlink()
    assert train_or_reuse(data, run, "small", {"folds": 3})["calls"] == 3
    shards(7)
    assert train_or_reuse(data, run, "small", {"folds": 3})["calls"] == 4
    shards(7, checksum="b")  # made again: as many simulations, other ones
    assert train_or_reuse(data, run, "small", {"folds": 3})["calls"] == 5
    assert train_or_reuse(data, run, "small", {"folds": 3})["calls"] == 5


def test_runs_trained_two_at_a_time_are_each_its_own_and_reused(tmp_path, monkeypatch):
    data = tmp_path / "data"
    (data / "sims").mkdir(parents=True)
    for i in range(3):
        with h5py.File(data / "sims" / f"sim_{i:06d}.h5", "w") as f:
            f.attrs["checksum"] = f"a{i}"

    def fake_train(d, r, cfg):
        r.mkdir(exist_ok=True)
        (r / "config.json").write_text(json.dumps(cfg))
        (r / "metrics.json").write_text(json.dumps({"n_simulations": 3, "skill": cfg["folds"],
                                                    "run": r.name}))

    monkeypatch.setattr(surrogate.train, "train_and_evaluate", fake_train)
    runs = {f"k{k}": (tmp_path / f"run{k}", "small", {"folds": k}) for k in (2, 3, 4)}
    first = train_all(data, runs, jobs=1)
    assert [(m["run"], m["skill"]) for m in first.values()] == [("run2", 2), ("run3", 3),
                                                                ("run4", 4)]
    # spawned processes do not see the fake: they can only reuse the finished runs, each its own
    assert train_all(data, runs, jobs=2) == first


def test_the_point_past_the_budget_starts_from_the_rows_dataset_without_touching_it(tmp_path):
    data = tmp_path / "scene" / "data"
    (data / "sims").mkdir(parents=True)
    (data / "geometry").mkdir()
    (data / "scene.toml").write_text("the scene")
    (data / "geometry" / "g1.h5").write_text("liver 1")
    for i in range(5):
        (data / "sims" / f"sim_{i:06d}.h5").write_text(f"shard {i}")
        (data / "sims" / f"sim_{i:06d}.xdmf").write_text(f"shard {i}'s XDMF")
    more = views.extension(data, 5, tmp_path / "scene" / "beyond_8" / "data")
    assert more == tmp_path / "scene" / "beyond_8" / "data"
    # a shard without its XDMF is not done for generate: both are there
    assert sorted(p.name for p in (more / "sims").iterdir()) == \
        sorted(f"sim_{i:06d}.{e}" for i in range(5) for e in ("h5", "xdmf"))
    assert (more / "sims" / "sim_000003.h5").read_text() == "shard 3"
    assert (more / "geometry" / "g1.h5").read_text() == "liver 1"
    assert (more / "scene.toml").read_text() == "the scene"
    # what generate then writes there stays there; a second call links nothing twice
    (more / "sims" / "sim_000005.h5").write_text("shard 5")
    assert views.extension(data, 5, more) == more
    assert len(list((data / "sims").iterdir())) == 10
    assert len(list((more / "sims").iterdir())) == 11
    # the learning curve's smaller views link the same way
    view = views.first(data, 2)
    assert sorted(p.name for p in (view / "sims").iterdir()) == \
        sorted(f"sim_{i:06d}.{e}" for i in range(2) for e in ("h5", "xdmf"))


def test_a_liver_is_registered_once_per_shape_model(tmp_path, monkeypatch):
    import types

    import numpy as np

    import surrogate.predict_liver as pl

    calls = []
    monkeypatch.setattr(pl, "read_liver_surface", lambda path: (np.zeros((3, 3)), np.zeros(
        (1, 3), int)))
    monkeypatch.setattr(pl, "place_liver", lambda pred, p, t, frame: (
        calls.append(frame) or (types.SimpleNamespace(made=len(calls)),
                                [f"warning {len(calls)}"])))
    liver = tmp_path / "liver.stl"
    liver.write_text("a liver")

    def model(lo):
        arrays = {k: np.arange(4.0) for k in (
            "template_points", "template_cells", "surface_triangles", "fixed_nodes", "mean",
            "components", "residuals", "schedule", "population_coefficients",
            "population_inverted", "population_fixed_area")}
        sm = types.SimpleNamespace(**arrays, coefficient_min=np.array([lo]),
                                   coefficient_max=np.array([1.0]), n_points=600)
        return types.SimpleNamespace(shape_model=sm)

    a, b = model(0.0), model(0.0)  # two designs of one dataset: the same shape model
    first = evaluate.place(a, liver, "LPS")
    assert evaluate.place(b, liver, "LPS") == first and len(calls) == 1
    evaluate.place(a, liver, "RAS")  # another frame
    evaluate.place(model(-1.0), liver, "LPS")  # other ranges: other warnings
    assert calls == ["LPS", "RAS", "LPS"]
    found = evaluate.place(a, liver, "LPS")[1]
    found.append("the caller's own")  # a caller's list is its own
    assert evaluate.place(a, liver, "LPS")[1] == ["warning 1"]


def test_a_view_without_some_livers_links_the_other_livers_simulations(tmp_path, monkeypatch):
    import types

    import data_spec.shards

    data = tmp_path / "data"
    (data / "sims").mkdir(parents=True)
    (data / "geometry").mkdir()
    (data / "scene.toml").write_text("the scene")
    on = {}
    for i, gid in enumerate(["g1", "g2", "g1", "g3"]):
        (data / "sims" / f"sim_{i:06d}.h5").write_text(f"shard {i}")
        (data / "sims" / f"sim_{i:06d}.xdmf").write_text(f"shard {i}'s XDMF")
        on[f"sim_{i:06d}.h5"] = gid
    monkeypatch.setattr(data_spec.shards, "read_shard",
                        lambda p: types.SimpleNamespace(geometry_id=on[p.name]))
    view = views.without(data, ["g1"], tmp_path / "view")
    assert sorted(p.name for p in (view / "sims").iterdir()) == \
        sorted(f"sim_{i:06d}.{e}" for i in (1, 3) for e in ("h5", "xdmf"))
    assert (view / "scene.toml").read_text() == "the scene"
    assert (view / "geometry").resolve() == (data / "geometry").resolve()
    assert not (view / "linear").exists()   # the data has no small-strain responses
    assert len(list((data / "sims").iterdir())) == 8   # nothing moved
    (data / "linear").mkdir()   # fem_sim linear --population: a view made then links them
    assert (views.without(data, ["g1"], tmp_path / "view2") / "linear").resolve() == \
        (data / "linear").resolve()
    # made again without another liver: the earlier view's links follow
    views.without(data, ["g3"], view)
    assert sorted(p.name for p in (view / "sims").iterdir()) == \
        sorted(f"sim_{i:06d}.{e}" for i in (0, 1, 2) for e in ("h5", "xdmf"))
    with pytest.raises(ValueError, match="g9"):
        views.without(data, ["g9"], tmp_path / "other")
