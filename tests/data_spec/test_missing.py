"""A dataset with a simulation deleted is not valid: validation compares the shards with the
scene's n_simulations and the XDMF files with their shards, names the missing index and the
command that makes it; the trainer says so before training on the rest."""

from data_spec import validate_dataset
from data_spec.__main__ import main as spec_main
from tests.fixtures import synthetic_dataset


def test_a_deleted_simulation_is_named_with_the_command_that_makes_it(tmp_path, capsys):
    d = synthetic_dataset(tmp_path / "d", n_sims=12)
    assert validate_dataset(d) == []
    for p in (d / "sims").glob("sim_000007.*"):  # the shard and its XDMF file
        p.unlink()
    problems = validate_dataset(d)
    assert len(problems) == 1, problems
    assert "1 of the scene's 12 simulations have no shard (simulation 7)" in problems[0]
    assert f"fem_sim generate {d}/scene.toml --out {d}" in problems[0]
    assert spec_main(["validate", str(d)]) != 0
    assert "simulation 7" in capsys.readouterr().err


def test_an_xdmf_file_without_its_shard_is_reported(tmp_path):
    d = synthetic_dataset(tmp_path / "d", n_sims=4)
    (d / "sims" / "sim_000002.h5").unlink()
    problems = validate_dataset(d)
    assert any("sim_000002.xdmf: an XDMF file without its shard" in p for p in problems)
    assert any("(simulation 2)" in p for p in problems)
