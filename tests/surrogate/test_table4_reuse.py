"""make table4's resume (bench/table4.py: train): a finished run is reused only for the same
config and as many simulations as the dataset holds now; its generation going on (or another
config) trains it again."""

import json
import sys
from pathlib import Path

import surrogate.train

sys.path.insert(0, str(Path(__file__).parents[2] / "bench"))
import table4  # noqa: E402


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

    def shards(n):
        for i in range(n):
            (data / "sims" / f"sim_{i:06d}.h5").touch()

    shards(4)
    assert table4.train(data, run, "small", {"folds": 2})["calls"] == 1
    assert table4.train(data, run, "small", {"folds": 2})["calls"] == 1  # reused
    assert table4.train(data, run, "small", {"folds": 3})["calls"] == 2  # another config
    shards(6)  # the generation went on
    m = table4.train(data, run, "small", {"folds": 3})
    assert (m["calls"], m["n_simulations"]) == (3, 6)
    assert table4.train(data, run, "small", {"folds": 3})["calls"] == 3
    # a run from before the count was kept beside it: its metrics' simulations stand in
    (run / "table4_data.json").unlink()
    assert table4.train(data, run, "small", {"folds": 3})["calls"] == 3
    shards(7)
    assert table4.train(data, run, "small", {"folds": 3})["calls"] == 4


def test_the_point_past_the_budget_starts_from_the_rows_dataset_without_touching_it(tmp_path):
    data = tmp_path / "scene" / "data"
    (data / "sims").mkdir(parents=True)
    (data / "geometry").mkdir()
    (data / "scene.toml").write_text("the scene")
    (data / "geometry" / "g1.h5").write_text("liver 1")
    for i in range(5):
        (data / "sims" / f"sim_{i:06d}.h5").write_text(f"shard {i}")
        (data / "sims" / f"sim_{i:06d}.xdmf").write_text(f"shard {i}'s XDMF")
    more = table4.extended(data, 8)
    assert more == tmp_path / "scene" / "beyond_8" / "data"
    # a shard without its XDMF is not done for generate: both are there
    assert sorted(p.name for p in (more / "sims").iterdir()) == \
        sorted(f"sim_{i:06d}.{e}" for i in range(5) for e in ("h5", "xdmf"))
    assert (more / "sims" / "sim_000003.h5").read_text() == "shard 3"
    assert (more / "geometry" / "g1.h5").read_text() == "liver 1"
    assert (more / "scene.toml").read_text() == "the scene"
    # what generate then writes there stays there; a second call links nothing twice
    (more / "sims" / "sim_000005.h5").write_text("shard 5")
    assert table4.extended(data, 8) == more
    assert len(list((data / "sims").iterdir())) == 10
    assert len(list((more / "sims").iterdir())) == 11
    # the learning curve's smaller views link the same way
    view = table4.subset(data, 2)
    assert sorted(p.name for p in (view / "sims").iterdir()) == \
        sorted(f"sim_{i:06d}.{e}" for i in range(2) for e in ("h5", "xdmf"))


def test_a_point_past_the_budget_at_the_papers_size_is_reported_as_measured_not_extrapolated():
    """Scene 2's row (600 simulations) is short of the paper's skill 0.085; a point past the
    budget at the paper's 1,500 names the paper's size and its best design's measured skill
    (the shortfall cites it); a point short of the paper's size keeps the curve's
    extrapolation."""
    def metrics(n, skill):
        return {"n_simulations": n, "skill": skill, "network": {"mee": 10 * skill}}

    def point(sims, skill, other):
        return {"sims": sims, "overrides": {"folds": 5}, "run": "run", "config": "basis",
                "curve_predicted": 0.05, "metrics": metrics(sims, skill),
                "side_by_side": [{"config": "paper_scene2", "metrics": metrics(sims, other)}]}

    row = {"sims": 600, "config": "basis", "metrics": metrics(600, 0.088),
           "skill_at_paper_size": 0.045, "side_by_side": [],
           "curve": [{"train_sims": 100, "skill": 0.23}, {"train_sims": 200, "skill": 0.14},
                     {"train_sims": 480, "skill": 0.088}]}
    full, part = point(1500, 0.061, 0.070), point(1000, 0.07, 0.09)
    text = table4.beyond_note(2, row, full)
    assert "This is the paper's size: the best design, reduced basis (`basis`), has skill " \
           "0.061 against the paper's 0.085; the paper's network, node-wise (`paper_scene2`), " \
           "0.070 (10 folds there, 5 here" in text
    assert "extrapolates" not in text
    assert "extrapolates to" in table4.beyond_note(2, row, part)
    # the side design wins: it is the one named
    assert "best design, node-wise (`paper_scene2`), has skill 0.050 against the paper's " \
           "0.085 (10" in table4.beyond_note(2, row, point(1500, 0.061, 0.050))
    assert "measured at the paper's" not in table4.shortfall(2, {**row, "beyond": [part]})[0]
    assert "measured at the paper's 1,500 simulations (past the budget, below), reduced " \
           "basis (`basis`) has skill 0.061: more simulations close the gap" in \
        table4.shortfall(2, {**row, "beyond": [part, full]})[0]
    assert "has skill 0.090: more simulations alone do not close it" in \
        table4.shortfall(2, {**row, "beyond": [point(1500, 0.09, 0.1)]})[0]


def test_a_liver_is_registered_once_per_shape_model(tmp_path, monkeypatch):
    import types

    import numpy as np

    import surrogate.predict_liver as pl

    calls = []
    monkeypatch.setattr(pl, "read_liver_surface", lambda path: (np.zeros((3, 3)), np.zeros(
        (1, 3), int)))
    monkeypatch.setattr(pl, "place_liver", lambda pred, p, t, frame: (
        calls.append(frame) or (f"placement {len(calls)}", [f"warning {len(calls)}"])))
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
    first = table4.place_unseen(a, liver, "LPS")
    assert table4.place_unseen(b, liver, "LPS") == first and len(calls) == 1
    table4.place_unseen(a, liver, "RAS")  # another frame
    table4.place_unseen(model(-1.0), liver, "LPS")  # other ranges: other warnings
    assert calls == ["LPS", "RAS", "LPS"]
    found = table4.place_unseen(a, liver, "LPS")[1]
    found.append("the caller's own")  # a caller's list is its own
    assert table4.place_unseen(a, liver, "LPS")[1] == ["warning 1"]
