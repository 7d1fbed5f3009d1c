"""surrogate.make_liver.timed_steps: a command of several steps timed as its user waits for it
(bench/surgical_loads.py --ready and bench/scene4_real.py time ``make liver`` with it)."""

import shutil

import pytest

from surrogate.make_liver import timed_steps


def test_each_step_runs_from_its_first_line_to_the_next_steps_and_a_failure_is_said():
    if shutil.which("bash") is None:
        pytest.skip("no bash here")
    script = "sleep 0.1; echo run first; sleep 0.4; echo run second; echo again second; sleep 0.2"
    t = timed_steps(["bash", "-c", script], {"one": "first", "two": "second"})
    assert t["ok"] and t["why"] == "" and list(t["steps"]) == ["checks", "one", "two"]
    assert 0.05 < t["steps"]["checks"] < t["steps"]["one"]
    assert 0.35 < t["steps"]["one"] < 5.0 and 0.15 < t["steps"]["two"] < 5.0
    assert sum(t["steps"].values()) == pytest.approx(t["seconds"])
    bad = timed_steps(["bash", "-c", "echo run first; echo broken >&2; exit 3"], {"one": "first"})
    assert not bad["ok"] and "broken" in bad["why"]
