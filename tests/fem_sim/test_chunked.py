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
