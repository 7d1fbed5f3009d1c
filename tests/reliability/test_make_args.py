"""Issue 81: ``make patient K=-1`` / ``K=abc`` and ``make liver AT="1 2 3"`` were refused only
by their last step, after minutes of FE work (the Makefile's arithmetic turned a bad K into
``--sims 1``). Their variables are checked first, each named with what it takes."""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).parents[2]
LIVER = ROOT.parent / "shared" / "data" / "livers" / "real" / "Amos-004.obj"


@pytest.fixture
def run(tmp_path):
    """A directory that looks like a trained run (its model/model.json)."""
    (tmp_path / "run" / "model").mkdir(parents=True)
    (tmp_path / "run" / "model" / "model.json").write_text("{}")
    return tmp_path / "run"


def _make(*args):
    if shutil.which("make") is None:
        pytest.skip("no make here")
    return subprocess.run(["make", "--no-print-directory", "-C", str(ROOT), *args],
                          capture_output=True, text=True, timeout=60)


@pytest.mark.parametrize("k", ["-1", "abc", "1.5"])
def test_make_patient_refuses_a_bad_k_before_any_work(run, k):
    proc = _make("patient", f"LIVER={LIVER}", f"MODEL={run}", f"K={k}")
    assert proc.returncode == 2
    assert f"make patient: K='{k}': expected a whole number >= 0" in proc.stderr
    assert "truth-scene" not in proc.stdout + proc.stderr   # no step ran


def test_make_liver_refuses_a_bad_at_and_names_every_wrong_variable(run, tmp_path):
    proc = _make("liver", f"LIVER={tmp_path / 'none.obj'}", f"MODEL={tmp_path}", "AT=1 2 3")
    assert proc.returncode == 2
    for said in ("LIVER=", "no such file", "MODEL=", "no model/model.json",
                 "AT='1 2 3': expected six finite numbers"):
        assert said in proc.stderr
    assert "truth-scene" not in proc.stdout + proc.stderr


def test_right_variables_pass_the_check():
    import importlib.util

    spec = importlib.util.spec_from_file_location("make_args", ROOT / "scripts" / "make_args.py")
    make_args = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(make_args)
    scene = str(ROOT / "data_spec" / "scenes" / "scene4_livers.toml")
    model = str(ROOT / "tests")   # not a run
    assert make_args.problems("liver", {"LIVER": str(LIVER), "MODEL": model, "PSCENE": scene,
                                        "AT": "1 2 3 0 0 -0.4"}) == [
        f"make liver: MODEL={model!r}: not a trained run: no model/model.json in it (surrogate "
        "train writes one)"]
    grasp = make_args.problems("liver", {"LIVER": str(LIVER), "MODEL": model, "PSCENE": scene,
                                         "GRASP": "1 2 3 0 0 20"})
    assert len(grasp) == 1 and "MODEL=" in grasp[0]   # a grasp instead of a force is right
    both = make_args.problems("liver", {"LIVER": str(LIVER), "PSCENE": scene,
                                        "AT": "1 2 3 0 0 -0.4", "GRASP": "1 2 nan 0 0 20"})
    assert "make liver: give one of AT or GRASP, not 2" in both
    assert any(p.startswith("make liver: GRASP='1 2 nan 0 0 20': expected six finite numbers")
               and "displacement in mm" in p for p in both)
    assert "make liver: give one of AT or GRASP" in make_args.problems("liver", {})
    assert make_args.problems("patient", {"LIVER": str(LIVER), "MODEL": model, "PSCENE": scene,
                                          "K": "0", "HELD": "6", "SYNTHETIC": "600",
                                          "ORDER": "2", "GREEN": "1", "FRAME": "auto"})[1:] == []


def test_make_liver_takes_the_shipped_models_when_no_model_is_given(tmp_path):
    """No MODEL: a grasp runs its steps on models/scene4_grasp, a force on
    models/scene4_forces (make -n: the commands, not run); a MODEL that is no trained run is
    still refused before any work."""
    grasp = _make("-n", "liver", f"LIVER={LIVER}", "GRASP=1 2 3 0 0 20")
    assert grasp.returncode == 0, grasp.stderr
    assert "surrogate.make_liver models/scene4_grasp" in grasp.stdout
    assert '--grasp "1 2 3 0 0 20"' in grasp.stdout
    force = _make("-n", "liver", f"LIVER={LIVER}", "AT=1 2 3 0 0 -0.4")
    assert force.returncode == 0, force.stderr
    assert "surrogate.make_liver models/scene4_forces" in force.stdout
    assert '--force "1 2 3 0 0 -0.4"' in force.stdout
    bad = _make("liver", f"LIVER={LIVER}", f"MODEL={tmp_path}", "AT=1 2 3 0 0 -0.4")
    assert bad.returncode == 2 and "not a trained run" in bad.stderr
    assert "surrogate.make_liver" not in bad.stdout + bad.stderr   # refused before any work


def test_make_patient_of_grasps_takes_the_shipped_model_and_the_site():
    """LOAD=grasp with no MODEL: the shipped model of grasps on scene4_grasp's rule, its
    grasps drawn around SITE, the liver's Green's function for grasps (make -n: the commands,
    not run); a SITE that is not a point, or another LOAD, is refused before any work."""
    proc = _make("-n", "patient", "LOAD=grasp", f"LIVER={LIVER}", "K=6", "SITE=1 2 3")
    assert proc.returncode == 0, proc.stderr
    for said in ("truth-scene models/scene4_grasp", "scene4_grasp.toml", "--near 1 2 3",
                 "--green --order 1", "surrogate adapt models/scene4_grasp"):
        assert said in " ".join(proc.stdout.split()), said
    for bad, why in (("SITE=1 2", "SITE='1 2': expected three finite numbers"),
                     ("LOAD=pull", "LOAD='pull': expected one of"),
                     ("MODEL=models/scene4_forces", "learned forces, LOAD='grasp' adapts a "
                                                    "model of grasps")):
        proc = _make("patient", "LOAD=grasp", f"LIVER={LIVER}", bad)
        assert proc.returncode == 2 and why in proc.stderr, proc.stderr
        assert "truth-scene" not in proc.stdout + proc.stderr
