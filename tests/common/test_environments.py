"""Each command says which environment runs it when started in the other one (the solver's
has no JAX, the trainer's no dolfinx or gmsh), instead of a ModuleNotFoundError traceback;
the check runs before any argument is used."""

import importlib.util

import pytest

from fem_sim.__main__ import main as sim_main
from surrogate.__main__ import main as surrogate_main

HAS_JAX = importlib.util.find_spec("jax") is not None
HAS_DOLFINX = importlib.util.find_spec("dolfinx") is not None


@pytest.mark.skipif(HAS_JAX, reason="the trainer environment runs these commands")
@pytest.mark.parametrize("argv", [["train", "--data", "d", "--run", "r"],
                                  ["evaluate", "run", "data"],
                                  ["predict-liver", "run", "liver.stl"]])
def test_trainer_commands_in_the_solver_environment_name_theirs(argv, capsys):
    assert surrogate_main(argv) == 2
    err = capsys.readouterr().err
    assert f"liverfem-surrogate {argv[0]}: JAX is not importable" in err
    assert "runs in the trainer environment (.venv-train/bin/python -m surrogate" in err


@pytest.mark.skipif(HAS_DOLFINX, reason="the solver environment runs these commands")
@pytest.mark.parametrize("argv", [["generate", "scene.toml", "--out", "d"],
                                  ["phantom", "1", "--out", "l.h5"]])
def test_solver_commands_in_the_trainer_environment_name_theirs(argv, capsys):
    assert sim_main(argv) == 2
    err = capsys.readouterr().err
    assert f"liverfem-sim {argv[0]}:" in err and "is not importable" in err
    assert "runs in the solver environment (.venv-solver/bin/python -m fem_sim" in err
