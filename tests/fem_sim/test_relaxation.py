"""The hot-spot relaxation (fem_sim/solver/relaxation.py): it lowers a concentrated residual
without touching the rest of the body, and the converged answer does not depend on it."""

import numpy as np
import pytest
from mpi4py import MPI

from fem_sim import Constraint, NodalLoad, OgdenMaterial, OgdenProblem
from fem_sim.geometry.phantom import make_phantom
from fem_sim.solver.relaxation import LocalRelaxation

SOFT = OgdenMaterial((2e-3,), (6.0,), 0.2)  # scene 3's softest material, K = 100 c1


def _case(h=12.0):
    g = make_phantom(0, h)
    fixed = g.regions["vena_cava"]
    surf = np.setdiff1d(g.surface_nodes, fixed)
    d = np.linalg.norm(g.points[surf][:, None] - g.points[fixed][None], axis=2).min(axis=1)
    return g, fixed, int(surf[np.argmax(d)])


@pytest.fixture(scope="module")
def case(compiled):
    compiled("tet")
    if MPI.COMM_WORLD.size > 1:
        pytest.skip("the relaxation runs with the serial C assembly")
    return _case()


@pytest.mark.parametrize("degree", [1, 2])
def test_relaxation_removes_a_local_residual_and_leaves_the_rest(case, degree):
    """From the converged state, a 0.3 mm bump pushed into the neighbourhood of the loaded
    node makes a residual concentrated there; one relaxation must bring |R| down at least 20x
    while the dofs outside the hot spot keep their values exactly."""
    g, fixed, node = case
    prob = OgdenProblem(MPI.COMM_WORLD, g.points, g.cells, degree=degree)
    force = np.array([0.0, 0.0, -0.1])
    sol = prob.solve(SOFT, [Constraint(fixed)], [NodalLoad([node], [force])], [0.5, 1.0])
    assert sol.status == "ok", sol.failure_reason
    eqs = prob.equations
    X = prob.disc.V.tabulate_dof_coordinates()
    r_node = np.linalg.norm(X - g.points[node], axis=1)
    u = eqs.state().reshape(-1, 3)
    u[:, 2] += 0.3 * np.exp(-(r_node / 6.0) ** 2)  # 0.3 mm bump, 6 mm wide
    eqs.set_state(u.ravel())
    assert eqs.update_points()
    r0 = eqs.residual(1.0)
    before = eqs.state()
    relax = LocalRelaxation(eqs, rings=2, max_nodes=1000)
    region = relax.region()
    assert region is not None and region.size <= 1000
    assert relax.relax(1.0, tol=1e-12) > 0
    assert eqs.update_points()
    r1 = eqs.residual(1.0)
    assert r1 < r0 / 20, (r0, r1)
    moved = np.flatnonzero(np.abs(eqs.state() - before) > 0) // 3
    assert moved.size and np.isin(moved, region).all()
    assert not np.isin(eqs.cons.owned, np.flatnonzero(eqs.state() != before)).any()


def test_converged_answer_does_not_depend_on_the_relaxation(case):
    """Soft material and a point load: the relaxation runs (local iterations > 0) and both
    runs agree to well within the Newton tolerance's reach."""
    g, fixed, node = case
    out = []
    for relax in (False, True):
        prob = OgdenProblem(MPI.COMM_WORLD, g.points, g.cells,
                            settings={"local_relaxation": relax, "rtol": 1e-10})
        sol = prob.solve(SOFT, [Constraint(fixed)], [NodalLoad([node], [[0.0, 0.0, -0.4]])],
                         np.linspace(0.1, 1.0, 10))
        assert sol.status == "ok", sol.failure_reason
        out.append(sol)
    assert out[0].local_iterations == 0 and out[1].local_iterations > 0
    u0, u1 = out[0].displacement, out[1].displacement
    assert np.abs(u0).max() > 20.0  # a large deformation
    assert np.abs(u1 - u0).max() <= 1e-6 * np.abs(u0).max()
