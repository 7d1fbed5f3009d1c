"""The README's solver example is demos/solver_api.py, run here serially and under
``mpirun -n 2`` (the dolfinx demos' habit), so the manual cannot rot: both runs succeed and
give the same displacement."""

import re
import subprocess
import sys
from pathlib import Path

import pytest

from fem_sim.batch.chunked import mpirun_env

ROOT = Path(__file__).parents[2]
ENV = mpirun_env()


def run(*prefix) -> str:
    out = subprocess.run([*prefix, sys.executable, str(ROOT / "demos" / "solver_api.py")],
                         env=ENV, capture_output=True, text=True, timeout=600)
    assert out.returncode == 0, out.stderr[-2000:]
    return out.stdout


@pytest.mark.mpi
def test_the_solver_demo_runs_serially_and_on_two_ranks_with_one_answer():
    serial, parallel = run(), run("mpirun", "-n", "2")
    pattern = r"(\d) rank\(s\): (\d+) nodes, max \|u\| ([\d.]+) mm"
    (r1, n1, u1), (r2, n2, u2) = (re.search(pattern, s).groups() for s in (serial, parallel))
    assert (r1, r2) == ("1", "2") and n1 == n2
    assert float(u1) == pytest.approx(float(u2), abs=0.011)  # printed to 0.01 mm
