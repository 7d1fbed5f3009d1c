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
