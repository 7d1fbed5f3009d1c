"""generate_chunks (the benches' driver of fem_sim generate): a dataset is grown in chunks, each
run over every shard from the first (so generate checks those already there), and a dataset
already complete is still handed to generate once (its shards may be of livers prepared
otherwise since)."""

import subprocess

import fem_sim.batch.chunked as chunked


def test_a_complete_dataset_is_checked_once_and_a_growing_one_per_chunk(tmp_path, monkeypatch):
    data = tmp_path / "d"
    (data / "sims").mkdir(parents=True)
    runs = []

    def fake_run(cmd, **kw):  # what generate leaves: shards 0..k
        upto = int(cmd[cmd.index("--only") + 1].split("..")[1])
        runs.append(cmd[cmd.index("--only") + 1])
        for i in range(upto):
            (data / "sims" / f"sim_{i:06d}.h5").touch()
        return subprocess.CompletedProcess(cmd, 0)

    monkeypatch.setattr(chunked.subprocess, "run", fake_run)
    assert chunked.generate_chunks("s.toml", data, 5, chunk=2)["sims"] == 5
    assert runs == ["0..2", "0..4", "0..5"]
    runs.clear()
    chunked.generate_chunks("s.toml", data, 5, chunk=2)  # complete: checked once
    assert runs == ["0..5"]
    runs.clear()
    chunked.generate_chunks("s.toml", data, 7, chunk=5)  # grown: its run checks the rest
    assert runs == ["0..7"]
    runs.clear()
    chunked.generate_chunks("s.toml", data, 7, chunk=5, budget_s=0.0)  # no time left
    assert runs == []


def test_a_liver_truth_of_another_scene_is_emptied_and_its_own_kept(tmp_path):
    """fem_sim.batch.chunked.liver_truth, the one FE truth of an unseen liver the benches
    share: the same scene keeps the data there (resumable); another scene (another
    placement) empties the data, the generation record and the named stale files first."""
    from fem_sim.batch.chunked import liver_truth

    d = tmp_path / "liver"
    data = liver_truth(d, "scene A", 3, generate=False)
    (data / "sims").mkdir(parents=True)
    (data / "sims" / "sim_000000.h5").write_text("x")
    for name in ("generation.json", "linear.json", "other.json"):
        (d / name).write_text("{}")
    assert liver_truth(d, "scene A", 3, generate=False) == data
    assert (data / "sims" / "sim_000000.h5").exists() and (d / "generation.json").exists()
    liver_truth(d, "scene B", 3, stale=("linear.json",), generate=False)
    assert (d / "scene.toml").read_text() == "scene B" and not data.exists()
    assert not (d / "generation.json").exists() and not (d / "linear.json").exists()
    assert (d / "other.json").exists()


def test_a_livers_small_strain_file_is_kept_only_when_it_holds_what_is_asked(tmp_path,
                                                                            monkeypatch):
    """linear_bases on a one-liver dataset (make patient's and make liver's fem_sim linear):
    a file of the same scene is kept when its order, its drawn loads and its Green's function
    cover what is asked; anything more runs fem_sim linear again with the flags asked, and
    the call returns its seconds."""
    import types

    import numpy as np

    import data_spec
    import data_spec.linear_fields as linear_fields

    data = tmp_path / "data"
    data.mkdir()
    (data / "linear.h5").touch()
    cases = np.r_[np.arange(4), linear_fields.SYNTHETIC_FIRST + np.arange(2)]
    have = types.SimpleNamespace(scene_hash="h", order=1, green=None, case_index=cases,
                                 synthetic=np.flatnonzero(cases >= linear_fields.SYNTHETIC_FIRST))
    monkeypatch.setattr(linear_fields, "read_dataset_linear", lambda d: have)
    monkeypatch.setattr(data_spec, "load_scene",
                        lambda s: types.SimpleNamespace(hash="h", n_simulations=4))
    runs = []
    monkeypatch.setattr(chunked.subprocess, "run", lambda cmd, **kw: runs.append(cmd))

    def kept(**kw) -> bool:
        return chunked.linear_bases(data, scene="s.toml", **kw) is None

    assert kept(order=1, synthetic=2) and kept(order=1) and not runs
    assert not kept(order=2) and runs[-1][runs[-1].index("--order") + 1] == "2"
    assert not kept(order=1, green=True) and "--green" in runs[-1]
    assert not kept(order=1, synthetic=3)
    assert runs[-1][runs[-1].index("--synthetic") + 1] == "3" and "--green" not in runs[-1]
    have.scene_hash = "another"
    assert not kept(order=1)
    have.scene_hash, have.order, have.green = "h", 2, np.zeros(1)
    assert kept(order=1, green=True, synthetic=1) and len(runs) == 4
    monkeypatch.setattr(data_spec, "load_scene",   # the scene grew: 5 simulations
                        lambda s: types.SimpleNamespace(hash="h", n_simulations=5))
    assert not kept(order=1)


def test_a_generation_rate_counts_the_preparation_once_for_the_whole_scene():
    """rate_figures by hand: 100 s on 2 ranks for simulations of 10, 20 and 30 s leave
    200 - 60 = 140 core-seconds of preparation; a 10-simulation scene then takes 140 + 10 x 20
    core-seconds, 3600 x 10 x 2 / 340 = 211.8 an hour, and the ranks alone 3600 x 2 / 20."""
    r = chunked.rate_figures(100.0, [10.0, 20.0, 30.0], 3, 10, 2)
    assert r["prepare_min"] == 140.0 / 2 / 60 and r["sim_s_median"] == 20.0
    assert abs(r["scene_per_hour"] - 72000.0 / 340.0) < 1e-9 and r["sims_per_hour"] == 360.0
    assert (r["sims"], r["ok"], r["scene_sims"]) == (3, 3, 10)
    # a run whose simulations took more core-seconds than its wall time had no preparation
    assert chunked.rate_figures(10.0, [15.0, 15.0], 2, 4, 2)["prepare_min"] == 0.0
