"""Extremes: 5x the nominal force on the softest material of scene 3's range, near-fixed loads,
K/mu = 1000. Each either converges (cut-backs allowed) or fails cleanly with a reason and its
converged steps; never NaN."""

import numpy as np
import pytest
from mpi4py import MPI

from fem_sim import Constraint, NodalLoad, OgdenMaterial, OgdenProblem
from fem_sim.phantom import make_phantom


@pytest.fixture(scope="module")
def liver():
    return make_phantom(0, 20.0)


def _check_clean(sol, n_steps):
    assert sol.status in ("ok", "failed")
    assert np.isfinite(sol.displacement).all()
    assert sol.displacement.shape[0] == sol.n_done
    if sol.status == "ok":
        assert sol.n_done == n_steps
    else:
        assert sol.failure_reason and sol.n_done < n_steps


@pytest.mark.parametrize("m", [6.0, 14.0])
def test_five_times_force_on_softest_material(liver, m):
    soft = OgdenMaterial((2.0e-3,), (m,), 200 * 1.0e-3)  # c1 = 2e-3 MPa: scene 3's minimum
    prob = OgdenProblem(MPI.COMM_WORLD, liver.points, liver.cells)
    tip = int(np.argmax(liver.points[:, 0]))
    fr = np.linspace(0.1, 1.0, 10)
    sol = prob.solve(soft, [Constraint(liver.regions["vena_cava"])],
                     [NodalLoad([tip], [[0.0, 0.0, -2.0]])], fr)
    _check_clean(sol, fr.size)


def test_force_next_to_the_fixed_region_and_high_bulk_ratio(liver):
    fixed = liver.regions["vena_cava"]
    surf = np.setdiff1d(liver.surface_nodes, fixed)
    d = np.linalg.norm(liver.points[surf][:, None] - liver.points[fixed][None], axis=2).min(1)
    near = int(surf[np.argmin(d)])
    mat = OgdenMaterial((4.1e-3,), (10.06,), 1000 * 4.1e-3 / 2)  # K/mu = 1000
    prob = OgdenProblem(MPI.COMM_WORLD, liver.points, liver.cells)
    fr = np.linspace(0.1, 1.0, 10)
    sol = prob.solve(mat, [Constraint(fixed)], [NodalLoad([near], [[0.0, 0.0, 2.0]])], fr)
    _check_clean(sol, fr.size)
