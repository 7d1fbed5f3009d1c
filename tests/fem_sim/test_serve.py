"""python -m fem_sim serve: fem_sim's commands read as JSON lines, one answer a line, the
standard output holding the answers only (what surrogate.make_liver reads)."""

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[2]
TINY = ROOT / "data_spec" / "scenes" / "tiny_scene1.toml"

pytest.importorskip("dolfinx", reason="fem_sim serve runs in the solver environment")


def test_serve_runs_commands_in_one_process_and_answers_each_line(tmp_path):
    """A Green's function near a point, a command of bad flags, a line that is not a list of
    words, a blank line (no answer), then the same command at radius 0 (the nearest node's
    responses alone): each answered in order with the command's exit code; the commands' own
    prints reach the standard error only."""
    from data_spec.linear_fields import linear_fields_path, read_linear_fields

    near = ["linear", str(TINY), "--out", str(tmp_path / "d"), "--green", "--green-near",
            "0 0 60"]
    lines = [json.dumps(near), json.dumps(["linear", "--bogus"]), "not json", "",
             json.dumps({"do": "mesh"}), json.dumps(["serve"]),
             json.dumps(near + ["--green-radius", "0"])]
    proc = subprocess.run([sys.executable, "-m", "fem_sim", "serve"], input="\n".join(lines),
                          capture_output=True, text=True, timeout=600, cwd=ROOT)
    assert proc.returncode == 0, proc.stderr[-2000:]
    answers = [json.loads(line) for line in proc.stdout.splitlines()]
    assert [a["rc"] for a in answers] == [0, 2, 2, 2, 2, 0]
    assert "not JSON" in answers[2]["error"] and "list of words" in answers[3]["error"]
    assert "small-strain responses" in proc.stderr and "--bogus" in proc.stderr
    lf = read_linear_fields(linear_fields_path(tmp_path / "d"))
    assert lf.green_nodes.size == 1 and lf.fixed_nodes.size > 0
    assert np.all(np.isfinite(lf.green))


def test_a_prepared_liver_problem_is_the_one_linear_uses(tmp_path):
    """``prepare MESH SCENE`` (make liver's, while the model is placed) builds the problem a
    later ``linear`` of a scene on that mesh uses (the same object: the mesh file's nodes and
    cells are the scene's, byte for byte), and its answers are those of a problem built anew;
    through serve, prepare and then linear are answered in order."""
    from data_spec.linear_fields import linear_fields_path, read_linear_fields
    from data_spec.shards import geometry_path
    from fem_sim.batch import linear

    near = {"green": True, "near": [0.0, 0.0, 60.0]}
    linear.linear_fields(TINY, tmp_path / "a", **near)
    first = read_linear_fields(linear_fields_path(tmp_path / "a"))
    mesh = geometry_path(tmp_path / "a", first.geometry_id)
    linear._PREPARED.clear()
    linear.prepare(mesh, TINY)
    built = linear._PREPARED["problem"]
    linear.linear_fields(TINY, tmp_path / "b", **near)
    assert linear._PREPARED["problem"] is built
    again = read_linear_fields(linear_fields_path(tmp_path / "b"))
    np.testing.assert_allclose(again.green, first.green, rtol=1e-10, atol=1e-14)
    np.testing.assert_allclose(again.displacement, first.displacement, rtol=1e-10, atol=1e-14)
    lines = [json.dumps(["prepare", str(mesh), str(TINY)]), json.dumps(["prepare", str(mesh)]),
             json.dumps(["linear", str(TINY), "--out", str(tmp_path / "c"), "--green",
                         "--green-near", "0 0 60"])]
    proc = subprocess.run([sys.executable, "-m", "fem_sim", "serve"], input="\n".join(lines),
                          capture_output=True, text=True, timeout=600, cwd=ROOT)
    assert [json.loads(a)["rc"] for a in proc.stdout.splitlines()] == [0, 2, 0]
    assert "expected prepare MESH SCENE" in proc.stderr
