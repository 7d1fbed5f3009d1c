"""surrogate.make_liver, what make liver runs: its steps' commands, and a failing step that
stops the rest with its own message and exit code."""

from pathlib import Path

import pytest

from data_spec.scene import GRASP_RADIUS
from surrogate.make_liver import _parser, _steps, load_points, main

ROOT = Path(__file__).resolve().parents[2]
SOLVER = ROOT / ".venv-solver" / "bin" / "python"
SCENE = ROOT / "data_spec" / "scenes" / "scene4_livers.toml"


def test_each_loads_point_is_where_the_greens_function_is_computed(tmp_path):
    assert load_points([1, 2, 3, 0, 0, 20, 4, 5, 6, 1, 1, 1]) == [1, 2, 3, 4, 5, 6]
    for bad in ([], [1, 2, 3, 0, 0]):
        with pytest.raises(ValueError, match="per load"):
            load_points(bad)
    a = _parser().parse_args(["RUN", "liver.obj", "--scene", "s.toml", "--dir", str(tmp_path),
                              "--solver", "py", "--grasp", "1 -2 3e-1 0 0 -20", "--frame",
                              "RAS"])
    steps = {name: (where, [str(w) for w in words]) for name, where, words in _steps(a, tmp_path)}
    assert [k for k in steps] == ["mesh", "place", "green", "predict"]
    assert steps["green"][0] == "solver" and steps["place"][0] == "trainer"
    green = steps["green"][1]
    assert [float(v) for v in green[green.index("--green-near") + 1].split()] == [1, -2, 0.3]
    assert float(green[green.index("--green-radius") + 1]) == GRASP_RADIUS   # the patch
    a.grasp, a.force = None, "1 2 3 0 0 -0.4"
    green = next(w for n, _, w in _steps(a, tmp_path) if n == "green")
    assert float(green[green.index("--green-radius") + 1]) == 0.0   # the force's node alone
    predict = steps["predict"][1]
    assert predict[predict.index("--grasp") + 1:][:6] == ["1", "-2", "3e-1", "0", "0", "-20"]
    assert "--frame" in predict and "--frame" in steps["place"][1]


def test_a_load_of_the_wrong_length_is_refused_before_any_step(tmp_path, capsys):
    assert main(["RUN", "liver.obj", "--scene", str(SCENE), "--dir", str(tmp_path / "d"),
                 "--solver", str(SOLVER), "--force", "1 2 3 0 0"]) == 2
    assert "AT" in capsys.readouterr().err and not (tmp_path / "d").exists()


def test_a_solver_that_cannot_start_is_said_before_any_step(tmp_path, capsys):
    assert main(["RUN", "liver.obj", "--scene", str(SCENE), "--dir", str(tmp_path / "d"),
                 "--solver", str(tmp_path / "no-python"), "--grasp", "1 2 3 0 0 20"]) == 2
    assert "--solver" in capsys.readouterr().err


def test_a_failing_step_stops_the_rest_with_its_message(tmp_path, capfd):
    """A liver file that cannot be meshed: the solver's message and exit code, no scene."""
    if not SOLVER.exists():
        pytest.skip("the solver environment is not set up (make setup)")
    bad = tmp_path / "liver.obj"
    bad.write_text("v 0 0 0\n")
    rc = main([str(ROOT / "models" / "scene4_grasp"), str(bad), "--scene", str(SCENE),
               "--dir", str(tmp_path / "d"), "--solver", str(SOLVER), "--grasp",
               "0 0 0 0 0 20"])
    err = capfd.readouterr().err
    assert rc == 2 and "meshing" not in err and "mesh failed" in err and "liver.obj" in err
    assert not (tmp_path / "d" / "scene.toml").exists()
